//! D-NeRF / Blender loader: `transforms_{train,val,test}.json`.
//!
//! Follows Deformable-3DGS `readCamerasFromTransforms`: `transform_matrix` is
//! camera-to-world in OpenGL axes (y up, z backward); negating its y and z columns gives
//! OpenCV axes, and its inverse is the world-to-camera `viewmat` (docs/architecture.md).
//! Intrinsics: `fl_x fl_y cx cy` when present (per frame, else at the top level), else `fx = fy = W / (2·tan(camera_angle_x/2))`
//! and the principal point at the image centre.

use crate::math::{invert, to_f32, Mat4};
use crate::{ply, Dataset, DatasetKind, Frame, ImageU8, LoadOptions, SceneError};
use rayon::prelude::*;
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
struct TransformsJson {
    camera_angle_x: Option<f64>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    frames: Vec<FrameJson>,
}

#[derive(Deserialize)]
struct FrameJson {
    file_path: String,
    time: Option<f64>,
    transform_matrix: Vec<Vec<f64>>,
    // Per-frame intrinsics (nerfstudio's convention, written by `semdynreg prepare` when
    // frames have different cameras) override the top-level ones.
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
}

/// Loads a D-NeRF scene folder. `transforms_train.json` is required; val/test are loaded
/// when present (an absent split is empty).
pub fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset, SceneError> {
    let mut splits = Vec::new();
    for split in ["train", "val", "test"] {
        let path = root.join(format!("transforms_{split}.json"));
        if split == "train" || path.is_file() {
            splits.push(load_split(root, &path, opts)?);
        } else {
            tracing::info!("{}: absent, split `{split}` left empty", path.display());
            splits.push(Vec::new());
        }
    }
    let test = splits.pop().unwrap_or_default();
    let val = splits.pop().unwrap_or_default();
    let train = splits.pop().unwrap_or_default();
    let ply_path = root.join("points3d.ply");
    let (point_cloud, point_colors) = if ply_path.is_file() {
        let (p, c) = ply::read_points_rgb(&ply_path)?;
        (Some(p), c)
    } else {
        (None, None)
    };
    Ok(Dataset {
        root: root.to_path_buf(),
        train,
        val,
        test,
        background: opts.background,
        kind: DatasetKind::DNerf,
        point_cloud,
        point_colors,
    })
}

fn load_split(root: &Path, json_path: &Path, opts: &LoadOptions) -> Result<Vec<Frame>, SceneError> {
    let meta: TransformsJson = crate::io::read_json(json_path)?;
    if meta.frames.is_empty() {
        return Err(SceneError::invalid(json_path, "`frames` is empty"));
    }
    if meta.camera_angle_x.is_none()
        && meta.fl_x.is_none()
        && meta.frames.iter().any(|f| f.fl_x.is_none())
    {
        return Err(SceneError::invalid(
            json_path,
            "neither `camera_angle_x` nor `fl_x` is given",
        ));
    }
    check_times(json_path, &meta.frames)?;
    meta.frames
        .par_iter()
        .enumerate()
        .map(|(i, f)| load_frame(root, json_path, &meta, i, f, opts))
        .collect()
}

/// A D-NeRF split gives every frame its `time`, or none (a static Blender scene: every
/// frame at t = 0, said once). Some with and some without is an error: the missing ones
/// would silently sit at t = 0.
fn check_times(json_path: &Path, frames: &[FrameJson]) -> Result<(), SceneError> {
    match frames.iter().position(|f| f.time.is_none()) {
        None => Ok(()),
        Some(_) if frames.iter().all(|f| f.time.is_none()) => {
            tracing::warn!(
                "{}: no frame has a `time`: a static scene, every frame at t = 0",
                json_path.display()
            );
            Ok(())
        }
        Some(i) => Err(SceneError::invalid(
            json_path,
            format!("frame {i} has no `time`, but other frames do"),
        )),
    }
}

fn load_frame(
    root: &Path,
    json_path: &Path,
    meta: &TransformsJson,
    index: usize,
    f: &FrameJson,
    opts: &LoadOptions,
) -> Result<Frame, SceneError> {
    let (image_path, file_path) = resolve_image(root, &f.file_path);
    if !image_path.is_file() {
        return Err(SceneError::invalid(
            json_path,
            format!(
                "frame {index}: image {} does not exist",
                image_path.display()
            ),
        ));
    }
    let image = ImageU8::load(&image_path, opts.background)?;
    check_size(json_path, &image_path, meta, &image)?;
    let c2w = parse_matrix(json_path, index, &f.transform_matrix)?;
    let viewmat = opengl_c2w_to_viewmat(&c2w).ok_or_else(|| {
        SceneError::invalid(
            json_path,
            format!("frame {index}: transform_matrix is singular or not finite"),
        )
    })?;
    let time = f.time.unwrap_or(0.0) as f32;
    if !time.is_finite() {
        return Err(SceneError::invalid(
            json_path,
            format!("frame {index}: time is not finite"),
        ));
    }
    let camera = intrinsics(meta, f, image.width, image.height, viewmat, opts.downscale)
        .map_err(|msg| SceneError::invalid(json_path, format!("frame {index}: {msg}")))?;
    let image = image.downscale(opts.downscale);
    if image.width == 0 || image.height == 0 {
        return Err(SceneError::invalid(
            &image_path,
            format!("smaller than the downscale factor {}", opts.downscale),
        ));
    }
    Ok(Frame {
        file_path,
        time,
        camera,
        image,
    })
}

/// D-NeRF `file_path`s look like `./train/r_000` (extension implied, `.png`); some
/// exports include the extension. Returns the image path and the normalized key.
fn resolve_image(root: &Path, file_path: &str) -> (PathBuf, String) {
    let rel = file_path.trim_start_matches("./");
    let as_is = root.join(rel);
    let has_ext = Path::new(rel).extension().is_some_and(|e| {
        let e = e.to_ascii_lowercase();
        e == "png" || e == "jpg" || e == "jpeg"
    });
    if has_ext {
        let key = Path::new(rel)
            .with_extension("")
            .to_string_lossy()
            .replace('\\', "/");
        (as_is, key)
    } else {
        (root.join(format!("{rel}.png")), rel.to_string())
    }
}

fn check_size(
    json_path: &Path,
    image_path: &Path,
    meta: &TransformsJson,
    image: &ImageU8,
) -> Result<(), SceneError> {
    if let (Some(w), Some(h)) = (meta.w, meta.h) {
        if (w.round() as i64, h.round() as i64) != (i64::from(image.width), i64::from(image.height))
        {
            return Err(SceneError::invalid(
                json_path,
                format!(
                    "image {} is {}×{} but the JSON says w = {w}, h = {h}",
                    image_path.display(),
                    image.width,
                    image.height
                ),
            ));
        }
    }
    Ok(())
}

fn parse_matrix(json_path: &Path, index: usize, rows: &[Vec<f64>]) -> Result<Mat4, SceneError> {
    let shape_ok = (rows.len() == 4 || rows.len() == 3) && rows.iter().all(|r| r.len() == 4);
    if !shape_ok {
        return Err(SceneError::invalid(
            json_path,
            format!("frame {index}: transform_matrix must be 4×4 (or 3×4)"),
        ));
    }
    let mut m = crate::math::IDENTITY;
    for (r, row) in rows.iter().enumerate() {
        for (c, &v) in row.iter().enumerate() {
            if !(v as f32).is_finite() {
                return Err(SceneError::invalid(
                    json_path,
                    format!("frame {index}: transform_matrix[{r}][{c}] = {v} is not a finite f32"),
                ));
            }
            m[r][c] = v;
        }
    }
    Ok(m)
}

/// OpenGL camera-to-world → OpenCV world-to-camera (docs/architecture.md conventions).
pub(crate) fn opengl_c2w_to_viewmat(c2w: &Mat4) -> Option<[[f32; 4]; 4]> {
    let mut m = *c2w;
    for row in m.iter_mut().take(3) {
        row[1] = -row[1];
        row[2] = -row[2];
    }
    to_f32(&invert(&m)?)
}

fn intrinsics(
    meta: &TransformsJson,
    frame: &FrameJson,
    width: u32,
    height: u32,
    viewmat: [[f32; 4]; 4],
    downscale: u32,
) -> Result<splat::Camera, String> {
    let fx = frame.fl_x.or(meta.fl_x).unwrap_or_else(|| {
        0.5 * f64::from(width) / (0.5 * meta.camera_angle_x.unwrap_or(1.0)).tan()
    });
    let fy = frame.fl_y.or(meta.fl_y).unwrap_or(fx);
    let cx = frame.cx.or(meta.cx).unwrap_or(0.5 * f64::from(width));
    let cy = frame.cy.or(meta.cy).unwrap_or(0.5 * f64::from(height));
    // A factor-f box filter maps pixel coordinate u to u/f exactly (edges stay on edges).
    let s = 1.0 / f64::from(downscale.max(1));
    let (fx, fy, cx, cy) = (
        (fx * s) as f32,
        (fy * s) as f32,
        (cx * s) as f32,
        (cy * s) as f32,
    );
    // `camera_angle_x` of 0 or π, a zero or huge `fl_x`, `cx` beyond f32: the rasterizer
    // would divide by these, so they are refused here, where the file can be named.
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
        return Err(format!(
            "focal length fx = {fx}, fy = {fy} (from fl_x/fl_y/camera_angle_x) must be finite and > 0"
        ));
    }
    if !(cx.is_finite() && cy.is_finite()) {
        return Err(format!(
            "principal point cx = {cx}, cy = {cy} is not finite"
        ));
    }
    Ok(splat::Camera {
        width: width / downscale.max(1),
        height: height / downscale.max(1),
        fx,
        fy,
        cx,
        cy,
        viewmat,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blender_camera_looking_down_minus_z_sees_origin_in_front() {
        // Camera at (0,0,4) in OpenGL axes looks along −z: the origin must be at depth 4
        // straight ahead (OpenCV z forward) and world +y must be image up (camera −y).
        let c2w = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 4.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let v = opengl_c2w_to_viewmat(&c2w).unwrap();
        let cam = splat::Camera {
            width: 10,
            height: 10,
            fx: 10.0,
            fy: 10.0,
            cx: 5.0,
            cy: 5.0,
            viewmat: v,
        };
        let p = cam.to_camera([0.0, 0.0, 0.0]);
        assert!((p[2] - 4.0).abs() < 1e-6 && p[0].abs() < 1e-6 && p[1].abs() < 1e-6);
        assert!(cam.to_camera([0.0, 1.0, 0.0])[1] < 0.0);
    }

    #[test]
    fn file_paths_are_normalized() {
        let (p, k) = resolve_image(Path::new("/s"), "./train/r_001");
        assert_eq!(
            (p, k.as_str()),
            (PathBuf::from("/s/train/r_001.png"), "train/r_001")
        );
        let (p, k) = resolve_image(Path::new("/s"), "train/r_001.jpg");
        assert_eq!(
            (p, k.as_str()),
            (PathBuf::from("/s/train/r_001.jpg"), "train/r_001")
        );
    }
}
