//! The best rigid transform between two point sets, its residual, and the residual's gradient
//! with respect to the target points (for the `"rigid"` consistency loss and the rigidity
//! metric).
//!
//! **Problem.** Given points `x_i`, `y_i` and weights `w_i ≥ 0` (`W = Σ w_i`; unweighted:
//! all 1), find the rotation `R` (`det R = +1`) and translation `t` minimizing
//! `E(R, t) = Σ w_i ‖y_i − (R x_i + t)‖² / W`. The minimum `E*` is the *residual*: zero
//! exactly when the `y_i` are a rigid motion of the `x_i`.
//!
//! **Method.** Kabsch 1976 solves this with an SVD of the cross-covariance and needs a sign
//! correction, or it returns a reflection for mirror-image or planar point sets. We use
//! Horn 1987 ("Closed-form solution of absolute orientation using unit quaternions", JOSA A
//! 4(4)): `t = ȳ − R x̄` for the weighted centroids, and `R` is the unit quaternion `q`
//! maximizing `qᵀ N q`, `N` a symmetric 4×4 built from the cross-covariance
//! `S = Σ w_i x'_i y'_iᵀ / W` of the centered points — the eigenvector of `N`'s largest
//! eigenvalue ([`super::eigen4`], Jacobi, f64). A unit quaternion is always a proper
//! rotation, so no reflection is ever returned: Horn's maximum over rotations is what Kabsch
//! gets with the sign correction. The residual is then evaluated directly (two passes, not
//! from the eigenvalue, which would cancel catastrophically for small residuals).
//!
//! **Gradient.** `E*(y) = min_{R,t} E(R, t; y)`. By the envelope theorem the derivative of
//! the minimum is the partial derivative at the minimizer,
//! `dE*/dy_i = 2 w_i / W · (y_i − R x_i − t)`: `R` and `t` depend on `y`, but `E` is
//! stationary in them at the optimum (on the rotation manifold for `R`), so that dependence
//! contributes nothing to first order (verified by finite differences in the tests).
//!
//! **Degenerate inputs** never panic and never produce NaN (for finite input):
//! - no points, or all weights zero ([`FitKind::Empty`]): identity, residual 0, gradient 0;
//! - coincident sources or coincident targets (weighted RMS distance to the centroid at most
//!   [`COINCIDENT_REL`]·(1 + largest |coordinate| of the centroid); this covers `n = 1`)
//!   ([`FitKind::Translation`]): `R = I`, `t = ȳ − x̄`. This is still optimal: when all
//!   `x'_i = 0` (or all `y'_i = 0`) every rotation gives the same `E`. With coincident
//!   targets `E*` has a kink there; the gradient returned is the identity rotation's;
//! - collinear sources (including `n = 2`) ([`FitKind::Rotation`]): the rotation about the
//!   line is not determined; the eigen-solver picks one deterministically. Every choice maps
//!   the line the same way, so the residual and the gradient do not depend on it.
//!
//! Non-finite coordinates or weights, negative weights and mismatched lengths are errors.

use thiserror::Error;

use super::eigen4::symmetric_eigen;

/// A point in f64.
pub type Point = [f64; 3];

/// Point sets whose weighted RMS distance to their centroid is at most this, relative to
/// `1 + max |centroid coordinate|`, count as coincident (f32 data resolves ~6e-8 at 1).
pub const COINCIDENT_REL: f64 = 1e-9;

/// `p ↦ R p + t` with `R` a proper rotation (row-major).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidTransform {
    pub rotation: [[f64; 3]; 3],
    pub translation: Point,
}

impl RigidTransform {
    pub const IDENTITY: Self = Self {
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
    };

    pub fn apply(&self, p: Point) -> Point {
        let r = &self.rotation;
        [0, 1, 2].map(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + self.translation[i])
    }

    /// `det R` (+1 up to rounding for every transform [`fit_rigid`] returns).
    pub fn det(&self) -> f64 {
        let r = &self.rotation;
        r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0])
    }
}

/// Which case of the fit applied (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitKind {
    /// No points or zero total weight.
    Empty,
    /// Coincident sources or targets: translation only.
    Translation,
    /// Horn's quaternion rotation plus translation.
    Rotation,
}

/// The optimum of one fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidFit {
    pub transform: RigidTransform,
    /// `E* = Σ w_i ‖y_i − (R x_i + t)‖² / W` (0 for [`FitKind::Empty`]).
    pub residual: f64,
    pub kind: FitKind,
}

#[derive(Clone, Debug, Error, PartialEq)]
pub enum FitError {
    #[error("rigid fit: {x} source points but {y} target points")]
    Length { x: usize, y: usize },
    #[error("rigid fit: {weights} weights for {points} points")]
    WeightLength { weights: usize, points: usize },
    #[error("rigid fit: {set} point {index} is not finite")]
    NonFinite { set: &'static str, index: usize },
    #[error("rigid fit: weight {index} is {value}, not finite and ≥ 0")]
    Weight { index: usize, value: f64 },
}

/// The best rigid transform from `x` to `y` (weights `None` = unweighted; Horn 1987).
pub fn fit_rigid(x: &[Point], y: &[Point], weights: Option<&[f64]>) -> Result<RigidFit, FitError> {
    let total = check(x, y, weights)?;
    if total == 0.0 {
        return Ok(RigidFit {
            transform: RigidTransform::IDENTITY,
            residual: 0.0,
            kind: FitKind::Empty,
        });
    }
    let w = |i: usize| weights.map_or(1.0, |w| w[i]);
    let (cx, cy) = (centroid(x, &w, total), centroid(y, &w, total));
    let kind = if coincident(x, cx, &w, total) || coincident(y, cy, &w, total) {
        FitKind::Translation
    } else {
        FitKind::Rotation
    };
    let rotation = match kind {
        FitKind::Rotation => horn_rotation(x, y, cx, cy, &w, total),
        _ => RigidTransform::IDENTITY.rotation,
    };
    let mut transform = RigidTransform {
        rotation,
        translation: [0.0; 3],
    };
    let rcx = transform.apply(cx);
    transform.translation = [0, 1, 2].map(|c| cy[c] - rcx[c]);
    let mut residual = 0.0;
    for i in 0..x.len() {
        residual += w(i) * norm2(sub(y[i], transform.apply(x[i])));
    }
    Ok(RigidFit {
        transform,
        residual: residual / total,
        kind,
    })
}

impl RigidFit {
    /// `dE*/dy_i = 2 w_i / W · (y_i − R x_i − t)` for each point (envelope theorem, module
    /// docs), for the same `x`, `y`, `weights` the fit was made from.
    pub fn gradient(
        &self,
        x: &[Point],
        y: &[Point],
        weights: Option<&[f64]>,
    ) -> Result<Vec<Point>, FitError> {
        let total = check(x, y, weights)?;
        if self.kind == FitKind::Empty || total == 0.0 {
            return Ok(vec![[0.0; 3]; x.len()]);
        }
        let grad = (0..x.len()).map(|i| {
            let s = 2.0 * weights.map_or(1.0, |w| w[i]) / total;
            sub(y[i], self.transform.apply(x[i])).map(|e| s * e)
        });
        Ok(grad.collect())
    }
}

/// Validates the inputs; returns the total weight `W`.
fn check(x: &[Point], y: &[Point], weights: Option<&[f64]>) -> Result<f64, FitError> {
    if x.len() != y.len() {
        return Err(FitError::Length {
            x: x.len(),
            y: y.len(),
        });
    }
    for (set, pts) in [("source", x), ("target", y)] {
        if let Some(index) = pts.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
            return Err(FitError::NonFinite { set, index });
        }
    }
    let Some(w) = weights else {
        return Ok(x.len() as f64);
    };
    if w.len() != x.len() {
        return Err(FitError::WeightLength {
            weights: w.len(),
            points: x.len(),
        });
    }
    if let Some(index) = w.iter().position(|v| !v.is_finite() || *v < 0.0) {
        return Err(FitError::Weight {
            index,
            value: w[index],
        });
    }
    Ok(w.iter().sum())
}

fn centroid(p: &[Point], w: &dyn Fn(usize) -> f64, total: f64) -> Point {
    let mut c = [0.0; 3];
    for (i, q) in p.iter().enumerate() {
        for k in 0..3 {
            c[k] += w(i) * q[k];
        }
    }
    c.map(|v| v / total)
}

/// Whether the weighted RMS distance to the centroid is negligible (see [`COINCIDENT_REL`]).
fn coincident(p: &[Point], c: Point, w: &dyn Fn(usize) -> f64, total: f64) -> bool {
    let spread: f64 = p
        .iter()
        .enumerate()
        .map(|(i, q)| w(i) * norm2(sub(*q, c)))
        .sum();
    let scale = 1.0 + c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    (spread / total).sqrt() <= COINCIDENT_REL * scale
}

/// Horn 1987, Sec. 4: the rotation of the top eigenvector of `N(S)`.
fn horn_rotation(
    x: &[Point],
    y: &[Point],
    cx: Point,
    cy: Point,
    w: &dyn Fn(usize) -> f64,
    total: f64,
) -> [[f64; 3]; 3] {
    // S[a][b] = Σ w x'_a y'_b / W (scaled by 1/W so that N's entries stay O(spread²)).
    let mut s = [[0.0; 3]; 3];
    for i in 0..x.len() {
        let (a, b) = (sub(x[i], cx), sub(y[i], cy));
        for (r, row) in s.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v += w(i) * a[r] * b[c] / total;
            }
        }
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    quat_to_matrix(symmetric_eigen(&n).top_vector())
}

/// Rotation matrix of the quaternion `(w, x, y, z)` (normalized here).
fn quat_to_matrix(q: [f64; 4]) -> [[f64; 3]; 3] {
    let len = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|v| v / len);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm2(a: Point) -> f64 {
    a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
}

#[cfg(test)]
#[path = "rigid_fit_tests.rs"]
mod tests;
