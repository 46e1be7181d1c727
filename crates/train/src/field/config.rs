//! `[field]`: the deformation network's shape, schedule and which Gaussians it is
//! evaluated on (Deformable-3DGS `arguments/__init__.py`, `deform_network`).

use crate::error::{check, Result, TrainError};
use serde::{Deserialize, Serialize};

/// Most parameters a config's field may have: keeps the allocation finite (a bad value is
/// refused, not an abort on a failed allocation). 2^26 = 67M, 256 MiB of f32 before Adam's
/// two moments; the faithful 8×256 field has 0.6M.
pub const MAX_FIELD_PARAMS: usize = 1 << 26;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FieldConfig {
    /// Hidden ReLU layers (Deformable-3DGS: D = 8) and their width (W = 256).
    pub depth: usize,
    pub width: usize,
    /// The encoded input is concatenated to the output of this hidden layer (D/2 = 4 in
    /// Deformable-3DGS, `skips = [D // 2]`); ≥ depth − 1 disables the skip.
    pub skip: usize,
    /// Positional-encoding frequencies of the mean (10) and of t (6 synthetic / 10 real).
    pub pos_freqs: usize,
    pub time_freqs: usize,
    /// Iterations with δ = 0 before the field is used (Deformable-3DGS `warm_up`: 3k).
    pub warm_up: u32,
    /// Evaluate the field only for Gaussians whose canonical mean projects inside the view
    /// enlarged by `visible_margin` (fraction of the image size); others get δ = 0 this step.
    pub visible_only: bool,
    pub visible_margin: f32,
    /// Apply the field's scale offset δs (Deformable-3DGS: yes). Off, the Gaussians keep their
    /// size over time: the field can move and turn them but not shrink them out of view, the
    /// "flip-book" of docs/regularizer.md. δx and δr are unaffected.
    pub deform_scale: bool,
    /// Deformable-3DGS's time network for D-NeRF scenes (`is_blender`): γ(t) → Linear(·,
    /// `time_net_width`) → ReLU → Linear(·, `time_net_out`) replaces γ(t) in the field's
    /// input (`crate::time_net`). 0 = off, γ(t) goes in directly (the official non-D-NeRF
    /// path). Official: 256 → 30.
    pub time_net_width: usize,
    pub time_net_out: usize,
    /// Factor on the head's PyTorch-default initial weights and bias (1 = Deformable-3DGS;
    /// our default 0).
    /// With a small field the default head moves every Gaussian by its own ~0.1 units the
    /// moment the field starts (8×256: a near-uniform ~0.05 shift; docs/fidelity.md,
    /// "Field start"); 0 starts the field at δ = 0, and it learns from there.
    pub head_init_scale: f32,
}

impl FieldConfig {
    /// Width of the field's time input: the time network's output, or γ(t) without one.
    pub fn time_input_dim(&self) -> usize {
        if self.time_net_width > 0 {
            self.time_net_out
        } else {
            crate::encoding::encoded_dim(1, self.time_freqs)
        }
    }

    /// Deformable-3DGS's network for D-NeRF exactly (`is_blender`): 8 × 256, skip after
    /// layer 4, γ(t) with 6 frequencies through the 256 → 30 time network, on every Gaussian.
    pub fn faithful() -> Self {
        Self {
            depth: 8,
            width: 256,
            skip: 4,
            pos_freqs: 10,
            time_freqs: 6,
            warm_up: 3000,
            visible_only: false,
            visible_margin: 0.15,
            deform_scale: true,
            time_net_width: 256,
            time_net_out: 30,
            head_init_scale: 1.0,
        }
    }
}

impl Default for FieldConfig {
    fn default() -> Self {
        // Faster default justified in docs/performance.md ("Training"): the faithful
        // 8×256 field costs more than the whole 60-minute budget on 2 cores.
        Self {
            depth: 4,
            width: 64,
            skip: 2,
            visible_only: true,
            time_net_width: 0,
            // A small field's default head scatters the Gaussians at its start (lego val
            // +2.18 dB, toycars +0.08/+0.13 dB with a zero head: docs/fidelity.md §2–3).
            head_init_scale: 0.0,
            ..Self::faithful()
        }
    }
}

impl FieldConfig {
    /// `[field]`'s keys, named when wrong. Checked before anything is allocated: a config
    /// (or a checkpoint's config.toml) asking for a 10^9-wide field would otherwise abort
    /// the process in `Mlp::new`.
    pub fn validate(&self) -> Result<()> {
        let f = self;
        check::at_least_one("field.depth", f.depth as u64)?;
        check::at_least_one("field.width", f.width as u64)?;
        if f.pos_freqs > 30 || f.time_freqs > 30 {
            return Err(TrainError::config(
                "field.pos_freqs/time_freqs",
                "must be ≤ 30 (2^f overflows f32 precision)",
            ));
        }
        if f.time_net_width > 0 && f.time_net_out == 0 {
            return Err(TrainError::config(
                "field.time_net_out",
                "must be > 0 when field.time_net_width is (0 width turns the time network off)",
            ));
        }
        if f.time_net_width > 4096 || f.time_net_out > 4096 {
            return Err(TrainError::config(
                "field.time_net_width/time_net_out",
                "must be ≤ 4096 (Deformable-3DGS: 256 and 30)",
            ));
        }
        self.validate_size()?;
        if !(f.head_init_scale.is_finite() && f.head_init_scale >= 0.0) {
            return Err(TrainError::config(
                "field.head_init_scale",
                format!("must be finite and ≥ 0, got {}", f.head_init_scale),
            ));
        }
        if !(f.visible_margin.is_finite() && f.visible_margin >= 0.0) {
            return Err(TrainError::config(
                "field.visible_margin",
                format!("must be ≥ 0, got {}", f.visible_margin),
            ));
        }
        Ok(())
    }

    /// At most [`MAX_FIELD_PARAMS`], by an upper bound of `Mlp::new`'s count: (depth + 1)
    /// layers of at most (in + width + 1) inputs (skip and bias included) × max(width, head)
    /// outputs.
    fn validate_size(&self) -> Result<()> {
        let f = self;
        let in_dim = crate::encoding::encoded_dim(3, f.pos_freqs) + f.time_input_dim();
        let params = (f.width.checked_add(in_dim + 1))
            .and_then(|fan_in| fan_in.checked_mul(f.width.max(super::HEAD)))
            .and_then(|layer| layer.checked_mul(f.depth.checked_add(1)?));
        if params.is_none_or(|p| p > MAX_FIELD_PARAMS) {
            return Err(TrainError::config(
                "field.depth/width",
                format!(
                    "a {}×{} field has over {MAX_FIELD_PARAMS} parameters (the faithful 8×256 has 0.6M)",
                    f.depth, f.width
                ),
            ));
        }
        Ok(())
    }
}
