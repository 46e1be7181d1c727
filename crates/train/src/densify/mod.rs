//! Density control: which Gaussians exist, chosen by `[densify] strategy`, as gsplat makes
//! densification a pluggable `Strategy`.
//!
//! - [`adaptive`]: 3DGS's adaptive density control (clone small and split large Gaussians
//!   whose mean view-space gradient is high, prune transparent and huge ones, reset
//!   opacities), exactly as Deformable-3DGS trains: the faithful default.
//! - [`mcmc`]: 3DGS as Markov Chain Monte Carlo (Kheradmand et al., NeurIPS 2024; gsplat's
//!   `MCMCStrategy`): a hard cap on the count, dead Gaussians relocated onto live ones
//!   (Eq. 9 of the paper, [`relocation`]), growth by sampling live ones, noise on the means
//!   of near-transparent Gaussians, and L1 penalties on opacity and scale.
//!
//! The trainer asks [`Schedule::at`] what to do at each iteration and calls [`refine`] on
//! refinement iterations; strategy-specific work stays in the strategy's module.

pub mod adaptive;
pub mod config;
pub mod mcmc;
pub mod relocation;

pub use adaptive::{densify_and_prune, reset_opacity};
pub use config::{DensifyConfig, MAX_SPLIT_CHILDREN};
pub use mcmc::McmcConfig;

use crate::state::GaussianState;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// `[densify] strategy`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Strategy {
    /// 3DGS adaptive density control (Deformable-3DGS's, the faithful default).
    #[default]
    Adaptive,
    /// 3DGS-MCMC with a hard cap (`[densify.mcmc]`).
    Mcmc,
}

/// What one refinement did, for logs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DensifyReport {
    pub cloned: usize,
    pub split: usize,
    pub pruned: usize,
    /// `mcmc`: dead Gaussians moved onto live ones, and Gaussians added.
    pub relocated: usize,
    pub added: usize,
}

/// What density control does at one (1-based) iteration.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Schedule {
    /// Accumulate view-space gradients and screen radii (`adaptive` only).
    pub collect_stats: bool,
    /// Refine the set of Gaussians after the optimizer step ([`refine`]).
    pub refine: bool,
    /// Cap opacities after refining (`adaptive`'s opacity reset).
    pub reset_opacity: bool,
    /// Take the Adam step on the Gaussians. 3DGS skips it on densification iterations:
    /// its new tensors have no `.grad` there (`adaptive` keeps that).
    pub step_gaussians: bool,
    /// Skip the opacity step (3DGS: right after an opacity reset).
    pub step_opacity: bool,
    /// Add the opacity and scale penalties' gradients and the position noise (`mcmc`).
    pub mcmc_terms: bool,
}

impl Schedule {
    /// The schedule at iteration `it`; `white_background` adds 3DGS's opacity reset at the
    /// start of densification on white-background scenes.
    pub fn at(cfg: &DensifyConfig, it: u32, white_background: bool) -> Self {
        let due = |until: u32| it < until && it > cfg.from && it.is_multiple_of(cfg.interval);
        match cfg.strategy {
            Strategy::Adaptive => {
                let window = it < cfg.until;
                let refine = due(cfg.until);
                let reset = window
                    && (it.is_multiple_of(cfg.opacity_reset_interval)
                        || (white_background && it == cfg.from));
                Self {
                    collect_stats: window,
                    refine,
                    reset_opacity: reset,
                    step_gaussians: !refine,
                    step_opacity: !reset,
                    mcmc_terms: false,
                }
            }
            Strategy::Mcmc => Self {
                collect_stats: false,
                refine: due(cfg.mcmc.until),
                reset_opacity: false,
                step_gaussians: true,
                step_opacity: true,
                mcmc_terms: true,
            },
        }
    }
}

/// One refinement by the configured strategy. `prune_screen` (adaptive) enables the
/// screen- and world-size prune.
pub fn refine(
    st: &mut GaussianState,
    cfg: &DensifyConfig,
    extent: f32,
    prune_screen: bool,
    rng: &mut impl Rng,
) -> DensifyReport {
    match cfg.strategy {
        Strategy::Adaptive => densify_and_prune(st, cfg, extent, prune_screen, rng),
        Strategy::Mcmc => mcmc::refine(st, &cfg.mcmc, cfg.min_opacity, rng),
    }
}

/// Largest of a Gaussian's three scales.
pub(crate) fn max_scale(log_scales: &[f32], i: usize) -> f32 {
    log_scales[i * 3..i * 3 + 3]
        .iter()
        .fold(f32::NEG_INFINITY, |a, &b| a.max(b))
        .exp()
}

/// Rotation matrix of a (not necessarily normalized) w,x,y,z quaternion, row-major.
pub(crate) fn rotation(q: &[f32]) -> [[f32; 3]; 3] {
    let n = (q.iter().map(|v| v * v).sum::<f32>()).sqrt().max(1e-12);
    crate::quat::to_matrix([q[0] / n, q[1] / n, q[2] / n, q[3] / n])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adaptive_schedule_follows_3dgs() {
        let c = DensifyConfig::default();
        let s = Schedule::at(&c, 600, false);
        assert!(s.refine && s.collect_stats && !s.step_gaussians && s.step_opacity);
        let s = Schedule::at(&c, 601, false);
        assert!(!s.refine && s.step_gaussians);
        let s = Schedule::at(&c, 3000, false);
        assert!(s.refine && s.reset_opacity && !s.step_opacity);
        assert!(Schedule::at(&c, c.from, true).reset_opacity);
        assert!(!Schedule::at(&c, c.from, false).reset_opacity);
        let s = Schedule::at(&c, c.until, false);
        assert!(!s.refine && !s.collect_stats && !s.reset_opacity);
        assert!(!Schedule::at(&c, c.from, false).refine, "from is exclusive");
        assert!(!s.mcmc_terms);
    }

    #[test]
    fn mcmc_schedule_refines_to_its_own_end_and_always_steps() {
        let c = DensifyConfig {
            strategy: Strategy::Mcmc,
            ..Default::default()
        };
        assert!(
            c.mcmc.until > c.until,
            "the test needs mcmc's longer window"
        );
        let late = (c.until / c.interval + 1) * c.interval;
        let s = Schedule::at(&c, late, true);
        assert!(s.refine && s.step_gaussians && s.step_opacity && s.mcmc_terms);
        assert!(!s.collect_stats && !s.reset_opacity);
        assert!(!Schedule::at(&c, c.mcmc.until, false).refine);
        assert!(!Schedule::at(&c, 3000 + 1, false).refine);
        assert!(!Schedule::at(&c, c.from, true).reset_opacity);
    }

    #[test]
    fn strategy_reads_from_toml() {
        let c: DensifyConfig = toml::from_str("strategy = \"mcmc\"\n[mcmc]\ncap = 1234\n").unwrap();
        assert_eq!(c.strategy, Strategy::Mcmc);
        assert_eq!(c.mcmc.cap, 1234);
        let e = toml::from_str::<DensifyConfig>("strategy = \"fast\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("adaptive") && e.contains("mcmc"), "{e}");
    }
}
