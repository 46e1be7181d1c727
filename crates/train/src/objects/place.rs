//! Placing object Gaussians in the world at time t, and the chain rule back.
//!
//! An object Gaussian stores its mean `x` and rotation `q` in its object's frame; at time
//! t, with the object's pose `(R, p)` (unit quaternion `r`):
//!
//! `x_w = R·x + p`, `q_w = r ⊗ q/|q|`, scale = exp(log_scale) (no δs: no flip-book),
//! opacity and colour unchanged.
//!
//! Backward, for the rasterizer's `g_x = dL/dx_w` and `g_q = dL/dq_w`:
//! `dL/dx = Rᵀ·g_x`, `dL/d(q/|q|) = r* ⊗ g_q`, and for the pose `dL/dp = Σ g_x`,
//! `dL/dR = Σ g_x·xᵀ`, `dL/dr = Σ g_q ⊗ (q/|q|)*` (the products' matrices are orthogonal
//! for unit quaternions, so their transposes are products with the conjugate).

use super::trajectory::{Pose, PoseGrad, TrajectoryGrad};
use super::RigidObject;
use crate::deform::{CanonicalGrads, Deformed};
use crate::model::GaussianModel;
use crate::quat;

pub use crate::state::NO_OBJECT;

/// The object-frame shape the poses place: means `N·3` and quaternions `N·4` (normalized
/// here), indexed by store row. Usually the store's own ([`Shape::of`]); with a residual
/// field, the store's plus the field's δ at the view's time ([`super::residual`]).
#[derive(Clone, Copy)]
pub struct Shape<'a> {
    pub means: &'a [f32],
    pub quats: &'a [f32],
}

impl<'a> Shape<'a> {
    /// The store's parameters as they are.
    pub fn of(model: &'a GaussianModel) -> Self {
        Self {
            means: &model.means,
            quats: &model.quats,
        }
    }
}

/// Rows of each object (in `objects` order), from the per-Gaussian object column.
pub fn rows_by_object(objects: &[RigidObject], column: &[u8], out: &mut Vec<Vec<u32>>) {
    let mut slot = [usize::MAX; 256];
    for (s, o) in objects.iter().enumerate() {
        slot[o.id as usize] = s;
    }
    out.resize_with(objects.len(), Vec::new);
    out.iter_mut().for_each(Vec::clear);
    for (i, &id) in column.iter().enumerate() {
        if id != NO_OBJECT {
            if let Some(rows) = out.get_mut(slot[id as usize]) {
                rows.push(i as u32);
            }
        }
    }
}

/// Overwrites the object rows of `out` (filled by `deform::apply` with δ = 0 there) with
/// their world placement at time `t`; `poses` receives each object's pose.
pub fn place(
    objects: &[RigidObject],
    rows: &[Vec<u32>],
    shape: Shape<'_>,
    t: f32,
    out: &mut Deformed,
    poses: &mut Vec<Pose>,
) {
    poses.clear();
    for (o, rows) in objects.iter().zip(rows) {
        let pose = o.trajectory.pose(t);
        for &i in rows {
            let i = i as usize;
            let x = [0, 1, 2].map(|c| shape.means[i * 3 + c]);
            out.means[i * 3..i * 3 + 3].copy_from_slice(&pose.apply(x));
            let u = quat::normalize(&shape.quats[i * 4..i * 4 + 4]).0;
            out.quats[i * 4..i * 4 + 4].copy_from_slice(&quat::mul(pose.q, u));
        }
        poses.push(pose);
    }
}

/// The rasterizer's gradients of the placed (world-space) means and quaternions.
pub struct WorldGrads<'a> {
    pub means: &'a [f32],
    pub quats: &'a [f32],
}

/// Chains the rasterizer's world-space gradients of the object rows back to their
/// object-frame parameters (overwriting `canon`'s means and quats there; `canon.log_scales`
/// from `deform::backward` is already right) and adds the pose gradients into `traj_grads`.
pub fn backward(
    objects: &[RigidObject],
    rows: &[Vec<u32>],
    shape: Shape<'_>,
    poses: &[Pose],
    world: WorldGrads<'_>,
    canon: &mut CanonicalGrads,
    traj_grads: &mut [TrajectoryGrad],
) {
    let (g_means, g_quats) = (world.means, world.quats);
    for (((o, rows), pose), tg) in objects.iter().zip(rows).zip(poses).zip(traj_grads) {
        let mut g = PoseGrad::default();
        let mut g_r = [[0.0f64; 3]; 3];
        let r_conj = quat::conj(pose.q);
        for &i in rows {
            let i = i as usize;
            let gx = [0, 1, 2].map(|c| g_means[i * 3 + c]);
            let x = [0, 1, 2].map(|c| shape.means[i * 3 + c]);
            canon.means[i * 3..i * 3 + 3].copy_from_slice(&quat::rotate_inv(&pose.r, gx));
            for a in 0..3 {
                g.p[a] += f64::from(gx[a]);
                for b in 0..3 {
                    g_r[a][b] += f64::from(gx[a]) * f64::from(x[b]);
                }
            }
            let gq: [f32; 4] = std::array::from_fn(|k| g_quats[i * 4 + k]);
            let (u, norm) = quat::normalize(&shape.quats[i * 4..i * 4 + 4]);
            let du = quat::mul(r_conj, gq);
            canon.quats[i * 4..i * 4 + 4].copy_from_slice(&quat::normalize_vjp(u, norm, du));
            let dr = quat::mul(gq, quat::conj(u));
            for (q, d) in g.q.iter_mut().zip(dr) {
                *q += f64::from(d);
            }
        }
        let from_r = quat::to_matrix_vjp(pose.q, &g_r);
        for (q, d) in g.q.iter_mut().zip(from_r) {
            *q += d;
        }
        if !o.is_static {
            o.trajectory.accumulate(pose, &g, tg);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deform;
    use crate::objects::trajectory::Trajectory;
    use crate::objects::RigidObject;

    fn model() -> GaussianModel {
        GaussianModel {
            means: vec![0.3, -0.2, 0.5, 1.0, 1.0, 1.0, -0.4, 0.1, 0.2],
            quats: vec![0.9, 0.1, -0.2, 0.3, 1.0, 0.0, 0.0, 0.0, 0.5, -0.5, 0.3, 0.1],
            log_scales: vec![-2.0; 9],
            opacity_logits: vec![0.0; 3],
            sh: vec![0.0; 3 * 48],
            sh_degree: 0,
        }
    }

    fn object() -> RigidObject {
        let tr = Trajectory {
            times: vec![0.0, 1.0],
            translations: vec![[0.1, 0.2, 0.0], [0.8, -0.3, 0.4]],
            rotations: vec![[1.0, 0.0, 0.0, 0.1], [0.7, 0.2, -0.3, 0.5]],
        };
        RigidObject::new(4, "box".into(), tr, false)
    }

    /// L = Σ w·x_w + Σ v·q_w over the placed rows; its gradients w.r.t. the object-frame
    /// means and quaternions and the knots match finite differences.
    #[test]
    fn chain_matches_finite_differences() {
        let column = [4u8, NO_OBJECT, 4];
        let w: Vec<f32> = (0..9).map(|k| ((k * 7 % 5) as f32 - 2.0) * 0.3).collect();
        let v: Vec<f32> = (0..12).map(|k| ((k * 3 % 7) as f32 - 3.0) * 0.2).collect();
        let t = 0.3;
        let loss = |m: &GaussianModel, o: &RigidObject| -> f64 {
            let mut rows = Vec::new();
            rows_by_object(std::slice::from_ref(o), &column, &mut rows);
            let mut d = Deformed::default();
            deform::apply(m, None, &mut d);
            let mut poses = Vec::new();
            place(
                std::slice::from_ref(o),
                &rows,
                Shape::of(m),
                t,
                &mut d,
                &mut poses,
            );
            let a: f64 = d.means.iter().zip(&w).map(|(a, b)| (a * b) as f64).sum();
            a + d
                .quats
                .iter()
                .zip(&v)
                .map(|(a, b)| (a * b) as f64)
                .sum::<f64>()
        };
        let (m, o) = (model(), object());
        let mut rows = Vec::new();
        rows_by_object(std::slice::from_ref(&o), &column, &mut rows);
        assert_eq!(rows, vec![vec![0, 2]]);
        let mut d = Deformed::default();
        deform::apply(&m, None, &mut d);
        let mut poses = Vec::new();
        place(
            std::slice::from_ref(&o),
            &rows,
            Shape::of(&m),
            t,
            &mut d,
            &mut poses,
        );
        let mut canon = CanonicalGrads::default();
        deform::backward(&m, &w, &v, &[0.0; 9], &mut canon);
        let mut tg = vec![TrajectoryGrad::zeros(2)];
        backward(
            std::slice::from_ref(&o),
            &rows,
            Shape::of(&m),
            &poses,
            WorldGrads {
                means: &w,
                quats: &v,
            },
            &mut canon,
            &mut tg,
        );
        let h = 1e-3;
        let fd = |f: &dyn Fn(&mut GaussianModel, &mut RigidObject, f32)| {
            let (mut mp, mut op, mut mm, mut om) = (m.clone(), o.clone(), m.clone(), o.clone());
            f(&mut mp, &mut op, h);
            f(&mut mm, &mut om, -h);
            (loss(&mp, &op) - loss(&mm, &om)) / (2.0 * h as f64)
        };
        for k in 0..9 {
            let g = fd(&|m, _, e| m.means[k] += e);
            assert!(
                (g - canon.means[k] as f64).abs() < 2e-3,
                "mean {k}: {g} vs {}",
                canon.means[k]
            );
        }
        for k in 0..12 {
            let g = fd(&|m, _, e| m.quats[k] += e);
            assert!(
                (g - canon.quats[k] as f64).abs() < 2e-3,
                "quat {k}: {g} vs {}",
                canon.quats[k]
            );
        }
        for i in 0..2 {
            for c in 0..3 {
                let g = fd(&|_, o, e| o.trajectory.translations[i][c] += e);
                assert!((g - tg[0].translations[i][c]).abs() < 2e-3);
            }
            for k in 0..4 {
                let g = fd(&|_, o, e| o.trajectory.rotations[i][k] += e);
                let got = tg[0].rotations[i][k];
                assert!((g - got).abs() < 3e-3, "knot {i} q{k}: {g} vs {got}");
            }
        }
    }
}
