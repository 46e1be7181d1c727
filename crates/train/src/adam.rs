//! Adam exactly as PyTorch's `torch.optim.Adam` (which 3DGS and Deformable-3DGS use):
//! bias-corrected step `p −= lr/(1−β1ᵗ) · m / (√v/√(1−β2ᵗ) + ε)`, one step counter per
//! parameter group (3DGS keeps the group's step when densification concatenates rows).
//! One deviation: moments that underflow into the subnormal range are set to zero
//! ([`flush_subnormal`]); the parameters it moves are at most lr·1.2e-23 away.

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

    /// One update of `params` with `grads`; `lr_of(k)` gives the rate of element `k`
    /// within a row of `row` floats (lets SH DC and SH rest share one buffer). Returns
    /// whether every updated parameter is finite (the trainer's divergence check, free
    /// here: the values are in registers; `crate::finite` then names the culprit).
    pub fn step_rows(
        &mut self,
        params: &mut [f32],
        grads: &[f32],
        hp: AdamHyper,
        row: usize,
        lr_of: impl Fn(usize) -> f32,
    ) -> bool {
        debug_assert_eq!(params.len(), grads.len());
        debug_assert_eq!(params.len(), self.m.len());
        self.step += 1;
        let bc1 = 1.0 - (hp.beta1 as f64).powi(self.step as i32);
        let bc2 = 1.0 - (hp.beta2 as f64).powi(self.step as i32);
        let k = StepConsts {
            hp,
            inv_bc1: (1.0 / bc1) as f32,
            inv_sqrt_bc2: (1.0 / bc2.sqrt()) as f32,
        };
        // Rates per element of a row, looked up by position (no `i % row` per element).
        let lrs: Vec<f32> = (0..row).map(lr_of).collect();
        let chunk = CHUNK * row;
        params
            .par_chunks_mut(chunk)
            .zip(grads.par_chunks(chunk))
            .zip(self.m.par_chunks_mut(chunk))
            .zip(self.v.par_chunks_mut(chunk))
            .map(|(((p, g), m), v)| {
                if row == 1 {
                    // The rate as a plain value: looked up as `lrs[0]` per element, the
                    // bounds check kept this loop scalar (2.5–3× slower on 20M floats).
                    update(p, g, m, v, std::iter::repeat(lrs[0]), &k)
                } else {
                    let rows = p.chunks_exact_mut(row).zip(g.chunks_exact(row));
                    let moments = m.chunks_exact_mut(row).zip(v.chunks_exact_mut(row));
                    let mut ok = true;
                    for ((p, g), (m, v)) in rows.zip(moments) {
                        ok &= update(p, g, m, v, lrs.iter().copied(), &k);
                    }
                    ok
                }
            })
            .reduce(|| true, |a, b| a && b)
    }

    /// Same as [`Adam::step_rows`] with one rate for every element.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], hp: AdamHyper, lr: f32) -> bool {
        self.step_rows(params, grads, hp, 1, |_| lr)
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

struct StepConsts {
    hp: AdamHyper,
    inv_bc1: f32,
    inv_sqrt_bc2: f32,
}

/// Moments below the smallest normal float are flushed to zero. A parameter that stops
/// receiving gradient decays its first moment by β1 each step into the subnormal range,
/// where x86 takes a microcode assist (~100× an ordinary multiply) on every operation
/// that produces or reads such a value: by iteration 40k of the full toycars run 14 % of
/// the SH moments were subnormal and Adam cost 3× its time at 20k (docs/performance.md,
/// v9). The one deviation from PyTorch's arithmetic moves a parameter by at most
/// lr·1.2e-38/ε = lr·1.2e-23, below the rounding of any parameter larger than ~1e-16.
#[inline(always)]
fn flush_subnormal(x: f32) -> f32 {
    if x.abs() < f32::MIN_POSITIVE {
        0.0
    } else {
        x
    }
}

/// Adam on one run of elements; `lr` yields the rate of each element in turn. Returns
/// whether every updated parameter is finite. Written as one zip so that the loop has no
/// bounds checks and vectorizes.
#[inline(always)]
fn update(
    p: &mut [f32],
    g: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    lr: impl Iterator<Item = f32>,
    k: &StepConsts,
) -> bool {
    let (b1, b2) = (k.hp.beta1, k.hp.beta2);
    // An integer OR of "exponent all ones" (Inf or NaN), which vectorizes.
    let mut nonfinite = 0u32;
    let moments = m.iter_mut().zip(v.iter_mut());
    for (((p, &gj), (m, v)), lr) in p.iter_mut().zip(g).zip(moments).zip(lr) {
        let mj = flush_subnormal(b1 * *m + (1.0 - b1) * gj);
        let vj = flush_subnormal(b2 * *v + (1.0 - b2) * gj * gj);
        *m = mj;
        *v = vj;
        let denom = vj.sqrt() * k.inv_sqrt_bc2 + k.hp.eps;
        let pj = *p - lr * k.inv_bc1 * mj / denom;
        *p = pj;
        nonfinite |= ((pj.to_bits() & 0x7f80_0000) == 0x7f80_0000) as u32;
    }
    nonfinite == 0
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

    const HP: AdamHyper = AdamHyper {
        beta1: 0.9,
        beta2: 0.999,
        eps: 1e-15,
    };

    #[test]
    fn decaying_moments_reach_zero_without_passing_through_subnormals() {
        // One gradient, then none: m decays by β1 per step and would go subnormal after
        // ~830 steps; it must jump from a normal float straight to 0.
        let mut a = Adam::zeros(1);
        let mut p = vec![0.5f32];
        a.step(&mut p, &[1.0], HP, 1e-3);
        for _ in 0..2000 {
            a.step(&mut p, &[0.0], HP, 1e-3);
            for x in [a.m[0], a.v[0]] {
                assert!(x == 0.0 || x.is_normal(), "subnormal moment {x:e}");
            }
        }
        assert_eq!(a.m[0], 0.0);
    }

    #[test]
    fn row_rates_apply_by_position_within_the_row() {
        // Rows of 3 with rates 1, 2, 3 must equal three one-rate groups, column by column.
        let (rows, row) = (5000, 3);
        let grads: Vec<f32> = (0..rows * row).map(|i| (i as f32 * 0.37).sin()).collect();
        let mut p: Vec<f32> = (0..rows * row).map(|i| (i as f32 * 0.11).cos()).collect();
        let p0 = p.clone();
        let mut a = Adam::zeros(p.len());
        a.step_rows(&mut p, &grads, HP, row, |k| (k + 1) as f32 * 1e-2);
        for col in 0..row {
            let pick =
                |v: &[f32]| -> Vec<f32> { v.iter().skip(col).step_by(row).copied().collect() };
            let mut pc = pick(&p0);
            let mut ac = Adam::zeros(rows);
            ac.step(&mut pc, &pick(&grads), HP, (col + 1) as f32 * 1e-2);
            assert_eq!(pick(&p), pc, "column {col}");
        }
    }
}
