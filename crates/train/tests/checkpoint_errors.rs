//! Bad checkpoints and configs give errors that name the file and the problem.

mod common;

use train::{checkpoint, TrainConfig, Trainer};

fn saved_run() -> (tempfile::TempDir, std::path::PathBuf) {
    let tr = Trainer::new(common::small_config(50), common::dataset(), 1).unwrap();
    let run = tempfile::tempdir().unwrap();
    let dir = checkpoint::save(&tr, run.path()).unwrap();
    (run, dir)
}

/// The message of loading the trainer from a checkpoint that must fail.
fn load_error(dir: &std::path::Path) -> String {
    checkpoint::load_trainer(dir, common::dataset())
        .err()
        .expect("loading should fail")
        .to_string()
}

#[test]
fn fresh_checkpoint_roundtrips() {
    let (_run, dir) = saved_run();
    let tr = checkpoint::load_trainer(&dir, common::dataset()).unwrap();
    let orig = Trainer::new(common::small_config(50), common::dataset(), 1).unwrap();
    assert_eq!(tr.state, orig.state);
    assert_eq!(tr.field.mlp.params, orig.field.mlp.params);
}

#[test]
fn garbage_state_file_is_a_clear_error() {
    let (_run, dir) = saved_run();
    std::fs::write(dir.join(checkpoint::STATE_NAME), b"not safetensors").unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("state.safetensors") && e.contains("not a readable safetensors"),
        "{e}"
    );
}

#[test]
fn nan_weights_are_rejected() {
    let (_run, dir) = saved_run();
    let p = dir.join(checkpoint::STATE_NAME);
    let mut bytes = std::fs::read(&p).unwrap();
    // The data section starts after the 8-byte header length and the JSON header;
    // field.params is the first tensor written, so its first f32 is at the data start.
    let hlen = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header = String::from_utf8(bytes[8..8 + hlen].to_vec()).unwrap();
    let entry = &header[header.find("\"field.params\"").unwrap()..];
    let offs = &entry[entry.find("data_offsets").unwrap()..];
    let start: usize = offs[offs.find('[').unwrap() + 1..offs.find(',').unwrap()]
        .trim()
        .parse()
        .unwrap();
    let at = 8 + hlen + start;
    bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&p, bytes).unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("field.params") && e.contains("non-finite"),
        "{e}"
    );
}

#[test]
fn missing_and_truncated_files_are_clear_errors() {
    let (run, dir) = saved_run();
    let ply = dir.join(checkpoint::PLY_NAME);
    let b = std::fs::read(&ply).unwrap();
    std::fs::write(&ply, &b[..b.len() / 2]).unwrap();
    let e = checkpoint::load_model(&dir).err().unwrap().to_string();
    assert!(
        e.contains("point_cloud.ply") && e.contains("truncated"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
    let e = checkpoint::latest(run.path()).err().unwrap().to_string();
    assert!(e.contains("does not exist"), "{e}");
    let e = checkpoint::latest(&run.path().join("nowhere"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("nowhere"), "{e}");
}

#[test]
fn bad_config_files_name_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.toml");
    std::fs::write(&p, "[lr]\nopacity = -0.5\n").unwrap();
    let e = TrainConfig::from_toml_file(&p).unwrap_err().to_string();
    assert!(e.contains("lr.opacity") && e.contains("c.toml"), "{e}");
    std::fs::write(&p, "[densify]\ngrad_treshold = 1e-4\n").unwrap();
    let e = TrainConfig::from_toml_file(&p).unwrap_err().to_string();
    assert!(e.contains("c.toml") && e.contains("grad_treshold"), "{e}");
    std::fs::write(&p, "iterations = \"many\"\n").unwrap();
    assert!(TrainConfig::from_toml_file(&p)
        .unwrap_err()
        .to_string()
        .contains("c.toml"));
    let e = TrainConfig::from_toml_file(&dir.path().join("absent.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("absent.toml"), "{e}");
}

/// Hook rows round-trip; a checkpoint that lists rows it does not hold names them.
#[test]
fn hook_rows_roundtrip_and_missing_rows_are_named() {
    let mut tr = Trainer::new(common::small_config(50), common::dataset(), 1).unwrap();
    let n = tr.state.len();
    tr.state.aux.push(train::state::AuxRows {
        name: "reg.test".into(),
        cols: 2,
        data: (0..2 * n).map(|i| i as f32 * 0.5).collect(),
    });
    let run = tempfile::tempdir().unwrap();
    let dir = checkpoint::save(&tr, run.path()).unwrap();
    let back = checkpoint::load_trainer(&dir, common::dataset()).unwrap();
    assert_eq!(back.state.aux, tr.state.aux);

    // Rewrite the state file with metadata that lists a second, absent set of rows.
    let p = dir.join(checkpoint::STATE_NAME);
    let bytes = std::fs::read(&p).unwrap();
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let mut meta = meta.metadata().clone().unwrap();
    meta.insert("aux".into(), "reg.test,reg.gone".into());
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let views: Vec<(String, safetensors::tensor::TensorView)> = st.tensors();
    std::fs::write(&p, safetensors::serialize(views, Some(meta)).unwrap()).unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("aux.reg.gone") && e.contains("state.safetensors"),
        "{e}"
    );
}
