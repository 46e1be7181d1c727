//! Shared fixtures: a tiny toycars scene generated once per test binary.

use std::path::PathBuf;
use std::sync::OnceLock;
use train::TrainConfig;

/// 64×48, 24 frames (test every 8th), generated into a temp folder kept for the process.
pub fn tiny_scene() -> PathBuf {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let cfg = scene::toycars::ToycarsConfig {
            width: 64,
            height: 48,
            frames: 24,
            supersample: false,
            ..Default::default()
        };
        scene::toycars::generate(&cfg, dir.path(), &|_, _| {}).unwrap();
        dir
    })
    .path()
    .to_path_buf()
}

pub fn dataset() -> scene::Dataset {
    scene::load_dataset(&tiny_scene(), &scene::LoadOptions::default()).unwrap()
}

/// A small, fast configuration for `iters` iterations. The 40k schedule rescaled this far
/// would reset opacities every 23 iterations; instead: field from 30%, densify every 10%
/// between 10% and 70%, no opacity reset, SH degree +1 every 20%.
pub fn small_config(iters: u32) -> TrainConfig {
    let mut c = TrainConfig {
        iterations: iters,
        ..Default::default()
    };
    c.init.random_points = 4000;
    c.field.depth = 3;
    c.field.width = 32;
    c.field.skip = 1;
    c.field.warm_up = iters * 3 / 10;
    c.lr.position_max_steps = iters;
    c.lr.field_max_steps = iters;
    c.densify.from = iters / 10;
    c.densify.until = iters * 7 / 10;
    c.densify.interval = (iters / 10).max(1);
    c.densify.screen_size_after = iters / 2;
    c.densify.opacity_reset_interval = iters * 10;
    c.sh.degree_interval = (iters / 5).max(1);
    c.log.keep_checkpoints = 1;
    c.validate().unwrap();
    c
}
