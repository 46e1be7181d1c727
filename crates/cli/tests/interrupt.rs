//! Ctrl-C during `semdynreg train`: the process exits cleanly, leaving a checkpoint of the
//! iteration it stopped at and the stopped segment's `timings.json` (resume from such a
//! checkpoint is tested in `crates/train/tests/training.rs`). Unix only: the signal is sent
//! with `kill -INT`.
#![cfg(unix)]

use serde_json::Value;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

fn read_json(path: &Path) -> Value {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// Waits until `path` exists (the training loop has logged, so the Ctrl-C handler is set).
fn wait_for(path: &Path, child: &mut std::process::Child) {
    let t0 = Instant::now();
    while !path.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("train exited ({status}) before writing {}", path.display());
        }
        assert!(
            t0.elapsed() < Duration::from_secs(300),
            "no {}",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn ctrl_c_saves_a_checkpoint_and_the_segments_timings() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let cfg = scene::toycars::ToycarsConfig {
        width: 32,
        height: 24,
        frames: 12,
        supersample: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, &scene_dir, &|_, _| {}).unwrap();
    let config = tmp.path().join("small.toml");
    // A schedule far longer than the test waits (only Ctrl-C ends it), logging early.
    let toml = "iterations = 1000000\n[init]\nrandom_points = 500\n[log]\nlog_interval = 5\n";
    std::fs::write(&config, toml).unwrap();
    let run = tmp.path().join("run");
    let mut child = Command::new(env!("CARGO_BIN_EXE_semdynreg"))
        .args(["train", scene_dir.to_str().unwrap(), "--out"])
        .arg(&run)
        .args(["--config", config.to_str().unwrap()])
        .spawn()
        .expect("start semdynreg train");
    wait_for(&run.join("metrics.jsonl"), &mut child);
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    assert!(status.success(), "train after Ctrl-C exited with {status}");

    let latest = std::fs::read_to_string(run.join("checkpoints/latest")).unwrap();
    let stopped: u32 = latest.trim().trim_start_matches("iter_").parse().unwrap();
    let timings = read_json(&run.join("timings.json"));
    assert_eq!(timings["total_iterations"].as_u64(), Some(stopped as u64));
    assert_eq!(timings["iterations"].as_u64(), Some(stopped as u64));
    let raster_ms = timings["ms_per_iteration"]["raster_forward"]
        .as_f64()
        .unwrap();
    assert!(raster_ms > 0.0, "{timings}");
    assert!(stopped < 1_000_000);
}
