//! Adam exactly as PyTorch's `torch.optim.Adam` (which 3DGS and Deformable-3DGS use):
//! bias-corrected step `p −= lr/(1−β1ᵗ) · m / (√v/√(1−β2ᵗ) + ε)`, one step counter per
//! parameter group (3DGS keeps the group's step when densification concatenates rows).

use rayon::prelude::*;

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Adam {
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    pub step: u64,
}

/// Hyper-parameters shared by every group.
#[derive(Clone, Copy, Debug)]
pub struct AdamHyper {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

const CHUNK: usize = 4096;

impl Adam {
    pub fn zeros(len: usize) -> Self {
        Self {
            m: vec![0.0; len],
            v: vec![0.0; len],
            step: 0,
        }
    }

    /// One update of `params` with `grads`; `lr_of(i)` gives the rate of element `i`
    /// within a row of `row` floats (lets SH DC and SH rest share one buffer).
    pub fn step_rows(
        &mut self,
        params: &mut [f32],
        grads: &[f32],
        hp: AdamHyper,
        row: usize,
        lr_of: impl Fn(usize) -> f32 + Sync,
    ) {
        debug_assert_eq!(params.len(), grads.len());
        debug_assert_eq!(params.len(), self.m.len());
        self.step += 1;
        let bc1 = 1.0 - (hp.beta1 as f64).powi(self.step as i32);
        let bc2 = 1.0 - (hp.beta2 as f64).powi(self.step as i32);
        let inv_bc1 = (1.0 / bc1) as f32;
        let inv_sqrt_bc2 = (1.0 / bc2.sqrt()) as f32;
        let chunk = CHUNK * row;
        params
            .par_chunks_mut(chunk)
            .zip(grads.par_chunks(chunk))
            .zip(self.m.par_chunks_mut(chunk))
            .zip(self.v.par_chunks_mut(chunk))
            .for_each(|(((p, g), m), v)| {
                for i in 0..p.len() {
                    let gi = g[i];
                    m[i] = hp.beta1 * m[i] + (1.0 - hp.beta1) * gi;
                    v[i] = hp.beta2 * v[i] + (1.0 - hp.beta2) * gi * gi;
                    let denom = v[i].sqrt() * inv_sqrt_bc2 + hp.eps;
                    p[i] -= lr_of(i % row) * inv_bc1 * m[i] / denom;
                }
            });
    }

    /// Same as [`Adam::step_rows`] with one rate for every element.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], hp: AdamHyper, lr: f32) {
        self.step_rows(params, grads, hp, 1, |_| lr);
    }

    pub fn retain(&mut self, row: usize, keep: &[bool]) {
        crate::model::retain_rows(&mut self.m, row, keep);
        crate::model::retain_rows(&mut self.v, row, keep);
    }

    /// New rows start with zero moments (3DGS `cat_tensors_to_optimizer`).
    pub fn append_zeros(&mut self, len: usize) {
        self.m.resize(self.m.len() + len, 0.0);
        self.v.resize(self.v.len() + len, 0.0);
    }

    /// Zeroes the moments (3DGS `replace_tensor_to_optimizer` after an opacity reset).
    pub fn reset(&mut self) {
        self.m.iter_mut().for_each(|x| *x = 0.0);
        self.v.iter_mut().for_each(|x| *x = 0.0);
    }
}

/// 3DGS `get_expon_lr_func` without delay: log-linear from `init` to `end` over `max_steps`.
pub fn expon_lr(init: f32, end: f32, max_steps: u32, step: u32) -> f32 {
    let t = (step as f64 / max_steps.max(1) as f64).clamp(0.0, 1.0);
    ((init as f64).ln() * (1.0 - t) + (end as f64).ln() * t).exp() as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_by_lr_times_sign() {
        // With bias correction, step 1 is lr·g/(|g|+ε') = lr·sign(g).
        let mut a = Adam::zeros(3);
        let mut p = vec![1.0f32, 1.0, 1.0];
        let hp = AdamHyper {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        };
        a.step(&mut p, &[2.0, -0.5, 0.0], hp, 0.1);
        assert!((p[0] - 0.9).abs() < 1e-6);
        assert!((p[1] - 1.1).abs() < 1e-6);
        assert_eq!(p[2], 1.0);
    }

    #[test]
    fn expon_lr_endpoints() {
        assert!((expon_lr(1e-2, 1e-4, 100, 0) - 1e-2).abs() < 1e-9);
        assert!((expon_lr(1e-2, 1e-4, 100, 50) - 1e-3).abs() < 1e-8);
        assert!((expon_lr(1e-2, 1e-4, 100, 500) - 1e-4).abs() < 1e-10);
    }
}
