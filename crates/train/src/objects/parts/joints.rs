//! Joints between neighbouring parts: the rigidity prior that keeps an articulated object
//! in one piece. Two parts are neighbours when some of their Gaussians nearly touch; their
//! joint is the midpoint of the closest such pair, a point in the object's frame (all parts
//! share that frame at the first view, where the object was lifted). At every time both
//! parts should carry the joint to the same place (a ball joint, as the links of a
//! kinematic chain):
//!
//! `L = w·|T_a(t)·c − T_b(t)·c|²`, `w = joint_weight / size²`,
//!
//! with `dL/dp_a = 2w·e`, `dL/dR_a = 2w·e·cᵀ` for `e = T_a·c − T_b·c`, and the opposite for b.

use super::super::trajectory::{Pose, PoseGrad, TrajectoryGrad};
use super::super::RigidObject;
use super::cluster::dist2;
use crate::quat;
use serde::{Deserialize, Serialize};

/// A joint between the bodies with column IDs `a` and `b` at `point` (object frame).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Joint {
    pub a: u8,
    pub b: u8,
    pub point: [f32; 3],
    /// `joint_weight / size²`.
    pub weight: f32,
}

/// The joints between the clusters of `labels` whose closest Gaussians are within `reach`
/// of each other, as label pairs `(a, b)` with `a < b` and the joint point.
pub fn find(means: &[f32], labels: &[u32], reach: f32) -> Vec<(u32, u32, [f32; 3])> {
    let k = labels.iter().copied().max().map_or(0, |m| m as usize + 1);
    let pt = |i: usize| [means[i * 3], means[i * 3 + 1], means[i * 3 + 2]];
    // Closest pair per label pair: (squared distance, i, j).
    let mut best = vec![(f32::INFINITY, 0usize, 0usize); k * k];
    for i in 0..labels.len() {
        for j in i + 1..labels.len() {
            let (a, b) = (labels[i] as usize, labels[j] as usize);
            if a == b {
                continue;
            }
            let slot = a.min(b) * k + a.max(b);
            let d = dist2(pt(i), pt(j));
            if d < best[slot].0 {
                best[slot] = (d, i, j);
            }
        }
    }
    let mut out = Vec::new();
    for a in 0..k {
        for b in a + 1..k {
            let (d, i, j) = best[a * k + b];
            if d <= reach * reach {
                let (p, q) = (pt(i), pt(j));
                out.push((a as u32, b as u32, [0, 1, 2].map(|c| 0.5 * (p[c] + q[c]))));
            }
        }
    }
    out
}

/// The median distance from a Gaussian to its nearest other one (over at most 512 of them,
/// evenly spaced): the spacing that says which clusters touch.
pub fn spacing(means: &[f32]) -> f32 {
    let n = means.len() / 3;
    if n < 2 {
        return 0.0;
    }
    let pt = |i: usize| [means[i * 3], means[i * 3 + 1], means[i * 3 + 2]];
    let step = n.div_ceil(512);
    let mut d: Vec<f32> = (0..n)
        .step_by(step)
        .map(|i| {
            (0..n)
                .filter(|&j| j != i)
                .map(|j| dist2(pt(i), pt(j)))
                .fold(f32::INFINITY, f32::min)
                .sqrt()
        })
        .collect();
    let mid = d.len() / 2;
    d.select_nth_unstable_by(mid, f32::total_cmp);
    d[mid]
}

/// Adds the joints' gradients at this time (the bodies' `poses`, aligned with `objects`)
/// into the trajectories' gradients `tg`; returns the loss. Joints whose bodies are not
/// both in `objects` are skipped.
pub fn add(
    joints: &[Joint],
    objects: &[RigidObject],
    poses: &[Pose],
    tg: &mut [TrajectoryGrad],
) -> f32 {
    let slot = |id: u8| objects.iter().position(|o| o.id == id);
    let mut loss = 0.0f64;
    for j in joints {
        let (Some(sa), Some(sb)) = (slot(j.a), slot(j.b)) else {
            continue;
        };
        let (pa, pb) = (poses[sa].apply(j.point), poses[sb].apply(j.point));
        let e: [f64; 3] = std::array::from_fn(|c| f64::from(pa[c] - pb[c]));
        let w = f64::from(j.weight);
        loss += w * e.iter().map(|v| v * v).sum::<f64>();
        for (s, sign) in [(sa, 1.0), (sb, -1.0)] {
            if objects[s].is_static {
                continue;
            }
            let gp = e.map(|v| 2.0 * w * sign * v);
            let g_r: [[f64; 3]; 3] =
                std::array::from_fn(|r| std::array::from_fn(|c| gp[r] * f64::from(j.point[c])));
            let g = PoseGrad {
                p: gp,
                q: quat::to_matrix_vjp(poses[s].q, &g_r),
            };
            objects[s].trajectory.accumulate(&poses[s], &g, &mut tg[s]);
        }
    }
    loss as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::trajectory::Trajectory;

    fn body(id: u8, p: [[f32; 3]; 2], q: [[f32; 4]; 2]) -> RigidObject {
        let tr = Trajectory {
            times: vec![0.0, 1.0],
            translations: p.to_vec(),
            rotations: q.to_vec(),
        };
        RigidObject::new(id, format!("b{id}"), tr, false)
    }

    /// The joint term's knot gradients match finite differences.
    #[test]
    fn gradient_matches_finite_differences() {
        let objects = vec![
            body(
                1,
                [[0.1, 0.0, 0.2], [0.3, -0.1, 0.0]],
                [[1.0, 0.1, 0.0, 0.2], [0.9, -0.2, 0.3, 0.1]],
            ),
            body(
                7,
                [[0.0, 0.2, 0.1], [0.2, 0.1, -0.3]],
                [[0.8, 0.0, 0.3, 0.1], [1.0, 0.2, 0.1, -0.1]],
            ),
        ];
        let joints = [Joint {
            a: 1,
            b: 7,
            point: [0.4, -0.3, 0.2],
            weight: 3.0,
        }];
        let t = 0.35;
        let loss = |o: &[RigidObject]| {
            let poses: Vec<Pose> = o.iter().map(|b| b.trajectory.pose(t)).collect();
            let mut tg = vec![TrajectoryGrad::zeros(2); 2];
            f64::from(add(&joints, o, &poses, &mut tg))
        };
        let poses: Vec<Pose> = objects.iter().map(|b| b.trajectory.pose(t)).collect();
        let mut tg = vec![TrajectoryGrad::zeros(2); 2];
        add(&joints, &objects, &poses, &mut tg);
        let h = 1e-3;
        for s in 0..2 {
            for k in 0..2 {
                for c in 0..7 {
                    let (mut a, mut b) = (objects.clone(), objects.clone());
                    let bump = |o: &mut RigidObject, e: f32| match c {
                        0..=2 => o.trajectory.translations[k][c] += e,
                        _ => o.trajectory.rotations[k][c - 3] += e,
                    };
                    bump(&mut a[s], h);
                    bump(&mut b[s], -h);
                    let fd = (loss(&a) - loss(&b)) / (2.0 * f64::from(h));
                    let got = match c {
                        0..=2 => tg[s].translations[k][c],
                        _ => tg[s].rotations[k][c - 3],
                    };
                    assert!(
                        (fd - got).abs() < 2e-3 * (1.0 + fd.abs()),
                        "body {s} knot {k} c{c}: {fd} vs {got}"
                    );
                }
            }
        }
    }

    #[test]
    fn finds_touching_clusters_only() {
        // Three clusters in a row along x; the first two touch, the third stands apart.
        let means = [
            0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.2, 0.0, 0.0, 0.3, 0.0, 0.0, 1.0, 0.0, 0.0,
        ];
        let labels = [0, 0, 1, 1, 2];
        let j = find(&means, &labels, 0.15);
        assert_eq!(j.len(), 1);
        assert_eq!((j[0].0, j[0].1), (0, 1));
        assert!((j[0].2[0] - 0.15).abs() < 1e-6);
        assert!((spacing(&means) - 0.1).abs() < 1e-6);
    }
}
