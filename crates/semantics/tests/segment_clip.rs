//! The `--labels clip` path of `semdynreg segment` end to end (the function the CLI calls):
//! SAM masks on a tiny toycars scene, each labelled by a small random-weight CLIP in the
//! OpenCLIP layout (the fixture of `clip_model.rs`), written as ID maps, previews and
//! `semantics.json`, then reused from the cache. Random weights label arbitrarily, so the test
//! checks the plumbing, not the labels: every written ID is a dictionary index or background,
//! and the record names the CLIP file. Needs the real MobileSAM weights (skips without them);
//! ≈15 s on 2 cores, most of it the SAM image encoder on the one training frame.

mod sam_common;

use std::path::{Path, PathBuf};

use sam_common::mobile_sam_path;
use semantics::automask::{MaskGenConfig, Sampling};
use semantics::segment::{
    record_path, segment_scene, GenConfigKey, LabelSource, MaskSource, SegmentOptions,
};

/// The tiny OpenCLIP-layout fixture, with its config beside it under the name the loader
/// looks for (`open_clip_config.json`), as a user's download would be laid out.
fn clip_weights(dir: &Path) -> PathBuf {
    let fixtures = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/clip");
    let weights = dir.join("open_clip_model.safetensors");
    std::fs::copy(fixtures.join("tiny_gelu.safetensors"), &weights).unwrap();
    std::fs::copy(
        fixtures.join("tiny_gelu.json"),
        dir.join("open_clip_config.json"),
    )
    .unwrap();
    weights
}

#[test]
fn clip_labels_run_end_to_end_and_cache() {
    let Some(sam) = mobile_sam_path() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("scene");
    // 3 frames: frame 0 test, 1 val, 2 train — one training frame to segment.
    let cfg = scene::toycars::ToycarsConfig {
        width: 160,
        height: 120,
        frames: 3,
        supersample: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, &root, &|_, _| {}).unwrap();
    let models = dir.path().join("clip");
    std::fs::create_dir_all(&models).unwrap();
    let gen = MaskGenConfig {
        sampling: Sampling::Grid(4),
        ..Default::default()
    };
    let dictionary: Vec<String> = ["white SUV", "yellow sedan", "green SUV"]
        .map(String::from)
        .to_vec();
    let opts = SegmentOptions {
        dictionary: dictionary.clone(),
        masks: MaskSource::Sam,
        labels: LabelSource::Clip,
        sam,
        clip: Some(clip_weights(&models)),
        tau: 0.5,
        generator: GenConfigKey::of(&gen),
        track: None,
    };

    let mut calls = 0;
    let report = segment_scene(&root, &opts, &gen, false, &mut |_, _| calls += 1).unwrap();
    assert!(!report.cached);
    assert_eq!(report.frames.len(), 1);
    assert_eq!(calls, 1, "one progress call per frame");
    let frame = &report.frames[0];
    assert!(frame.masks > 0, "SAM found no masks on the toycars frame");
    let ids = scene::load_mask(&scene::semantics_path(&root, &frame.file_path)).unwrap();
    assert_eq!((ids.width, ids.height), (160, 120));
    assert!(
        ids.data
            .iter()
            .all(|&v| v == 255 || (v as usize) < dictionary.len()),
        "an ID outside the dictionary was written"
    );
    assert!(semantics::segment::preview_path(&root, &frame.file_path).is_file());
    let record = std::fs::read_to_string(record_path(&root)).unwrap();
    let record: serde_json::Value = serde_json::from_str(&record).unwrap();
    assert_eq!(record["options"]["labels"], "clip");
    assert!(record["clip_checkpoint_bytes"].as_u64().unwrap() > 0);

    let again = segment_scene(&root, &opts, &gen, false, &mut |_, _| {}).unwrap();
    assert!(again.cached, "an unchanged second run must reuse the cache");
    assert_eq!(again.frames[0].masks, frame.masks);
}

#[test]
fn clip_labels_without_weights_name_the_missing_file() {
    // CLIP is loaded before SAM, so this needs no SAM weights.
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("scene");
    let cfg = scene::toycars::ToycarsConfig {
        width: 64,
        height: 48,
        frames: 3,
        supersample: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, &root, &|_, _| {}).unwrap();
    let gen = MaskGenConfig::default();
    let missing = dir.path().join("no_such_clip.safetensors");
    let opts = SegmentOptions {
        dictionary: vec!["white SUV".into()],
        masks: MaskSource::Sam,
        labels: LabelSource::Clip,
        sam: dir.path().join("mobile_sam.pt"),
        clip: Some(missing.clone()),
        tau: 0.5,
        generator: GenConfigKey::of(&gen),
        track: None,
    };
    let err = segment_scene(&root, &opts, &gen, false, &mut |_, _| {})
        .expect_err("missing CLIP weights must fail")
        .to_string();
    assert!(
        err.contains(&missing.display().to_string()),
        "error does not name the file: {err}"
    );
}
