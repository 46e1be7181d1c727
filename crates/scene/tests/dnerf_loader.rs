//! D-NeRF loader on fixtures written here: cameras, compositing, downscale, and one error
//! per kind of bad input, each naming the file and the problem.

use scene::{load_dataset, save_rgba_png, DatasetKind, LoadOptions};
use serde_json::json;
use std::path::Path;

const IDENT: [[f64; 4]; 4] = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 4.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// A 4×2 RGBA image: left half opaque red, right half transparent.
fn write_image(path: &Path, w: u32, h: u32) {
    let mut px = Vec::new();
    for _ in 0..h {
        for x in 0..w {
            px.extend(if x < w / 2 {
                [255, 0, 0, 255]
            } else {
                [0, 255, 0, 0]
            });
        }
    }
    save_rgba_png(path, w, h, &px).unwrap();
}

fn write_split(root: &Path, split: &str, frames: serde_json::Value, extra: serde_json::Value) {
    let mut doc = json!({"camera_angle_x": 0.6, "frames": frames});
    if let (Some(d), Some(e)) = (doc.as_object_mut(), extra.as_object()) {
        d.extend(e.clone());
    }
    std::fs::write(
        root.join(format!("transforms_{split}.json")),
        serde_json::to_vec(&doc).unwrap(),
    )
    .unwrap();
}

fn fixture(root: &Path) {
    for (split, n) in [("train", 3), ("val", 1), ("test", 1)] {
        let mut frames = Vec::new();
        for i in 0..n {
            write_image(&root.join(format!("{split}/r_{i:03}.png")), 4, 2);
            frames.push(json!({"file_path": format!("./{split}/r_{i:03}"), "time": i as f64 / 2.0, "transform_matrix": IDENT}));
        }
        write_split(root, split, json!(frames), json!({}));
    }
}

fn err_text(root: &Path) -> String {
    load_dataset(root, &LoadOptions::default())
        .unwrap_err()
        .to_string()
}

#[test]
fn loads_cameras_times_and_composited_images() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    let opts = LoadOptions {
        background: [1.0, 1.0, 1.0],
        downscale: 1,
    };
    let ds = load_dataset(dir.path(), &opts).unwrap();
    assert_eq!(ds.kind, DatasetKind::DNerf);
    assert_eq!((ds.train.len(), ds.val.len(), ds.test.len()), (3, 1, 1));
    let f = &ds.train[2];
    assert_eq!(f.file_path, "train/r_002");
    assert_eq!(f.time, 1.0);
    let cam = &f.camera;
    let fx = 0.5 * 4.0 / (0.3f32).tan();
    assert!((cam.fx - fx).abs() < 1e-4 && (cam.fy - fx).abs() < 1e-4);
    assert_eq!((cam.cx, cam.cy, cam.width, cam.height), (2.0, 1.0, 4, 2));
    // Blender camera at z = 4 looking down −z: the origin projects to the principal point.
    let (px, depth) = cam.project([0.0, 0.0, 0.0]).unwrap();
    assert!((px[0] - 2.0).abs() < 1e-5 && (px[1] - 1.0).abs() < 1e-5 && (depth - 4.0).abs() < 1e-5);
    // Left half red, right half the white background.
    assert_eq!(&f.image.data[..3], &[255, 0, 0]);
    assert_eq!(&f.image.data[9..12], &[255, 255, 255]);
    assert!(ds.scene_extent() >= 0.0);
    assert_eq!(ds.gt_mask_path(f), dir.path().join("masks/train/r_002.png"));
}

#[test]
fn downscale_halves_image_and_intrinsics() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    let ds = load_dataset(
        dir.path(),
        &LoadOptions {
            background: [0.0; 3],
            downscale: 2,
        },
    )
    .unwrap();
    let c = &ds.train[0].camera;
    assert_eq!(
        (
            ds.train[0].image.width,
            ds.train[0].image.height,
            c.width,
            c.height
        ),
        (2, 1, 2, 1)
    );
    assert_eq!((c.cx, c.cy), (1.0, 0.5));
    assert_eq!(&ds.train[0].image.data, &[255, 0, 0, 0, 0, 0]);
}

#[test]
fn missing_image_is_named() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    std::fs::remove_file(dir.path().join("val/r_000.png")).unwrap();
    let e = err_text(dir.path());
    assert!(
        e.contains("transforms_val.json")
            && e.contains("r_000.png")
            && e.contains("does not exist"),
        "{e}"
    );
}

#[test]
fn malformed_json_is_named() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    std::fs::write(dir.path().join("transforms_test.json"), "{\"frames\": [").unwrap();
    let e = err_text(dir.path());
    assert!(
        e.contains("transforms_test.json") && e.contains("malformed JSON"),
        "{e}"
    );
}

#[test]
fn image_size_disagreeing_with_json_is_named() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    let frames = json!([{"file_path": "./train/r_000", "time": 0.0, "transform_matrix": IDENT}]);
    write_split(dir.path(), "train", frames, json!({"w": 8, "h": 2}));
    let e = err_text(dir.path());
    assert!(
        e.contains("transforms_train.json") && e.contains("is 4×2") && e.contains("w = 8"),
        "{e}"
    );
}

#[test]
fn non_finite_and_singular_matrices_are_named() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    let mut m = IDENT;
    m[0][3] = 1e300; // finite in JSON, infinite as f32
    write_split(
        dir.path(),
        "train",
        json!([{"file_path": "./train/r_000", "time": 0.0, "transform_matrix": m}]),
        json!({}),
    );
    let e = err_text(dir.path());
    assert!(
        e.contains("transforms_train.json") && e.contains("not a finite"),
        "{e}"
    );
    let zero = [[0.0f64; 4]; 4];
    write_split(
        dir.path(),
        "train",
        json!([{"file_path": "./train/r_000", "time": 0.0, "transform_matrix": zero}]),
        json!({}),
    );
    let e = err_text(dir.path());
    assert!(
        e.contains("transforms_train.json") && e.contains("singular"),
        "{e}"
    );
}

/// Times are all given or all absent (a static scene, t = 0); a split with some missing
/// is an error naming the file and the frame, not frames silently at t = 0.
#[test]
fn times_are_all_or_none() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    let frame = |i: usize, t: Option<f64>| {
        let mut f = json!({"file_path": format!("./train/r_{i:03}"), "transform_matrix": IDENT});
        if let Some(t) = t {
            f["time"] = json!(t);
        }
        f
    };
    let mixed = json!([frame(0, Some(0.0)), frame(1, None), frame(2, Some(1.0))]);
    write_split(dir.path(), "train", mixed, json!({}));
    let e = err_text(dir.path());
    assert!(
        e.contains("transforms_train.json") && e.contains("frame 1 has no `time`"),
        "{e}"
    );
    let none = json!([frame(0, None), frame(1, None), frame(2, None)]);
    write_split(dir.path(), "train", none, json!({}));
    let d = load_dataset(dir.path(), &LoadOptions::default()).unwrap();
    assert!(d.train.iter().all(|f| f.time == 0.0));
}

#[test]
fn empty_frame_list_is_named() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    write_split(dir.path(), "val", json!([]), json!({}));
    let e = err_text(dir.path());
    assert!(
        e.contains("transforms_val.json") && e.contains("`frames` is empty"),
        "{e}"
    );
}

#[test]
fn unknown_folder_and_bad_png_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let e = err_text(dir.path());
    assert!(e.contains("unknown scene format"), "{e}");
    fixture(dir.path());
    std::fs::write(dir.path().join("train/r_001.png"), b"not a png").unwrap();
    let e = err_text(dir.path());
    assert!(
        e.contains("r_001.png") && e.contains("cannot read image"),
        "{e}"
    );
}
