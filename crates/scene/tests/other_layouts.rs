//! The layouts other tools write — COLMAP sparse models (binary and text), LLFF
//! (`poses_bounds.npy`, `precomputed.json`) and nerfstudio's `transforms.json` — loaded by
//! `scene::load_dataset`: round trips of a known camera set, and each format's axis
//! convention checked from its definition (a camera in front of the origin must see it at
//! the principal point, world +x to the right and world +y up), not from our writer.

#[path = "formats_common/mod.rs"]
mod formats_common;

use formats_common::*;
use scene::colmap::ModelFormat;
use scene::{load_dataset, DatasetKind, Frame, LoadOptions};
use std::path::Path;

fn load(root: &Path) -> scene::Dataset {
    load_dataset(root, &LoadOptions::default()).unwrap()
}

/// All frames in file-name order.
fn frames(ds: &scene::Dataset) -> Vec<&Frame> {
    let mut f: Vec<&Frame> = ds.all_frames().collect();
    f.sort_by(|a, b| a.file_path.cmp(&b.file_path));
    f.dedup_by(|a, b| a.file_path == b.file_path);
    f
}

fn assert_same(got: &[&Frame], want: &[splat::Camera], tol: f32) {
    assert_eq!(got.len(), want.len());
    for (f, c) in got.iter().zip(want) {
        let g = &f.camera;
        assert_eq!((g.width, g.height), (c.width, c.height), "{}", f.file_path);
        for (a, b) in [(g.fx, c.fx), (g.fy, c.fy), (g.cx, c.cx), (g.cy, c.cy)] {
            assert!((a - b).abs() < 1e-3, "{}: {g:?} vs {c:?}", f.file_path);
        }
        for r in 0..4 {
            for k in 0..4 {
                assert!(
                    (g.viewmat[r][k] - c.viewmat[r][k]).abs() < tol,
                    "{}: viewmat {:?} vs {:?}",
                    f.file_path,
                    g.viewmat,
                    c.viewmat
                );
            }
        }
    }
}

fn times(got: &[&Frame]) -> Vec<f32> {
    got.iter().map(|f| f.time).collect()
}

#[test]
fn colmap_binary_and_text_round_trip() {
    let cams = arc_cameras(10, 32, 24, 30.0);
    for format in [ModelFormat::Binary, ModelFormat::Text] {
        let dir = tempfile::tempdir().unwrap();
        write_colmap(dir.path(), &cams, format);
        let ds = load(dir.path());
        assert_eq!(ds.kind, DatasetKind::Colmap);
        let f = frames(&ds);
        assert_same(&f, &cams, 1e-5);
        assert_eq!(f[0].file_path, "images/frame_000");
        let t = times(&f);
        assert!(
            (t[0] - 0.0).abs() < 1e-6
                && (t[9] - 1.0).abs() < 1e-6
                && (t[3] - 1.0 / 3.0).abs() < 1e-6
        );
        // Every 8th frame in name order is held out: frames 0 and 8.
        let test: Vec<&str> = ds.test.iter().map(|f| f.file_path.as_str()).collect();
        assert_eq!(test, ["images/frame_000", "images/frame_008"]);
        assert_eq!(ds.train.len(), 8);
        let pts = ds.point_cloud.as_ref().unwrap();
        assert_eq!(pts.len(), 5);
        assert!((pts[2][2] - 0.6).abs() < 1e-6);
        let cols = ds.point_colors.as_ref().unwrap();
        assert!((cols[1][0] - 10.0 / 255.0).abs() < 1e-6);
        // The model itself survives the write/read exactly.
        let m = scene::colmap::read_model(&dir.path().join("sparse/0")).unwrap();
        let b = tempfile::tempdir().unwrap();
        scene::colmap::write_model(&m, b.path(), format).unwrap();
        assert_eq!(scene::colmap::read_model(b.path()).unwrap(), m);
    }
}

#[test]
fn llff_and_precomputed_round_trip() {
    let cams = arc_cameras(9, 32, 24, 28.0);
    let dir = tempfile::tempdir().unwrap();
    write_llff_npy(dir.path(), &cams);
    let ds = load(dir.path());
    assert_eq!(ds.kind, DatasetKind::Llff);
    assert_same(&frames(&ds), &cams, 1e-5);
    assert!(ds.point_cloud.is_none());
    // The points of a COLMAP model beside it are in the same world.
    write_colmap(&dir.path().join("colmap_tmp"), &cams, ModelFormat::Binary);
    std::fs::rename(
        dir.path().join("colmap_tmp/sparse"),
        dir.path().join("sparse"),
    )
    .unwrap();
    assert_eq!(load(dir.path()).point_cloud.unwrap().len(), 5);

    let dir = tempfile::tempdir().unwrap();
    write_precomputed(dir.path(), &cams);
    let ds = load(dir.path());
    assert_eq!(ds.kind, DatasetKind::Llff);
    let f = frames(&ds);
    assert_same(&f, &cams, 1e-5);
    assert_eq!(f[0].file_path, "images/image000000");
    assert_eq!(times(&f)[8], 1.0);
    // Downscaled: the focal length follows the image.
    let half = load_dataset(
        dir.path(),
        &LoadOptions {
            downscale: 2,
            ..Default::default()
        },
    )
    .unwrap();
    let c = &half.train[0].camera;
    assert_eq!((c.width, c.height, c.fx, c.cx), (16, 12, 14.0, 8.0));
}

#[test]
fn nerfstudio_round_trip_with_and_without_time() {
    let cams = arc_cameras(9, 32, 24, 26.0);
    let dir = tempfile::tempdir().unwrap();
    write_nerfstudio(dir.path(), &cams, None);
    let ds = load(dir.path());
    assert_eq!(ds.kind, DatasetKind::Nerfstudio);
    let f = frames(&ds);
    assert_same(&f, &cams, 1e-5);
    assert_eq!(f[0].file_path, "images/frame_00001");
    assert_eq!(times(&f)[4], 0.5);
    assert_eq!(ds.test.len(), 2);
    assert_eq!(ds.point_cloud.as_ref().unwrap().len(), 5);

    // Times in seconds are mapped onto [0, 1]; a frame without one among others is an error.
    let secs: Vec<f64> = (0..9).map(|k| 10.0 + 0.5 * (k * k) as f64).collect();
    write_nerfstudio(dir.path(), &cams, Some(&secs));
    let f2 = load(dir.path());
    let got = times(&frames(&f2));
    assert!(
        (got[2] - 2.0 / 32.0).abs() < 1e-6 && got[8] == 1.0 && got[0] == 0.0,
        "{got:?}"
    );
    let mut v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("transforms.json")).unwrap())
            .unwrap();
    v["frames"][3].as_object_mut().unwrap().remove("time");
    std::fs::write(dir.path().join("transforms.json"), v.to_string()).unwrap();
    let e = load_dataset(dir.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("transforms.json") && e.contains("no `time`"),
        "{e}"
    );
}

/// One camera 5 units from the origin looking at it, in each format's own axes: the origin
/// must project to the principal point at depth 5, world +x to the right, world +y up
/// (the camera's "up" is world +y in every case below).
#[test]
fn each_format_convention_from_its_definition() {
    let (w, h, f) = (32u32, 24u32, 30.0f64);
    let check = |ds: &scene::Dataset, what: &str| {
        let c = &ds.train.first().or(ds.test.first()).unwrap().camera;
        let (px, z) = c.project([0.0, 0.0, 0.0]).unwrap();
        assert!((z - 5.0).abs() < 1e-4, "{what}: depth {z}");
        assert!(
            (px[0] - 16.0).abs() < 1e-3 && (px[1] - 12.0).abs() < 1e-3,
            "{what}: {px:?}"
        );
        let (r, _) = c.project([0.5, 0.0, 0.0]).unwrap();
        assert!(r[0] > 16.5, "{what}: world +x must be image right: {r:?}");
        let (u, _) = c.project([0.0, 0.5, 0.0]).unwrap();
        assert!(u[1] < 11.5, "{what}: world +y must be image up: {u:?}");
    };
    // Camera at z = +5 looking down −z, up +y: OpenGL columns right (1,0,0), up (0,1,0),
    // back (0,0,1); OpenCV's world-to-camera rotation diag(1, −1, −1).
    let png = |root: &Path, name: &str| write_png(&root.join(name), w, h, 0);

    // COLMAP: world-to-camera qvec of diag(1,−1,−1) = rotation by π about x: (0, 1, 0, 0);
    // t = −R·c = (0, 0, 5).
    for fmt in ["bin", "txt"] {
        let d = tempfile::tempdir().unwrap();
        let r = d.path();
        std::fs::create_dir_all(r.join("sparse/0")).unwrap();
        png(r, "images/a.png");
        png(r, "images/b.png");
        if fmt == "txt" {
            std::fs::write(
                r.join("sparse/0/cameras.txt"),
                format!("# c\n1 SIMPLE_PINHOLE {w} {h} {f} 16 12\n"),
            )
            .unwrap();
            std::fs::write(
                r.join("sparse/0/images.txt"),
                "# i\n1 0 1 0 0 0 0 5 1 b.png\n\n2 0 1 0 0 0 0 5 1 a.png\n1 2 -1 3.5 4 7\n",
            )
            .unwrap();
        } else {
            let mut m = scene::colmap::ColmapModel::default();
            m.cameras.insert(
                1,
                scene::colmap::ColmapCamera {
                    id: 1,
                    model: 0,
                    width: w.into(),
                    height: h.into(),
                    params: vec![f, 16.0, 12.0],
                },
            );
            for (id, name) in [(1, "b.png"), (2, "a.png")] {
                m.images.push(scene::colmap::ColmapImage {
                    id,
                    qvec: [0.0, 1.0, 0.0, 0.0],
                    tvec: [0.0, 0.0, 5.0],
                    camera_id: 1,
                    name: name.into(),
                    points2d: Vec::new(),
                });
            }
            scene::colmap::write_model(&m, &r.join("sparse/0"), ModelFormat::Binary).unwrap();
        }
        let ds = load(r);
        check(&ds, &format!("COLMAP {fmt}"));
        assert_eq!(ds.test[0].file_path, "images/a", "name order");
    }

    // LLFF poses_bounds.npy: columns (down, right, back) = ((0,−1,0), (1,0,0), (0,0,1)).
    {
        let d = tempfile::tempdir().unwrap();
        let r = d.path();
        png(r, "images/0.png");
        let rows = [
            [0.0, 1.0, 0.0, 0.0, f64::from(h)],
            [-1.0, 0.0, 0.0, 0.0, f64::from(w)],
            [0.0, 0.0, 1.0, 5.0, f],
        ];
        let mut data: Vec<f64> = rows.iter().flatten().copied().collect();
        data.extend([1.0, 10.0]);
        let mut npy = Vec::new();
        {
            use npyz::WriterBuilder;
            let mut wr = npyz::WriteOptions::<f64>::new()
                .default_dtype()
                .shape(&[1, 17])
                .writer(&mut npy)
                .begin_nd()
                .unwrap();
            wr.extend(data).unwrap();
            wr.finish().unwrap();
        }
        std::fs::write(r.join("poses_bounds.npy"), npy).unwrap();
        check(&load(r), "LLFF poses_bounds.npy");
    }
    // precomputed.json and nerfstudio: OpenGL columns (right, up, back).
    let gl = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 5.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    {
        let d = tempfile::tempdir().unwrap();
        let r = d.path();
        png(r, "images/0.png");
        let hwf = [f64::from(h), f64::from(w), f];
        let pose: Vec<Vec<f64>> = (0..3)
            .map(|i| {
                let mut row = gl[i].to_vec();
                row.push(hwf[i]);
                row
            })
            .collect();
        let v = serde_json::json!({"poses": [pose]});
        std::fs::write(r.join("precomputed.json"), v.to_string()).unwrap();
        check(&load(r), "LLFF precomputed.json");
    }
    {
        let d = tempfile::tempdir().unwrap();
        let r = d.path();
        png(r, "images/0.png");
        let v = serde_json::json!({"fl_x": f, "w": w, "h": h,
            "frames": [{"file_path": "images/0.png", "transform_matrix": gl}]});
        std::fs::write(r.join("transforms.json"), v.to_string()).unwrap();
        check(&load(r), "nerfstudio transforms.json");
    }
}

#[test]
fn broken_layouts_name_the_file() {
    let cams = arc_cameras(4, 32, 24, 30.0);
    let d = tempfile::tempdir().unwrap();
    write_colmap(d.path(), &cams, ModelFormat::Binary);
    std::fs::remove_file(d.path().join("images/frame_002.png")).unwrap();
    let e = load_dataset(d.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("frame_002.png") && e.contains("does not exist"),
        "{e}"
    );

    let d = tempfile::tempdir().unwrap();
    write_llff_npy(d.path(), &cams);
    std::fs::remove_file(d.path().join("images/img003.png")).unwrap();
    let e = load_dataset(d.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("poses_bounds.npy") && e.contains("4 poses but 3 images"),
        "{e}"
    );

    let d = tempfile::tempdir().unwrap();
    let e = load_dataset(d.path(), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unknown scene format") && e.contains("prepare"),
        "{e}"
    );
}
