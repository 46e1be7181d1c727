//! Iteration time by phase at 480×360 on toycars scene1 (16 frames, 100k random initial
//! Gaussians, density control off so every step sees the same Gaussians), for each field
//! option: the default 4×64 on the visible Gaussians, 4×64 on all of them, 2×32, and the
//! faithful 8×256. Prints one line per option with the ms per phase:
//!
//! ```text
//! [PERF_ITERS=5] [PERF_ONLY_DEFAULT=1] cargo bench -p train --bench iteration_breakdown
//! ```
//!
//! `PERF_ONLY_DEFAULT=1` times only the default field. The same breakdown on a trained model
//! (the Gaussians a real run has, not the random init), densification off:
//!
//! ```text
//! PERF_CHECKPOINT=RUN/checkpoints/iter_NNNNNNN PERF_SCENE=SCENE [PERF_ITERS=5] \
//!     cargo bench -p train --bench iteration_breakdown
//! ```
//!
//! `benches/trained_state.rs` is the finer tool for a trained state (medians per phase, A/B
//! of the reference paths).

use train::config::FieldConfig;
use train::{TrainConfig, Trainer};

fn scene_480() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let cfg = scene::toycars::ToycarsConfig {
        frames: 16,
        supersample: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, dir.path(), &|_, _| {}).unwrap();
    dir
}

fn measure(name: &str, field: FieldConfig, dir: &std::path::Path, iters: u32) {
    let ds = scene::load_dataset(dir, &scene::LoadOptions::default()).unwrap();
    let mut cfg = TrainConfig {
        field: FieldConfig {
            warm_up: 0,
            ..field
        },
        ..Default::default()
    };
    cfg.densify.from = 1_000_000; // measure at a fixed Gaussian count (100k random init)
    cfg.densify.until = 0;
    let tr = Trainer::new(cfg, ds, 0).unwrap();
    time_steps(name, tr, iters);
}

/// Warm up 3 steps, then time `iters` and print ms per phase.
fn time_steps(name: &str, mut tr: Trainer, iters: u32) {
    for _ in 0..3 {
        tr.step().unwrap();
    }
    tr.timings = Default::default();
    let t0 = std::time::Instant::now();
    for _ in 0..iters {
        tr.step().unwrap();
    }
    let total = t0.elapsed().as_secs_f64() * 1e3 / iters as f64;
    let parts: Vec<String> = tr
        .timings
        .per_iteration_ms()
        .iter()
        .map(|(k, v)| format!("{k} {v:.1}"))
        .collect();
    println!(
        "{name}: N={} pairs {:.1}M total {total:.1} ms/iter | {}",
        tr.state.len(),
        tr.evaluated_pairs() as f64 / 1e6,
        parts.join(", ")
    );
}

fn main() {
    if std::env::var_os("PERF_CHECKPOINT").is_some() {
        iteration_breakdown_checkpoint();
    } else {
        iteration_breakdown_480x360();
    }
}

fn iters() -> u32 {
    std::env::var("PERF_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5)
}

fn iteration_breakdown_480x360() {
    let dir = scene_480();
    let iters = iters();
    let d = FieldConfig::default();
    measure("default 4x64 visible", d.clone(), dir.path(), iters);
    if std::env::var("PERF_ONLY_DEFAULT").is_ok() {
        return;
    }
    measure(
        "4x64 all",
        FieldConfig {
            visible_only: false,
            ..d.clone()
        },
        dir.path(),
        iters,
    );
    measure(
        "2x32 visible",
        FieldConfig {
            depth: 2,
            width: 32,
            skip: 0,
            ..d.clone()
        },
        dir.path(),
        iters,
    );
    measure(
        "faithful 8x256",
        FieldConfig::faithful(),
        dir.path(),
        iters.min(2),
    );
}

/// Breakdown at a checkpoint's state, densification off (`PERF_CHECKPOINT`, `PERF_SCENE`).
fn iteration_breakdown_checkpoint() {
    let (Ok(ckpt), Ok(scene)) = (
        std::env::var("PERF_CHECKPOINT"),
        std::env::var("PERF_SCENE"),
    ) else {
        eprintln!("set PERF_SCENE (the scene folder of PERF_CHECKPOINT's run)");
        std::process::exit(2);
    };
    let ds = scene::load_dataset(scene.as_ref(), &scene::LoadOptions::default()).unwrap();
    let mut tr = train::checkpoint::load_trainer(ckpt.as_ref(), ds).unwrap();
    tr.cfg.densify.until = 0;
    let iters = iters();
    time_steps(&format!("checkpoint iteration {}", tr.iteration), tr, iters);
}
