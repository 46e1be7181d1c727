//! Deformation consistency against ground-truth rigid motion (for `compare`): how far the
//! Gaussians of a vehicle stray from where the vehicle's true rigid motion puts them.
//!
//! Definition. Gaussians are attached to vehicle `o` once, at a reference time `t_ref`: `G_o` is
//! built (as in [`super::ObjectGroups`]) from the top-k of a render at `t_ref` and the
//! ground-truth instance mask of that view. Each member's anchor is its deformed position at
//! `t_ref`, `a_i = x_i(t_ref)`; the vehicle's true motion from `t_ref` to `t` is
//! `M_o(t) = P_o(t) · P_o(t_ref)⁻¹` (`P` = object_to_world), so the rigid prediction is
//! `M_o(t)·a_i` and the error is `‖x_i(t) − M_o(t)·a_i‖`. Per test time,
//! `e(t) = sqrt(Σ_o Σ_{i∈G_o} err² / Σ_o |G_o|)` pools all vehicles (a Gaussian in two
//! vehicles' groups counts once for each); the reported number is the mean of `e(t)` over the
//! test times, in world units, lower is better. Per-object values are computed the same way.
//!
//! Reference frame choice. The anchor is the deformed position at `t_ref`, not the canonical
//! position: in Deformable 3DGS the canonical space is learned and coincides with no frame, so
//! `δx(·, t_ref)` is generally non-zero and mapping canonical positions through `P_o(t_ref)⁻¹`
//! would charge even a perfectly rigid reconstruction with its canonical offset. With the
//! deformed anchor, `e(t_ref) = 0` by construction and `e(t)` measures only motion that is not
//! the vehicle's rigid motion (for a still vehicle, `M_o = I`: any drift). Callers may pass
//! canonical positions as anchors when their canonical space is the `t_ref` frame.
//!
//! Scale for reading it. Per object we also report `rms_if_still`: the same RMS for Gaussians
//! that stayed at their anchors (`‖a_i − M_o(t)·a_i‖`, i.e. how far the vehicle moved them
//! away from where they were), and `follow = 1 − rms / rms_if_still`: 1 when the Gaussians
//! ride rigidly with the vehicle, 0 when they might as well not have moved (undefined for
//! a vehicle that does not move).

use std::collections::BTreeMap;

use serde::Serialize;

use super::error::RegError;

/// A rigid object-to-world transform in f64 (rotation `r`, row-major, and translation `t`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidPose {
    r: [[f64; 3]; 3],
    t: [f64; 3],
}

/// Tolerance on `RᵀR = I`, the bottom row and `det R = 1` (poses are stored as f32).
const RIGID_TOL: f64 = 1e-4;

impl RigidPose {
    /// From a row-major 4×4 `object_to_world` (toycars `objects.json`); errors unless rigid.
    pub fn from_matrix(object: u8, m: &[[f32; 4]; 4]) -> Result<Self, RegError> {
        let f = |i: usize, j: usize| f64::from(m[i][j]);
        let r = [0, 1, 2].map(|i| [f(i, 0), f(i, 1), f(i, 2)]);
        let pose = Self {
            r,
            t: [f(0, 3), f(1, 3), f(2, 3)],
        };
        let not_rigid = |problem: String| RegError::NotRigid { object, problem };
        let bottom = [f(3, 0), f(3, 1), f(3, 2), f(3, 3) - 1.0];
        if bottom.iter().any(|v| !v.is_finite() || v.abs() > RIGID_TOL) {
            return Err(not_rigid(format!(
                "bottom row is {:?}, not (0, 0, 0, 1)",
                m[3]
            )));
        }
        for i in 0..3 {
            for j in 0..3 {
                let dot: f64 = (0..3).map(|k| r[k][i] * r[k][j]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                if !dot.is_finite() || (dot - want).abs() > RIGID_TOL {
                    return Err(not_rigid(format!("RᵀR[{i}][{j}] = {dot}, not {want}")));
                }
            }
        }
        if pose.det() < 0.0 {
            return Err(not_rigid("rotation is a reflection (det < 0)".into()));
        }
        Ok(pose)
    }

    fn det(&self) -> f64 {
        let r = &self.r;
        r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0])
    }

    /// `self · other⁻¹` (for rigid `other`: `R_o⁻¹ = R_oᵀ`).
    fn after_inverse_of(&self, other: &Self) -> Self {
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| self.r[i][k] * other.r[j][k]).sum();
            }
        }
        let rt = apply_rot(&r, &other.t);
        Self {
            r,
            t: [0, 1, 2].map(|i| self.t[i] - rt[i]),
        }
    }

    fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let q = apply_rot(&self.r, &p);
        [q[0] + self.t[0], q[1] + self.t[1], q[2] + self.t[2]]
    }
}

fn apply_rot(r: &[[f64; 3]; 3], p: &[f64; 3]) -> [f64; 3] {
    r.map(|row| row[0] * p[0] + row[1] * p[1] + row[2] * p[2])
}

/// One vehicle at one test time: its group (from `t_ref`) and its true poses.
#[derive(Clone, Copy, Debug)]
pub struct ObjectTrack<'a> {
    pub object: u8,
    /// `G_o` built at `t_ref` from the ground-truth mask.
    pub members: &'a [u32],
    /// `object_to_world` at `t_ref`.
    pub pose_ref: &'a [[f32; 4]; 4],
    /// `object_to_world` at the test time `t`.
    pub pose_t: &'a [[f32; 4]; 4],
}

/// Sums over one track's members at one time (see module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SquaredErrors {
    /// `Σ ‖x_i(t) − M(t)·a_i‖²`.
    pub sum: f64,
    /// `Σ ‖a_i − M(t)·a_i‖²`: the same had the Gaussians stayed at their anchors.
    pub sum_if_still: f64,
    pub count: usize,
}

/// The squared errors of one track's members at one time (see module docs).
pub fn squared_errors(
    track: &ObjectTrack<'_>,
    anchor: &[f32],
    deformed: &[f32],
) -> Result<SquaredErrors, RegError> {
    let motion = RigidPose::from_matrix(track.object, track.pose_t)?
        .after_inverse_of(&RigidPose::from_matrix(track.object, track.pose_ref)?);
    let n = anchor.len() / 3;
    check_positions("anchor", anchor.len(), n)?;
    check_positions("deformed", deformed.len(), n)?;
    let (mut sum, mut sum_if_still) = (0.0, 0.0);
    for &i in track.members {
        let i = i as usize;
        if i >= n {
            return Err(RegError::PositionLength {
                name: "anchor",
                len: anchor.len(),
                expected: (i + 1) * 3,
            });
        }
        let a = [0, 1, 2].map(|c| f64::from(anchor[i * 3 + c]));
        let want = motion.apply(a);
        let sq = |x: [f64; 3]| (0..3).map(|c| (x[c] - want[c]).powi(2)).sum::<f64>();
        sum += sq([0, 1, 2].map(|c| f64::from(deformed[i * 3 + c])));
        sum_if_still += sq(a);
    }
    Ok(SquaredErrors {
        sum,
        sum_if_still,
        count: track.members.len(),
    })
}

fn check_positions(name: &'static str, len: usize, n: usize) -> Result<(), RegError> {
    if len != n * 3 {
        return Err(RegError::PositionLength {
            name,
            len,
            expected: n * 3,
        });
    }
    Ok(())
}

/// RMS error at one test time.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TimeRms {
    pub time: f32,
    pub rms: f64,
    pub samples: usize,
}

/// Mean over test times of the per-time RMS, per object.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ObjectRms {
    pub object: u8,
    pub rms: f64,
    /// The same for Gaussians that stayed at their anchors (see module docs).
    pub rms_if_still: f64,
}

impl ObjectRms {
    /// `1 − rms / rms_if_still`: 1 = rides with the vehicle, 0 = as if it had not moved;
    /// `None` for a vehicle that does not move (its Gaussians move less than 1e-6 units).
    pub fn follow(&self) -> Option<f64> {
        (self.rms_if_still > 1e-6).then(|| 1.0 - self.rms / self.rms_if_still)
    }
}

/// The metric for a run (`deformation_consistency_rms` = `rms`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ConsistencyReport {
    /// Mean over test times of `e(t)` (world units).
    pub rms: f64,
    pub per_time: Vec<TimeRms>,
    pub per_object: Vec<ObjectRms>,
}

/// Collects test times one by one (each needs the model's positions at that time).
#[derive(Clone, Debug, Default)]
pub struct ConsistencyAccumulator {
    per_time: Vec<TimeRms>,
    /// Per object: (RMS, RMS if still) at each time.
    per_object: BTreeMap<u8, Vec<(f64, f64)>>,
}

impl ConsistencyAccumulator {
    pub fn new() -> Self {
        Self::default()
    }

    /// Add test time `time`: `anchor` = positions at `t_ref`, `deformed` = positions at `time`
    /// (both `N·3`). Empty groups contribute nothing; a time with no samples is not recorded.
    pub fn add_time(
        &mut self,
        time: f32,
        tracks: &[ObjectTrack<'_>],
        anchor: &[f32],
        deformed: &[f32],
    ) -> Result<(), RegError> {
        let (mut sum, mut count) = (0.0, 0usize);
        for track in tracks {
            let e = squared_errors(track, anchor, deformed)?;
            if e.count > 0 {
                let rms = |s: f64| (s / e.count as f64).sqrt();
                let v = (rms(e.sum), rms(e.sum_if_still));
                self.per_object.entry(track.object).or_default().push(v);
            }
            sum += e.sum;
            count += e.count;
        }
        if count > 0 {
            let rms = (sum / count as f64).sqrt();
            self.per_time.push(TimeRms {
                time,
                rms,
                samples: count,
            });
        }
        Ok(())
    }

    pub fn report(&self) -> Result<ConsistencyReport, RegError> {
        if self.per_time.is_empty() {
            return Err(RegError::NoConsistencySamples);
        }
        let mean = |v: &mut dyn Iterator<Item = f64>, n: usize| v.sum::<f64>() / n as f64;
        let rms = mean(
            &mut self.per_time.iter().map(|t| t.rms),
            self.per_time.len(),
        );
        let per_object = self
            .per_object
            .iter()
            .map(|(&object, v)| ObjectRms {
                object,
                rms: mean(&mut v.iter().map(|p| p.0), v.len()),
                rms_if_still: mean(&mut v.iter().map(|p| p.1), v.len()),
            })
            .collect();
        Ok(ConsistencyReport {
            rms,
            per_time: self.per_time.clone(),
            per_object,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Yaw by `a` radians about z, then translate by `t`.
    fn pose(a: f32, t: [f32; 3]) -> [[f32; 4]; 4] {
        let (s, c) = a.sin_cos();
        [
            [c, -s, 0.0, t[0]],
            [s, c, 0.0, t[1]],
            [0.0, 0.0, 1.0, t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    #[test]
    fn relative_motion_composes() {
        let a = RigidPose::from_matrix(0, &pose(0.3, [1.0, 2.0, 0.5])).unwrap();
        let b = RigidPose::from_matrix(0, &pose(-0.7, [0.0, -1.0, 0.2])).unwrap();
        let m = b.after_inverse_of(&a);
        // A point fixed in the object: local q → a(q) at t_ref, b(q) at t.
        let q = [0.4, -0.3, 0.9];
        let (pa, pb) = (a.apply(q), b.apply(q));
        let got = m.apply(pa);
        for c in 0..3 {
            assert!((got[c] - pb[c]).abs() < 1e-6, "{got:?} vs {pb:?}");
        }
    }

    #[test]
    fn rejects_non_rigid_and_reflections() {
        let mut m = pose(0.2, [0.0; 3]);
        m[0][0] *= 1.5;
        assert!(matches!(
            RigidPose::from_matrix(4, &m),
            Err(RegError::NotRigid { object: 4, .. })
        ));
        let mut m = pose(0.0, [0.0; 3]);
        m[2][2] = -1.0;
        assert!(RigidPose::from_matrix(1, &m)
            .unwrap_err()
            .to_string()
            .contains("reflection"));
        let mut m = pose(0.0, [0.0; 3]);
        m[3][0] = 0.5;
        assert!(RigidPose::from_matrix(1, &m).is_err());
    }

    #[test]
    fn rigid_reconstruction_scores_zero_and_offsets_score_their_size() {
        // Three Gaussians on a vehicle that turns and drives; a fourth is not in the group.
        let (p_ref, p_t) = (pose(0.1, [0.0, 0.0, 0.0]), pose(0.9, [1.0, 0.5, 0.0]));
        let motion = RigidPose::from_matrix(0, &p_t)
            .unwrap()
            .after_inverse_of(&RigidPose::from_matrix(0, &p_ref).unwrap());
        let anchor = [
            0.1f32, 0.2, 0.0, -0.3, 0.1, 0.2, 0.5, 0.5, 0.1, 9.0, 9.0, 9.0,
        ];
        let mut deformed = Vec::new();
        for i in 0..4 {
            let a = [0, 1, 2].map(|c| f64::from(anchor[i * 3 + c]));
            deformed.extend(motion.apply(a).map(|v| v as f32));
        }
        let members = [0u32, 1, 2];
        let track = ObjectTrack {
            object: 0,
            members: &members,
            pose_ref: &p_ref,
            pose_t: &p_t,
        };
        let mut acc = ConsistencyAccumulator::new();
        acc.add_time(0.5, &[track], &anchor, &deformed).unwrap();
        assert!(acc.report().unwrap().rms < 1e-6);
        // Displace one of three by 0.3 → e = sqrt(0.09 / 3); a second time with error 0.
        let mut off = deformed.clone();
        off[4] += 0.3;
        let mut acc = ConsistencyAccumulator::new();
        acc.add_time(0.5, &[track], &anchor, &off).unwrap();
        acc.add_time(0.7, &[track], &anchor, &deformed).unwrap();
        let r = acc.report().unwrap();
        let want = (0.09f64 / 3.0).sqrt();
        assert!((r.per_time[0].rms - want).abs() < 1e-6, "{r:?}");
        assert!((r.rms - want / 2.0).abs() < 1e-6);
        assert_eq!(r.per_object.len(), 1);
        // Had they stayed at their anchors, the error would be the vehicle's displacement of
        // them; following exactly but for one offset Gaussian at one time scores near 1.
        let still: f64 = (0..3)
            .map(|i| {
                let a = [0, 1, 2].map(|c| f64::from(anchor[i * 3 + c]));
                let m = motion.apply(a);
                (0..3).map(|c| (m[c] - a[c]).powi(2)).sum::<f64>()
            })
            .sum();
        let still = (still / 3.0).sqrt();
        let o = &r.per_object[0];
        assert!((o.rms_if_still - still).abs() < 1e-6, "{o:?}");
        let follow = o.follow().unwrap();
        assert!((follow - (1.0 - want / 2.0 / still)).abs() < 1e-6);
        // Gaussians that stay at their anchors follow 0.
        let mut acc = ConsistencyAccumulator::new();
        acc.add_time(0.5, &[track], &anchor, &anchor).unwrap();
        assert!(acc.report().unwrap().per_object[0].follow().unwrap().abs() < 1e-9);
        assert_eq!(r.per_time[0].samples, 3);
    }

    #[test]
    fn still_vehicle_measures_drift_and_empty_input_is_an_error() {
        let p = pose(0.4, [0.2, 0.0, 0.0]);
        let members = [0u32];
        let track = ObjectTrack {
            object: 2,
            members: &members,
            pose_ref: &p,
            pose_t: &p,
        };
        let mut acc = ConsistencyAccumulator::new();
        assert_eq!(acc.report(), Err(RegError::NoConsistencySamples));
        acc.add_time(0.1, &[track], &[1.0, 1.0, 1.0], &[1.0, 1.0, 1.5])
            .unwrap();
        assert!((acc.report().unwrap().rms - 0.5).abs() < 1e-6);
        assert_eq!(acc.report().unwrap().per_object[0].follow(), None);
        let bad = acc.add_time(0.2, &[track], &[1.0, 1.0], &[1.0, 1.0, 1.0]);
        assert!(matches!(
            bad,
            Err(RegError::PositionLength { name: "anchor", .. })
        ));
        let far = [5u32];
        let t = ObjectTrack {
            members: &far,
            ..track
        };
        assert!(acc.add_time(0.3, &[t], &[0.0; 3], &[0.0; 3]).is_err());
    }
}
