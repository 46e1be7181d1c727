//! `[densify]`: which strategy controls the Gaussians' number, when, and its thresholds
//! (3DGS `arguments/__init__.py`, `OptimizationParams`).

use crate::error::{check, Result, TrainError};
use serde::{Deserialize, Serialize};

/// Most children a config may split a Gaussian into (3DGS: 2); keeps the allocation finite.
pub const MAX_SPLIT_CHILDREN: usize = 64;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DensifyConfig {
    /// Which Gaussians exist (docs/training.md "Density control"): `adaptive` is 3DGS's
    /// clone/split/prune with opacity resets, as Deformable-3DGS trains (the faithful
    /// default); `mcmc` is 3DGS-MCMC (Kheradmand et al. 2024, as gsplat's `MCMCStrategy`):
    /// a hard cap, dead Gaussians relocated onto live ones, noise on near-transparent ones.
    pub strategy: super::Strategy,
    /// Refinement runs at iterations `from < it < until` that are multiples of `interval`
    /// (`mcmc` ends at `mcmc.until` instead).
    pub from: u32,
    pub until: u32,
    pub interval: u32,
    /// Threshold on the mean view-space gradient norm in 3DGS NDC units.
    pub grad_threshold: f32,
    pub percent_dense: f32,
    pub min_opacity: f32,
    /// Prune Gaussians whose screen radius exceeded this many pixels, once past
    /// `screen_size_after` iterations (3DGS: 20 px after the first opacity reset).
    pub screen_size: f32,
    pub screen_size_after: u32,
    /// Prune Gaussians larger than this fraction of the scene extent.
    pub world_size_factor: f32,
    pub opacity_reset_interval: u32,
    pub reset_opacity: f32,
    /// Children per split Gaussian (3DGS: 2), scaled down by 1/(0.8·children).
    pub split_children: usize,
    /// The `mcmc` strategy's constants (ignored by `adaptive`).
    pub mcmc: super::McmcConfig,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        Self {
            from: 500,
            until: 15_000,
            interval: 100,
            grad_threshold: 2e-4,
            percent_dense: 0.01,
            min_opacity: 0.005,
            screen_size: 20.0,
            screen_size_after: 3000,
            world_size_factor: 0.1,
            opacity_reset_interval: 3000,
            reset_opacity: 0.01,
            split_children: 2,
            strategy: super::Strategy::Adaptive,
            mcmc: super::McmcConfig::default(),
        }
    }
}

impl DensifyConfig {
    /// `[densify]`'s keys, named when wrong.
    pub fn validate(&self) -> Result<()> {
        let d = self;
        check::at_least_one("densify.interval", d.interval as u64)?;
        check::at_least_one(
            "densify.opacity_reset_interval",
            d.opacity_reset_interval as u64,
        )?;
        check::positive("densify.grad_threshold", d.grad_threshold)?;
        check::unit("densify.percent_dense", d.percent_dense)?;
        check::unit("densify.min_opacity", d.min_opacity)?;
        check::positive("densify.screen_size", d.screen_size)?;
        check::positive("densify.world_size_factor", d.world_size_factor)?;
        if !(d.reset_opacity > 0.0 && d.reset_opacity < 1.0) {
            return Err(TrainError::config(
                "densify.reset_opacity",
                format!("must be in (0, 1), got {}", d.reset_opacity),
            ));
        }
        check::at_least_one("densify.split_children", d.split_children as u64)?;
        d.mcmc
            .validate()
            .map_err(|(key, why)| TrainError::config(&format!("densify.mcmc.{key}"), why))?;
        if d.split_children > MAX_SPLIT_CHILDREN {
            return Err(TrainError::config(
                "densify.split_children",
                format!("must be ≤ {MAX_SPLIT_CHILDREN}, got {}", d.split_children),
            ));
        }
        Ok(())
    }
}
