//! An object's trajectory `T_o(t) ∈ SE(3)`: one pose per knot (the training frames' times),
//! translation interpolated linearly and rotation by normalized lerp between neighbouring
//! knots, extrapolated at constant velocity beyond the first and last knot (test frames
//! lie between and around the training frames). drivestudio's rigid nodes keep the same
//! table of per-frame poses and interpolate it for held-out frames.

use crate::quat;

/// Knot times (ascending) with a pose each: `x_world = R(q)·x_object + p`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    pub times: Vec<f32>,
    pub translations: Vec<[f32; 3]>,
    /// w, x, y, z; unnormalized (normalized where used, like the Gaussians' quaternions).
    pub rotations: Vec<[f32; 4]>,
}

/// The pose at one time and how it was interpolated (for the gradient).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Unit rotation quaternion and its matrix.
    pub q: [f32; 4],
    pub r: [[f32; 3]; 3],
    pub p: [f32; 3],
    /// Knots `i0`, `i1` and the weight `a` of `i1` (outside [0, 1] when extrapolating).
    i0: usize,
    i1: usize,
    a: f32,
    /// The interpolated quaternion before normalization, and the sign applied to knot i1's.
    q_raw: [f32; 4],
    sign1: f32,
}

impl Pose {
    /// The identity pose (`x_world = x_object`).
    pub fn identity() -> Self {
        Self {
            q: [1.0, 0.0, 0.0, 0.0],
            r: quat::to_matrix([1.0, 0.0, 0.0, 0.0]),
            p: [0.0; 3],
            i0: 0,
            i1: 0,
            a: 0.0,
            q_raw: [1.0, 0.0, 0.0, 0.0],
            sign1: 1.0,
        }
    }

    /// Object frame → world.
    pub fn apply(&self, x: [f32; 3]) -> [f32; 3] {
        let v = quat::rotate(&self.r, x);
        [v[0] + self.p[0], v[1] + self.p[1], v[2] + self.p[2]]
    }

    /// The row-major 4×4 object-to-world matrix `[[R, p], [0, 0, 0, 1]]` (the convention of
    /// toycars' objects.json).
    pub fn to_matrix(&self) -> [[f32; 4]; 4] {
        let r = &self.r;
        let p = self.p;
        [
            [r[0][0], r[0][1], r[0][2], p[0]],
            [r[1][0], r[1][1], r[1][2], p[1]],
            [r[2][0], r[2][1], r[2][2], p[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// World → object frame.
    pub fn invert(&self, x: [f32; 3]) -> [f32; 3] {
        quat::rotate_inv(
            &self.r,
            [x[0] - self.p[0], x[1] - self.p[1], x[2] - self.p[2]],
        )
    }
}

/// `dL/d(pose)` at one time: translation, and the unit quaternion (tangent part taken later).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoseGrad {
    pub p: [f64; 3],
    pub q: [f64; 4],
}

/// Per-knot gradients of a trajectory (`translations`, `rotations` layouts).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrajectoryGrad {
    pub translations: Vec<[f64; 3]>,
    pub rotations: Vec<[f64; 4]>,
}

impl TrajectoryGrad {
    pub fn zeros(knots: usize) -> Self {
        Self {
            translations: vec![[0.0; 3]; knots],
            rotations: vec![[0.0; 4]; knots],
        }
    }
}

impl Trajectory {
    /// A trajectory that holds one pose at all times.
    pub fn constant(time: f32, p: [f32; 3], q: [f32; 4]) -> Self {
        Self {
            times: vec![time],
            translations: vec![p],
            rotations: vec![q],
        }
    }

    pub fn len(&self) -> usize {
        self.times.len()
    }

    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// Knots and the weight of the second at time `t` (linear extrapolation outside).
    fn segment(&self, t: f32) -> (usize, usize, f32) {
        let n = self.times.len();
        if n < 2 {
            return (0, 0, 0.0);
        }
        let j = self.times.partition_point(|&k| k <= t).clamp(1, n - 1);
        let (t0, t1) = (self.times[j - 1], self.times[j]);
        let a = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
        (j - 1, j, a)
    }

    /// The pose at time `t`.
    pub fn pose(&self, t: f32) -> Pose {
        assert!(!self.is_empty(), "a trajectory has at least one knot");
        let (i0, i1, a) = self.segment(t);
        let (p0, p1) = (self.translations[i0], self.translations[i1]);
        let p = std::array::from_fn(|c| p0[c] + a * (p1[c] - p0[c]));
        let q0 = quat::normalize(&self.rotations[i0]).0;
        let q1 = quat::normalize(&self.rotations[i1]).0;
        // The shorter arc: q and −q are the same rotation.
        let sign1 = if dot4(q0, q1) < 0.0 { -1.0 } else { 1.0 };
        let q_raw = std::array::from_fn(|k| (1.0 - a) * q0[k] + a * sign1 * q1[k]);
        let q = quat::normalize(&q_raw).0;
        Pose {
            q,
            r: quat::to_matrix(q),
            p,
            i0,
            i1,
            a,
            q_raw,
            sign1,
        }
    }

    /// Adds `g` (the gradient w.r.t. `pose`'s translation and unit quaternion) into the
    /// knots it was interpolated from.
    pub fn accumulate(&self, pose: &Pose, g: &PoseGrad, out: &mut TrajectoryGrad) {
        let (u, norm) = quat::normalize(&pose.q_raw);
        let gq = g.q.map(|v| v as f32);
        let d_raw = quat::normalize_vjp(u, norm, gq);
        let a = pose.a;
        for (i, w, s) in [(pose.i0, 1.0 - a, 1.0), (pose.i1, a, pose.sign1)] {
            if w == 0.0 {
                continue;
            }
            for c in 0..3 {
                out.translations[i][c] += f64::from(w) * g.p[c];
            }
            let (ui, ni) = quat::normalize(&self.rotations[i]);
            let dk = d_raw.map(|v| v * w * s);
            let d = quat::normalize_vjp(ui, ni, dk);
            for (r, d) in out.rotations[i].iter_mut().zip(d) {
                *r += f64::from(d);
            }
        }
    }

    /// Largest distance of the origin's path from its position at the first knot, and the
    /// largest rotation angle (radians) from the first knot's: how much the object moves.
    pub fn motion_extent(&self) -> (f32, f32) {
        let (Some(p0), Some(q0)) = (self.translations.first(), self.rotations.first()) else {
            return (0.0, 0.0);
        };
        let q0 = quat::normalize(q0).0;
        let mut dist = 0.0f32;
        let mut angle = 0.0f32;
        for (p, q) in self.translations.iter().zip(&self.rotations) {
            let d =
                ((p[0] - p0[0]).powi(2) + (p[1] - p0[1]).powi(2) + (p[2] - p0[2]).powi(2)).sqrt();
            dist = dist.max(d);
            angle = angle.max(quat::angle_between(q0, quat::normalize(q).0));
        }
        (dist, angle)
    }
}

fn dot4(a: [f32; 4], b: [f32; 4]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn yaw(a: f32) -> [f32; 4] {
        quat::from_rotvec([0.0, 0.0, a])
    }

    #[test]
    fn interpolates_between_and_extrapolates_beyond_knots() {
        let tr = Trajectory {
            times: vec![0.2, 0.4, 0.8],
            translations: vec![[0.0; 3], [1.0, 0.0, 0.0], [1.0, 2.0, 0.0]],
            rotations: vec![yaw(0.0), yaw(0.2), yaw(0.6)],
        };
        let p = tr.pose(0.3);
        assert!((p.p[0] - 0.5).abs() < 1e-6);
        assert!((quat::to_rotvec(p.q)[2] - 0.1).abs() < 1e-3);
        // Exactly at a knot: that knot's pose.
        let p = tr.pose(0.4);
        assert_eq!(p.p, [1.0, 0.0, 0.0]);
        // Constant velocity before the first and after the last knot.
        let p = tr.pose(0.0);
        assert!((p.p[0] + 1.0).abs() < 1e-6, "{:?}", p.p);
        let p = tr.pose(1.0);
        assert!((p.p[1] - 3.0).abs() < 1e-5, "{:?}", p.p);
        assert!((quat::to_rotvec(p.q)[2] - 0.8).abs() < 2e-2);
        // The shorter arc even when a knot stores −q.
        let mut flipped = tr.clone();
        flipped.rotations[1] = flipped.rotations[1].map(|v| -v);
        assert!((quat::to_rotvec(flipped.pose(0.3).q)[2] - 0.1).abs() < 1e-3);
    }

    #[test]
    fn point_mapping_inverts() {
        let tr = Trajectory::constant(
            0.0,
            [0.3, -0.2, 0.1],
            quat::normalize(&[0.8, 0.2, -0.1, 0.4]).0,
        );
        let pose = tr.pose(0.5);
        let x = [0.7, 0.1, -0.4];
        let back = pose.invert(pose.apply(x));
        for c in 0..3 {
            assert!((back[c] - x[c]).abs() < 1e-5);
        }
        // The 4×4 matrix maps points as `apply` does.
        let m = pose.to_matrix();
        let y = pose.apply(x);
        for (r, row) in m.iter().enumerate().take(3) {
            let v = row[0] * x[0] + row[1] * x[1] + row[2] * x[2] + row[3];
            assert!((v - y[r]).abs() < 1e-6);
        }
        assert_eq!(m[3], [0.0, 0.0, 0.0, 1.0]);
    }

    /// The knot gradients of `L = w·p(t) + v·q(t)` match finite differences.
    #[test]
    fn knot_gradients_match_finite_differences() {
        let tr = Trajectory {
            times: vec![0.1, 0.5],
            translations: vec![[0.2, 0.0, -0.1], [0.9, 0.4, 0.3]],
            rotations: vec![[1.0, 0.1, 0.0, 0.2], [-0.7, 0.2, -0.3, -0.6]],
        };
        let (w, v) = ([0.3, -0.8, 0.5], [0.2, 0.9, -0.4, 0.6]);
        let loss = |tr: &Trajectory| -> f64 {
            let p = tr.pose(0.35);
            (0..3).map(|c| w[c] * p.p[c] as f64).sum::<f64>()
                + (0..4).map(|k| v[k] * p.q[k] as f64).sum::<f64>()
        };
        let pose = tr.pose(0.35);
        let mut g = TrajectoryGrad::zeros(2);
        tr.accumulate(&pose, &PoseGrad { p: w, q: v }, &mut g);
        for i in 0..2 {
            for k in 0..4 {
                let (mut a, mut b) = (tr.clone(), tr.clone());
                a.rotations[i][k] += 1e-3;
                b.rotations[i][k] -= 1e-3;
                let fd = (loss(&a) - loss(&b)) / 2e-3;
                assert!(
                    (fd - g.rotations[i][k]).abs() < 2e-3,
                    "q{i}{k}: {fd} vs {}",
                    g.rotations[i][k]
                );
            }
            for c in 0..3 {
                let (mut a, mut b) = (tr.clone(), tr.clone());
                a.translations[i][c] += 1e-3;
                b.translations[i][c] -= 1e-3;
                let fd = (loss(&a) - loss(&b)) / 2e-3;
                assert!((fd - g.translations[i][c]).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn motion_extent_measures_the_path() {
        let tr = Trajectory {
            times: vec![0.0, 0.5, 1.0],
            translations: vec![[0.0; 3], [0.3, 0.4, 0.0], [0.0, 0.1, 0.0]],
            rotations: vec![yaw(0.0), yaw(0.5), yaw(0.1)],
        };
        let (d, a) = tr.motion_extent();
        assert!((d - 0.5).abs() < 1e-6);
        assert!((a - 0.5).abs() < 1e-4);
    }
}
