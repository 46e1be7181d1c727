//! Rigid parts from point tracks: `N` points at rest (`x`, `N·3`) and where they are at
//! each of `T` times (`tracks[t]`, `N·3`) are cut into at most `k` groups that each move
//! rigidly, with one pose per time for each. This is the motion segmentation of objects
//! taken over from the deformation field (`objects::adopt`): the tracks are the field's own
//! motion of the object's Gaussians.
//!
//! The fit alternates, as k-means does with rigid motions in place of centres (the
//! "motion segmentation by iterated model fitting" of the multi-body structure-from-motion
//! literature): start from `k` spatial clusters of the rest positions ([`super::cluster`]);
//! fit each group's least-squares rigid motion at every time (Horn 1987,
//! `regularizer::rigid_fit`); move each point to the group whose motions carry it closest
//! to its track (mean squared distance over the times); repeat until no point moves. Groups
//! left with fewer than [`MIN_POINTS`] points are dropped, and two groups that one rigid
//! motion explains almost as well as two ([`Merge`]) are joined, so a body that moves as
//! one comes out as one part.

use super::super::trajectory::Trajectory;
use super::cluster;
use crate::quat;
use crate::regularizer::rigid_fit::{fit_rigid, Point, RigidTransform};

/// A group needs this many points to fix a rotation robustly.
pub const MIN_POINTS: usize = 8;
/// Alternations at most (each one a fit per group and time, and a reassignment).
const ROUNDS: usize = 12;
/// Lloyd iterations of the spatial start.
const KMEANS_ITERS: usize = 20;

/// The groups found: a label per point (`0..parts`), each group's motion at the knot
/// times, and how well the motions explain the tracks.
#[derive(Clone, Debug)]
pub struct TrackFit {
    pub labels: Vec<u32>,
    pub trajectories: Vec<Trajectory>,
    /// RMS over points and times of the distance between a point's track and where its
    /// group's motion carries it.
    pub rms: f32,
    /// The same per group.
    pub part_rms: Vec<f32>,
    /// RMS over a group's points and the times of their distance from rest: what holding
    /// the group still would leave.
    pub still_rms: Vec<f32>,
}

impl TrackFit {
    pub fn parts(&self) -> usize {
        self.trajectories.len()
    }
}

/// When two groups are one ([`join_alike`]).
#[derive(Clone, Copy, Debug)]
pub struct Merge {
    /// Two motions must lower the pair's mean squared distance to its tracks by this
    /// share against one (`objects.parts_min_gain`).
    pub min_gain: f32,
    /// A pair that one motion explains within this RMS distance is one group, whatever
    /// the gain (noise of the tracks).
    pub floor: f32,
}

/// Fits at most `k` rigid groups to the tracks (module docs). `k = 1` is the one rigid
/// motion that explains all points best.
pub fn fit(x: &[f32], tracks: &[Vec<f32>], times: &[f32], k: usize, rule: Merge) -> TrackFit {
    let n = x.len() / 3;
    let xs: Vec<Point> = points(x);
    let ys: Vec<Vec<Point>> = tracks.iter().map(|t| points(t)).collect();
    let mut labels = cluster::kmeans(x, k.max(1), KMEANS_ITERS);
    for _ in 0..ROUNDS {
        let motions = motions(&xs, &ys, &labels);
        let next = reassign(&xs, &ys, &motions);
        let moved = next != labels;
        labels = next;
        if !moved {
            break;
        }
    }
    labels = join_alike(&xs, &ys, labels, rule);
    let motions = motions(&xs, &ys, &labels);
    let parts = motions.len();
    let (mut err, mut still) = (vec![0.0f64; parts], vec![0.0f64; parts]);
    let mut count = vec![0usize; parts];
    for i in 0..n {
        let l = labels[i] as usize;
        count[l] += ys.len();
        for (t, y) in ys.iter().enumerate() {
            err[l] += dist2(motions[l][t].apply(xs[i]), y[i]);
            still[l] += dist2(xs[i], y[i]);
        }
    }
    let total: f64 = err.iter().sum();
    let rms_of = |s: f64, c: usize| (s / c.max(1) as f64).sqrt() as f32;
    TrackFit {
        trajectories: motions.iter().map(|m| trajectory(m, times)).collect(),
        rms: rms_of(total, n * ys.len()),
        part_rms: err
            .iter()
            .zip(&count)
            .map(|(&s, &c)| rms_of(s, c))
            .collect(),
        still_rms: still
            .iter()
            .zip(&count)
            .map(|(&s, &c)| rms_of(s, c))
            .collect(),
        labels,
    }
}

fn points(v: &[f32]) -> Vec<Point> {
    v.chunks_exact(3)
        .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
        .collect()
}

fn dist2(a: Point, b: Point) -> f64 {
    (0..3).map(|c| (a[c] - b[c]).powi(2)).sum()
}

/// Each group's least-squares rigid motion at every time (groups numbered `0..max + 1`;
/// an empty group gets the identity).
fn motions(xs: &[Point], ys: &[Vec<Point>], labels: &[u32]) -> Vec<Vec<RigidTransform>> {
    let k = labels.iter().copied().max().map_or(1, |m| m as usize + 1);
    (0..k as u32)
        .map(|g| {
            let idx: Vec<usize> = (0..xs.len()).filter(|&i| labels[i] == g).collect();
            let src: Vec<Point> = idx.iter().map(|&i| xs[i]).collect();
            ys.iter()
                .map(|y| {
                    let dst: Vec<Point> = idx.iter().map(|&i| y[i]).collect();
                    fit_rigid(&src, &dst, None)
                        .map(|f| f.transform)
                        .unwrap_or(RigidTransform::IDENTITY)
                })
                .collect()
        })
        .collect()
}

/// Each point to the group whose motions carry it closest to its track; groups left with
/// fewer than [`MIN_POINTS`] points give theirs to the next closest, and the labels are
/// packed.
fn reassign(xs: &[Point], ys: &[Vec<Point>], motions: &[Vec<RigidTransform>]) -> Vec<u32> {
    let k = motions.len();
    let cost: Vec<f64> = (0..xs.len())
        .flat_map(|i| {
            motions.iter().map(move |m| {
                ys.iter()
                    .zip(m)
                    .map(|(y, tr)| dist2(tr.apply(xs[i]), y[i]))
                    .sum::<f64>()
            })
        })
        .collect();
    let mut alive = vec![true; k];
    loop {
        let labels: Vec<u32> = (0..xs.len())
            .map(|i| {
                (0..k)
                    .filter(|&g| alive[g])
                    .min_by(|&a, &b| cost[i * k + a].total_cmp(&cost[i * k + b]))
                    .unwrap_or(0) as u32
            })
            .collect();
        let mut count = vec![0usize; k];
        labels.iter().for_each(|&l| count[l as usize] += 1);
        let small = (0..k).find(|&g| alive[g] && count[g] < MIN_POINTS);
        match small {
            Some(g) if alive.iter().filter(|&&a| a).count() > 1 => alive[g] = false,
            _ => return pack(labels),
        }
    }
}

/// Labels renumbered `0..` in order of first use of the group (empty groups dropped).
fn pack(labels: Vec<u32>) -> Vec<u32> {
    let mut map = std::collections::HashMap::new();
    labels
        .iter()
        .map(|l| {
            let next = map.len() as u32;
            *map.entry(*l).or_insert(next)
        })
        .collect()
}

/// Groups joined wherever one rigid motion explains a pair almost as well as two: the
/// pair's mean squared distance to its tracks under one motion is within `1 / (1 −
/// min_gain)` of that under two, or its RMS is below `floor` (union of every such pair).
fn join_alike(xs: &[Point], ys: &[Vec<Point>], labels: Vec<u32>, rule: Merge) -> Vec<u32> {
    let k = labels.iter().copied().max().map_or(1, |m| m as usize + 1);
    if k < 2 {
        return labels;
    }
    // The summed squared distance of the selected groups' points to their tracks under
    // one motion fitted to them all, and how many (point, time) terms it sums.
    let sq = |sel: &dyn Fn(u32) -> bool| -> (f64, usize) {
        let idx: Vec<usize> = (0..labels.len()).filter(|&i| sel(labels[i])).collect();
        let src: Vec<Point> = idx.iter().map(|&i| xs[i]).collect();
        let dst: Vec<Vec<Point>> = ys
            .iter()
            .map(|y| idx.iter().map(|&i| y[i]).collect())
            .collect();
        let m = &motions(&src, &dst, &vec![0; idx.len()])[0];
        let e: f64 = dst
            .iter()
            .zip(m)
            .map(|(y, tr)| {
                src.iter()
                    .zip(y)
                    .map(|(&x, &y)| dist2(tr.apply(x), y))
                    .sum::<f64>()
            })
            .sum();
        (e, idx.len() * ys.len())
    };
    let own: Vec<f64> = (0..k as u32).map(|g| sq(&|l| l == g).0).collect();
    let groups = super::merge::group(k, |a, b| {
        let (joint, n) = sq(&|l| l == a as u32 || l == b as u32);
        let split = own[a] + own[b];
        joint * (1.0 - f64::from(rule.min_gain)) <= split
            || joint / n.max(1) as f64 <= f64::from(rule.floor).powi(2)
    });
    pack(labels.iter().map(|&l| groups[l as usize]).collect())
}

/// The knots of one group: its pose at each time.
fn trajectory(motions: &[RigidTransform], times: &[f32]) -> Trajectory {
    Trajectory {
        times: times.to_vec(),
        translations: motions
            .iter()
            .map(|m| m.translation.map(|v| v as f32))
            .collect(),
        rotations: motions
            .iter()
            .map(|m| quat::from_matrix(&m.rotation))
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULE: Merge = Merge {
        min_gain: 0.1,
        floor: 1e-4,
    };

    /// Two bars side by side along x: the left one still, the right one turning about the
    /// z axis through the joint at the origin, as an arm on a body.
    fn arm(turn: impl Fn(f32) -> f32, times: &[f32]) -> (Vec<f32>, Vec<Vec<f32>>) {
        let mut x = Vec::new();
        for i in 0..40 {
            let s = i as f32 / 39.0;
            let side = if i % 2 == 0 { 1.0 } else { -1.0 };
            x.extend([-1.0 + s, 0.05 * side, 0.02 * (i % 3) as f32]);
            x.extend([s, 0.05 * side, 0.02 * (i % 3) as f32]);
        }
        let tracks = times
            .iter()
            .map(|&t| {
                let a = turn(t);
                x.chunks_exact(3)
                    .flat_map(|p| {
                        if p[0] <= 0.0 {
                            [p[0], p[1], p[2]]
                        } else {
                            let (c, s) = (a.cos(), a.sin());
                            [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]
                        }
                    })
                    .collect()
            })
            .collect();
        (x, tracks)
    }

    #[test]
    fn a_turning_arm_and_a_still_body_come_out_as_two_exact_parts() {
        let times: Vec<f32> = (0..6).map(|t| t as f32 / 5.0).collect();
        let (x, tracks) = arm(|t| 1.2 * t, &times);
        let one = fit(&x, &tracks, &times, 1, RULE);
        assert_eq!(one.parts(), 1);
        assert!(
            one.rms > 0.1,
            "one rigid body cannot explain the arm: {}",
            one.rms
        );
        let two = fit(&x, &tracks, &times, 4, RULE);
        assert_eq!(two.parts(), 2, "{:?}", two.part_rms);
        assert!(two.rms < 0.02, "rms {}", two.rms);
        // Every point on the still bar shares a label, every point on the arm the other,
        // except the joint point at x = 0, which both motions carry exactly.
        let body = two.labels[0];
        for (i, p) in x.chunks_exact(3).enumerate() {
            if p[0] < -1e-3 {
                assert_eq!(two.labels[i], body, "point {i}");
            } else if p[0] > 1e-3 {
                assert_ne!(two.labels[i], body, "point {i}");
            }
        }
        let b = body as usize;
        assert!(two.still_rms[b] < 1e-4 && two.still_rms[1 - b] > 0.1);
        let (_, angle) = two.trajectories[1 - b].motion_extent();
        assert!((angle - 1.2).abs() < 1e-3, "arm turned {angle}");
    }

    #[test]
    fn a_body_that_moves_as_one_is_one_part_whatever_k() {
        let times: Vec<f32> = (0..5).map(|t| t as f32 / 4.0).collect();
        let (x, _) = arm(|_| 0.0, &times);
        let tracks: Vec<Vec<f32>> = times
            .iter()
            .map(|&t| {
                x.iter()
                    .enumerate()
                    .map(|(i, &v)| v + if i % 3 == 0 { t } else { 0.0 })
                    .collect()
            })
            .collect();
        let f = fit(&x, &tracks, &times, 4, RULE);
        assert_eq!(f.parts(), 1);
        assert!(f.rms < 1e-5);
        let p = f.trajectories[0].pose(1.0).p;
        assert!((p[0] - 1.0).abs() < 1e-5 && p[1].abs() < 1e-5, "{p:?}");
    }
}
