//! `segment --masks alpha` on a D-NeRF fixture written here: every training frame's ID map
//! is its RGBA silhouette as object 0, a second run reuses the cache, and a scene of RGB
//! frames is refused with the file named. No weights needed.

use semantics::automask::MaskGenConfig;
use semantics::segment::{segment_scene, GenConfigKey, LabelSource, MaskSource, SegmentOptions};
use serde_json::json;
use std::path::Path;

const POSE: [[f64; 4]; 4] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 4.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// Frame `i` of a 6×4 scene: an opaque square whose left edge moves one pixel per frame.
fn square(i: usize) -> Vec<u8> {
    let mut px = Vec::new();
    for y in 0..4 {
        for x in 0..6 {
            let inside = (1..3).contains(&y) && (i..i + 2).contains(&x);
            px.extend([200, 100, 50, if inside { 255 } else { 0 }]);
        }
    }
    px
}

fn scene(root: &Path, rgba: bool) {
    let mut frames = Vec::new();
    for i in 0..3 {
        let path = root.join(format!("train/r_{i:03}.png"));
        if rgba {
            scene::save_rgba_png(&path, 6, 4, &square(i)).unwrap();
        } else {
            let rgb: Vec<u8> = square(i)
                .chunks(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            let img = scene::ImageU8 {
                width: 6,
                height: 4,
                data: rgb,
            };
            img.save_png(&path).unwrap();
        }
        frames.push(json!({"file_path": format!("./train/r_{i:03}"), "time": i as f64 / 2.0, "transform_matrix": POSE}));
    }
    for split in ["train", "val", "test"] {
        let doc = json!({"camera_angle_x": 0.6, "frames": frames});
        std::fs::write(
            root.join(format!("transforms_{split}.json")),
            serde_json::to_vec(&doc).unwrap(),
        )
        .unwrap();
    }
}

fn options() -> SegmentOptions {
    SegmentOptions {
        dictionary: vec!["lego".into()],
        masks: MaskSource::Alpha,
        labels: LabelSource::Gt,
        sam: "unused.pt".into(),
        clip: None,
        tau: 0.5,
        generator: GenConfigKey::of(&MaskGenConfig::default()),
        track: None,
    }
}

#[test]
fn alpha_silhouettes_become_object_zero_and_are_cached() {
    let dir = tempfile::tempdir().unwrap();
    scene(dir.path(), true);
    let gen = MaskGenConfig::default();
    let report = segment_scene(dir.path(), &options(), &gen, false, &mut |_, _| {}).unwrap();
    assert!(!report.cached);
    assert_eq!(report.frames.len(), 3);
    for (i, f) in report.frames.iter().enumerate() {
        assert_eq!(f.masks, 1);
        let ids = scene::load_mask(&scene::semantics_path(dir.path(), &f.file_path)).unwrap();
        let want: Vec<u8> = square(i)
            .chunks(4)
            .map(|p| if p[3] == 255 { 0 } else { 255 })
            .collect();
        assert_eq!(ids.data, want, "frame {i}");
    }
    let again = segment_scene(dir.path(), &options(), &gen, false, &mut |_, _| {}).unwrap();
    assert!(again.cached);
}

#[test]
fn frames_without_alpha_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    scene(dir.path(), false);
    let gen = MaskGenConfig::default();
    let err = segment_scene(dir.path(), &options(), &gen, false, &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("r_000.png") && err.contains("no alpha"),
        "{err}"
    );
    assert!(!dir.path().join("semantics/semantics.json").exists());
}
