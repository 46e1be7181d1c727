//! Every constant of training in one TOML-serializable struct, composed of one section per
//! module: `[init]` ([`crate::init`]), `[field]` ([`crate::field`]), `[densify]`
//! ([`crate::densify`]), `[loss]` ([`crate::loss`]), `[reg]` ([`crate::regularizer`]) and
//! `[objects]` ([`crate::objects`]) are defined and validated beside the code that reads
//! them; the loop's own sections (`[lr]`, `[sh]`, `[log]`) live here. Defaults follow
//! Deformable-3DGS (Yang et al., CVPR 2024, `arguments/__init__.py`) and 3DGS
//! (Kerbl et al. 2023); unknown keys are rejected so a typo is an error, not a silently
//! ignored setting.

use crate::error::{check, Result, TrainError};
use serde::{Deserialize, Serialize};
use std::path::Path;

pub use crate::densify::{DensifyConfig, MAX_SPLIT_CHILDREN};
pub use crate::field::{FieldConfig, MAX_FIELD_PARAMS};
pub use crate::init::{InitConfig, MAX_RANDOM_POINTS};
pub use crate::loss::LossConfig;

/// Smallest densification interval `--iters` rescales to (3DGS's own: 100 views).
pub const MIN_DENSIFY_INTERVAL: u32 = 100;
/// Smallest opacity-reset interval `--iters` rescales to.
pub const MIN_OPACITY_RESET_INTERVAL: u32 = 1000;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Total iterations of the schedule (Deformable-3DGS: 40k).
    pub iterations: u32,
    pub init: InitConfig,
    pub field: FieldConfig,
    pub lr: LrConfig,
    pub densify: DensifyConfig,
    pub sh: ShConfig,
    pub loss: LossConfig,
    pub log: LogConfig,
    /// The SemDynReg regularizer (paper Sec. 3.3–3.4); off unless enabled here or by `--reg`.
    pub reg: crate::regularizer::RegConfig,
    /// Rigid objects (our extension beyond the paper, docs/objects.md); off unless enabled
    /// here or by `--objects`.
    pub objects: crate::objects::ObjectsConfig,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LrConfig {
    /// Means: `position_init·spatial_scale → position_final·spatial_scale` exponentially over
    /// `position_max_steps` (3DGS `get_expon_lr_func`; Deformable-3DGS uses s = 5).
    pub position_init: f32,
    pub position_final: f32,
    pub position_max_steps: u32,
    pub spatial_scale: f32,
    /// Field: `field_init → field_final` over `field_max_steps` (8e-4 → 1.6e-6 over 40k).
    pub field_init: f32,
    pub field_final: f32,
    pub field_max_steps: u32,
    pub sh_dc: f32,
    pub sh_rest: f32,
    pub opacity: f32,
    pub scaling: f32,
    pub rotation: f32,
    pub adam_beta1: f32,
    pub adam_beta2: f32,
    pub adam_eps: f32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShConfig {
    pub max_degree: usize,
    pub degree_interval: u32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LogConfig {
    /// Every this many iterations: test evaluation, checkpoint, metrics log line (0 = never).
    pub eval_interval: u32,
    pub checkpoint_interval: u32,
    pub log_interval: u32,
    /// Frames used by the periodic evaluation (0 = all).
    pub eval_frames: usize,
    /// Split the periodic evaluation scores: `test` (default), `val` (D-NeRF lego, whose
    /// released test set is inconsistent with its training set: Deformable-3DGS's README
    /// says to score val) or `train`.
    pub eval_split: EvalSplit,
    /// Checkpoints kept on disk (older ones are deleted).
    pub keep_checkpoints: usize,
    /// Also save a checkpoint, kept whatever `keep_checkpoints` says, when the run's wall
    /// time (every resumed segment, evaluations and saves included) first passes each of
    /// these marks, in minutes: quality after 10, 30, 60 minutes is `eval --iteration` of
    /// those (`train --checkpoint-minutes`; docs/performance.md "Time to quality").
    pub checkpoint_minutes: Vec<f64>,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            iterations: 40_000,
            init: InitConfig::default(),
            field: FieldConfig::default(),
            lr: LrConfig::default(),
            densify: DensifyConfig::default(),
            sh: ShConfig::default(),
            loss: LossConfig::default(),
            log: LogConfig::default(),
            reg: crate::regularizer::RegConfig {
                enabled: false,
                ..Default::default()
            },
            objects: crate::objects::ObjectsConfig::default(),
        }
    }
}

impl Default for LrConfig {
    fn default() -> Self {
        Self {
            position_init: 1.6e-4,
            position_final: 1.6e-6,
            position_max_steps: 30_000,
            spatial_scale: 5.0,
            field_init: 8e-4,
            field_final: 1.6e-6,
            field_max_steps: 40_000,
            sh_dc: 2.5e-3,
            sh_rest: 1.25e-4, // feature_lr / 20, computed in double as the official
            opacity: 0.05,
            scaling: 5e-3,
            rotation: 1e-3,
            adam_beta1: 0.9,
            adam_beta2: 0.999,
            adam_eps: 1e-15,
        }
    }
}

impl Default for ShConfig {
    fn default() -> Self {
        Self {
            max_degree: 3,
            degree_interval: 1000,
        }
    }
}

/// A data split, as named in configs and on the command line.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EvalSplit {
    Train,
    Val,
    #[default]
    Test,
}

impl EvalSplit {
    pub fn name(self) -> &'static str {
        match self {
            Self::Train => "train",
            Self::Val => "val",
            Self::Test => "test",
        }
    }

    /// The frames of this split.
    pub fn frames(self, d: &scene::Dataset) -> &[scene::Frame] {
        match self {
            Self::Train => &d.train,
            Self::Val => &d.val,
            Self::Test => &d.test,
        }
    }
}

impl Default for LogConfig {
    fn default() -> Self {
        Self {
            eval_interval: 5000,
            checkpoint_interval: 5000,
            log_interval: 100,
            eval_frames: 0,
            eval_split: EvalSplit::Test,
            keep_checkpoints: 2,
            checkpoint_minutes: Vec::new(),
        }
    }
}

impl TrainConfig {
    /// Reads a TOML file (missing keys take defaults) and validates it.
    pub fn from_toml_file(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| TrainError::io(path, e))?;
        let cfg: TrainConfig = toml::from_str(&text).map_err(|e| TrainError::ConfigParse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        cfg.validate().map_err(|e| e.in_config_file(path))?;
        Ok(cfg)
    }

    /// The config of a new run as the CLI builds it: `file` (or the defaults), rescaled to
    /// `iters` iterations when given.
    pub fn for_run(file: Option<&Path>, iters: Option<u32>) -> Result<Self> {
        let cfg = match file {
            Some(p) => Self::from_toml_file(p)?,
            None => Self::default(),
        };
        match (iters, file) {
            // A schedule that rescales to an invalid value came from the file's values.
            // (`--iters 0` is the command line's fault, not the file's.)
            (Some(n), Some(p)) if n > 0 => cfg.rescaled(n).map_err(|e| e.in_config_file(p)),
            (Some(n), _) => cfg.rescaled(n),
            (None, _) => Ok(cfg),
        }
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("config serializes: plain numbers and bools only")
    }

    /// Rescales the schedule to `iters` iterations (`--iters`), so a short run keeps the
    /// shape of the 40k schedule: every milestone (warm-up, densification window, learning
    /// rate decay, SH steps, regularizer window) moves proportionally. Two intervals are
    /// windows of statistics rather than milestones and do not shrink below
    /// [`MIN_DENSIFY_INTERVAL`] and [`MIN_OPACITY_RESET_INTERVAL`] (or their configured
    /// values when those are smaller; the start of size pruning, tied to the first reset in
    /// 3DGS, takes the latter floor too): the view-space gradient that decides densification
    /// is a mean over the views seen since the last densification, and Gaussians need a few
    /// hundred steps to recover from an opacity reset before the next one. Scaled
    /// proportionally, a 3k run would densify every 8 steps and reset every 225, which
    /// prunes 100k Gaussians to ~6k and leaves a blurred scene (docs/training.md).
    pub fn rescaled(&self, iters: u32) -> Result<Self> {
        if iters == 0 {
            return Err(TrainError::config("iterations", "must be ≥ 1"));
        }
        let f = iters as f64 / self.iterations as f64;
        let at = |v: u32| (v as f64 * f).round() as u32;
        let every = |v: u32| if v == 0 { 0 } else { at(v).max(1) };
        let window = |v: u32, floor: u32| {
            if v == 0 {
                0
            } else {
                every(v).max(v.min(floor))
            }
        };
        let mut c = self.clone();
        c.iterations = iters;
        c.field.warm_up = at(c.field.warm_up);
        c.lr.position_max_steps = every(c.lr.position_max_steps);
        c.lr.field_max_steps = every(c.lr.field_max_steps);
        c.densify.from = at(c.densify.from);
        c.densify.until = at(c.densify.until);
        c.densify.mcmc.until = at(c.densify.mcmc.until);
        c.densify.interval = window(c.densify.interval, MIN_DENSIFY_INTERVAL);
        // 3DGS starts the size pruning after the first opacity reset
        // (`size_threshold = 20 if iteration > opacity_reset_interval`), so it takes the
        // reset's floor too: pruning by world size at step 225 of a 3k run removes the random
        // init (its scales are the neighbour spacing, ~0.1 for 20k points) before it adapts.
        c.densify.screen_size_after =
            window(c.densify.screen_size_after, MIN_OPACITY_RESET_INTERVAL);
        c.densify.opacity_reset_interval =
            window(c.densify.opacity_reset_interval, MIN_OPACITY_RESET_INTERVAL);
        c.sh.degree_interval = every(c.sh.degree_interval);
        c.log.eval_interval = every(c.log.eval_interval);
        c.log.checkpoint_interval = every(c.log.checkpoint_interval);
        c.log.log_interval = every(c.log.log_interval);
        c.reg.start_iter = at(c.reg.start_iter as u32) as u64;
        c.reg.end_iter = at(c.reg.end_iter as u32) as u64;
        c.objects = self.objects.rescaled(self.iterations, iters);
        c.validate()?;
        Ok(c)
    }

    /// Rejects values that would make training meaningless or crash, naming the key; each
    /// section checks its own keys.
    pub fn validate(&self) -> Result<()> {
        check::at_least_one("iterations", self.iterations as u64)?;
        self.init.validate()?;
        self.field.validate()?;
        self.lr.validate()?;
        self.densify.validate()?;
        if self.sh.max_degree > 3 {
            return Err(TrainError::config(
                "sh.max_degree",
                format!("must be ≤ 3, got {}", self.sh.max_degree),
            ));
        }
        check::at_least_one("sh.degree_interval", self.sh.degree_interval as u64)?;
        if let Some(m) = self
            .log
            .checkpoint_minutes
            .iter()
            .find(|m| !(m.is_finite() && **m > 0.0))
        {
            return Err(TrainError::config(
                "log.checkpoint_minutes",
                format!("must be finite and > 0, got {m}"),
            ));
        }
        self.loss.validate()?;
        self.reg
            .validate()
            .map_err(|e| TrainError::config("reg", e.to_string()))?;
        self.objects
            .validate()
            .map_err(|e| TrainError::config("objects", e))?;
        Ok(())
    }
}

impl LrConfig {
    /// Learning rates finite and ≥ 0 (> 0 where a schedule divides by them), betas in [0, 1).
    fn validate(&self) -> Result<()> {
        let l = self;
        for (n, v) in [
            ("lr.position_init", l.position_init),
            ("lr.position_final", l.position_final),
            ("lr.spatial_scale", l.spatial_scale),
            ("lr.field_init", l.field_init),
            ("lr.field_final", l.field_final),
            ("lr.adam_eps", l.adam_eps),
        ] {
            check::positive(n, v)?;
        }
        for (n, v) in [
            ("lr.sh_dc", l.sh_dc),
            ("lr.sh_rest", l.sh_rest),
            ("lr.opacity", l.opacity),
            ("lr.scaling", l.scaling),
            ("lr.rotation", l.rotation),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(TrainError::config(
                    n,
                    format!("must be finite and ≥ 0, got {v}"),
                ));
            }
        }
        let beta_ok = |b: f32| (0.0..1.0).contains(&b);
        if !beta_ok(l.adam_beta1) || !beta_ok(l.adam_beta2) {
            return Err(TrainError::config(
                "lr.adam_beta1/adam_beta2",
                "must be in [0, 1)",
            ));
        }
        check::at_least_one("lr.position_max_steps", l.position_max_steps as u64)?;
        check::at_least_one("lr.field_max_steps", l.field_max_steps as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_roundtrip() {
        let c = TrainConfig::default();
        c.validate().unwrap();
        let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(back, c);
    }

    #[test]
    fn unknown_key_is_an_error() {
        let e = toml::from_str::<TrainConfig>("[field]\nwidht = 3\n").unwrap_err();
        assert!(e.to_string().contains("widht"), "{e}");
    }

    /// The new field keys name themselves when wrong; a bad eval split is a parse error.
    #[test]
    fn bad_time_network_head_scale_and_split_are_named() {
        let err = |f: fn(&mut TrainConfig)| {
            let mut c = TrainConfig::default();
            f(&mut c);
            c.validate().unwrap_err().to_string()
        };
        let e = err(|c| (c.field.time_net_width, c.field.time_net_out) = (256, 0));
        assert!(e.contains("field.time_net_out"), "{e}");
        let e = err(|c| c.field.time_net_width = 1 << 20);
        assert!(e.contains("field.time_net_width"), "{e}");
        let e = err(|c| c.field.head_init_scale = -1.0);
        assert!(e.contains("field.head_init_scale"), "{e}");
        let e = toml::from_str::<TrainConfig>("[log]\neval_split = \"dev\"\n").unwrap_err();
        assert!(e.to_string().contains("dev"), "{e}");
        let c: TrainConfig = toml::from_str("[log]\neval_split = \"val\"\n").unwrap();
        assert_eq!(c.log.eval_split, EvalSplit::Val);
    }

    /// The shortest schedules too: `objects.start_iter` must not round to 0.
    #[test]
    fn every_short_schedule_rescales_to_a_valid_config() {
        for n in 1..=64 {
            let c = TrainConfig::default()
                .rescaled(n)
                .unwrap_or_else(|e| panic!("{n}: {e}"));
            c.validate().unwrap_or_else(|e| panic!("--iters {n}: {e}"));
        }
    }

    #[test]
    fn rescale_keeps_proportions() {
        let c = TrainConfig::default().rescaled(400).unwrap();
        assert_eq!(c.iterations, 400);
        assert_eq!(c.field.warm_up, 30);
        assert_eq!(c.densify.from, 5);
        assert_eq!(c.densify.until, 150);
        assert_eq!(c.densify.interval, MIN_DENSIFY_INTERVAL);
        assert_eq!(c.densify.opacity_reset_interval, MIN_OPACITY_RESET_INTERVAL);
        assert_eq!(c.densify.screen_size_after, MIN_OPACITY_RESET_INTERVAL);
        assert_eq!(c.lr.position_max_steps, 300);
        assert_eq!(c.sh.degree_interval, 10);
        assert!(TrainConfig::default().rescaled(0).is_err());
        // Intervals configured below the floors stay as configured.
        let mut small = TrainConfig::default();
        small.densify.interval = 10;
        assert_eq!(small.rescaled(400).unwrap().densify.interval, 10);
        // A longer schedule scales the intervals up as usual.
        let long = TrainConfig::default().rescaled(80_000).unwrap();
        assert_eq!(long.densify.interval, 200);
        assert_eq!(long.densify.opacity_reset_interval, 6000);
    }

    #[test]
    fn bad_values_name_the_key() {
        let mut c = TrainConfig::default();
        c.lr.adam_eps = -1.0;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("lr.adam_eps"), "{e}");
        let mut c = TrainConfig::default();
        c.densify.min_opacity = f32::NAN;
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("min_opacity"));
        let mut c = TrainConfig::default();
        c.sh.max_degree = 4;
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("sh.max_degree"));
    }
}
