//! Nerfies / HyperNeRF loader: `dataset.json` (ids and splits), `metadata.json` (time per
//! id), `camera/<id>.json`, `rgb/{N}x/<id>.png`, optional `scene.json` (`center`, `scale`)
//! and `points.npy`.
//!
//! Camera JSON (nerfies `camera.py`): `orientation` is the world-to-camera rotation (rows
//! are the camera axes, OpenCV: x right, y down, z forward), `position` the camera centre,
//! so `p_cam = orientation · (p − position)`; `fy = focal_length · pixel_aspect_ratio`,
//! `principal_point` in pixels at full size, `image_size` = [w, h] at full size. Radial and
//! tangential distortion and skew are ignored: the rasterizer is a pinhole (Deformable-3DGS
//! ignores them as well; it also ignores the principal point, which we keep).
//! As in Deformable-3DGS `readNerfiesInfo`, positions become `(position − center)·scale`
//! and time is `time_id / max time_id` over the loaded frames.

use crate::{Dataset, DatasetKind, Frame, ImageU8, LoadOptions, SceneError};
use rayon::prelude::*;
use serde::Deserialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
struct DatasetJson {
    ids: Option<Vec<String>>,
    train_ids: Option<Vec<String>>,
    val_ids: Option<Vec<String>>,
}

#[derive(Deserialize)]
struct MetadataEntry {
    time_id: Option<f64>,
    warp_id: Option<f64>,
}

#[derive(Deserialize)]
struct SceneJson {
    center: [f64; 3],
    scale: f64,
}

#[derive(Deserialize)]
struct CameraJson {
    orientation: [[f64; 3]; 3],
    position: [f64; 3],
    focal_length: f64,
    principal_point: [f64; 2],
    image_size: [f64; 2],
    #[serde(default = "one")]
    pixel_aspect_ratio: f64,
}

fn one() -> f64 {
    1.0
}

/// Loads a Nerfies/HyperNeRF scene. Splits: `train_ids`/`val_ids` when given (val doubles
/// as test, as in Deformable-3DGS); otherwise HyperNeRF's convention of
/// `ids[::4]` for training and `ids[2::4]` for val and test.
pub fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset, SceneError> {
    let ds_path = root.join("dataset.json");
    let ds: DatasetJson = crate::io::read_json(&ds_path)?;
    let (train_ids, val_ids) = split_ids(&ds_path, ds)?;
    let meta_path = root.join("metadata.json");
    let meta: HashMap<String, MetadataEntry> = crate::io::read_json(&meta_path)?;
    let times = normalized_times(&meta_path, &meta, train_ids.iter().chain(&val_ids))?;
    let scene = read_scene_json(root)?;
    let load_all = |ids: &[String]| -> Result<Vec<Frame>, SceneError> {
        ids.par_iter()
            .map(|id| load_frame(root, id, times[id], &scene, opts))
            .collect()
    };
    let train = load_all(&train_ids)?;
    let val = load_all(&val_ids)?;
    let point_cloud = read_points(root, &scene)?;
    Ok(Dataset {
        root: root.to_path_buf(),
        train,
        test: val.clone(),
        val,
        background: opts.background,
        kind: DatasetKind::Nerfies,
        point_cloud,
        // Nerfies' `points.npy` holds positions only.
        point_colors: None,
    })
}

fn split_ids(path: &Path, ds: DatasetJson) -> Result<(Vec<String>, Vec<String>), SceneError> {
    let (train, val) = match (ds.train_ids, ds.val_ids, ds.ids) {
        (Some(t), v, _) => (t, v.unwrap_or_default()),
        (None, _, Some(ids)) => {
            let pick = |r: usize| {
                ids.iter()
                    .enumerate()
                    .filter(|(i, _)| i % 4 == r)
                    .map(|(_, s)| s.clone())
                    .collect()
            };
            (pick(0), pick(2))
        }
        (None, _, None) => {
            return Err(SceneError::invalid(
                path,
                "neither `train_ids` nor `ids` is given",
            ))
        }
    };
    if train.is_empty() {
        return Err(SceneError::invalid(path, "the training id list is empty"));
    }
    Ok((train, val))
}

fn normalized_times<'a>(
    path: &Path,
    meta: &HashMap<String, MetadataEntry>,
    ids: impl Iterator<Item = &'a String>,
) -> Result<HashMap<String, f32>, SceneError> {
    let mut raw = HashMap::new();
    for id in ids {
        let e = meta.get(id).ok_or_else(|| {
            SceneError::invalid(path, format!("no entry for id `{id}` of dataset.json"))
        })?;
        let t = e
            .time_id
            .or(e.warp_id)
            .ok_or_else(|| SceneError::invalid(path, format!("id `{id}` has no `time_id`")))?;
        // Time ids count frames: a negative one would normalize to a time below 0.
        if !(t.is_finite() && t >= 0.0) {
            return Err(SceneError::invalid(
                path,
                format!("id `{id}`: time_id {t} is not a finite number ≥ 0"),
            ));
        }
        raw.insert(id.clone(), t);
    }
    let max = raw.values().fold(0.0f64, |a, &b| a.max(b));
    Ok(raw
        .into_iter()
        .map(|(k, t)| (k, if max > 0.0 { (t / max) as f32 } else { 0.0 }))
        .collect())
}

fn read_scene_json(root: &Path) -> Result<SceneJson, SceneError> {
    let path = root.join("scene.json");
    if !path.is_file() {
        return Ok(SceneJson {
            center: [0.0; 3],
            scale: 1.0,
        });
    }
    let s: SceneJson = crate::io::read_json(&path)?;
    if !(s.scale.is_finite() && s.scale > 0.0 && s.center.iter().all(|v| v.is_finite())) {
        return Err(SceneError::invalid(
            &path,
            "`scale` must be finite and > 0 and `center` finite",
        ));
    }
    Ok(s)
}

fn load_frame(
    root: &Path,
    id: &str,
    time: f32,
    scene: &SceneJson,
    opts: &LoadOptions,
) -> Result<Frame, SceneError> {
    let cam_path = root.join("camera").join(format!("{id}.json"));
    let cam: CameraJson = crate::io::read_json(&cam_path)?;
    let n = opts.downscale;
    let (image_path, prescaled) = find_image(root, id, n).ok_or_else(|| {
        SceneError::invalid(
            &root.join("rgb"),
            format!("no image for id `{id}` in rgb/{n}x/ or rgb/1x/"),
        )
    })?;
    let image = ImageU8::load(&image_path, opts.background)?;
    let f = if prescaled { n } else { 1 };
    let expect = [
        (cam.image_size[0] / f64::from(f)).round(),
        (cam.image_size[1] / f64::from(f)).round(),
    ];
    if expect != [f64::from(image.width), f64::from(image.height)] {
        return Err(SceneError::invalid(
            &cam_path,
            format!(
                "image {} is {}×{} but image_size / {f} = {}×{}",
                image_path.display(),
                image.width,
                image.height,
                expect[0],
                expect[1]
            ),
        ));
    }
    let image = if prescaled { image } else { image.downscale(n) };
    if image.width == 0 || image.height == 0 {
        return Err(SceneError::invalid(
            &image_path,
            format!("smaller than the downscale factor {n}"),
        ));
    }
    let camera = camera(
        &cam_path,
        &cam,
        scene,
        f64::from(n),
        image.width,
        image.height,
    )?;
    Ok(Frame {
        file_path: id.to_string(),
        time,
        camera,
        image,
    })
}

/// `rgb/{n}x/<id>.png|jpg`, else `rgb/1x/...` to be box-filtered; bool = already at 1/n.
fn find_image(root: &Path, id: &str, n: u32) -> Option<(PathBuf, bool)> {
    for (dir, prescaled) in [(format!("{n}x"), true), ("1x".to_string(), n == 1)] {
        for ext in ["png", "jpg", "jpeg"] {
            let p = root.join("rgb").join(&dir).join(format!("{id}.{ext}"));
            if p.is_file() {
                return Some((p, prescaled));
            }
        }
    }
    None
}

fn camera(
    path: &Path,
    c: &CameraJson,
    scene: &SceneJson,
    n: f64,
    w: u32,
    h: u32,
) -> Result<splat::Camera, SceneError> {
    let pos: Vec<f64> = (0..3)
        .map(|k| (c.position[k] - scene.center[k]) * scene.scale)
        .collect();
    let mut m = crate::math::IDENTITY;
    for (row, o) in m.iter_mut().zip(&c.orientation) {
        row[..3].copy_from_slice(o);
        row[3] = -(0..3).map(|k| o[k] * pos[k]).sum::<f64>();
    }
    let viewmat = crate::math::to_f32(&m).ok_or_else(|| {
        SceneError::invalid(
            path,
            "orientation/position not finite as f32 (after scene.json's center and scale)",
        )
    })?;
    let vals = [
        c.focal_length / n,
        c.focal_length * c.pixel_aspect_ratio / n,
        c.principal_point[0] / n,
        c.principal_point[1] / n,
    ];
    if vals.iter().any(|v| !(*v as f32).is_finite()) || vals[0] <= 0.0 || vals[1] <= 0.0 {
        return Err(SceneError::invalid(
            path,
            "focal_length/principal_point not finite or focal ≤ 0",
        ));
    }
    Ok(splat::Camera {
        width: w,
        height: h,
        fx: vals[0] as f32,
        fy: vals[1] as f32,
        cx: vals[2] as f32,
        cy: vals[3] as f32,
        viewmat,
    })
}

fn read_points(root: &Path, scene: &SceneJson) -> Result<Option<Vec<[f32; 3]>>, SceneError> {
    let path = root.join("points.npy");
    if !path.is_file() {
        return Ok(None);
    }
    let flat = read_npy_f64(&path, 3)?;
    Ok(Some(
        flat.chunks_exact(3)
            .map(|p| {
                let mut q = [0.0f32; 3];
                for k in 0..3 {
                    q[k] = ((p[k] - scene.center[k]) * scene.scale) as f32;
                }
                q
            })
            .collect(),
    ))
}

/// A `.npy` array of shape (N, `cols`), f32 or f64, flattened; non-finite values refused.
pub(crate) fn read_npy_f64(path: &Path, cols: u64) -> Result<Vec<f64>, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    check_npy_preamble(&bytes).map_err(|m| SceneError::invalid(path, m))?;
    let npy = npyz::NpyFile::new(&bytes[..]).map_err(|e| SceneError::io(path, e))?;
    let shape = npy.shape().to_vec();
    if shape.len() != 2 || shape[1] != cols {
        return Err(SceneError::invalid(
            path,
            format!("expected shape (N, {cols}), found {shape:?}"),
        ));
    }
    // The data must be there before npyz allocates the shape's worth of values.
    let need = shape[0].checked_mul(cols).and_then(|n| n.checked_mul(4));
    if need.is_none_or(|n| n > bytes.len() as u64) {
        return Err(SceneError::invalid(
            path,
            format!(
                "shape {shape:?} does not fit in the file's {} bytes",
                bytes.len()
            ),
        ));
    }
    let flat: Vec<f64> = match npy.dtype() {
        npyz::DType::Plain(t) if t.size_field() == 4 => npy
            .into_vec::<f32>()
            .map(|v| v.into_iter().map(f64::from).collect()),
        _ => npy.into_vec::<f64>(),
    }
    .map_err(|e| SceneError::io(path, e))?;
    if let Some(i) = flat.iter().position(|v| !v.is_finite()) {
        return Err(SceneError::invalid(
            path,
            format!("value {i} ({}) is not finite", flat[i]),
        ));
    }
    Ok(flat)
}

/// The `.npy` header length must fit in the file: npyz allocates it before reading, and in
/// format versions 2 and 3 it is a u32 (found by fuzzing: one flipped version bit made a
/// 5-point file ask for 630 MiB).
fn check_npy_preamble(bytes: &[u8]) -> Result<(), String> {
    let (Some(b"\x93NUMPY"), Some(&major)) = (bytes.get(..6), bytes.get(6)) else {
        return Err("not a .npy file (no \\x93NUMPY magic)".into());
    };
    let (start, len) = match major {
        1 => (
            10,
            bytes
                .get(8..10)
                .map(|b| usize::from(u16::from_le_bytes([b[0], b[1]]))),
        ),
        2 | 3 => (
            12,
            bytes
                .get(8..12)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize),
        ),
        v => return Err(format!("unsupported .npy format version {v}")),
    };
    match len {
        Some(len) if start + len <= bytes.len() => Ok(()),
        _ => Err(format!(
            "its header length runs past the end of the file ({} bytes)",
            bytes.len()
        )),
    }
}
