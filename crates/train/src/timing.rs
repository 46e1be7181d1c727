//! Wall time per phase of an iteration, accumulated for the performance breakdown.

use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    FieldForward,
    Deform,
    RasterForward,
    Loss,
    Hook,
    RasterBackward,
    FieldBackward,
    Optimizer,
    Densify,
}

pub const PHASES: [Phase; 9] = [
    Phase::FieldForward,
    Phase::Deform,
    Phase::RasterForward,
    Phase::Loss,
    Phase::Hook,
    Phase::RasterBackward,
    Phase::FieldBackward,
    Phase::Optimizer,
    Phase::Densify,
];

impl Phase {
    pub fn name(self) -> &'static str {
        match self {
            Phase::FieldForward => "field_forward",
            Phase::Deform => "deform",
            Phase::RasterForward => "raster_forward",
            Phase::Loss => "loss",
            Phase::Hook => "hook",
            Phase::RasterBackward => "raster_backward",
            Phase::FieldBackward => "field_backward",
            Phase::Optimizer => "optimizer",
            Phase::Densify => "densify",
        }
    }
}

/// Seconds per phase and the number of iterations they cover.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepTimings {
    pub seconds: [f64; 9],
    pub iterations: u64,
}

impl StepTimings {
    pub fn record(&mut self, phase: Phase, since: Instant) {
        let i = PHASES
            .iter()
            .position(|&p| p == phase)
            .expect("listed phase");
        self.seconds[i] += since.elapsed().as_secs_f64();
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
