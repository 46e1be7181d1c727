//! The training configs shipped in `configs/` (README, docs/performance.md) parse, validate
//! and rescale as the CLI reads them, so a documented command cannot fail on its config.

use std::path::PathBuf;
use train::TrainConfig;

#[test]
fn every_shipped_config_parses_and_rescales() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).expect("configs/ exists") {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        TrainConfig::from_toml_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        TrainConfig::for_run(Some(&path), Some(13_000))
            .unwrap_or_else(|e| panic!("{} with --iters: {e}", path.display()));
        seen += 1;
    }
    assert!(seen >= 1, "no config in {}", dir.display());
}

#[test]
fn the_one_hour_config_selects_mcmc_with_its_cap() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/mcmc-one-hour.toml");
    let c = TrainConfig::from_toml_file(&path).unwrap();
    assert_eq!(c.densify.strategy, train::densify::Strategy::Mcmc);
    assert_eq!(c.densify.mcmc.cap, 120_000);
}
