//! Adam on a trajectory's knots, one optimizer state per knot so that a knot steps only
//! when a view at its time produced a gradient (each training view touches one knot; a
//! dense update would keep moving every knot on momentum alone).

use super::trajectory::{Trajectory, TrajectoryGrad};
use crate::adam::{Adam, AdamHyper};

/// Per-knot Adam moments for the translation (3) and the rotation quaternion (4).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KnotAdam {
    pub translation: Vec<Adam>,
    pub rotation: Vec<Adam>,
}

impl KnotAdam {
    pub fn zeros(knots: usize) -> Self {
        Self {
            translation: (0..knots).map(|_| Adam::zeros(3)).collect(),
            rotation: (0..knots).map(|_| Adam::zeros(4)).collect(),
        }
    }

    /// Steps knot `k` with its gradient; the quaternion is renormalized afterwards so that
    /// its scale, which the rotation ignores, cannot drift.
    pub fn step_knot(
        &mut self,
        tr: &mut Trajectory,
        g: &TrajectoryGrad,
        k: usize,
        hp: AdamHyper,
        lr: (f32, f32),
    ) {
        let gt = g.translations[k].map(|v| v as f32);
        self.translation[k].step(&mut tr.translations[k], &gt, hp, lr.0);
        let gq = g.rotations[k].map(|v| v as f32);
        self.rotation[k].step(&mut tr.rotations[k], &gq, hp, lr.1);
        tr.rotations[k] = crate::quat::normalize(&tr.rotations[k]).0;
    }

    /// Steps every knot whose gradient is not zero.
    pub fn step_touched(
        &mut self,
        tr: &mut Trajectory,
        g: &TrajectoryGrad,
        hp: AdamHyper,
        lr: (f32, f32),
    ) {
        for k in 0..tr.len() {
            let touched = g.translations[k].iter().any(|&v| v != 0.0)
                || g.rotations[k].iter().any(|&v| v != 0.0);
            if touched {
                self.step_knot(tr, g, k, hp, lr);
            }
        }
    }
}
