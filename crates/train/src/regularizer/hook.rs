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
        let mut id_maps = Vec::with_capacity(dataset.train.len());
        for frame in &dataset.train {
            let path = dataset.semantics_path(frame);
            if !path.is_file() {
                return Err(TrainError::Data(format!(
                    "object-ID map {} is missing: run `semdynreg segment {}` first (or train with --no-reg)",
                    path.display(),
                    dataset.root.display()
                )));
            }
            let mask = scene::load_mask(&path).map_err(|e| TrainError::Data(e.to_string()))?;
            let (w, h) = (frame.image.width, frame.image.height);
            id_maps.push(resample_nearest(&mask.data, mask.width, mask.height, w, h));
        }
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

/// Nearest-neighbour resampling of an 8-bit label map (labels must not be blended).
fn resample_nearest(src: &[u8], sw: u32, sh: u32, dw: u32, dh: u32) -> Vec<u8> {
    if (sw, sh) == (dw, dh) {
        return src.to_vec();
    }
    let mut out = Vec::with_capacity((dw * dh) as usize);
    for i in 0..dh {
        let si = (((i as f32 + 0.5) * sh as f32 / dh as f32) as u32).min(sh - 1);
        for j in 0..dw {
            let sj = (((j as f32 + 0.5) * sw as f32 / dw as f32) as u32).min(sw - 1);
            out.push(src[(si * sw + sj) as usize]);
        }
    }
    out
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
        self.last = self.reg.apply(topk, id_map, deform, &mut grad, persist)?;
        Ok(self.last.weighted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_resampling_keeps_labels() {
        // 2×2 → 4×4: every label is replicated, none is invented.
        let src = [0u8, 1, 2, 255];
        let out = resample_nearest(&src, 2, 2, 4, 4);
        assert_eq!(out[0], 0);
        assert_eq!(out[3], 1);
        assert_eq!(out[12], 2);
        assert_eq!(out[15], 255);
        assert!(out.iter().all(|v| src.contains(v)));
        // Same size is a copy.
        assert_eq!(resample_nearest(&src, 2, 2, 2, 2), src.to_vec());
    }
}
