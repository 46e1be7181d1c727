//! The in-memory data set every format is loaded into, and the paths of the per-frame
//! files other crates keep beside it (ground-truth masks, cached object-ID maps).

use crate::{colmap, dnerf, llff, nerfies, nerfstudio, ImageU8, SceneError};
use std::path::{Path, PathBuf};

/// One image with its camera and time.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Path relative to the scene root, without extension and without a leading `./`
    /// (`train/r_000` for D-NeRF, the image id for Nerfies). Keys masks and object-ID maps.
    pub file_path: String,
    /// Normalized time in [0, 1].
    pub time: f32,
    pub camera: splat::Camera,
    pub image: ImageU8,
}

/// Which on-disk format a data set came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DatasetKind {
    /// D-NeRF / Blender `transforms_{train,val,test}.json` (also the toycars scenes).
    DNerf,
    /// Nerfies / HyperNeRF `dataset.json` + `metadata.json` + `camera/*.json`.
    Nerfies,
    /// nerfstudio `transforms.json` (one file, per-frame `time` optional).
    Nerfstudio,
    /// LLFF `poses_bounds.npy`, or `precomputed.json` (poses after nerf-pytorch's loader).
    Llff,
    /// A COLMAP sparse model (`sparse/0/` or `sparse/`, binary or text) with `images/`.
    Colmap,
}

/// A loaded scene: frames of each split, as u8 images.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub root: PathBuf,
    pub train: Vec<Frame>,
    pub val: Vec<Frame>,
    pub test: Vec<Frame>,
    /// The background RGBA images were composited over (and the renderer should use).
    pub background: [f32; 3],
    pub kind: DatasetKind,
    /// Sparse points shipped with the scene (`points3d.ply` for D-NeRF, `points.npy` for
    /// Nerfies, in the same world frame as the cameras), when present.
    pub point_cloud: Option<Vec<[f32; 3]>>,
    /// Colours of `point_cloud` in [0, 1], when the file has them (PLY `red green blue`).
    pub point_colors: Option<Vec<[f32; 3]>>,
}

/// How to load a data set.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadOptions {
    /// Background for RGBA images, in [0, 1]. Default black, as Deformable-3DGS without
    /// `--white_background`; D-NeRF synthetic results are usually reported on white.
    pub background: [f32; 3],
    /// Integer downscale factor (1 = full resolution). Nerfies uses `rgb/{N}x/` when it
    /// exists, else box-filters `rgb/1x/`.
    pub downscale: u32,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            background: [0.0; 3],
            downscale: 1,
        }
    }
}

impl Dataset {
    /// Scene radius as 3DGS computes it (`getNerfppNorm`): 1.1 × the largest distance of
    /// a training camera centre from the centres' mean. Uses all frames when train is empty.
    pub fn scene_extent(&self) -> f32 {
        let frames: Vec<&Frame> = if self.train.is_empty() {
            self.all_frames().collect()
        } else {
            self.train.iter().collect()
        };
        if frames.is_empty() {
            return 1.0;
        }
        let centres: Vec<[f32; 3]> = frames.iter().map(|f| f.camera.center()).collect();
        let mut mean = [0.0f32; 3];
        for c in &centres {
            for k in 0..3 {
                mean[k] += c[k] / centres.len() as f32;
            }
        }
        let max = centres
            .iter()
            .map(|c| {
                ((c[0] - mean[0]).powi(2) + (c[1] - mean[1]).powi(2) + (c[2] - mean[2]).powi(2))
                    .sqrt()
            })
            .fold(0.0f32, f32::max);
        1.1 * max
    }

    /// Every frame of every split, train then val then test.
    pub fn all_frames(&self) -> impl Iterator<Item = &Frame> {
        self.train.iter().chain(&self.val).chain(&self.test)
    }

    /// Ground-truth instance mask of a frame: `ROOT/masks/<file_path>.png` (toycars).
    pub fn gt_mask_path(&self, frame: &Frame) -> PathBuf {
        mask_path(&self.root, &frame.file_path)
    }

    /// Cached object-ID map made by `semantics`: `ROOT/semantics/<file_path>.png`.
    pub fn semantics_path(&self, frame: &Frame) -> PathBuf {
        semantics_path(&self.root, &frame.file_path)
    }
}

/// `ROOT/masks/<file_path>.png`.
pub fn mask_path(root: &Path, file_path: &str) -> PathBuf {
    root.join("masks").join(format!("{file_path}.png"))
}

/// The image file of a frame whose `file_path` names it relative to the scene root with its
/// extension implied (D-NeRF, Blender, toycars): the first of `.png`, `.jpg`, `.jpeg` (or
/// the path itself) that exists. `None` for layouts that keep images elsewhere (Nerfies'
/// `rgb/<scale>x/`, COLMAP's `images/`).
pub fn image_file(root: &Path, file_path: &str) -> Option<PathBuf> {
    let as_is = root.join(file_path);
    std::iter::once(as_is.clone())
        .filter(|p| p.extension().is_some())
        .chain(
            ["png", "PNG", "jpg", "jpeg"]
                .iter()
                .map(|e| root.join(format!("{file_path}.{e}"))),
        )
        .find(|p| p.is_file())
}

/// Ground-truth part map of a scene with articulated objects (toycars' crane):
/// `ROOT/parts/<file_path>.png`, per pixel of an articulated object the part it shows (0 the
/// body, `k + 1` its part `k` in `objects.json`), 255 elsewhere.
pub fn part_map_path(root: &Path, file_path: &str) -> PathBuf {
    root.join("parts").join(format!("{file_path}.png"))
}

/// `ROOT/semantics/<file_path>.png`.
pub fn semantics_path(root: &Path, file_path: &str) -> PathBuf {
    root.join("semantics").join(format!("{file_path}.png"))
}

/// The scene layouts [`load_dataset`] recognizes, in the order it tries them, each with
/// the file that marks it.
pub const LAYOUTS: [(&str, &str); 6] = [
    ("transforms_train.json", "D-NeRF"),
    ("dataset.json", "Nerfies"),
    ("transforms.json", "nerfstudio"),
    ("poses_bounds.npy", "LLFF"),
    ("precomputed.json", "LLFF (nerf-pytorch poses)"),
    ("sparse/0/cameras.{bin,txt}", "COLMAP"),
];

/// Which layout a scene folder holds (`None`: none recognized), by the first marker file
/// of [`LAYOUTS`] present.
pub fn detect_kind(path: &Path) -> Option<DatasetKind> {
    if path.join("transforms_train.json").is_file() {
        Some(DatasetKind::DNerf)
    } else if path.join("dataset.json").is_file() {
        Some(DatasetKind::Nerfies)
    } else if path.join("transforms.json").is_file() {
        Some(DatasetKind::Nerfstudio)
    } else if path.join("poses_bounds.npy").is_file() || path.join("precomputed.json").is_file() {
        Some(DatasetKind::Llff)
    } else if colmap::find_model_dir(path).is_some() {
        Some(DatasetKind::Colmap)
    } else {
        None
    }
}

/// Loads a scene folder, detecting the format ([`LAYOUTS`]): `transforms_train.json` →
/// D-NeRF, `dataset.json` → Nerfies/HyperNeRF, `transforms.json` → nerfstudio,
/// `poses_bounds.npy` or `precomputed.json` → LLFF, `sparse/0/` (or `sparse/`, or the
/// folder itself) holding `cameras.bin`/`.txt` → COLMAP.
pub fn load_dataset(path: &Path, opts: &LoadOptions) -> Result<Dataset, SceneError> {
    if opts.downscale == 0 {
        return Err(SceneError::Argument("downscale factor must be ≥ 1".into()));
    }
    if !path.is_dir() {
        return Err(SceneError::invalid(
            path,
            "not a folder (expected a scene folder)",
        ));
    }
    let ds = match detect_kind(path) {
        Some(DatasetKind::DNerf) => dnerf::load(path, opts)?,
        Some(DatasetKind::Nerfies) => nerfies::load(path, opts)?,
        Some(DatasetKind::Nerfstudio) => nerfstudio::load(path, opts)?,
        Some(DatasetKind::Llff) => llff::load(path, opts)?,
        Some(DatasetKind::Colmap) => colmap::load(path, opts)?,
        None => {
            let known: Vec<String> = LAYOUTS
                .iter()
                .map(|(file, name)| format!("{file} ({name})"))
                .collect();
            return Err(SceneError::invalid(
                path,
                format!(
                    "unknown scene format: none of {} found (a video or a folder of images: `semdynreg prepare`)",
                    known.join(", ")
                ),
            ));
        }
    };
    tracing::info!(
        "{}: {:?} scene, {} train / {} val / {} test frames",
        path.display(),
        ds.kind,
        ds.train.len(),
        ds.val.len(),
        ds.test.len()
    );
    Ok(ds)
}
