//! Automatic mask generation on SAM, following `SamAutomaticMaskGenerator`
//! (segment_anything/automatic_mask_generator.py) for a single crop: a point grid, batched
//! decoding against one shared image embedding, filtering by predicted IoU and stability
//! score, masks brought back to the original resolution exactly as `postprocess_masks`, box
//! NMS — then the project's additions (docs/architecture.md "SemDynReg" 1): optional
//! small-region clean-up and non-overlapping masks.
//!
//! Defaults are SAM's (`pred_iou_thresh` 0.88, `stability_score_thresh` 0.95, offset 1.0,
//! `box_nms_thresh` 0.7, `min_mask_region_area` 0, 32×32 points). The faster
//! [`Sampling::Adaptive`] mode prompts a coarse grid first and then only the fine-grid points
//! that no accepted mask covers yet.

pub mod generate;
pub mod mask;
pub mod nms;
pub mod regions;
pub mod upsample;

use serde::Serialize;

pub use generate::{generate, generate_from_embedding, stability_score};
pub use mask::{BoxMask, BoxXyxy};

/// Which points prompt the decoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Sampling {
    /// A regular `n`×`n` grid (SAM's `points_per_side`).
    Grid(usize),
    /// A `coarse`² grid, then the points of a `fine`² grid not covered by any mask found so far.
    Adaptive { coarse: usize, fine: usize },
}

/// Thresholds and sampling of the generator.
#[derive(Debug, Clone, Serialize)]
pub struct MaskGenConfig {
    pub sampling: Sampling,
    pub pred_iou_thresh: f32,
    pub stability_score_thresh: f32,
    pub stability_score_offset: f32,
    pub mask_threshold: f32,
    pub box_nms_thresh: f32,
    /// SAM's `min_mask_region_area`: holes and islands below this many pixels are removed.
    pub min_region_area: usize,
    /// Masks with fewer pixels than this after the non-overlapping assignment are dropped.
    pub min_mask_area: usize,
}

impl Default for MaskGenConfig {
    fn default() -> Self {
        Self {
            sampling: Sampling::Grid(32),
            pred_iou_thresh: 0.88,
            stability_score_thresh: 0.95,
            stability_score_offset: 1.0,
            mask_threshold: 0.0,
            box_nms_thresh: 0.7,
            min_region_area: 0,
            min_mask_area: 16,
        }
    }
}

/// A mask that passed the IoU and stability filters.
#[derive(Debug, Clone)]
pub struct Candidate {
    pub mask: BoxMask,
    pub pred_iou: f32,
    pub stability: f32,
    /// The prompt point, original-image pixels.
    pub point: (f32, f32),
}

/// Per-mask summary of the final, non-overlapping masks.
#[derive(Debug, Clone, Serialize)]
pub struct MaskInfo {
    pub bbox: BoxXyxy,
    pub area: usize,
    pub pred_iou: f32,
    pub stability: f32,
    pub point: (f32, f32),
}

/// Counts and timings of one run.
#[derive(Debug, Clone, Default, Serialize)]
pub struct GenStats {
    pub prompts: usize,
    pub upscaled_prompts: usize,
    pub candidates: usize,
    pub after_nms: usize,
    pub decode_s: f64,
    pub post_s: f64,
}

/// The generator's result: a label map (`u16::MAX` = no mask) and one entry per label.
#[derive(Debug, Clone)]
pub struct AutoMasks {
    pub height: usize,
    pub width: usize,
    pub labels: Vec<u16>,
    pub masks: Vec<MaskInfo>,
    pub stats: GenStats,
}

/// SAM's `build_point_grid`: cell centres of an n×n grid in [0, 1]², rows (y) outer.
pub fn point_grid(n: usize) -> Vec<(f32, f32)> {
    let c = |i: usize| (2 * i + 1) as f32 / (2 * n) as f32;
    (0..n)
        .flat_map(|j| (0..n).map(move |i| (c(i), c(j))))
        .collect()
}
