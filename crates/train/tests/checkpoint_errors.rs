//! Bad checkpoints and configs give errors that name the file and the problem.

mod common;

use train::{checkpoint, TrainConfig, Trainer};

fn saved_run() -> (tempfile::TempDir, std::path::PathBuf) {
    let tr = Trainer::new(common::small_config(50), common::dataset(), 1).unwrap();
    let run = tempfile::tempdir().unwrap();
    let dir = checkpoint::save(&tr, run.path()).unwrap();
    (run, dir)
}

/// Rewrites `checksums.json` to match the files as they are now, as if the damage below
/// had been written that way: it then reaches the loader's own checks.
fn unverified(dir: &std::path::Path) {
    let p = dir.join(train::integrity::CHECKSUMS_NAME);
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    let files = v["files"].as_object_mut().unwrap();
    for (name, crc) in files.iter_mut() {
        *crc = train::integrity::crc_hex(&std::fs::read(dir.join(name)).unwrap()).into();
    }
    v["tensors"] = serde_json::json!({});
    std::fs::write(&p, v.to_string()).unwrap();
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
    let field = |t: &train::Trainer| {
        let node = t.nodes.get::<train::field_node::FieldNode>().unwrap();
        node.field.mlp.params.clone()
    };
    assert_eq!(field(&tr), field(&orig));
}

#[test]
fn garbage_state_file_is_a_clear_error() {
    let (_run, dir) = saved_run();
    std::fs::write(dir.join(checkpoint::STATE_NAME), b"not safetensors").unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("state.safetensors") && e.contains("no longer parses"),
        "{e}"
    );
    unverified(&dir);
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
        e.contains("field.params") && e.contains("fails its checksum"),
        "{e}"
    );
    unverified(&dir);
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
    unverified(&dir);
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
    assert!(e.contains("outside the tensors"), "{e}");
    unverified(&dir);
    let e = load_error(&dir);
    assert!(
        e.contains("aux.reg.gone") && e.contains("state.safetensors"),
        "{e}"
    );
}

/// Flips one bit at byte `at` of `path`.
fn flip(path: &std::path::Path, at: usize) {
    let mut b = std::fs::read(path).unwrap();
    b[at] ^= 0x04;
    std::fs::write(path, b).unwrap();
}

/// The byte range of tensor `name`'s data in a safetensors file.
fn tensor_range(bytes: &[u8], name: &str) -> std::ops::Range<usize> {
    let hlen = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + hlen]).unwrap();
    let offs = &header[name]["data_offsets"];
    let (a, b) = (offs[0].as_u64().unwrap(), offs[1].as_u64().unwrap());
    8 + hlen + a as usize..8 + hlen + b as usize
}

/// A flipped bit inside an Adam moment leaves a finite number that nothing else would
/// notice: the checksum refuses it and names the tensor, for resume and for eval/render.
#[test]
fn a_flipped_bit_in_any_tensor_is_refused_with_file_and_tensor_named() {
    let (_run, dir) = saved_run();
    let p = dir.join(checkpoint::STATE_NAME);
    let bytes = std::fs::read(&p).unwrap();
    for name in ["adam.means.m", "stats.denom", "rng.seed", "field.params"] {
        let r = tensor_range(&bytes, name);
        std::fs::write(&p, &bytes).unwrap();
        flip(&p, r.start + (r.end - r.start) / 2);
        let e = load_error(&dir);
        assert!(
            e.contains("state.safetensors")
                && e.contains(&format!("tensor `{name}` fails its checksum")),
            "{name}: {e}"
        );
        let e = checkpoint::load_model(&dir)
            .err()
            .expect("eval refuses too")
            .to_string();
        assert!(e.contains(name), "{e}");
    }
    std::fs::write(&p, &bytes).unwrap();
    assert!(checkpoint::load_trainer(&dir, common::dataset()).is_ok());

    // The PLY: the last vertex's last float is `rot_3` (3DGS property order).
    let ply = dir.join(checkpoint::PLY_NAME);
    let len = std::fs::metadata(&ply).unwrap().len() as usize;
    flip(&ply, len - 2);
    let e = load_error(&dir);
    assert!(
        e.contains("point_cloud.ply") && e.contains("tensor `quats` fails its checksum"),
        "{e}"
    );
}

#[test]
fn a_changed_config_or_checksum_file_is_refused() {
    let (_run, dir) = saved_run();
    let cfg = dir.join(checkpoint::CONFIG_NAME);
    let text = std::fs::read_to_string(&cfg).unwrap();
    std::fs::write(&cfg, text.replacen("iterations = 50", "iterations = 51", 1)).unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("config.toml") && e.contains("fails its checksum"),
        "{e}"
    );
    std::fs::write(&cfg, &text).unwrap();
    let sums = dir.join(train::integrity::CHECKSUMS_NAME);
    std::fs::write(&sums, "{not json").unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("checksums.json") && e.contains("not readable"),
        "{e}"
    );
}

/// A folder without `checksums.json` is an incomplete save, unless its state says it was
/// written before checksums existed (format `semdynreg-train-1`): that one still loads.
#[test]
fn missing_checksums_refuse_new_checkpoints_and_admit_old_ones() {
    let (_run, dir) = saved_run();
    std::fs::remove_file(dir.join(train::integrity::CHECKSUMS_NAME)).unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("lacks checksums.json") && e.contains("incomplete"),
        "{e}"
    );
    let p = dir.join(checkpoint::STATE_NAME);
    let bytes = std::fs::read(&p).unwrap();
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let mut meta = meta.metadata().clone().unwrap();
    assert_eq!(meta["format"], "semdynreg-train-2");
    meta.insert("format".into(), "semdynreg-train-1".into());
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    std::fs::write(
        &p,
        safetensors::serialize(st.tensors(), Some(meta)).unwrap(),
    )
    .unwrap();
    assert!(checkpoint::load_trainer(&dir, common::dataset()).is_ok());
}
