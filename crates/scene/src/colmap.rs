//! COLMAP sparse models: `cameras`, `images`, `points3D`, binary (`.bin`) or text (`.txt`),
//! read and written as COLMAP 3.x does (`src/colmap/base/reconstruction.cc`,
//! `ReadCamerasBinary`/`ReadCamerasText` and their siblings; format documented at
//! <https://colmap.github.io/format.html>), and a scene folder holding one
//! (`images/` + `sparse/0/` or `sparse/`) loaded as a [`Dataset`].
//!
//! Conventions: an image's `qvec` (w, x, y, z) and `tvec` are the world-to-camera rotation
//! and translation with OpenCV camera axes (x right, y down, z forward), which is exactly
//! `splat::Camera::viewmat`. COLMAP's pixel coordinates put the centre of the top-left
//! pixel at (0.5, 0.5), as the rasterizer does, so `cx cy` are kept as they are.

use crate::{Dataset, DatasetKind, Frame, ImageU8, LoadOptions, SceneError};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// COLMAP camera models by id (`src/colmap/base/camera_models.h`): name and parameter count.
pub const CAMERA_MODELS: [(&str, usize); 11] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
];

/// One COLMAP camera (intrinsics shared by the images that name its id).
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapCamera {
    pub id: u32,
    /// Index into [`CAMERA_MODELS`].
    pub model: usize,
    pub width: u64,
    pub height: u64,
    pub params: Vec<f64>,
}

impl ColmapCamera {
    pub fn model_name(&self) -> &'static str {
        CAMERA_MODELS[self.model].0
    }

    /// Pinhole part `(fx, fy, cx, cy)`: the single-focal models repeat `f`.
    pub fn pinhole(&self) -> [f64; 4] {
        let p = &self.params;
        match self.model {
            0 | 2 | 3 | 8 | 9 => [p[0], p[0], p[1], p[2]],
            _ => [p[0], p[1], p[2], p[3]],
        }
    }

    /// Whether the model has distortion parameters that are not zero (the rasterizer is a
    /// pinhole: such images must be undistorted first, `colmap image_undistorter`).
    pub fn has_distortion(&self) -> bool {
        let first = match self.model {
            0 | 2 | 3 | 8 | 9 => 3,
            _ => 4,
        };
        self.params[first.min(self.params.len())..]
            .iter()
            .any(|v| *v != 0.0)
    }
}

/// One registered image: world-to-camera pose and the file name under the image folder.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapImage {
    pub id: u32,
    /// Rotation quaternion (w, x, y, z), world to camera.
    pub qvec: [f64; 4],
    pub tvec: [f64; 3],
    pub camera_id: u32,
    pub name: String,
    /// Keypoints `(x, y, point3D id)`; `u64::MAX` (binary) or `-1` (text) = no 3D point.
    pub points2d: Vec<(f64, f64, u64)>,
}

impl ColmapImage {
    /// The world-to-camera 4×4 (`[R(q) | t]`), `R` from the normalized quaternion.
    pub fn viewmat(&self) -> crate::math::Mat4 {
        let r = quat_to_rot(self.qvec);
        let mut m = crate::math::IDENTITY;
        for i in 0..3 {
            m[i][..3].copy_from_slice(&r[i]);
            m[i][3] = self.tvec[i];
        }
        m
    }
}

/// One sparse point with its colour and mean reprojection error (pixels).
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapPoint {
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    pub error: f64,
    /// `(image id, keypoint index)` of every observation.
    pub track: Vec<(u32, u32)>,
}

/// A sparse model: what COLMAP's mapper writes into `sparse/N/`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColmapModel {
    pub cameras: BTreeMap<u32, ColmapCamera>,
    pub images: Vec<ColmapImage>,
    pub points: Vec<ColmapPoint>,
}

/// Text or binary files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelFormat {
    Binary,
    Text,
}

impl ColmapModel {
    /// Mean of the points' reprojection errors, as `colmap model_analyzer` reports it
    /// (`Reconstruction::ComputeMeanReprojectionError`: the mean over points with an error).
    pub fn mean_reprojection_error(&self) -> Option<f64> {
        let errs: Vec<f64> = self
            .points
            .iter()
            .map(|p| p.error)
            .filter(|e| *e >= 0.0)
            .collect();
        (!errs.is_empty()).then(|| errs.iter().sum::<f64>() / errs.len() as f64)
    }
}

/// Which format the model folder holds: `cameras.bin` → binary, else `cameras.txt` → text.
pub fn model_format(dir: &Path) -> Option<ModelFormat> {
    if dir.join("cameras.bin").is_file() {
        Some(ModelFormat::Binary)
    } else if dir.join("cameras.txt").is_file() {
        Some(ModelFormat::Text)
    } else {
        None
    }
}

/// Reads `dir/{cameras,images,points3D}.{bin,txt}` (binary preferred). `points3D` may be
/// missing (an empty point list).
pub fn read_model(dir: &Path) -> Result<ColmapModel, SceneError> {
    let format = model_format(dir).ok_or_else(|| {
        SceneError::invalid(
            dir,
            "no cameras.bin or cameras.txt (not a COLMAP sparse model)",
        )
    })?;
    let ext = match format {
        ModelFormat::Binary => "bin",
        ModelFormat::Text => "txt",
    };
    let path = |n: &str| dir.join(format!("{n}.{ext}"));
    let read = |p: &Path| std::fs::read(p).map_err(|e| SceneError::io(p, e));
    let (cams, imgs) = (path("cameras"), path("images"));
    let pts = path("points3D");
    let model = match format {
        ModelFormat::Binary => ColmapModel {
            cameras: binary::cameras(&read(&cams)?).map_err(|m| SceneError::invalid(&cams, m))?,
            images: binary::images(&read(&imgs)?).map_err(|m| SceneError::invalid(&imgs, m))?,
            points: if pts.is_file() {
                binary::points(&read(&pts)?).map_err(|m| SceneError::invalid(&pts, m))?
            } else {
                Vec::new()
            },
        },
        ModelFormat::Text => ColmapModel {
            cameras: text::cameras(&read(&cams)?).map_err(|m| SceneError::invalid(&cams, m))?,
            images: text::images(&read(&imgs)?).map_err(|m| SceneError::invalid(&imgs, m))?,
            points: if pts.is_file() {
                text::points(&read(&pts)?).map_err(|m| SceneError::invalid(&pts, m))?
            } else {
                Vec::new()
            },
        },
    };
    for img in &model.images {
        if !model.cameras.contains_key(&img.camera_id) {
            return Err(SceneError::invalid(
                &imgs,
                format!(
                    "image {} (`{}`) names camera {}, which {} does not hold",
                    img.id,
                    img.name,
                    img.camera_id,
                    cams.display()
                ),
            ));
        }
    }
    Ok(model)
}

/// Writes the model into `dir` (created) in the given format, each file atomically.
pub fn write_model(model: &ColmapModel, dir: &Path, format: ModelFormat) -> Result<(), SceneError> {
    let (ext, c, i, p) = match format {
        ModelFormat::Binary => (
            "bin",
            binary::write_cameras(model),
            binary::write_images(model),
            binary::write_points(model),
        ),
        ModelFormat::Text => (
            "txt",
            text::write_cameras(model).into_bytes(),
            text::write_images(model).into_bytes(),
            text::write_points(model).into_bytes(),
        ),
    };
    for (name, bytes) in [("cameras", c), ("images", i), ("points3D", p)] {
        crate::io::write_atomic(&dir.join(format!("{name}.{ext}")), |w| w.write_all(&bytes))?;
    }
    Ok(())
}

/// Rotation matrix of a (normalized) quaternion (w, x, y, z), COLMAP's `QuaternionToRotationMatrix`.
pub fn quat_to_rot(q: [f64; 4]) -> [[f64; 3]; 3] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = q.map(|v| v / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Quaternion (w, x, y, z), w ≥ 0, of a rotation matrix (Shepperd's method).
pub fn rot_to_quat(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let tr = r[0][0] + r[1][1] + r[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
        [
            (r[2][1] - r[1][2]) / s,
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
        ]
    };
    if q[0] < 0.0 {
        q.map(|v| -v)
    } else {
        q
    }
}

fn check_camera(id: u32, model: i64, width: u64, height: u64) -> Result<usize, String> {
    let m = usize::try_from(model)
        .ok()
        .filter(|m| *m < CAMERA_MODELS.len())
        .ok_or_else(|| format!("camera {id}: unknown camera model id {model}"))?;
    if width == 0 || height == 0 || width > 1 << 20 || height > 1 << 20 {
        return Err(format!(
            "camera {id}: image size {width}×{height} out of range"
        ));
    }
    Ok(m)
}

mod binary {
    //! Little-endian binary files: counts are u64, ids u32 (points u64), reals f64.
    use super::*;

    pub(super) struct Reader<'a> {
        b: &'a [u8],
        at: usize,
    }

    impl<'a> Reader<'a> {
        fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
            let end = self.at.checked_add(n).filter(|e| *e <= self.b.len());
            let Some(end) = end else {
                return Err(format!(
                    "truncated: {n} more bytes needed at offset {} of {}",
                    self.at,
                    self.b.len()
                ));
            };
            let s = &self.b[self.at..end];
            self.at = end;
            Ok(s)
        }
        fn u64(&mut self) -> Result<u64, String> {
            Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
        }
        fn u32(&mut self) -> Result<u32, String> {
            Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
        }
        fn i32(&mut self) -> Result<i32, String> {
            Ok(i32::from_le_bytes(self.take(4)?.try_into().unwrap()))
        }
        fn f64(&mut self) -> Result<f64, String> {
            Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap()))
        }
        /// A count of records of at least `min_size` bytes each: a count the rest of the file
        /// cannot hold is refused before anything is allocated for it.
        fn count(&mut self, min_size: usize, what: &str) -> Result<usize, String> {
            let n = self.u64()?;
            let left = (self.b.len() - self.at) as u64;
            if n.checked_mul(min_size as u64)
                .is_none_or(|need| need > left)
            {
                return Err(format!(
                    "{what} count {n} needs more than the {left} bytes left in the file"
                ));
            }
            Ok(n as usize)
        }
        fn finish(&self) -> Result<(), String> {
            if self.at == self.b.len() {
                Ok(())
            } else {
                Err(format!(
                    "{} unexpected bytes at the end",
                    self.b.len() - self.at
                ))
            }
        }
    }

    fn reader(b: &[u8]) -> Reader<'_> {
        Reader { b, at: 0 }
    }

    pub fn cameras(b: &[u8]) -> Result<BTreeMap<u32, ColmapCamera>, String> {
        let mut r = reader(b);
        let n = r.count(24, "camera")?;
        let mut out = BTreeMap::new();
        for _ in 0..n {
            let id = r.u32()?;
            let model = r.i32()?;
            let (w, h) = (r.u64()?, r.u64()?);
            let m = check_camera(id, i64::from(model), w, h)?;
            let params = (0..CAMERA_MODELS[m].1)
                .map(|_| r.f64())
                .collect::<Result<Vec<_>, _>>()?;
            let cam = ColmapCamera {
                id,
                model: m,
                width: w,
                height: h,
                params,
            };
            if out.insert(id, cam).is_some() {
                return Err(format!("camera id {id} appears twice"));
            }
        }
        r.finish()?;
        Ok(out)
    }

    pub fn images(b: &[u8]) -> Result<Vec<ColmapImage>, String> {
        let mut r = reader(b);
        let n = r.count(73, "image")?;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let id = r.u32()?;
            let q = [r.f64()?, r.f64()?, r.f64()?, r.f64()?];
            let t = [r.f64()?, r.f64()?, r.f64()?];
            let camera_id = r.u32()?;
            let start = r.at;
            let len = r.b[start..]
                .iter()
                .position(|&c| c == 0)
                .ok_or_else(|| format!("image {id}: name not terminated"))?;
            let name = std::str::from_utf8(r.take(len)?)
                .map_err(|_| format!("image {id}: name is not UTF-8"))?
                .to_string();
            r.take(1)?;
            let k = r.count(24, "keypoint")?;
            let mut points2d = Vec::with_capacity(k);
            for _ in 0..k {
                points2d.push((r.f64()?, r.f64()?, r.u64()?));
            }
            out.push(ColmapImage {
                id,
                qvec: q,
                tvec: t,
                camera_id,
                name,
                points2d,
            });
        }
        r.finish()?;
        Ok(out)
    }

    pub fn points(b: &[u8]) -> Result<Vec<ColmapPoint>, String> {
        let mut r = reader(b);
        let n = r.count(51, "point")?;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            let id = r.u64()?;
            let xyz = [r.f64()?, r.f64()?, r.f64()?];
            let c = r.take(3)?;
            let rgb = [c[0], c[1], c[2]];
            let error = r.f64()?;
            let k = r.count(8, "track")?;
            let mut track = Vec::with_capacity(k);
            for _ in 0..k {
                track.push((r.u32()?, r.u32()?));
            }
            out.push(ColmapPoint {
                id,
                xyz,
                rgb,
                error,
                track,
            });
        }
        r.finish()?;
        Ok(out)
    }

    pub fn write_cameras(m: &ColmapModel) -> Vec<u8> {
        let mut b = (m.cameras.len() as u64).to_le_bytes().to_vec();
        for c in m.cameras.values() {
            b.extend(c.id.to_le_bytes());
            b.extend((c.model as i32).to_le_bytes());
            b.extend(c.width.to_le_bytes());
            b.extend(c.height.to_le_bytes());
            for p in &c.params {
                b.extend(p.to_le_bytes());
            }
        }
        b
    }

    pub fn write_images(m: &ColmapModel) -> Vec<u8> {
        let mut b = (m.images.len() as u64).to_le_bytes().to_vec();
        for i in &m.images {
            b.extend(i.id.to_le_bytes());
            for v in i.qvec.iter().chain(&i.tvec) {
                b.extend(v.to_le_bytes());
            }
            b.extend(i.camera_id.to_le_bytes());
            b.extend(i.name.as_bytes());
            b.push(0);
            b.extend((i.points2d.len() as u64).to_le_bytes());
            for (x, y, id) in &i.points2d {
                b.extend(x.to_le_bytes());
                b.extend(y.to_le_bytes());
                b.extend(id.to_le_bytes());
            }
        }
        b
    }

    pub fn write_points(m: &ColmapModel) -> Vec<u8> {
        let mut b = (m.points.len() as u64).to_le_bytes().to_vec();
        for p in &m.points {
            b.extend(p.id.to_le_bytes());
            for v in p.xyz {
                b.extend(v.to_le_bytes());
            }
            b.extend(p.rgb);
            b.extend(p.error.to_le_bytes());
            b.extend((p.track.len() as u64).to_le_bytes());
            for (i, k) in &p.track {
                b.extend(i.to_le_bytes());
                b.extend(k.to_le_bytes());
            }
        }
        b
    }
}

mod text {
    //! Text files: `#` comments, whitespace-separated fields; `images.txt` has two lines
    //! per image, the second (keypoints) possibly empty, exactly as COLMAP reads it.
    use super::*;

    fn lines(b: &[u8]) -> Result<Vec<(usize, &str)>, String> {
        let s = std::str::from_utf8(b).map_err(|_| "not UTF-8 text".to_string())?;
        Ok(s.lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .collect())
    }

    fn num<T: std::str::FromStr>(tok: Option<&str>, line: usize, what: &str) -> Result<T, String> {
        let tok = tok.ok_or_else(|| format!("line {line}: `{what}` missing"))?;
        tok.parse()
            .map_err(|_| format!("line {line}: `{what}` = `{tok}` is not a valid number"))
    }

    pub fn cameras(b: &[u8]) -> Result<BTreeMap<u32, ColmapCamera>, String> {
        let mut out = BTreeMap::new();
        for (ln, l) in lines(b)? {
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let mut it = l.split_whitespace();
            let id: u32 = num(it.next(), ln, "CAMERA_ID")?;
            let name = it
                .next()
                .ok_or_else(|| format!("line {ln}: MODEL missing"))?;
            let model = CAMERA_MODELS
                .iter()
                .position(|(n, _)| *n == name)
                .map(|m| m as i64)
                .ok_or_else(|| format!("line {ln}: unknown camera model `{name}`"))?;
            let (w, h) = (num(it.next(), ln, "WIDTH")?, num(it.next(), ln, "HEIGHT")?);
            let m = check_camera(id, model, w, h).map_err(|e| format!("line {ln}: {e}"))?;
            let params = it
                .map(|t| num::<f64>(Some(t), ln, "PARAMS"))
                .collect::<Result<Vec<_>, _>>()?;
            if params.len() != CAMERA_MODELS[m].1 {
                return Err(format!(
                    "line {ln}: {name} has {} parameters, {} given",
                    CAMERA_MODELS[m].1,
                    params.len()
                ));
            }
            let cam = ColmapCamera {
                id,
                model: m,
                width: w,
                height: h,
                params,
            };
            if out.insert(id, cam).is_some() {
                return Err(format!("line {ln}: camera id {id} appears twice"));
            }
        }
        Ok(out)
    }

    pub fn images(b: &[u8]) -> Result<Vec<ColmapImage>, String> {
        let mut out = Vec::new();
        let ls = lines(b)?;
        let mut it = ls.into_iter();
        while let Some((ln, l)) = it.next() {
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let mut t = l.split_whitespace();
            let id: u32 = num(t.next(), ln, "IMAGE_ID")?;
            let mut q = [0.0; 4];
            for (k, v) in q.iter_mut().enumerate() {
                *v = num(t.next(), ln, ["QW", "QX", "QY", "QZ"][k])?;
            }
            let mut tv = [0.0; 3];
            for (k, v) in tv.iter_mut().enumerate() {
                *v = num(t.next(), ln, ["TX", "TY", "TZ"][k])?;
            }
            let camera_id: u32 = num(t.next(), ln, "CAMERA_ID")?;
            // A name may hold spaces: everything after the ninth field.
            let name = t.collect::<Vec<_>>().join(" ");
            if name.is_empty() {
                return Err(format!("line {ln}: NAME missing"));
            }
            let mut points2d = Vec::new();
            if let Some((pl, p)) = it.next() {
                let toks: Vec<&str> = p.split_whitespace().collect();
                if !toks.len().is_multiple_of(3) {
                    return Err(format!(
                        "line {pl}: POINTS2D is not a list of X Y POINT3D_ID"
                    ));
                }
                for c in toks.chunks_exact(3) {
                    let pid: i64 = num(Some(c[2]), pl, "POINT3D_ID")?;
                    points2d.push((
                        num(Some(c[0]), pl, "X")?,
                        num(Some(c[1]), pl, "Y")?,
                        if pid < 0 { u64::MAX } else { pid as u64 },
                    ));
                }
            }
            out.push(ColmapImage {
                id,
                qvec: q,
                tvec: tv,
                camera_id,
                name,
                points2d,
            });
        }
        Ok(out)
    }

    pub fn points(b: &[u8]) -> Result<Vec<ColmapPoint>, String> {
        let mut out = Vec::new();
        for (ln, l) in lines(b)? {
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let mut t = l.split_whitespace();
            let id: u64 = num(t.next(), ln, "POINT3D_ID")?;
            let xyz = [
                num(t.next(), ln, "X")?,
                num(t.next(), ln, "Y")?,
                num(t.next(), ln, "Z")?,
            ];
            let rgb = [
                num(t.next(), ln, "R")?,
                num(t.next(), ln, "G")?,
                num(t.next(), ln, "B")?,
            ];
            let error = num(t.next(), ln, "ERROR")?;
            let rest: Vec<&str> = t.collect();
            if !rest.len().is_multiple_of(2) {
                return Err(format!(
                    "line {ln}: TRACK is not a list of IMAGE_ID POINT2D_IDX"
                ));
            }
            let track = rest
                .chunks_exact(2)
                .map(|c| {
                    Ok((
                        num(Some(c[0]), ln, "IMAGE_ID")?,
                        num(Some(c[1]), ln, "POINT2D_IDX")?,
                    ))
                })
                .collect::<Result<Vec<_>, String>>()?;
            out.push(ColmapPoint {
                id,
                xyz,
                rgb,
                error,
                track,
            });
        }
        Ok(out)
    }

    pub fn write_cameras(m: &ColmapModel) -> String {
        let mut s = format!(
            "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n# Number of cameras: {}\n",
            m.cameras.len()
        );
        for c in m.cameras.values() {
            s += &format!("{} {} {} {}", c.id, c.model_name(), c.width, c.height);
            for p in &c.params {
                s += &format!(" {p:?}");
            }
            s.push('\n');
        }
        s
    }

    pub fn write_images(m: &ColmapModel) -> String {
        let mut s = format!(
            "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n# Number of images: {}\n",
            m.images.len()
        );
        for i in &m.images {
            let [qw, qx, qy, qz] = i.qvec;
            let [tx, ty, tz] = i.tvec;
            s += &format!(
                "{} {qw:?} {qx:?} {qy:?} {qz:?} {tx:?} {ty:?} {tz:?} {} {}\n",
                i.id, i.camera_id, i.name
            );
            let pts: Vec<String> = i
                .points2d
                .iter()
                .map(|(x, y, id)| {
                    let id = if *id == u64::MAX { -1 } else { *id as i64 };
                    format!("{x:?} {y:?} {id}")
                })
                .collect();
            s += &pts.join(" ");
            s.push('\n');
        }
        s
    }

    pub fn write_points(m: &ColmapModel) -> String {
        let mut s = format!(
            "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n# Number of points: {}\n",
            m.points.len()
        );
        for p in &m.points {
            let [x, y, z] = p.xyz;
            let [r, g, b] = p.rgb;
            s += &format!("{} {x:?} {y:?} {z:?} {r} {g} {b} {:?}", p.id, p.error);
            for (i, k) in &p.track {
                s += &format!(" {i} {k}");
            }
            s.push('\n');
        }
        s
    }
}

/// The sparse model folder of a COLMAP scene: `sparse/0/`, else `sparse/`, else the root
/// itself (a bare model folder beside `images/`).
pub(crate) fn find_model_dir(root: &Path) -> Option<PathBuf> {
    [
        root.join("sparse").join("0"),
        root.join("sparse"),
        root.to_path_buf(),
    ]
    .into_iter()
    .find(|d| model_format(d).is_some())
}

/// Frames in file-name order: time `k/(n−1)`; every 8th (k % 8 == 0) held out as test
/// (and val), LLFF's and 3DGS's `llffhold = 8`.
pub(crate) const HOLDOUT: usize = 8;

/// Loads a COLMAP scene: `ROOT/sparse/0/` (or `sparse/`) and the images it names under
/// `ROOT/images/`. Distortion is ignored (warned once): undistort first.
pub fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset, SceneError> {
    let dir = find_model_dir(root).ok_or_else(|| {
        SceneError::invalid(
            root,
            "no COLMAP sparse model (sparse/0/cameras.bin or .txt)",
        )
    })?;
    let model = read_model(&dir)?;
    let ext = match model_format(&dir) {
        Some(ModelFormat::Text) => "txt",
        _ => "bin",
    };
    let cams_file = dir.join(format!("cameras.{ext}"));
    let imgs_file = dir.join(format!("images.{ext}"));
    if model.images.is_empty() {
        return Err(SceneError::invalid(
            &imgs_file,
            "the model has no registered image",
        ));
    }
    for c in model.cameras.values() {
        if c.has_distortion() {
            tracing::warn!(
                "{}: camera {} ({}) has lens distortion, which is ignored (the rasterizer is a \
                 pinhole): run `colmap image_undistorter` first, or `semdynreg prepare`",
                cams_file.display(),
                c.id,
                c.model_name()
            );
        }
    }
    let mut images: Vec<&ColmapImage> = model.images.iter().collect();
    images.sort_by(|a, b| a.name.cmp(&b.name));
    let n = images.len();
    let frames = images
        .par_iter()
        .enumerate()
        .map(|(k, img)| {
            let cam = &model.cameras[&img.camera_id];
            let image_path = root.join("images").join(&img.name);
            let time = if n > 1 {
                k as f32 / (n - 1) as f32
            } else {
                0.0
            };
            let key = format!(
                "images/{}",
                Path::new(&img.name)
                    .with_extension("")
                    .to_string_lossy()
                    .replace('\\', "/")
            );
            let size = [cam.width as f64, cam.height as f64];
            let [fx, fy, cx, cy] = cam.pinhole();
            let pose = crate::math::to_f32(&img.viewmat()).filter(|_| {
                img.qvec.iter().chain(&img.tvec).all(|v| v.is_finite())
                    && img.qvec.iter().any(|v| *v != 0.0)
            });
            let viewmat = pose.ok_or_else(|| {
                SceneError::invalid(
                    &imgs_file,
                    format!(
                        "image `{}`: pose (qvec, tvec) is not finite or zero",
                        img.name
                    ),
                )
            })?;
            let frame = pinhole_frame(
                &image_path,
                key,
                time,
                size,
                [fx, fy, cx, cy],
                viewmat,
                opts,
                &cams_file,
            )
            .map_err(|e| {
                // Name the file that names the image, too.
                SceneError::invalid(
                    &imgs_file,
                    format!("image `{}` (camera {}): {e}", img.name, img.camera_id),
                )
            })?;
            Ok((k, frame))
        })
        .collect::<Result<Vec<_>, SceneError>>()?;
    let (train, test) = split_holdout(frames);
    let (point_cloud, point_colors) = points_of(&model);
    Ok(Dataset {
        root: root.to_path_buf(),
        train,
        val: test.clone(),
        test,
        background: opts.background,
        kind: DatasetKind::Colmap,
        point_cloud,
        point_colors,
    })
}

/// Positions and colours of a model's points (`None` when it has none).
pub fn points_of(model: &ColmapModel) -> PointsPair {
    let pts: Vec<&ColmapPoint> = model
        .points
        .iter()
        .filter(|p| p.xyz.iter().all(|v| (*v as f32).is_finite()))
        .collect();
    if pts.is_empty() {
        return (None, None);
    }
    (
        Some(pts.iter().map(|p| p.xyz.map(|v| v as f32)).collect()),
        Some(
            pts.iter()
                .map(|p| p.rgb.map(|c| f32::from(c) / 255.0))
                .collect(),
        ),
    )
}

/// Splits `(index, frame)` pairs: index % [`HOLDOUT`] == 0 → test, the rest → train (a
/// single frame is trained on, with no test frame).
pub(crate) fn split_holdout(frames: Vec<(usize, Frame)>) -> (Vec<Frame>, Vec<Frame>) {
    if frames.len() < 2 {
        return (frames.into_iter().map(|(_, f)| f).collect(), Vec::new());
    }
    let (test, train): (Vec<_>, Vec<_>) = frames.into_iter().partition(|(k, _)| k % HOLDOUT == 0);
    (
        train.into_iter().map(|(_, f)| f).collect(),
        test.into_iter().map(|(_, f)| f).collect(),
    )
}

/// One frame of a pinhole camera whose intrinsics are given for an image of `size`
/// (`[w, h]`): the image must exist; when its size differs (e.g. a downsized copy), the
/// intrinsics are scaled by the ratio of widths and heights. `source` names the file the
/// intrinsics came from, for errors.
#[allow(clippy::too_many_arguments)]
pub(crate) fn pinhole_frame(
    image_path: &Path,
    key: String,
    time: f32,
    size: [f64; 2],
    k: [f64; 4],
    viewmat: [[f32; 4]; 4],
    opts: &LoadOptions,
    source: &Path,
) -> Result<Frame, SceneError> {
    if !image_path.is_file() {
        return Err(SceneError::invalid(
            source,
            format!("image {} does not exist", image_path.display()),
        ));
    }
    let image = ImageU8::load(image_path, opts.background)?;
    if !(size[0] > 0.0 && size[1] > 0.0) {
        return Err(SceneError::invalid(
            source,
            format!("image size {size:?} is not > 0"),
        ));
    }
    let sx = f64::from(image.width) / size[0] / f64::from(opts.downscale);
    let sy = f64::from(image.height) / size[1] / f64::from(opts.downscale);
    let image = image.downscale(opts.downscale);
    if image.width == 0 || image.height == 0 {
        return Err(SceneError::invalid(
            image_path,
            format!("smaller than the downscale factor {}", opts.downscale),
        ));
    }
    let (fx, fy, cx, cy) = (
        (k[0] * sx) as f32,
        (k[1] * sy) as f32,
        (k[2] * sx) as f32,
        (k[3] * sy) as f32,
    );
    if !(fx.is_finite()
        && fy.is_finite()
        && fx > 0.0
        && fy > 0.0
        && cx.is_finite()
        && cy.is_finite())
    {
        return Err(SceneError::invalid(
            source,
            format!(
                "{}: intrinsics fx = {fx}, fy = {fy}, cx = {cx}, cy = {cy} must be finite with focal lengths > 0",
                image_path.display()
            ),
        ));
    }
    Ok(Frame {
        file_path: key,
        time,
        camera: splat::Camera {
            width: image.width,
            height: image.height,
            fx,
            fy,
            cx,
            cy,
            viewmat,
        },
        image,
    })
}

/// Point cloud of a COLMAP model folder, when `dir` holds one (for loaders whose poses are
/// in COLMAP's world, e.g. LLFF's `poses_bounds.npy`).
pub(crate) fn read_points_of_dir(dir: &Path) -> Result<PointsPair, SceneError> {
    if model_format(dir).is_none() {
        return Ok((None, None));
    }
    Ok(points_of(&read_model(dir)?))
}

/// Positions and colours of a point cloud, each `None` when absent.
pub type PointsPair = (Option<Vec<[f32; 3]>>, Option<Vec<[f32; 3]>>);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_round_trip() {
        for q in [
            [1.0, 0.0, 0.0, 0.0],
            [0.2, 0.9, -0.3, 0.1],
            [0.0, 0.0, 1.0, 0.0],
            [0.01, -0.6, 0.7, 0.3],
        ] {
            let n = (q.iter().map(|v: &f64| v * v).sum::<f64>()).sqrt();
            let q: [f64; 4] = q.map(|v| v / n);
            let back = rot_to_quat(&quat_to_rot(q));
            let s = if q[0] < 0.0 { -1.0 } else { 1.0 };
            for k in 0..4 {
                assert!((back[k] - s * q[k]).abs() < 1e-12, "{q:?} {back:?}");
            }
        }
    }
}
