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

/// `configs/deformable-3dgs.toml` is the official protocol: the field is exactly
/// `FieldConfig::faithful()` (8×256, the is_blender time network, every Gaussian), the
/// rates and the densification window are our defaults (which follow the official ones),
/// and only the dead view-space prune is switched off.
#[test]
fn the_deformable_3dgs_config_is_the_faithful_protocol() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/deformable-3dgs.toml");
    let c = TrainConfig::from_toml_file(&path).unwrap();
    let d = TrainConfig::default();
    assert_eq!(c.iterations, 40_000);
    assert_eq!(c.field, train::config::FieldConfig::faithful());
    assert_eq!(c.lr, d.lr);
    assert_eq!(c.init, d.init);
    assert_eq!(c.sh, d.sh);
    assert_eq!(c.loss, d.loss);
    assert_eq!(c.densify.strategy, train::densify::Strategy::Adaptive);
    assert!(c.densify.screen_size >= 1e9);
    let mut rest = c.densify.clone();
    rest.screen_size = d.densify.screen_size;
    assert_eq!(rest, d.densify);
    assert!(!c.reg.enabled && !c.objects.enabled);
}
