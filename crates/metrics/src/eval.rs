//! The three metrics on one image pair, full frame or on a crop: what the CLI and the
//! evaluation reports call.

use crate::crop::{crop_rgb, BBox, MIN_CROP_SIDE};
use crate::{psnr, Lpips, LpipsError, SsimError, SsimVariant, SsimWorkspace};

/// Metric values for one pair. `psnr` is `+inf` for identical images (see [`crate::psnr`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Scores {
    #[serde(serialize_with = "finite_or_null")]
    pub psnr: f64,
    pub ssim: f32,
    /// `None` when LPIPS was not requested.
    pub lpips: Option<f32>,
}

/// JSON has no infinity: non-finite values are written as `null` (docs/metrics.md).
fn finite_or_null<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    if v.is_finite() {
        s.serialize_f64(*v)
    } else {
        s.serialize_none()
    }
}

/// Errors from [`evaluate`] and [`evaluate_crop`].
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("images differ in size: {0}x{1} vs {2}x{3}")]
    SizeMismatch(usize, usize, usize, usize),
    #[error("crop box {0:?} lies outside the {1}x{2} image")]
    EmptyCrop(BBox, usize, usize),
    #[error(transparent)]
    Ssim(#[from] SsimError),
    #[error(transparent)]
    Lpips(#[from] LpipsError),
}

/// PSNR, SSIM (`variant`) and, if a model is given, LPIPS of `a` (e.g. a render) against
/// `b` (ground truth), both RGB HWC in [0, 1] of `width × height`.
pub fn evaluate(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    variant: SsimVariant,
    lpips: Option<&Lpips>,
) -> Result<Scores, EvalError> {
    let ssim = SsimWorkspace::new().ssim_variant(a, b, width, height, variant)?;
    let lpips = lpips.map(|m| m.distance(a, b, width, height)).transpose()?;
    Ok(Scores {
        psnr: psnr(a, b),
        ssim,
        lpips,
    })
}

/// [`evaluate`] on a crop: `bbox` is clamped to the image and grown to at least
/// [`MIN_CROP_SIDE`] px (see `crop`); returns the box actually scored.
pub fn evaluate_crop(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    bbox: BBox,
    variant: SsimVariant,
    lpips: Option<&Lpips>,
) -> Result<(BBox, Scores), EvalError> {
    let clamped = bbox
        .clamp(width, height)
        .ok_or(EvalError::EmptyCrop(bbox, width, height))?;
    let boxed = clamped.grow_to(MIN_CROP_SIDE, width, height);
    let (ca, cb) = (crop_rgb(a, width, boxed), crop_rgb(b, width, boxed));
    let scores = evaluate(&ca, &cb, boxed.w, boxed.h, variant, lpips)?;
    Ok((boxed, scores))
}
