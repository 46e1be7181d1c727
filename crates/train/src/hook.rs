//! The extension point for losses on the deformation (the SemDynReg regularizer): after
//! the forward render, a hook sees δ and the render's per-pixel top-k contributors and adds
//! its `dL/dδ`, which joins the photometric gradient before the field's backward pass.

use crate::field::DeformOutput;
use crate::state::AuxStore;
use scene::Frame;

/// What a hook sees of one iteration.
pub struct HookContext<'a> {
    /// 1-based iteration being computed.
    pub iteration: u32,
    /// Index of the view in `dataset.train`.
    pub frame_index: usize,
    pub frame: &'a Frame,
    /// False during warm-up: δ is zero and no gradient reaches the field.
    pub field_active: bool,
    pub width: u32,
    pub height: u32,
    /// Per-pixel top-k of the training render (`H·W·k`, see `splat::ForwardOutput`).
    pub topk: usize,
    pub topk_ids: &'a [u32],
    pub topk_weights: &'a [f32],
    /// This iteration's deformation (zero for Gaussians the field was not evaluated on).
    pub delta: &'a DeformOutput,
    /// The model's canonical means (`N·3`), the points `δx` moves: a field Gaussian's
    /// deformed mean is `means + δx` (rigid objects are placed by their poses instead).
    pub means: &'a [f32],
    /// Ascending indices of the Gaussians the field was evaluated on (`[field]
    /// visible_only`); the others have δ = 0 and no field gradient this iteration.
    pub field_rows: &'a [u32],
}

pub type HookError = Box<dyn std::error::Error + Send + Sync>;

pub trait DeformHook {
    /// Top-k the rasterizer should record for this hook at `iteration` (0 = none, which
    /// keeps the forward pass free of top-k work outside the hook's active window).
    fn topk(&self, iteration: u32) -> usize;

    /// Adds `dL_extra/dδ` into `d_delta` (zeroed, sized like `ctx.delta`) and returns
    /// `L_extra` (already weighted). Only used when `ctx.field_active`. `rows` holds the
    /// per-Gaussian state the hook keeps across iterations (densified and checkpointed with
    /// the Gaussians).
    fn apply(
        &mut self,
        ctx: &HookContext,
        rows: &mut AuxStore,
        d_delta: &mut DeformOutput,
    ) -> Result<f32, HookError>;
}
