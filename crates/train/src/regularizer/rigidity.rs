//! Rigidity residual of a trained run (beside [`super::consistency`], for `eval` and
//! `compare`): how rigidly the Gaussians attached to a vehicle move, whatever the motion.
//!
//! Definition. The Gaussians of vehicle `o` are attached once, at the reference time
//! `t_ref` (the same groups as the consistency metric). At each test time `t`, fit the best
//! rigid transform ([`super::rigid_fit`], Horn 1987, unweighted) from the members' positions
//! at `t_ref` (`a_i`) to their positions at `t` (`x_i(t)`), and take the RMS residual
//! `r_o(t) = sqrt(min_{R,t} (1/|G_o|) Σ ‖x_i(t) − (R a_i + t)‖²)`. Per object the report is the
//! mean of `r_o(t)` over the test times; pooled, per time `sqrt(Σ_o |G_o|·r_o(t)² / Σ_o |G_o|)`
//! (each vehicle fitted alone; a Gaussian in two groups counts once for each), then the
//! mean over the test times. World units, lower is better; `r_o(t_ref) = 0`.
//!
//! Reading it beside `follow`. No ground truth enters: Gaussians that stand still (a
//! flip-book that never learned the motion) are perfectly rigid too and score 0. `follow`
//! says whether the Gaussians move *with* the vehicle, this metric whether they move
//! *together*; a good reconstruction of a rigid vehicle has both.

use std::collections::BTreeMap;

use serde::Serialize;

use super::consistency::TimeRms;
use super::error::RegError;
use super::rigid_fit::{fit_rigid, Point};

/// The Gaussians attached to one vehicle (`G_o` from `t_ref`).
#[derive(Clone, Copy, Debug)]
pub struct Attached<'a> {
    pub object: u8,
    pub members: &'a [u32],
}

/// Mean over test times of one vehicle's RMS residual.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ObjectRigidity {
    pub object: u8,
    pub rms: f64,
}

/// The metric for a run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RigidityReport {
    /// Mean over test times of the pooled per-time RMS residual (world units).
    pub rms: f64,
    pub per_time: Vec<TimeRms>,
    pub per_object: Vec<ObjectRigidity>,
}

/// Collects test times one by one (each needs the model's positions at that time).
#[derive(Clone, Debug, Default)]
pub struct RigidityAccumulator {
    per_time: Vec<TimeRms>,
    per_object: BTreeMap<u8, Vec<f64>>,
}

impl RigidityAccumulator {
    pub fn new() -> Self {
        Self::default()
    }

    /// Add test time `time`: `anchor` = positions at `t_ref`, `deformed` = positions at `time`
    /// (both `N·3`). Empty groups contribute nothing; a time with no samples is not recorded.
    pub fn add_time(
        &mut self,
        time: f32,
        groups: &[Attached<'_>],
        anchor: &[f32],
        deformed: &[f32],
    ) -> Result<(), RegError> {
        let n = anchor.len() / 3;
        check_positions("anchor", anchor.len(), n * 3)?;
        check_positions("deformed", deformed.len(), n * 3)?;
        let (mut sum, mut count) = (0.0, 0usize);
        for g in groups.iter().filter(|g| !g.members.is_empty()) {
            let residual = residual(g, anchor, deformed, n)?;
            self.per_object
                .entry(g.object)
                .or_default()
                .push(residual.sqrt());
            sum += residual * g.members.len() as f64;
            count += g.members.len();
        }
        if count > 0 {
            self.per_time.push(TimeRms {
                time,
                rms: (sum / count as f64).sqrt(),
                samples: count,
            });
        }
        Ok(())
    }

    pub fn report(&self) -> Result<RigidityReport, RegError> {
        if self.per_time.is_empty() {
            return Err(RegError::NoRigiditySamples);
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let per_time_rms: Vec<f64> = self.per_time.iter().map(|t| t.rms).collect();
        Ok(RigidityReport {
            rms: mean(&per_time_rms),
            per_time: self.per_time.clone(),
            per_object: self
                .per_object
                .iter()
                .map(|(&object, v)| ObjectRigidity {
                    object,
                    rms: mean(v),
                })
                .collect(),
        })
    }
}

/// Mean squared residual of the best rigid fit of one group from `anchor` to `deformed`.
fn residual(g: &Attached<'_>, anchor: &[f32], deformed: &[f32], n: usize) -> Result<f64, RegError> {
    let gather = |buf: &[f32]| -> Result<Vec<Point>, RegError> {
        g.members
            .iter()
            .map(|&i| {
                let i = i as usize;
                if i >= n {
                    return Err(RegError::PositionLength {
                        name: "anchor",
                        len: buf.len(),
                        expected: (i + 1) * 3,
                    });
                }
                Ok([0, 1, 2].map(|c| f64::from(buf[i * 3 + c])))
            })
            .collect()
    };
    let (a, x) = (gather(anchor)?, gather(deformed)?);
    let fit = fit_rigid(&a, &x, None).map_err(|source| RegError::RigidFit {
        object: g.object,
        source,
    })?;
    Ok(fit.residual)
}

fn check_positions(name: &'static str, len: usize, expected: usize) -> Result<(), RegError> {
    if len != expected || !len.is_multiple_of(3) {
        return Err(RegError::PositionLength {
            name,
            len,
            expected,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Yaw by `a` about z and translate by `t`, applied to flat positions.
    fn turned(p: &[f32], a: f32, t: [f32; 3]) -> Vec<f32> {
        let (s, c) = a.sin_cos();
        p.chunks(3)
            .flat_map(|q| {
                [
                    c * q[0] - s * q[1] + t[0],
                    s * q[0] + c * q[1] + t[1],
                    q[2] + t[2],
                ]
            })
            .collect()
    }

    #[test]
    fn rigid_motion_scores_zero_and_a_wobble_scores_its_size() {
        // Four Gaussians of a car and one of the road (not attached).
        let anchor = [
            -0.5f32, -0.2, 0.0, 0.5, -0.2, 0.0, 0.5, 0.2, 0.1, -0.3, 0.1, 0.3, 9.0, 9.0, 9.0,
        ];
        let members = [0u32, 1, 2, 3];
        let car = [Attached {
            object: 3,
            members: &members,
        }];
        let mut acc = RigidityAccumulator::new();
        acc.add_time(0.0, &car, &anchor, &anchor).unwrap();
        let turn = turned(&anchor, 105f32.to_radians(), [1.0, 0.5, 0.0]);
        acc.add_time(0.5, &car, &anchor, &turn).unwrap();
        let r = acc.report().unwrap();
        assert!(r.rms < 1e-6 && r.per_object[0].rms < 1e-6, "{r:?}");
        // Standing still is rigid too.
        let mut still = RigidityAccumulator::new();
        still.add_time(0.5, &car, &anchor, &anchor).unwrap();
        assert_eq!(still.report().unwrap().rms, 0.0);
        // Stretch the car along x by 10 %: a non-rigid deformation has a positive residual,
        // below the RMS of the stretch itself (the fit absorbs what it can).
        let stretched: Vec<f32> = anchor
            .chunks(3)
            .flat_map(|q| [q[0] * 1.1, q[1], q[2]])
            .collect();
        let mut acc = RigidityAccumulator::new();
        acc.add_time(0.7, &car, &anchor, &turned(&stretched, 0.3, [0.0; 3]))
            .unwrap();
        let r = acc.report().unwrap();
        let stretch_rms = (anchor[..12]
            .chunks(3)
            .map(|q| (0.1 * q[0] as f64).powi(2))
            .sum::<f64>()
            / 4.0)
            .sqrt();
        assert!(
            r.rms > 1e-3 && r.rms <= stretch_rms + 1e-6,
            "{r:?} vs {stretch_rms}"
        );
        assert_eq!(r.per_time[0].samples, 4);
    }

    #[test]
    fn pooling_and_errors() {
        let anchor = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        // Gaussian 1 tilts up about the y axis (the pair {0, 1} stays rigid); Gaussian 2
        // moves away from both (the triple {0, 1, 2} does not).
        let mut moved = anchor;
        (moved[3], moved[5], moved[7]) = (0.8, 0.6, 1.5);
        let (a, b) = ([0u32, 1], [0u32, 1, 2]);
        let groups = [
            Attached {
                object: 1,
                members: &a,
            },
            Attached {
                object: 2,
                members: &b,
            },
        ];
        let mut acc = RigidityAccumulator::new();
        acc.add_time(0.2, &groups, &anchor, &moved).unwrap();
        let r = acc.report().unwrap();
        let (ra, rb) = (r.per_object[0].rms, r.per_object[1].rms);
        assert!(ra < 1e-6 && rb > 1e-3, "{r:?}");
        let pooled = ((2.0 * ra * ra + 3.0 * rb * rb) / 5.0).sqrt();
        assert!((r.rms - pooled).abs() < 1e-12);
        let empty = RigidityAccumulator::new();
        assert_eq!(empty.report(), Err(RegError::NoRigiditySamples));
        let far = [7u32];
        let bad = [Attached {
            object: 1,
            members: &far,
        }];
        assert!(acc.add_time(0.3, &bad, &anchor, &anchor).is_err());
        assert!(acc.add_time(0.3, &groups, &anchor, &anchor[..6]).is_err());
        let mut nan = anchor;
        nan[0] = f32::NAN;
        let err = acc.add_time(0.3, &groups, &anchor, &nan).unwrap_err();
        assert!(matches!(err, RegError::RigidFit { object: 1, .. }), "{err}");
    }
}
