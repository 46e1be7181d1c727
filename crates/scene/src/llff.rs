//! LLFF scenes: `poses_bounds.npy` (LLFF's `imgs2poses`, Mildenhall et al. 2019,
//! <https://github.com/Fyusion/LLFF>) or `precomputed.json` (the poses after
//! nerf-pytorch's `load_llff_data`, as Non-Rigid NeRF's `preprocess.py` stores them), with
//! the images in `images/` in file-name order.
//!
//! `poses_bounds.npy` is an N × 17 array: per frame a row-major 3 × 5 matrix — a
//! camera-to-world 3 × 4 whose rotation columns are the camera's (down, right, backwards)
//! axes in COLMAP's world, then the column `[height, width, focal]` — and the near/far
//! bounds. OpenCV axes (right, down, forward) are the columns (1, 0, −2).
//!
//! `precomputed.json` holds `poses` (N × 3 × 5) already turned to OpenGL axes (right, up,
//! backwards), recentred and rescaled, with the same fifth column, and `bds`, `i_test`.
//!
//! The focal length is for `width`: for images of another size it is scaled by their width
//! (nerf-pytorch does this for `images_N/`). The principal point is the image centre. Time
//! is the frame order; every 8th frame is held out (LLFF's `llffhold`). The points of a
//! COLMAP model in `sparse/0/` are used for `poses_bounds.npy` (same world); a
//! `precomputed.json` scene was rescaled, so it has none.

use crate::colmap::{pinhole_frame, split_holdout};
use crate::math::Mat4;
use crate::{Dataset, DatasetKind, Frame, LoadOptions, SceneError};
use rayon::prelude::*;
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
struct Precomputed {
    poses: Vec<[[f64; 5]; 3]>,
}

/// Loads `ROOT/poses_bounds.npy` (preferred) or `ROOT/precomputed.json` with `ROOT/images/`.
pub fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset, SceneError> {
    let npy = root.join("poses_bounds.npy");
    let (source, poses, opengl) = if npy.is_file() {
        (npy.clone(), read_poses_bounds(&npy)?, false)
    } else {
        let p = root.join("precomputed.json");
        let pre: Precomputed = crate::io::read_json(&p)?;
        (p, pre.poses, true)
    };
    if poses.is_empty() {
        return Err(SceneError::invalid(&source, "no poses"));
    }
    let images = list_images(&root.join("images"))?;
    if images.len() != poses.len() {
        return Err(SceneError::invalid(
            &source,
            format!(
                "{} poses but {} images in {}",
                poses.len(),
                images.len(),
                root.join("images").display()
            ),
        ));
    }
    let n = poses.len();
    let frames = poses
        .par_iter()
        .zip(images.par_iter())
        .enumerate()
        .map(|(k, (m, img))| {
            let [h, w, f] = [m[0][4], m[1][4], m[2][4]];
            let viewmat = viewmat_of(m, opengl).ok_or_else(|| {
                SceneError::invalid(&source, format!("pose {k} is singular or not finite"))
            })?;
            let key = format!(
                "images/{}",
                Path::new(img.file_name().unwrap_or_default())
                    .with_extension("")
                    .to_string_lossy()
            );
            let time = if n > 1 {
                k as f32 / (n - 1) as f32
            } else {
                0.0
            };
            let frame = pinhole_frame(
                img,
                key,
                time,
                [w, h],
                [f, f, 0.5 * w, 0.5 * h],
                viewmat,
                opts,
                &source,
            )?;
            Ok((k, frame))
        })
        .collect::<Result<Vec<(usize, Frame)>, SceneError>>()?;
    let (train, test) = split_holdout(frames);
    let (point_cloud, point_colors) = if opengl {
        (None, None)
    } else {
        crate::colmap::read_points_of_dir(&root.join("sparse").join("0"))?
    };
    Ok(Dataset {
        root: root.to_path_buf(),
        train,
        val: test.clone(),
        test,
        background: opts.background,
        kind: DatasetKind::Llff,
        point_cloud,
        point_colors,
    })
}

/// Image files (png, jpg, jpeg; any case) of a folder in file-name order.
pub(crate) fn list_images(dir: &Path) -> Result<Vec<PathBuf>, SceneError> {
    let rd = std::fs::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
    let mut out = Vec::new();
    for e in rd {
        let p = e.map_err(|e| SceneError::io(dir, e))?.path();
        let ext = p
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        if p.is_file() && matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg")) {
            out.push(p);
        }
    }
    out.sort();
    Ok(out)
}

/// The world-to-camera (OpenCV) of one 3 × 5 pose; `None` when singular or not finite.
fn viewmat_of(m: &[[f64; 5]; 3], opengl: bool) -> Option<[[f32; 4]; 4]> {
    if m.iter().flatten().any(|v| !(*v as f32).is_finite()) {
        return None;
    }
    let mut c2w: Mat4 = crate::math::IDENTITY;
    for r in 0..3 {
        let (right, down, fwd) = if opengl {
            // (right, up, back)
            (m[r][0], -m[r][1], -m[r][2])
        } else {
            // (down, right, back)
            (m[r][1], m[r][0], -m[r][2])
        };
        c2w[r] = [right, down, fwd, m[r][3]];
    }
    crate::math::to_f32(&crate::math::invert(&c2w)?)
}

/// `poses_bounds.npy` as 3 × 5 matrices (f32 or f64, shape (N, 17)).
fn read_poses_bounds(path: &Path) -> Result<Vec<[[f64; 5]; 3]>, SceneError> {
    let flat = crate::nerfies::read_npy_f64(path, 17)?;
    Ok(flat
        .chunks_exact(17)
        .map(|r| std::array::from_fn(|i| std::array::from_fn(|j| r[5 * i + j])))
        .collect())
}
