//! Loading images for evaluation: any format the `image` crate reads (PNG, JPEG), 8- or
//! 16-bit, converted to RGB f32 in [0, 1]. An alpha channel is dropped, as 3DGS's
//! `metrics.py` does (`[:, :3]`): renders and ground truth are expected to be composited on
//! the same background already.

use std::path::{Path, PathBuf};

/// An RGB image, HWC interleaved, values in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

/// The image could not be read or decoded.
#[derive(Debug, thiserror::Error)]
#[error("cannot read image {path}: {source}")]
pub struct ImageLoadError {
    pub path: PathBuf,
    #[source]
    pub source: image::ImageError,
}

/// Reads `path` as RGB f32 in [0, 1].
pub fn load_rgb(path: &Path) -> Result<RgbImage, ImageLoadError> {
    let img = image::open(path).map_err(|source| ImageLoadError {
        path: path.to_owned(),
        source,
    })?;
    let rgb = img.to_rgb32f();
    Ok(RgbImage {
        width: rgb.width() as usize,
        height: rgb.height() as usize,
        data: rgb.into_raw(),
    })
}
