//! Writers of small scenes in the formats other tools produce (COLMAP sparse models, LLFF
//! `poses_bounds.npy` and `precomputed.json`, nerfstudio `transforms.json`), from cameras in
//! the project's convention: the loaders' round-trip tests and the fuzz seeds.
#![allow(dead_code)]

use scene::colmap::{self, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint, ModelFormat};
use scene::math::{invert, Mat4};
use std::path::Path;

/// `n` cameras on an arc looking at the origin, `w`×`h`, focal `f`, centred principal point.
pub fn arc_cameras(n: usize, w: u32, h: u32, f: f32) -> Vec<splat::Camera> {
    (0..n)
        .map(|k| {
            let a = -0.6 + 1.2 * k as f64 / (n.max(2) - 1) as f64;
            let c = [3.0 * a.sin(), -0.8, -3.0 * a.cos()];
            // forward to the origin, right ⟂ world y, down = forward × right.
            let fwd = norm([-c[0], -c[1], -c[2]]);
            let right = norm(cross([0.0, 1.0, 0.0], fwd));
            let right = [-right[0], -right[1], -right[2]];
            let down = cross(fwd, right);
            let rows = [right, down, fwd];
            let mut v = [[0.0f32; 4]; 4];
            for i in 0..3 {
                for j in 0..3 {
                    v[i][j] = rows[i][j] as f32;
                }
                v[i][3] = -(0..3).map(|j| rows[i][j] * c[j]).sum::<f64>() as f32;
            }
            v[3][3] = 1.0;
            splat::Camera {
                width: w,
                height: h,
                fx: f,
                fy: f,
                cx: 0.5 * w as f32,
                cy: 0.5 * h as f32,
                viewmat: v,
            }
        })
        .collect()
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f64; 3]) -> [f64; 3] {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    a.map(|v| v / n)
}

fn view64(c: &splat::Camera) -> Mat4 {
    c.viewmat.map(|r| r.map(f64::from))
}

/// Camera-to-world (OpenCV columns: right, down, forward).
pub fn c2w(c: &splat::Camera) -> Mat4 {
    invert(&view64(c)).unwrap()
}

/// A PNG of `w`×`h` per frame at `dir/name`, distinct per `k`.
pub fn write_png(path: &Path, w: u32, h: u32, k: usize) {
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([(x * 7 + k as u32 * 13) as u8, (y * 9) as u8, (40 * k) as u8])
    });
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    img.save(path).unwrap();
}

/// Sparse points for the seeds.
pub fn points() -> Vec<ColmapPoint> {
    (0..5)
        .map(|k| ColmapPoint {
            id: k + 1,
            xyz: [0.1 * k as f64, -0.2, 0.3 * k as f64],
            rgb: [10 * k as u8, 200, 255],
            error: 0.5 + 0.1 * k as f64,
            track: vec![(1, k as u32), (2, k as u32)],
        })
        .collect()
}

/// `ROOT/images/frame_KKK.png` and `ROOT/sparse/0/` (one PINHOLE camera).
pub fn write_colmap(root: &Path, cams: &[splat::Camera], format: ModelFormat) {
    let c0 = &cams[0];
    let mut model = ColmapModel::default();
    model.cameras.insert(
        1,
        ColmapCamera {
            id: 1,
            model: 1,
            width: u64::from(c0.width),
            height: u64::from(c0.height),
            params: vec![
                f64::from(c0.fx),
                f64::from(c0.fy),
                f64::from(c0.cx),
                f64::from(c0.cy),
            ],
        },
    );
    // Registered in an order other than the names', as COLMAP's mapper does.
    for (k, c) in cams.iter().enumerate().rev() {
        let v = view64(c);
        let r = [
            [v[0][0], v[0][1], v[0][2]],
            [v[1][0], v[1][1], v[1][2]],
            [v[2][0], v[2][1], v[2][2]],
        ];
        model.images.push(ColmapImage {
            id: k as u32 + 1,
            qvec: colmap::rot_to_quat(&r),
            tvec: [v[0][3], v[1][3], v[2][3]],
            camera_id: 1,
            name: format!("frame_{k:03}.png"),
            points2d: vec![(1.5, 2.5, 1), (3.0, 4.0, u64::MAX)],
        });
        write_png(
            &root.join(format!("images/frame_{k:03}.png")),
            c.width,
            c.height,
            k,
        );
    }
    model.points = points();
    colmap::write_model(&model, &root.join("sparse/0"), format).unwrap();
}

/// `ROOT/poses_bounds.npy` + `ROOT/images/`: LLFF's (down, right, back) columns.
pub fn write_llff_npy(root: &Path, cams: &[splat::Camera]) {
    let mut data = Vec::new();
    for (k, c) in cams.iter().enumerate() {
        let m = c2w(c);
        for r in 0..3 {
            let row = [m[r][1], m[r][0], -m[r][2], m[r][3]];
            data.extend(row);
            data.push([f64::from(c.height), f64::from(c.width), f64::from(c.fx)][r]);
        }
        data.extend([0.5, 10.0]);
        write_png(
            &root.join(format!("images/img{k:03}.png")),
            c.width,
            c.height,
            k,
        );
    }
    let mut npy = Vec::new();
    {
        use npyz::WriterBuilder;
        let mut w = npyz::WriteOptions::<f64>::new()
            .default_dtype()
            .shape(&[cams.len() as u64, 17])
            .writer(&mut npy)
            .begin_nd()
            .unwrap();
        w.extend(data).unwrap();
        w.finish().unwrap();
    }
    std::fs::write(root.join("poses_bounds.npy"), npy).unwrap();
}

/// `ROOT/precomputed.json` + `ROOT/images/`: OpenGL (right, up, back) columns.
pub fn write_precomputed(root: &Path, cams: &[splat::Camera]) {
    let mut poses = Vec::new();
    for (k, c) in cams.iter().enumerate() {
        let m = c2w(c);
        let hwf = [f64::from(c.height), f64::from(c.width), f64::from(c.fx)];
        let pose: Vec<Vec<f64>> = (0..3)
            .map(|r| vec![m[r][0], -m[r][1], -m[r][2], m[r][3], hwf[r]])
            .collect();
        poses.push(pose);
        write_png(
            &root.join(format!("images/image{k:06}.png")),
            c.width,
            c.height,
            k,
        );
    }
    let v = serde_json::json!({"poses": poses, "bds": vec![[0.1, 5.0]; cams.len()], "i_test": 1});
    std::fs::write(
        root.join("precomputed.json"),
        serde_json::to_vec(&v).unwrap(),
    )
    .unwrap();
}

/// `ROOT/transforms.json` (nerfstudio) + `ROOT/images/` + `ROOT/sparse_pc.ply`, with a
/// per-frame `time` when given; frames listed in reverse name order.
pub fn write_nerfstudio(root: &Path, cams: &[splat::Camera], times: Option<&[f64]>) {
    let c0 = &cams[0];
    let mut frames = Vec::new();
    for (k, c) in cams.iter().enumerate().rev() {
        let mut m = c2w(c);
        for row in m.iter_mut().take(3) {
            row[1] = -row[1];
            row[2] = -row[2];
        }
        let mut f = serde_json::json!({
            "file_path": format!("images/frame_{:05}.png", k + 1),
            "transform_matrix": m,
            "colmap_im_id": k + 1,
        });
        if let Some(t) = times {
            f["time"] = serde_json::json!(t[k]);
        }
        frames.push(f);
        write_png(
            &root.join(format!("images/frame_{:05}.png", k + 1)),
            c.width,
            c.height,
            k,
        );
    }
    let v = serde_json::json!({
        "w": c0.width, "h": c0.height, "fl_x": c0.fx, "fl_y": c0.fy, "cx": c0.cx, "cy": c0.cy,
        "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "camera_model": "OPENCV",
        "frames": frames,
        "applied_transform": [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0]],
        "ply_file_path": "sparse_pc.ply",
    });
    std::fs::write(
        root.join("transforms.json"),
        serde_json::to_vec_pretty(&v).unwrap(),
    )
    .unwrap();
    let pts: Vec<[f32; 3]> = points().iter().map(|p| p.xyz.map(|v| v as f32)).collect();
    let cols: Vec<[f32; 3]> = points()
        .iter()
        .map(|p| p.rgb.map(|c| f32::from(c) / 255.0))
        .collect();
    scene::write_ply_points_rgb(&root.join("sparse_pc.ply"), &pts, Some(&cols)).unwrap();
}
