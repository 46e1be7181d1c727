//! Photometric loss of 3DGS/Deformable-3DGS: `(1−λ)·L1 + λ·(1 − SSIM)` (λ = 0.2), with
//! SSIM 11×11, σ = 1.5 from `metrics` (the 3DGS variant), and its gradient w.r.t. the render.

use crate::error::{check, Result};
use metrics::SsimWorkspace;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LossConfig {
    /// `L = (1 − λ)·L1 + λ·(1 − SSIM)` (3DGS: λ = 0.2).
    pub lambda_dssim: f32,
}

impl Default for LossConfig {
    fn default() -> Self {
        Self { lambda_dssim: 0.2 }
    }
}

impl LossConfig {
    /// `[loss]`'s keys, named when wrong.
    pub fn validate(&self) -> Result<()> {
        check::unit("loss.lambda_dssim", self.lambda_dssim)
    }
}

#[derive(Default)]
pub struct PhotoLoss {
    ssim: SsimWorkspace,
    ssim_grad: Vec<f32>,
}

/// Values of one evaluation of the loss.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossValue {
    pub total: f32,
    pub l1: f32,
    pub ssim: f32,
}

impl PhotoLoss {
    /// Loss of `render` against `gt` (`H·W·3`), writing `dL/drender` into `grad`.
    pub fn eval(
        &mut self,
        render: &[f32],
        gt: &[f32],
        width: u32,
        height: u32,
        lambda: f32,
        grad: &mut Vec<f32>,
    ) -> LossValue {
        let n = render.len();
        grad.resize(n, 0.0);
        self.ssim_grad.resize(n, 0.0);
        let ssim = self.ssim.ssim_with_grad(
            render,
            gt,
            width as usize,
            height as usize,
            &mut self.ssim_grad,
        );
        let mut l1 = 0.0f64;
        let w1 = (1.0 - lambda) / n as f32;
        for i in 0..n {
            let d = render[i] - gt[i];
            l1 += d.abs() as f64;
            // sign(0) = 0 as torch.abs's subgradient.
            let s = if d > 0.0 {
                1.0
            } else if d < 0.0 {
                -1.0
            } else {
                0.0
            };
            grad[i] = w1 * s - lambda * self.ssim_grad[i];
        }
        let l1 = (l1 / n as f64) as f32;
        LossValue {
            total: (1.0 - lambda) * l1 + lambda * (1.0 - ssim),
            l1,
            ssim,
        }
    }
}
