//! Wall time per phase of an iteration, accumulated for the performance breakdown (field
//! forward/backward, projection, rasterization forward/backward, loss, hook, optimizer,
//! densification, the rigid objects' mask term). Projection is timed inside the rasterizer's calls
//! ([`splat::Timings::project`]) and moved out of the rasterization phases.

use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    FieldForward,
    Deform,
    /// Projection to 2D and SH colour (forward).
    Projection,
    /// Binning, depth sort and the tile kernels (forward).
    RasterForward,
    Loss,
    Hook,
    /// Tile kernels and the per-Gaussian gradient sums (backward).
    RasterBackward,
    /// Projection and SH backward.
    ProjectionBackward,
    FieldBackward,
    Optimizer,
    Densify,
    /// The rigid objects' mask term (their objects-only renders).
    Objects,
}

pub const PHASES: [Phase; 12] = [
    Phase::FieldForward,
    Phase::Deform,
    Phase::Projection,
    Phase::RasterForward,
    Phase::Loss,
    Phase::Hook,
    Phase::RasterBackward,
    Phase::ProjectionBackward,
    Phase::FieldBackward,
    Phase::Optimizer,
    Phase::Densify,
    Phase::Objects,
];

impl Phase {
    pub fn name(self) -> &'static str {
        match self {
            Phase::FieldForward => "field_forward",
            Phase::Deform => "deform",
            Phase::Projection => "projection",
            Phase::RasterForward => "raster_forward",
            Phase::Loss => "loss",
            Phase::Hook => "hook",
            Phase::RasterBackward => "raster_backward",
            Phase::ProjectionBackward => "projection_backward",
            Phase::FieldBackward => "field_backward",
            Phase::Optimizer => "optimizer",
            Phase::Densify => "densify",
            Phase::Objects => "objects",
        }
    }
}

/// Seconds per phase and the number of iterations they cover.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepTimings {
    pub seconds: [f64; PHASES.len()],
    pub iterations: u64,
}

fn index(phase: Phase) -> usize {
    PHASES
        .iter()
        .position(|&p| p == phase)
        .expect("listed phase")
}

impl StepTimings {
    pub fn record(&mut self, phase: Phase, since: Instant) {
        self.seconds[index(phase)] += since.elapsed().as_secs_f64();
    }

    /// Moves `seconds` from `from` to `to`: a sub-phase timed inside `from`'s call.
    pub fn move_seconds(&mut self, from: Phase, to: Phase, seconds: f64) {
        let s = seconds.clamp(0.0, self.seconds[index(from)]);
        self.seconds[index(from)] -= s;
        self.seconds[index(to)] += s;
    }

    pub fn add(&mut self, other: &StepTimings) {
        for (a, b) in self.seconds.iter_mut().zip(other.seconds) {
            *a += b;
        }
        self.iterations += other.iterations.max(1);
    }

    /// Milliseconds per iteration for each phase, by name.
    pub fn per_iteration_ms(&self) -> Vec<(&'static str, f64)> {
        let n = self.iterations.max(1) as f64;
        PHASES
            .iter()
            .zip(self.seconds)
            .map(|(p, s)| (p.name(), 1e3 * s / n))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moved_seconds_keep_the_total_and_never_go_negative() {
        let mut t = StepTimings::default();
        t.seconds[index(Phase::RasterForward)] = 0.5;
        t.iterations = 2;
        t.move_seconds(Phase::RasterForward, Phase::Projection, 0.2);
        t.move_seconds(Phase::RasterBackward, Phase::ProjectionBackward, 0.3);
        let ms: std::collections::HashMap<_, _> = t.per_iteration_ms().into_iter().collect();
        assert!((ms["projection"] - 100.0).abs() < 1e-9);
        assert!((ms["raster_forward"] - 150.0).abs() < 1e-9);
        assert_eq!(
            ms["projection_backward"], 0.0,
            "clamped to what the phase had"
        );
        assert_eq!(ms.len(), PHASES.len());
    }
}
