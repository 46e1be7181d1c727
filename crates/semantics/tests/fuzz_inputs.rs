//! Seeded mutation fuzzing of the weight files `semantics` reads
//! (docs/robustness.md): SAM checkpoints (`.pt`: a PyTorch zip holding a pickle and raw
//! storages; and safetensors), CLIP safetensors in the OpenCLIP and Hugging Face layouts
//! (with a mutated config JSON beside them, or none, when the shapes are inferred), CLIP
//! PyTorch pickles.
//!
//! The `.pt` seed is written here: a stored zip with `archive/data.pkl` (protocol-2 pickle
//! of a state dict, as `torch.save` writes it, including `_rebuild_parameter` and
//! `_rebuild_from_type_v2` wrappers), `archive/data/N` storages and `archive/version`, with
//! the first MobileSAM keys, so that the backbone is detected and loading proceeds to the
//! first missing tensor. The CLIP seeds are the tiny random models of tests/fixtures/clip.
//!
//! Property per case (scene/tests/fuzz_common): no panic, no hang, no allocation above the
//! limit, an error that names the file.
//!
//! CI: `cargo test -p semantics --test fuzz_inputs`. Long run (20× the CI counts, or
//! `FUZZ_CASES` per format; `FUZZ_SEED` for another stream):
//!
//! ```text
//! cargo test -p semantics --test fuzz_inputs -- --ignored --nocapture
//! ```

#[macro_use]
#[path = "../../scene/tests/fuzz_common/mod.rs"]
mod fuzz_common;

use fuzz_common::{
    apply, apply_safetensors, check_load, finish, mutations, runner, stored_zip, Kind, Mutation,
    Tally,
};
use proptest::prelude::*;
use semantics::clip::{ClipModel, LoadOptions};
use semantics::sam::Sam;
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/clip")
        .join(name)
}

// ---- the PyTorch `.pt` seed

/// One tensor of the seed state dict.
struct Entry {
    name: &'static str,
    storage: &'static str,
    elem_size: usize,
    shape: Vec<usize>,
    /// Column-major (Fortran) strides instead of row-major.
    fortran: bool,
    /// How the tensor is wrapped: 0 plain `_rebuild_tensor_v2`, 1 `_rebuild_parameter`,
    /// 2 `_rebuild_from_type_v2`.
    wrap: u8,
}

fn entries() -> Vec<Entry> {
    let e = |name, storage, elem_size, shape: &[usize], fortran, wrap| Entry {
        name,
        storage,
        elem_size,
        shape: shape.to_vec(),
        fortran,
        wrap,
    };
    vec![
        e(
            "image_encoder.patch_embed.seq.0.c.weight",
            "FloatStorage",
            4,
            &[32, 3, 3, 3],
            false,
            0,
        ),
        e(
            "image_encoder.patch_embed.seq.0.bn.weight",
            "FloatStorage",
            4,
            &[32],
            false,
            1,
        ),
        e(
            "image_encoder.patch_embed.seq.0.bn.bias",
            "HalfStorage",
            2,
            &[32],
            false,
            0,
        ),
        e(
            "image_encoder.patch_embed.seq.0.bn.running_mean",
            "DoubleStorage",
            8,
            &[32],
            false,
            2,
        ),
        e(
            "image_encoder.patch_embed.seq.0.bn.running_var",
            "FloatStorage",
            4,
            &[32],
            false,
            0,
        ),
        e(
            "image_encoder.patch_embed.seq.2.c.weight",
            "FloatStorage",
            4,
            &[4, 6],
            true,
            0,
        ),
        e(
            "image_encoder.patch_embed.seq.0.bn.num_batches_tracked",
            "LongStorage",
            8,
            &[],
            false,
            0,
        ),
    ]
}

fn op_unicode(p: &mut Vec<u8>, s: &str) {
    p.push(b'X');
    p.extend((s.len() as u32).to_le_bytes());
    p.extend(s.as_bytes());
}

fn op_int(p: &mut Vec<u8>, v: usize) {
    if v < 256 {
        p.extend([b'K', v as u8]);
    } else {
        p.push(b'J');
        p.extend((v as i32).to_le_bytes());
    }
}

fn op_global(p: &mut Vec<u8>, module: &str, name: &str) {
    p.push(b'c');
    p.extend(format!("{module}\n{name}\n").as_bytes());
}

fn op_tuple(p: &mut Vec<u8>, vals: &[usize]) {
    p.push(b'(');
    for &v in vals {
        op_int(p, v);
    }
    p.push(b't');
}

fn op_ordered_dict(p: &mut Vec<u8>) {
    op_global(p, "collections", "OrderedDict");
    p.extend([b')', b'R']);
}

/// `_rebuild_tensor_v2(storage, offset, size, stride, requires_grad, hooks)` as a REDUCE.
fn op_rebuild(p: &mut Vec<u8>, key: usize, e: &Entry) {
    let numel: usize = e.shape.iter().product();
    let mut stride = vec![1usize; e.shape.len()];
    if e.fortran {
        for d in 1..e.shape.len() {
            stride[d] = stride[d - 1] * e.shape[d - 1];
        }
    } else {
        for d in (0..e.shape.len().saturating_sub(1)).rev() {
            stride[d] = stride[d + 1] * e.shape[d + 1];
        }
    }
    op_global(p, "torch._utils", "_rebuild_tensor_v2");
    p.push(b'(');
    p.push(b'(');
    op_unicode(p, "storage");
    op_global(p, "torch", e.storage);
    op_unicode(p, &key.to_string());
    op_unicode(p, "cpu");
    op_int(p, numel);
    p.extend([b't', b'Q']);
    op_int(p, 0);
    op_tuple(p, &e.shape);
    op_tuple(p, &stride);
    p.push(0x89); // NEWFALSE
    op_ordered_dict(p);
    p.extend([b't', b'R']);
}

fn pickle(es: &[Entry]) -> Vec<u8> {
    let mut p = vec![0x80, 2];
    op_ordered_dict(&mut p);
    p.push(b'(');
    for (k, e) in es.iter().enumerate() {
        op_unicode(&mut p, e.name);
        match e.wrap {
            1 => {
                op_global(&mut p, "torch._utils", "_rebuild_parameter");
                p.push(b'(');
                op_rebuild(&mut p, k, e);
                p.push(0x89);
                op_ordered_dict(&mut p);
                p.extend([b't', b'R']);
            }
            2 => {
                op_global(&mut p, "torch._tensor", "_rebuild_from_type_v2");
                p.push(b'(');
                op_global(&mut p, "torch._utils", "_rebuild_tensor_v2");
                op_global(&mut p, "torch", "Tensor");
                // The args tuple of the inner rebuild, then an empty state.
                let mut inner = Vec::new();
                op_rebuild(&mut inner, k, e);
                // Drop the inner GLOBAL and the trailing REDUCE: keep the argument tuple.
                let g = b"ctorch._utils\n_rebuild_tensor_v2\n".len();
                p.extend(&inner[g..inner.len() - 1]);
                p.push(b'}');
                p.extend([b't', b'R']);
            }
            _ => op_rebuild(&mut p, k, e),
        }
    }
    p.extend([b'u', b'.']);
    p
}

fn storages(es: &[Entry]) -> Vec<(String, Vec<u8>)> {
    es.iter()
        .enumerate()
        .map(|(k, e)| {
            let n: usize = e.shape.iter().product::<usize>() * e.elem_size;
            let bytes = (0..n)
                .map(|i| {
                    if i % e.elem_size == e.elem_size - 1 {
                        0x3c
                    } else {
                        (i * 7) as u8
                    }
                })
                .collect();
            (format!("archive/data/{k}"), bytes)
        })
        .collect()
}

/// Which part of the `.pt` a case mutates: the zip as a whole, or (zipped again, with
/// valid CRCs) the pickle or one storage.
#[derive(Clone, Debug)]
enum PtTarget {
    Zip,
    Pickle,
    Storage(proptest::sample::Index),
}

fn pt_bytes(target: &PtTarget, muts: &[Mutation]) -> Vec<u8> {
    let es = entries();
    let mut files = vec![("archive/data.pkl".to_string(), pickle(&es))];
    files.extend(storages(&es));
    files.push(("archive/version".to_string(), b"3\n".to_vec()));
    match target {
        PtTarget::Zip => apply(&stored_zip(&files), muts, Kind::Binary),
        PtTarget::Pickle => {
            files[0].1 = apply(&files[0].1, muts, Kind::Binary);
            stored_zip(&files)
        }
        PtTarget::Storage(i) => {
            let k = 1 + i.index(es.len());
            files[k].1 = apply(&files[k].1, muts, Kind::Binary);
            stored_zip(&files)
        }
    }
}

fn pt_target() -> impl Strategy<Value = PtTarget> {
    prop_oneof![
        1 => Just(PtTarget::Zip),
        2 => Just(PtTarget::Pickle),
        1 => any::<proptest::sample::Index>().prop_map(PtTarget::Storage),
    ]
}

/// A file loader run on each case; its error must name `file`.
fn fuzz_weights<S: Strategy>(
    format: &str,
    file: &str,
    cases: u32,
    strategy: S,
    write: impl Fn(&Path, S::Value),
    load: fn(&Path) -> Result<(), String>,
) where
    S::Value: std::fmt::Debug,
{
    let work = tempfile::tempdir().unwrap();
    let path = work.path().join(file);
    let tally = Tally::new();
    let mut r = runner(format, cases);
    let t = tally.clone();
    let result = r.run(&strategy, |v| {
        write(&path, v);
        let p = path.clone();
        check_load(&t, &[file], move || load(&p))?;
        Ok(())
    });
    finish(format, result, &tally);
}

fn sam_pt(cases: u32) {
    fuzz_weights(
        "SAM .pt",
        "mobile_sam.pt",
        cases,
        (pt_target(), mutations(Kind::Binary)),
        |p, (target, muts)| std::fs::write(p, pt_bytes(&target, &muts)).unwrap(),
        |p| Sam::load(p).map(|_| ()).map_err(|e| e.to_string()),
    );
}

/// The `.pt` seed's tensors as safetensors (SAM also loads that form).
fn sam_safetensors_seed() -> Vec<u8> {
    let es = entries();
    let mut map = std::collections::HashMap::new();
    for ((_, bytes), e) in storages(&es).into_iter().zip(&es) {
        let floats: Vec<f32> = bytes
            .chunks(e.elem_size)
            .map(|c| c[0] as f32 / 255.0)
            .collect();
        let t = candle_core::Tensor::from_vec(floats, e.shape.clone(), &candle_core::Device::Cpu)
            .unwrap();
        map.insert(e.name.to_string(), t);
    }
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s.safetensors");
    candle_core::safetensors::save(&map, &p).unwrap();
    std::fs::read(p).unwrap()
}

fn sam_safetensors(cases: u32) {
    let seed = sam_safetensors_seed();
    fuzz_weights(
        "SAM safetensors",
        "mobile_sam.safetensors",
        cases,
        fuzz_common::safetensors_mutations(),
        move |p, muts| std::fs::write(p, apply_safetensors(&seed, &muts)).unwrap(),
        |p| Sam::load(p).map(|_| ()).map_err(|e| e.to_string()),
    );
}

fn clip_pt(cases: u32) {
    fuzz_weights(
        "CLIP PyTorch pickle",
        "open_clip_pytorch_model.bin",
        cases,
        (pt_target(), mutations(Kind::Binary)),
        |p, (target, muts)| std::fs::write(p, pt_bytes(&target, &muts)).unwrap(),
        |p| {
            ClipModel::load(p, &LoadOptions::default())
                .map(|_| ())
                .map_err(|e| e.to_string())
        },
    );
}

/// CLIP safetensors of `seed` (a fixture), with its config JSON beside it as
/// `open_clip_config.json` or (`infer`) without one.
fn clip_safetensors(format: &str, seed: &str, cases: u32) {
    let weights = std::fs::read(fixture(&format!("{seed}.safetensors"))).unwrap();
    let config = std::fs::read(fixture(&format!("{seed}.json"))).unwrap();
    let work = tempfile::tempdir().unwrap();
    let path = work.path().join("open_clip_model.safetensors");
    let cfg_path = work.path().join("open_clip_config.json");
    let tally = Tally::new();
    let mut r = runner(format, cases);
    let t = tally.clone();
    // Mutate the weights (config beside them or not) or the config.
    let strategy = (0u8..3, fuzz_common::safetensors_mutations());
    let result = r.run(&strategy, |(what, muts)| {
        match what {
            0 => {
                std::fs::write(&path, apply_safetensors(&weights, &muts)).unwrap();
                std::fs::write(&cfg_path, &config).unwrap();
            }
            1 => {
                std::fs::write(&path, apply_safetensors(&weights, &muts)).unwrap();
                let _ = std::fs::remove_file(&cfg_path);
            }
            _ => {
                std::fs::write(&path, &weights).unwrap();
                std::fs::write(&cfg_path, apply(&config, &muts, Kind::Json)).unwrap();
            }
        }
        let p = path.clone();
        let names: &[&str] = if what == 2 {
            &["open_clip_config.json", "open_clip_model.safetensors"]
        } else {
            &["open_clip_model.safetensors", "open_clip_config.json"]
        };
        check_load(&t, names, move || {
            ClipModel::load(&p, &LoadOptions::default()).map(|_| ())
        })?;
        Ok(())
    });
    finish(format, result, &tally);
}

formats! {
    fuzz_sam_pt: 600 => sam_pt;
    fuzz_sam_safetensors: 300 => sam_safetensors;
    fuzz_clip_pt: 200 => clip_pt;
    fuzz_clip_openclip_safetensors: 200 => |n| clip_safetensors("CLIP OpenCLIP safetensors", "tiny_gelu", n);
    fuzz_clip_hf_safetensors: 150 => |n| clip_safetensors("CLIP Hugging Face safetensors", "tiny_quickgelu_hf", n);
}
