//! The SemDynReg loss and its gradient (paper Sec. 3.4):
//!
//! `L_reg^(o) = λx/|G_o| Σ_i ‖δx_i − δx̄_o‖² + λr/|G_o| Σ_i ‖δr_i − δr̄_o‖² + λs/|G_o| Σ_i ‖δs_i − δs̄_o‖²`,
//! `L_reg = Σ_o L_reg^(o)` over non-static objects (`‖δx̄_o‖ > τ_d`), `L = L_rgb + λ·L_reg`.
//!
//! The paper writes δr ∈ R³; our deformation field (Deformable 3DGS) outputs a 4-vector
//! quaternion offset, so the rotation term is the squared deviation in R⁴.
//!
//! Gradient: for a group of size n with mean m, `d/dδ_j (1/n) Σ_i ‖δ_i − m‖² =
//! (2/n)(δ_j − m) − (2/n²) Σ_i (δ_i − m) = (2/n)(δ_j − m)`, because the centered deviations
//! sum to zero — the mean's own dependence on δ_j cancels (checked by finite differences in
//! the tests). The static-skip decision is a step function of δ and is treated as constant.
//! A Gaussian in two groups receives the sum of both groups' gradients.

use super::config::RegConfig;
use super::error::RegError;
use super::grouping::{Group, ObjectGroups};
use super::stats::ObjectStats;

/// Per-Gaussian deformation offsets from the field at the current time, flat `f32`:
/// `dx` `N·3`, `dr` `N·4` (w,x,y,z quaternion offset), `ds` `N·3`.
#[derive(Clone, Copy, Debug)]
pub struct DeformView<'a> {
    pub dx: &'a [f32],
    pub dr: &'a [f32],
    pub ds: &'a [f32],
}

/// Gradient buffers with the layouts of [`DeformView`]; the regularizer ADDS into them.
#[derive(Debug)]
pub struct DeformGradMut<'a> {
    pub dx: &'a mut [f32],
    pub dr: &'a mut [f32],
    pub ds: &'a mut [f32],
}

/// Scalar results of one evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RegLoss {
    /// `L_reg = Σ_o L_reg^(o)` (λx, λr, λs applied, λ not).
    pub l_reg: f32,
    /// `λ·L_reg`, the term added to the training loss; the gradient is of this.
    pub weighted: f32,
    /// Objects regularized.
    pub active: usize,
    /// Objects skipped (static, or an empty group).
    pub skipped: usize,
}

/// Evaluate the paper's `L_reg` over `groups` for the offsets `deform`, add `d(λ·L_reg)/dδ`
/// into `grad` when given, and write one [`ObjectStats`] per group into `stats` (cleared
/// first). This is always the paper's loss: `cfg.consistency` is not read here
/// ([`super::Regularizer`] dispatches; the rigid loss is [`super::rigid_loss::evaluate_rigid`]).
pub fn evaluate(
    groups: &ObjectGroups,
    deform: DeformView<'_>,
    cfg: &RegConfig,
    mut grad: Option<&mut DeformGradMut<'_>>,
    stats: &mut Vec<ObjectStats>,
) -> Result<RegLoss, RegError> {
    let n = check_deform(deform, groups.n_gaussians())?;
    if let Some(g) = grad.as_deref() {
        check_grad(g, n)?;
    }
    stats.clear();
    let mut out = RegLoss::default();
    let mut l_reg = 0.0f64;
    for group in groups.iter() {
        let s = object_pass(group, deform, cfg, grad.as_deref_mut());
        stats.push(s);
        if s.skipped {
            out.skipped += 1;
        } else {
            out.active += 1;
            l_reg += f64::from(s.loss);
        }
    }
    out.l_reg = l_reg as f32;
    out.weighted = (f64::from(cfg.lambda) * l_reg) as f32;
    Ok(out)
}

/// The paper's per-object statistics of one group (no gradient), for the rigid loss's log.
pub(super) fn paper_stats(group: Group<'_>, d: DeformView<'_>, cfg: &RegConfig) -> ObjectStats {
    object_pass(group, d, cfg, None)
}

/// Means of δx, δr, δs over one group (f64 for accuracy over up to N members; zero-padded).
struct Moments {
    dx: [f64; 4],
    dr: [f64; 4],
    ds: [f64; 4],
}

/// One object's loss, stats and gradient in two passes over its members: the means, then the
/// centered deviations together with the gradient (whose scale is known once the mean of δx
/// has decided the static skip). Members are gathered from `N`-long buffers, so the passes
/// are memory-bound; fusing keeps them at two reads of δ and one read-modify-write of dL/dδ.
fn object_pass(
    group: Group<'_>,
    d: DeformView<'_>,
    cfg: &RegConfig,
    grad: Option<&mut DeformGradMut<'_>>,
) -> ObjectStats {
    let m = group.members;
    let mu = means(m, d);
    let mean_dx_norm = mu.dx.iter().map(|v| v * v).sum::<f64>().sqrt();
    let skipped = m.is_empty() || mean_dx_norm <= f64::from(cfg.tau_d);
    // d(λ·λc/n Σ‖δ_i − m‖²)/dδ_j = 2·λ·λc/n · (δ_j − m)  (see module docs).
    let base = 2.0 * f64::from(cfg.lambda) / m.len().max(1) as f64;
    let scale = [cfg.lambda_x, cfg.lambda_r, cfg.lambda_s].map(|l| base * f64::from(l));
    let grad = if skipped { None } else { grad };
    let [dev_x, dev_r, dev_s] = deviations(m, d, &mu, scale, grad);
    let loss = if skipped {
        0.0
    } else {
        f64::from(cfg.lambda_x) * dev_x
            + f64::from(cfg.lambda_r) * dev_r
            + f64::from(cfg.lambda_s) * dev_s
    };
    ObjectStats {
        object: group.object,
        pixels: group.pixels,
        group_size: m.len() as u32,
        mean_dx_norm: mean_dx_norm as f32,
        dev_x: dev_x as f32,
        dev_r: dev_r as f32,
        dev_s: dev_s as f32,
        loss: loss as f32,
        skipped,
        persistent: 0,
        rigid_residual: None,
    }
}

fn means(members: &[u32], d: DeformView<'_>) -> Moments {
    let mut mu = Moments {
        dx: [0.0; 4],
        dr: [0.0; 4],
        ds: [0.0; 4],
    };
    for &i in members {
        let i = i as usize;
        accumulate(&mut mu.dx, &d.dx[i * 3..i * 3 + 3]);
        accumulate(&mut mu.dr, &d.dr[i * 4..i * 4 + 4]);
        accumulate(&mut mu.ds, &d.ds[i * 3..i * 3 + 3]);
    }
    let inv = 1.0 / members.len().max(1) as f64;
    Moments {
        dx: mu.dx.map(|a| a * inv),
        dr: mu.dr.map(|a| a * inv),
        ds: mu.ds.map(|a| a * inv),
    }
}

fn accumulate(acc: &mut [f64; 4], v: &[f32]) {
    for (a, &x) in acc.iter_mut().zip(v) {
        *a += f64::from(x);
    }
}

/// `(1/n) Σ_i ‖v_i − m‖²` for δx, δr, δs (two-pass, centered, for accuracy); when `grad` is
/// given also `grad_i += scale·(v_i − m)` per component.
fn deviations(
    members: &[u32],
    d: DeformView<'_>,
    mu: &Moments,
    scale: [f64; 3],
    mut grad: Option<&mut DeformGradMut<'_>>,
) -> [f64; 3] {
    let mut dev = [0.0f64; 3];
    for &i in members {
        let i = i as usize;
        let (x, r, s) = (i * 3..i * 3 + 3, i * 4..i * 4 + 4, i * 3..i * 3 + 3);
        match grad.as_deref_mut() {
            Some(g) => {
                dev[0] += centered(&d.dx[x.clone()], &mu.dx, scale[0], Some(&mut g.dx[x]));
                dev[1] += centered(&d.dr[r.clone()], &mu.dr, scale[1], Some(&mut g.dr[r]));
                dev[2] += centered(&d.ds[s.clone()], &mu.ds, scale[2], Some(&mut g.ds[s]));
            }
            None => {
                dev[0] += centered(&d.dx[x], &mu.dx, 0.0, None);
                dev[1] += centered(&d.dr[r], &mu.dr, 0.0, None);
                dev[2] += centered(&d.ds[s], &mu.ds, 0.0, None);
            }
        }
    }
    let inv = 1.0 / members.len().max(1) as f64;
    dev.map(|v| v * inv)
}

/// `‖v − m‖²` for one vector, adding `scale·(v − m)` into `grad` when given.
#[inline(always)]
fn centered(v: &[f32], m: &[f64; 4], scale: f64, grad: Option<&mut [f32]>) -> f64 {
    let mut sq = 0.0;
    match grad {
        Some(g) => {
            for ((gv, &x), &mu) in g.iter_mut().zip(v).zip(m) {
                let e = f64::from(x) - mu;
                sq += e * e;
                *gv += (scale * e) as f32;
            }
        }
        None => {
            for (&x, &mu) in v.iter().zip(m) {
                let e = f64::from(x) - mu;
                sq += e * e;
            }
        }
    }
    sq
}

pub(super) fn check_deform(d: DeformView<'_>, groups_n: usize) -> Result<usize, RegError> {
    let n = d.dx.len() / 3;
    check_len("dx", d.dx.len(), 3, n)?;
    check_len("dr", d.dr.len(), 4, n)?;
    check_len("ds", d.ds.len(), 3, n)?;
    if n != groups_n {
        return Err(RegError::GaussianCount {
            groups_n,
            deform_n: n,
        });
    }
    Ok(n)
}

pub(super) fn check_grad(g: &DeformGradMut<'_>, n: usize) -> Result<(), RegError> {
    check_len("grad dx", g.dx.len(), 3, n)?;
    check_len("grad dr", g.dr.len(), 4, n)?;
    check_len("grad ds", g.ds.len(), 3, n)
}

fn check_len(name: &'static str, len: usize, dim: usize, n: usize) -> Result<(), RegError> {
    if len != n * dim {
        return Err(RegError::DeformLength {
            name,
            len,
            expected: n * dim,
            n,
        });
    }
    Ok(())
}
