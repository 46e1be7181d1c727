//! Wires the SemDynReg regularizer into training: a [`DeformHook`] that, while the
//! regularizer is active (paper Sec. 4.1: from 10k to 40k iterations), asks the rasterizer
//! for the per-pixel top-k, groups Gaussians by the training view's object-ID map (Sec. 3.3)
//! and adds `λ·∇L_reg` to the field's `dL/dδ` (Sec. 3.4).

use super::{
    DeformGradMut, DeformView, ObjectStats, Persist, RegConfig, RegLoss, Regularizer, TopKView,
    VOTES_NAME,
};
use crate::error::{Result, TrainError};
use crate::field::DeformOutput;
use crate::hook::{DeformHook, HookContext, HookError};
use crate::state::AuxStore;
use scene::Dataset;

/// The regularizer plus one object-ID map per training frame, at the training resolution.
pub struct SemanticHook {
    reg: Regularizer,
    id_maps: Vec<Vec<u8>>,
    last: RegLoss,
}

impl SemanticHook {
    /// Loads `SCENE/semantics/<file_path>.png` for every training frame (made by
    /// `semdynreg segment`); maps made at another resolution are resampled (nearest) to
    /// the frame's size, since `--downscale` may differ from the segmentation's.
    pub fn load(cfg: RegConfig, dataset: &Dataset) -> Result<Self> {
        let mut reg =
            Regularizer::new(cfg).map_err(|e| TrainError::config("reg", e.to_string()))?;
        let id_maps = crate::id_maps::load(dataset)?;
        reg.set_objects(id_maps.iter().map(Vec::as_slice));
        Ok(Self {
            reg,
            id_maps,
            last: RegLoss::default(),
        })
    }

    /// Per-object statistics of the last active iteration (for the training log).
    pub fn stats(&self) -> &[ObjectStats] {
        self.reg.stats()
    }

    /// The loss of the last active iteration.
    pub fn last_loss(&self) -> RegLoss {
        self.last
    }

    pub fn active_at(&self, iteration: u32) -> bool {
        self.reg.active_at(iteration as u64)
    }
}

impl DeformHook for SemanticHook {
    fn topk(&self, iteration: u32) -> usize {
        if self.active_at(iteration) {
            self.reg.render_topk()
        } else {
            0
        }
    }

    fn apply(
        &mut self,
        ctx: &HookContext,
        rows: &mut AuxStore,
        d_delta: &mut DeformOutput,
    ) -> std::result::Result<f32, HookError> {
        if ctx.topk == 0 || !self.active_at(ctx.iteration) {
            return Ok(0.0);
        }
        let id_map = &self.id_maps[ctx.frame_index];
        let topk = TopKView {
            ids: ctx.topk_ids,
            stride: ctx.topk,
        };
        let deform = DeformView {
            dx: &ctx.delta.dx,
            dr: &ctx.delta.dr,
            ds: &ctx.delta.ds,
        };
        let mut grad = DeformGradMut {
            dx: &mut d_delta.dx,
            dr: &mut d_delta.dr,
            ds: &mut d_delta.ds,
        };
        let persist = match self.reg.votes_cols() {
            Some(cols) => Some(Persist {
                weights: ctx.topk_weights,
                rows: ctx.field_rows,
                votes: rows.get_or_zeros(VOTES_NAME, cols)?,
            }),
            None => None,
        };
        let means = ctx.means;
        self.last = self
            .reg
            .apply(topk, id_map, means, deform, &mut grad, persist)?;
        Ok(self.last.weighted)
    }
}
