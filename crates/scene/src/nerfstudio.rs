//! nerfstudio's `transforms.json` (written by `ns-process-data`; format:
//! <https://docs.nerf.studio/quickstart/data_conventions.html>).
//!
//! `transform_matrix` is camera-to-world with OpenGL axes, as in D-NeRF (converted the same
//! way, `dnerf::opengl_c2w_to_viewmat`). Intrinsics `fl_x fl_y cx cy w h` are given at the
//! top level or per frame (a frame's own win); `file_path` is relative to the JSON's folder
//! and includes its extension. Distortion (`k1 k2 k3 k4 p1 p2`) is ignored with a warning.
//! Time: a per-frame `time` when every frame has one (kept when all lie in [0, 1], else
//! mapped linearly from [min, max] onto it),
//! else the frame order by `file_path`. Splits: `train_filenames` / `test_filenames` (and
//! `val_filenames`) when given, else every 8th frame in `file_path` order is held out. The
//! `ply_file_path` point cloud (nerfstudio writes it in the frame of the poses) is loaded
//! when present.

use crate::colmap::{pinhole_frame, HOLDOUT};
use crate::dnerf::opengl_c2w_to_viewmat;
use crate::{Dataset, DatasetKind, Frame, LoadOptions, SceneError};
use rayon::prelude::*;
use serde::Deserialize;
use std::collections::HashSet;
use std::path::Path;

#[derive(Deserialize, Default, Clone, Copy)]
struct Intrinsics {
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    k1: Option<f64>,
    k2: Option<f64>,
    k3: Option<f64>,
    k4: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
}

impl Intrinsics {
    fn or(self, d: Intrinsics) -> Intrinsics {
        Intrinsics {
            fl_x: self.fl_x.or(d.fl_x),
            fl_y: self.fl_y.or(d.fl_y),
            cx: self.cx.or(d.cx),
            cy: self.cy.or(d.cy),
            w: self.w.or(d.w),
            h: self.h.or(d.h),
            k1: self.k1.or(d.k1),
            k2: self.k2.or(d.k2),
            k3: self.k3.or(d.k3),
            k4: self.k4.or(d.k4),
            p1: self.p1.or(d.p1),
            p2: self.p2.or(d.p2),
        }
    }

    fn distorted(&self) -> bool {
        [self.k1, self.k2, self.k3, self.k4, self.p1, self.p2]
            .iter()
            .any(|v| v.is_some_and(|v| v != 0.0))
    }
}

#[derive(Deserialize)]
struct TransformsJson {
    #[serde(flatten)]
    intrinsics: Intrinsics,
    frames: Vec<FrameJson>,
    ply_file_path: Option<String>,
    train_filenames: Option<Vec<String>>,
    val_filenames: Option<Vec<String>>,
    test_filenames: Option<Vec<String>>,
}

#[derive(Deserialize)]
struct FrameJson {
    file_path: String,
    transform_matrix: Vec<Vec<f64>>,
    time: Option<f64>,
    #[serde(flatten)]
    intrinsics: Intrinsics,
}

/// Loads `ROOT/transforms.json` and its images.
pub fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset, SceneError> {
    let json_path = root.join("transforms.json");
    let meta: TransformsJson = crate::io::read_json(&json_path)?;
    if meta.frames.is_empty() {
        return Err(SceneError::invalid(&json_path, "`frames` is empty"));
    }
    let mut order: Vec<usize> = (0..meta.frames.len()).collect();
    order.sort_by(|&a, &b| meta.frames[a].file_path.cmp(&meta.frames[b].file_path));
    let times = times(&json_path, &meta.frames, &order)?;
    if meta
        .frames
        .iter()
        .any(|f| f.intrinsics.or(meta.intrinsics).distorted())
    {
        tracing::warn!(
            "{}: lens distortion (k1…p2) is ignored (the rasterizer is a pinhole); undistort the images first",
            json_path.display()
        );
    }
    let frames = order
        .par_iter()
        .enumerate()
        .map(|(rank, &i)| {
            let f = &meta.frames[i];
            load_frame(root, &json_path, &meta, i, f, times[i], opts).map(|fr| (rank, i, fr))
        })
        .collect::<Result<Vec<(usize, usize, Frame)>, SceneError>>()?;
    let (train, val, test) = split(&json_path, &meta, frames)?;
    let (point_cloud, point_colors) = match &meta.ply_file_path {
        Some(p) => {
            let path = root.join(p.trim_start_matches("./"));
            let (pts, cols) = crate::ply::read_points_rgb(&path)?;
            (Some(pts), cols)
        }
        None => (None, None),
    };
    Ok(Dataset {
        root: root.to_path_buf(),
        train,
        val,
        test,
        background: opts.background,
        kind: DatasetKind::Nerfstudio,
        point_cloud,
        point_colors,
    })
}

/// Per-frame `time` for all frames (divided by the largest), none (frame order), or an
/// error when only some have one.
fn times(path: &Path, frames: &[FrameJson], order: &[usize]) -> Result<Vec<f32>, SceneError> {
    let n = frames.len();
    if frames.iter().all(|f| f.time.is_none()) {
        let mut t = vec![0.0; n];
        for (rank, &i) in order.iter().enumerate() {
            t[i] = if n > 1 {
                rank as f32 / (n - 1) as f32
            } else {
                0.0
            };
        }
        return Ok(t);
    }
    let mut raw = Vec::with_capacity(n);
    for (i, f) in frames.iter().enumerate() {
        let t = f.time.ok_or_else(|| {
            SceneError::invalid(
                path,
                format!("frame {i} has no `time`, but other frames do"),
            )
        })?;
        if !(t.is_finite() && t >= 0.0) {
            return Err(SceneError::invalid(
                path,
                format!("frame {i}: time {t} is not a finite number ≥ 0"),
            ));
        }
        raw.push(t);
    }
    let max = raw.iter().fold(0.0f64, |a, &b| a.max(b));
    let min = raw.iter().fold(f64::INFINITY, |a, &b| a.min(b));
    // Times already in [0, 1] are kept; others (seconds, frame numbers) are mapped onto it.
    Ok(raw
        .into_iter()
        .map(|t| {
            if max <= 1.0 || max - min <= 0.0 {
                t as f32
            } else {
                ((t - min) / (max - min)) as f32
            }
        })
        .collect())
}

fn load_frame(
    root: &Path,
    json_path: &Path,
    meta: &TransformsJson,
    index: usize,
    f: &FrameJson,
    time: f32,
    opts: &LoadOptions,
) -> Result<Frame, SceneError> {
    let k = f.intrinsics.or(meta.intrinsics);
    let bad = |msg: String| SceneError::invalid(json_path, format!("frame {index}: {msg}"));
    let (Some(fx), Some(w), Some(h)) = (k.fl_x, k.w, k.h) else {
        return Err(bad(
            "`fl_x`, `w` and `h` are needed (top level or per frame)".into(),
        ));
    };
    let fy = k.fl_y.unwrap_or(fx);
    let cx = k.cx.unwrap_or(0.5 * w);
    let cy = k.cy.unwrap_or(0.5 * h);
    let rows = &f.transform_matrix;
    let shape_ok = (rows.len() == 4 || rows.len() == 3) && rows.iter().all(|r| r.len() == 4);
    if !shape_ok {
        return Err(bad("transform_matrix must be 4×4 (or 3×4)".into()));
    }
    let mut c2w = crate::math::IDENTITY;
    for (r, row) in rows.iter().enumerate() {
        c2w[r].copy_from_slice(row);
    }
    let viewmat = opengl_c2w_to_viewmat(&c2w)
        .filter(|_| rows.iter().flatten().all(|v| (*v as f32).is_finite()))
        .ok_or_else(|| bad("transform_matrix is singular or not finite".into()))?;
    let rel = f.file_path.trim_start_matches("./");
    let key = Path::new(rel)
        .with_extension("")
        .to_string_lossy()
        .replace('\\', "/");
    pinhole_frame(
        &root.join(rel),
        key,
        time,
        [w, h],
        [fx, fy, cx, cy],
        viewmat,
        opts,
        json_path,
    )
}

type Splits = (Vec<Frame>, Vec<Frame>, Vec<Frame>);

/// nerfstudio's explicit `*_filenames` lists when present, else the every-8th holdout.
fn split(
    json_path: &Path,
    meta: &TransformsJson,
    frames: Vec<(usize, usize, Frame)>,
) -> Result<Splits, SceneError> {
    let Some(train_names) = &meta.train_filenames else {
        let (mut train, mut test) = (Vec::new(), Vec::new());
        let n = frames.len();
        for (rank, _, f) in frames {
            if n > 1 && rank % HOLDOUT == 0 {
                test.push(f);
            } else {
                train.push(f);
            }
        }
        return Ok((train, test.clone(), test));
    };
    let set = |v: &Option<Vec<String>>| -> HashSet<String> {
        v.iter()
            .flatten()
            .map(|s| s.trim_start_matches("./").to_string())
            .collect()
    };
    let (tr, va, te) = (
        set(&Some(train_names.clone())),
        set(&meta.val_filenames),
        set(&meta.test_filenames),
    );
    let (mut train, mut val, mut test) = (Vec::new(), Vec::new(), Vec::new());
    for (_, i, f) in frames {
        let name = meta.frames[i].file_path.trim_start_matches("./");
        if tr.contains(name) {
            train.push(f.clone());
        }
        if va.contains(name) {
            val.push(f.clone());
        }
        if te.contains(name) {
            test.push(f);
        }
    }
    if train.is_empty() {
        return Err(SceneError::invalid(
            json_path,
            "`train_filenames` names none of the frames' file_path",
        ));
    }
    if test.is_empty() {
        test = val.clone();
    }
    if val.is_empty() {
        val = test.clone();
    }
    Ok((train, val, test))
}
