//! Nerfies/HyperNeRF loader on a fixture written here: camera convention
//! (`p_cam = orientation · (p − position)`), scene.json normalization, rgb/{N}x/ choice,
//! time normalization, and named errors.

use scene::{load_dataset, DatasetKind, ImageU8, LoadOptions};
use serde_json::json;
use std::path::Path;

fn write(path: &Path, v: serde_json::Value) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, serde_json::to_vec(&v).unwrap()).unwrap();
}

/// Camera 90° about y: camera z (forward) = world −x; it sits at world x = 3 (before the
/// scene.json normalization), so it looks at the origin.
fn fixture(root: &Path) {
    let ids = ["a", "b", "c", "d", "e"];
    write(
        &root.join("dataset.json"),
        json!({"count": 5, "num_exemplars": 5, "ids": ids}),
    );
    let meta: serde_json::Map<String, serde_json::Value> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| {
            (
                id.to_string(),
                json!({"time_id": i * 2, "warp_id": i * 2, "camera_id": 0}),
            )
        })
        .collect();
    write(&root.join("metadata.json"), json!(meta));
    write(
        &root.join("scene.json"),
        json!({"center": [1.0, 0.0, 0.0], "scale": 0.5, "near": 0.1, "far": 10.0}),
    );
    for id in ids {
        write(
            &root.join(format!("camera/{id}.json")),
            json!({"orientation": [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]], "position": [5.0, 0.0, 0.0],
                   "focal_length": 8.0, "principal_point": [4.0, 3.0], "skew": 0.0, "pixel_aspect_ratio": 1.5,
                   "radial_distortion": [0.0, 0.0, 0.0], "tangential_distortion": [0.0, 0.0], "image_size": [8, 6]}),
        );
        ImageU8 {
            width: 8,
            height: 6,
            data: vec![200; 8 * 6 * 3],
        }
        .save_png(&root.join(format!("rgb/1x/{id}.png")))
        .unwrap();
        ImageU8 {
            width: 4,
            height: 3,
            data: vec![100; 4 * 3 * 3],
        }
        .save_png(&root.join(format!("rgb/2x/{id}.png")))
        .unwrap();
    }
}

#[test]
fn loads_nerfies_cameras_and_times() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    let ds = load_dataset(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(ds.kind, DatasetKind::Nerfies);
    // HyperNeRF split: ids[::4] train (a, e), ids[2::4] val/test (c).
    let names: Vec<&str> = ds.train.iter().map(|f| f.file_path.as_str()).collect();
    assert_eq!(names, ["a", "e"]);
    assert_eq!(ds.val[0].file_path, "c");
    assert_eq!(
        (ds.train[0].time, ds.train[1].time, ds.val[0].time),
        (0.0, 1.0, 0.5)
    );
    let cam = &ds.train[0].camera;
    assert_eq!((cam.fx, cam.fy, cam.cx, cam.cy), (8.0, 12.0, 4.0, 3.0));
    // Normalized centre: (5 − 1)·0.5 = 2 on x. The world origin is 2 units ahead.
    let c = cam.center();
    assert!(
        (c[0] - 2.0).abs() < 1e-6 && c[1].abs() < 1e-6 && c[2].abs() < 1e-6,
        "{c:?}"
    );
    let (px, depth) = cam.project([0.0, 0.0, 0.0]).unwrap();
    assert!((px[0] - 4.0).abs() < 1e-5 && (px[1] - 3.0).abs() < 1e-5 && (depth - 2.0).abs() < 1e-6);
    // World +z is camera +x (orientation row 0): it projects right of centre.
    assert!(cam.project([0.0, 0.0, 0.1]).unwrap().0[0] > 4.0);
}

#[test]
fn downscale_uses_prescaled_folder() {
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
    let f = &ds.train[0];
    assert_eq!(
        (f.image.width, f.image.height, f.image.data[0]),
        (4, 3, 100)
    );
    assert_eq!((f.camera.fx, f.camera.cx, f.camera.width), (4.0, 2.0, 4));
}

#[test]
fn bad_nerfies_inputs_are_named() {
    let dir = tempfile::tempdir().unwrap();
    fixture(dir.path());
    std::fs::remove_file(dir.path().join("camera/e.json")).unwrap();
    let e = load_dataset(dir.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("e.json"), "{e}");

    fixture(dir.path());
    ImageU8 {
        width: 7,
        height: 6,
        data: vec![0; 7 * 6 * 3],
    }
    .save_png(&dir.path().join("rgb/1x/a.png"))
    .unwrap();
    let e = load_dataset(dir.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("a.json") && e.contains("is 7×6"), "{e}");

    fixture(dir.path());
    write(
        &dir.path().join("metadata.json"),
        json!({"a": {"time_id": 0}}),
    );
    let e = load_dataset(dir.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("metadata.json") && e.contains("no entry for id `e`"),
        "{e}"
    );

    write(&dir.path().join("dataset.json"), json!({"ids": []}));
    let e = load_dataset(dir.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("dataset.json") && e.contains("empty"), "{e}");
}
