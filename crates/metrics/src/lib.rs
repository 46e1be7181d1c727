//! Image quality metrics for SemDynReg (docs/architecture.md): PSNR, SSIM (3DGS
//! variant with its gradient for the training loss, and the scikit-image variant), LPIPS,
//! and per-object crops. Images are RGB, HWC interleaved `f32` in [0, 1].

pub mod crop;
pub mod eval;
pub mod image_io;
pub mod lpips;
pub mod psnr;
pub mod ssim;

pub use crop::{bbox_from_mask, BBox, MIN_CROP_SIDE};
pub use eval::{evaluate, evaluate_crop, EvalError, Scores};
pub use image_io::{load_rgb, ImageLoadError, RgbImage};
pub use lpips::{Lpips, LpipsError, LpipsNet};
pub use psnr::psnr;
pub use ssim::{ssim, ssim_skimage, ssim_with_grad, SsimError, SsimVariant, SsimWorkspace};
