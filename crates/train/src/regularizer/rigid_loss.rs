//! The rigid-aware consistency loss (`[reg] consistency = "rigid"`, beyond the paper).
//!
//! Per object `o` with group `G_o`, `x_i` = the Gaussian's canonical mean and
//! `y_i = x_i + δx_i` its deformed mean at the view's time:
//!
//! `L^(o) = λx · min_{R,t} (1/|G_o|) Σ_{i∈G_o} ‖y_i − (R x_i + t)‖²`   (Horn 1987, [`super::rigid_fit`]),
//!
//! `L_reg = Σ_o L^(o)`, and `λ·L_reg` joins the training loss. Why: the paper's
//! `mean‖δx_i − δx̄_o‖²` is zero only for a pure translation. A turning car has
//! `δx_i = (R − I) x_i + t`, different at its front and rear, so the paper's loss penalizes
//! the correct answer; this one is zero for every rigid motion and measures only the
//! non-rigid part.
//!
//! Only positions enter (`λr`, `λs` are not read). The paper's rotation term is wrong for a
//! turn in the same way: a rigid rotation `q_R` turns every Gaussian to `q_R ⊗ q_i`, so the
//! additive offsets `δr_i = q_R ⊗ q_i − q_i` differ with each `q_i`. A rigid-aware
//! version would tie `δr_i` to the fitted `R` (a second term with its own weight and
//! quaternion-sign care), and a scale term (a rigid motion has `δs = 0`) would regularize
//! shape, not motion; neither is needed to make a group move *together*, which the
//! positions alone decide. They are left out so that "rigid" is zero for every rigid motion
//! and `λx` is its one weight.
//!
//! No static skip: a parked car is rigid too, and its residual is its non-rigid wobble, which
//! is what this loss should remove; `τ_d` is not read. Empty groups are skipped.
//!
//! Gradient: `dL^(o)/dδx_i = dL^(o)/dy_i = λx · 2/|G_o| · (y_i − R x_i − t)` by the envelope
//! theorem: this is the gradient through the residual with the fit `R, t` held fixed, and
//! because the fit is optimal, `R, t`'s own dependence on `δx` contributes nothing to first
//! order, so holding it fixed is exact, not an approximation (`rigid_fit` and
//! `tests/regularizer_rigid.rs` check it by finite differences). A Gaussian in two groups
//! gets both terms.

use super::config::RegConfig;
use super::error::RegError;
use super::grouping::{Group, ObjectGroups};
use super::loss::{check_deform, check_grad, paper_stats, DeformGradMut, DeformView, RegLoss};
use super::rigid_fit::{fit_rigid, Point};
use super::stats::ObjectStats;

/// Evaluate the rigid `L_reg` over `groups` for canonical `means` (`N·3`) and offsets
/// `deform`, add `d(λ·L_reg)/dδx` into `grad.dx` when given (δr, δs get nothing), and write
/// one [`ObjectStats`] per group into `stats` (cleared first): the paper's deviations for
/// comparison, `rigid_residual`, and `loss = λx·rigid_residual`.
pub fn evaluate_rigid(
    groups: &ObjectGroups,
    means: &[f32],
    deform: DeformView<'_>,
    cfg: &RegConfig,
    mut grad: Option<&mut DeformGradMut<'_>>,
    stats: &mut Vec<ObjectStats>,
) -> Result<RegLoss, RegError> {
    let n = check_deform(deform, groups.n_gaussians())?;
    if means.len() != n * 3 {
        return Err(RegError::PositionLength {
            name: "means",
            len: means.len(),
            expected: n * 3,
        });
    }
    if let Some(g) = grad.as_deref() {
        check_grad(g, n)?;
    }
    stats.clear();
    let mut out = RegLoss::default();
    let mut l_reg = 0.0f64;
    let mut buf = Buffers::default();
    for group in groups.iter() {
        let s = object_pass(group, means, deform, cfg, grad.as_deref_mut(), &mut buf)?;
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

/// Gathered positions, reused across groups.
#[derive(Default)]
struct Buffers {
    x: Vec<Point>,
    y: Vec<Point>,
}

/// One object's fit, stats and gradient.
fn object_pass(
    group: Group<'_>,
    means: &[f32],
    d: DeformView<'_>,
    cfg: &RegConfig,
    grad: Option<&mut DeformGradMut<'_>>,
    buf: &mut Buffers,
) -> Result<ObjectStats, RegError> {
    let mut s = paper_stats(group, d, cfg);
    s.skipped = group.members.is_empty();
    if s.skipped {
        s.loss = 0.0;
        s.rigid_residual = Some(0.0);
        return Ok(s);
    }
    buf.x.clear();
    buf.y.clear();
    for &i in group.members {
        let i = i as usize * 3;
        let x: Point = [0, 1, 2].map(|c| f64::from(means[i + c]));
        buf.x.push(x);
        buf.y.push([0, 1, 2].map(|c| x[c] + f64::from(d.dx[i + c])));
    }
    let object = group.object;
    let err = |source| RegError::RigidFit { object, source };
    let fit = fit_rigid(&buf.x, &buf.y, None).map_err(err)?;
    if let Some(g) = grad {
        let scale = f64::from(cfg.lambda) * f64::from(cfg.lambda_x);
        let dy = fit.gradient(&buf.x, &buf.y, None).map_err(err)?;
        for (&i, gi) in group.members.iter().zip(&dy) {
            let i = i as usize * 3;
            for (gd, v) in g.dx[i..i + 3].iter_mut().zip(gi) {
                *gd += (scale * v) as f32;
            }
        }
    }
    s.rigid_residual = Some(fit.residual as f32);
    s.loss = (f64::from(cfg.lambda_x) * fit.residual) as f32;
    Ok(s)
}
