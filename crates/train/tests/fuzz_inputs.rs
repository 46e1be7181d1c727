//! Seeded mutation fuzzing of the files a training checkpoint is read from
//! (docs/robustness.md): `config.toml` (also as a `--config` file),
//! `point_cloud.ply` and `state.safetensors`, through `TrainConfig::from_toml_file`,
//! `ply::read`, `checkpoint::load_model` and `checkpoint::load_trainer`.
//!
//! Property per case (scene/tests/fuzz_common): no panic, no hang, no allocation above the
//! limit, an error that names the file; a checkpoint that loads must also train: one step
//! of the resumed trainer returns (Ok or a typed error) without panicking.
//!
//! CI: `cargo test -p train --test fuzz_inputs`. Long run (20× the CI counts, or
//! `FUZZ_CASES` per format; `FUZZ_SEED` for another stream):
//!
//! ```text
//! cargo test -p train --test fuzz_inputs -- --ignored --nocapture
//! ```

#[macro_use]
#[path = "../../scene/tests/fuzz_common/mod.rs"]
mod fuzz_common;

use fuzz_common::{apply, apply_safetensors, check_load, finish, mutations, runner, Kind, Tally};
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use train::{checkpoint, TrainConfig, Trainer};

/// A 32×24 toycars scene, loaded once.
fn dataset() -> &'static scene::Dataset {
    static DS: OnceLock<(tempfile::TempDir, scene::Dataset)> = OnceLock::new();
    &DS.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let cfg = scene::toycars::ToycarsConfig {
            width: 32,
            height: 24,
            frames: 8,
            supersample: false,
            shadows: false,
            ..Default::default()
        };
        scene::toycars::generate(&cfg, dir.path(), &|_, _| {}).unwrap();
        let ds = scene::load_dataset(dir.path(), &scene::LoadOptions::default()).unwrap();
        (dir, ds)
    })
    .1
}

/// A checkpoint of a few iterations of a tiny model (SH degree 1 by then, field active).
fn checkpoint_seed() -> &'static Path {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let mut cfg = TrainConfig {
            iterations: 20,
            ..Default::default()
        };
        cfg.init.random_points = 150;
        (cfg.field.depth, cfg.field.width, cfg.field.skip) = (2, 8, 1);
        cfg.field.warm_up = 2;
        cfg.sh.degree_interval = 3;
        (cfg.densify.from, cfg.densify.interval) = (2, 2);
        cfg.validate().unwrap();
        let mut tr = Trainer::new(cfg, dataset().clone(), 3).unwrap();
        for _ in 0..5 {
            tr.step().unwrap();
        }
        let run = tempfile::tempdir().unwrap();
        let dir = checkpoint::save(&tr, run.path()).unwrap();
        (run, dir)
    })
    .1
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

/// Which loader a case goes through.
#[derive(Clone, Copy, Debug)]
enum Via {
    Model,
    Trainer,
}

/// Mutates `file` of a private copy of the seed checkpoint and loads it.
fn fuzz_checkpoint_file(format: &str, file: &'static str, cases: u32) {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("iter_0000005");
    copy_dir(checkpoint_seed(), &dir);
    let target = dir.join(file);
    let original = std::fs::read(&target).unwrap();
    let kind = match file {
        checkpoint::CONFIG_NAME => Kind::Toml,
        checkpoint::PLY_NAME => Kind::Text,
        _ => Kind::Json, // the safetensors header; see apply_safetensors
    };
    let tally = Tally::new();
    let mut r = runner(format, cases);
    let t = tally.clone();
    let via = prop_oneof![Just(Via::Model), Just(Via::Trainer)];
    let sums = dir.join(train::integrity::CHECKSUMS_NAME);
    let sums_original = std::fs::read(&sums).unwrap();
    let result = r.run(
        &(mutations(kind), via, any::<bool>()),
        |(muts, via, resign)| {
            let bytes = match file {
                checkpoint::STATE_NAME => apply_safetensors(&original, &muts),
                _ => apply(&original, &muts, kind),
            };
            // Half the cases pass the checksums (as if the damage had been written that way),
            // so the loaders' own checks are fuzzed too, not only the checksum test.
            if resign {
                let mut v: serde_json::Value = serde_json::from_slice(&sums_original).unwrap();
                v["files"][file] = train::integrity::crc_hex(&bytes).into();
                v["tensors"].as_object_mut().unwrap().remove(file);
                std::fs::write(&sums, v.to_string()).unwrap();
            }
            std::fs::write(&target, bytes).unwrap();
            let d = dir.clone();
            let got = match via {
                Via::Model => {
                    check_load(&t, &[file], move || checkpoint::load_model(&d).map(|_| ()))?
                }
                Via::Trainer => check_load(&t, &[file], move || {
                    let mut tr = checkpoint::load_trainer(&d, dataset().clone())?;
                    if !tr.state.is_aligned() {
                        return Err(train::TrainError::Data(
                            "loaded state is not aligned".into(),
                        ));
                    }
                    // A loaded checkpoint must train; a typed error (say, divergence of
                    // mutated weights) is fine, a panic is not.
                    let _ = tr.step();
                    Ok(())
                })?,
            };
            std::fs::write(&target, &original).unwrap();
            std::fs::write(&sums, &sums_original).unwrap();
            let _ = got;
            Ok(())
        },
    );
    finish(format, result, &tally);
}

fn config_file(cases: u32) {
    let work = tempfile::tempdir().unwrap();
    let path = work.path().join("small.toml");
    let seeds = [
        std::fs::read(checkpoint_seed().join(checkpoint::CONFIG_NAME)).unwrap(),
        b"iterations = 300\n[init]\nrandom_points = 500\n[field]\ndepth = 2\nwidth = 16\n".to_vec(),
    ];
    let tally = Tally::new();
    let mut r = runner("--config TOML", cases);
    let t = tally.clone();
    let result = r.run(
        &(
            0..seeds.len(),
            mutations(Kind::Toml),
            prop::option::of(1u32..100_000),
        ),
        |(s, muts, iters)| {
            std::fs::write(&path, apply(&seeds[s], &muts, Kind::Toml)).unwrap();
            let p = path.clone();
            check_load(&t, &["small.toml"], move || {
                TrainConfig::for_run(Some(&p), iters)
            })?;
            Ok(())
        },
    );
    finish("--config TOML", result, &tally);
}

fn ply_file(cases: u32) {
    let work = tempfile::tempdir().unwrap();
    let path = work.path().join("model.ply");
    let seed = std::fs::read(checkpoint_seed().join(checkpoint::PLY_NAME)).unwrap();
    let tally = Tally::new();
    let mut r = runner("3DGS PLY", cases);
    let t = tally.clone();
    let result = r.run(&mutations(Kind::Text), |muts| {
        std::fs::write(&path, apply(&seed, &muts, Kind::Text)).unwrap();
        let p = path.clone();
        check_load(&t, &["model.ply"], move || train::ply::read(&p))?;
        Ok(())
    });
    finish("3DGS PLY", result, &tally);
}

formats! {
    fuzz_checkpoint_config_toml: 300 => |n| fuzz_checkpoint_file("checkpoint config.toml", checkpoint::CONFIG_NAME, n);
    fuzz_checkpoint_point_cloud_ply: 400 => |n| fuzz_checkpoint_file("checkpoint point_cloud.ply", checkpoint::PLY_NAME, n);
    fuzz_checkpoint_state_safetensors: 600 => |n| fuzz_checkpoint_file("checkpoint state.safetensors", checkpoint::STATE_NAME, n);
    fuzz_config_toml: 500 => config_file;
    fuzz_ply_read: 400 => ply_file;
}
