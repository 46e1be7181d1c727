//! Every constant of training in one TOML-serializable struct. Defaults follow
//! Deformable-3DGS (Yang et al., CVPR 2024, `arguments/__init__.py`) and 3DGS
//! (Kerbl et al. 2023) as listed in issue 5; unknown keys are rejected so a typo is an error,
//! not a silently ignored setting.

use crate::error::{Result, TrainError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Smallest densification interval `--iters` rescales to (3DGS's own: 100 views).
pub const MIN_DENSIFY_INTERVAL: u32 = 100;
/// Smallest opacity-reset interval `--iters` rescales to.
pub const MIN_OPACITY_RESET_INTERVAL: u32 = 1000;
/// Upper bounds that keep a config's allocations finite (a bad value is refused, not an
/// abort on a failed allocation): the deformation MLP's parameter count (2^26 = 67M, 256
/// MiB of f32 before Adam's two moments; the faithful field has 0.6M), the random
/// initialization's points (3DGS uses 100k) and the children per split Gaussian (3DGS: 2).
pub const MAX_FIELD_PARAMS: usize = 1 << 26;
pub const MAX_RANDOM_POINTS: usize = 50_000_000;
pub const MAX_SPLIT_CHILDREN: usize = 64;

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
pub struct InitConfig {
    /// Use the scene's point cloud when it has one; otherwise random points.
    pub use_point_cloud: bool,
    /// Random init: number of points uniform in [−extent, extent]³ (3DGS synthetic: 100k, 1.3).
    pub random_points: usize,
    pub random_extent: f32,
    /// Initial opacity (3DGS: 0.1).
    pub opacity: f32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FieldConfig {
    /// Hidden ReLU layers (Deformable-3DGS: D = 8) and their width (W = 256).
    pub depth: usize,
    pub width: usize,
    /// The encoded input is concatenated to the output of this hidden layer (D/2 = 4 in
    /// Deformable-3DGS, `skips = [D // 2]`); ≥ depth − 1 disables the skip.
    pub skip: usize,
    /// Positional-encoding frequencies of the mean (10) and of t (6 synthetic / 10 real).
    pub pos_freqs: usize,
    pub time_freqs: usize,
    /// Iterations with δ = 0 before the field is used (Deformable-3DGS `warm_up`: 3k).
    pub warm_up: u32,
    /// Evaluate the field only for Gaussians whose canonical mean projects inside the view
    /// enlarged by `visible_margin` (fraction of the image size); others get δ = 0 this step.
    pub visible_only: bool,
    pub visible_margin: f32,
    /// Apply the field's scale offset δs (Deformable-3DGS: yes). Off, the Gaussians keep their
    /// size over time: the field can move and turn them but not shrink them out of view, the
    /// "flip-book" of docs/regularizer.md. δx and δr are unaffected.
    pub deform_scale: bool,
    /// Deformable-3DGS's time network for D-NeRF scenes (`is_blender`): γ(t) → Linear(·,
    /// `time_net_width`) → ReLU → Linear(·, `time_net_out`) replaces γ(t) in the field's
    /// input (`crate::time_net`). 0 = off, γ(t) goes in directly (the official non-D-NeRF
    /// path). Official: 256 → 30.
    pub time_net_width: usize,
    pub time_net_out: usize,
    /// Factor on the head's PyTorch-default initial weights and bias (1 = Deformable-3DGS;
    /// our default 0).
    /// With a small field the default head moves every Gaussian by its own ~0.1 units the
    /// moment the field starts (8×256: a near-uniform ~0.05 shift; docs/fidelity.md,
    /// "Field start"); 0 starts the field at δ = 0, and it learns from there.
    pub head_init_scale: f32,
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
pub struct DensifyConfig {
    /// Which Gaussians exist (docs/training.md "Density control"): `adaptive` is 3DGS's
    /// clone/split/prune with opacity resets, as Deformable-3DGS trains (the faithful
    /// default); `mcmc` is 3DGS-MCMC (Kheradmand et al. 2024, as gsplat's `MCMCStrategy`):
    /// a hard cap, dead Gaussians relocated onto live ones, noise on near-transparent ones.
    pub strategy: crate::densify::Strategy,
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
    pub mcmc: crate::densify::McmcConfig,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShConfig {
    pub max_degree: usize,
    pub degree_interval: u32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LossConfig {
    /// `L = (1 − λ)·L1 + λ·(1 − SSIM)` (3DGS: λ = 0.2).
    pub lambda_dssim: f32,
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

impl Default for InitConfig {
    fn default() -> Self {
        Self {
            use_point_cloud: true,
            random_points: 100_000,
            random_extent: 1.3,
            opacity: 0.1,
        }
    }
}

impl FieldConfig {
    /// Width of the field's time input: the time network's output, or γ(t) without one.
    pub fn time_input_dim(&self) -> usize {
        if self.time_net_width > 0 {
            self.time_net_out
        } else {
            crate::encoding::encoded_dim(1, self.time_freqs)
        }
    }

    /// Deformable-3DGS's network for D-NeRF exactly (`is_blender`): 8 × 256, skip after
    /// layer 4, γ(t) with 6 frequencies through the 256 → 30 time network, on every Gaussian.
    pub fn faithful() -> Self {
        Self {
            depth: 8,
            width: 256,
            skip: 4,
            pos_freqs: 10,
            time_freqs: 6,
            warm_up: 3000,
            visible_only: false,
            visible_margin: 0.15,
            deform_scale: true,
            time_net_width: 256,
            time_net_out: 30,
            head_init_scale: 1.0,
        }
    }
}

impl Default for FieldConfig {
    fn default() -> Self {
        // Faster default justified in docs/performance.md ("Training"): the faithful
        // 8×256 field costs more than the whole 60-minute budget on 2 cores.
        Self {
            depth: 4,
            width: 64,
            skip: 2,
            visible_only: true,
            time_net_width: 0,
            // A small field's default head scatters the Gaussians at its start (lego val
            // +2.18 dB, toycars +0.08/+0.13 dB with a zero head: docs/fidelity.md §2–3).
            head_init_scale: 0.0,
            ..Self::faithful()
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
            strategy: crate::densify::Strategy::Adaptive,
            mcmc: crate::densify::McmcConfig::default(),
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

impl Default for LossConfig {
    fn default() -> Self {
        Self { lambda_dssim: 0.2 }
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

    /// Rejects values that would make training meaningless or crash, naming the key.
    pub fn validate(&self) -> Result<()> {
        let pos = |name: &str, v: f32| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(TrainError::config(
                    name,
                    format!("must be finite and > 0, got {v}"),
                ))
            }
        };
        let unit = |name: &str, v: f32| -> Result<()> {
            if v.is_finite() && (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(TrainError::config(
                    name,
                    format!("must be in [0, 1], got {v}"),
                ))
            }
        };
        let nonzero = |name: &str, v: u64| -> Result<()> {
            if v > 0 {
                Ok(())
            } else {
                Err(TrainError::config(name, "must be ≥ 1"))
            }
        };
        nonzero("iterations", self.iterations as u64)?;
        let i = &self.init;
        pos("init.random_extent", i.random_extent)?;
        if i.random_points > MAX_RANDOM_POINTS {
            return Err(TrainError::config(
                "init.random_points",
                format!("must be ≤ {MAX_RANDOM_POINTS}, got {}", i.random_points),
            ));
        }
        if !(i.opacity > 0.0 && i.opacity < 1.0) {
            return Err(TrainError::config(
                "init.opacity",
                format!("must be in (0, 1), got {}", i.opacity),
            ));
        }
        let f = &self.field;
        nonzero("field.depth", f.depth as u64)?;
        nonzero("field.width", f.width as u64)?;
        if f.pos_freqs > 30 || f.time_freqs > 30 {
            return Err(TrainError::config(
                "field.pos_freqs/time_freqs",
                "must be ≤ 30 (2^f overflows f32 precision)",
            ));
        }
        // Checked before anything is allocated: a config (or a checkpoint's config.toml)
        // asking for a 10^9-wide field would otherwise abort the process in `Mlp::new`.
        if f.time_net_width > 0 && f.time_net_out == 0 {
            return Err(TrainError::config(
                "field.time_net_out",
                "must be > 0 when field.time_net_width is (0 width turns the time network off)",
            ));
        }
        if f.time_net_width > 4096 || f.time_net_out > 4096 {
            return Err(TrainError::config(
                "field.time_net_width/time_net_out",
                "must be ≤ 4096 (Deformable-3DGS: 256 and 30)",
            ));
        }
        let in_dim = crate::encoding::encoded_dim(3, f.pos_freqs) + f.time_input_dim();
        // An upper bound of `Mlp::new`'s count: (depth + 1) layers of at most
        // (in + width + 1) inputs (skip and bias included) × max(width, head) outputs.
        let params = (f.width.checked_add(in_dim + 1))
            .and_then(|fan_in| fan_in.checked_mul(f.width.max(crate::field::HEAD)))
            .and_then(|layer| layer.checked_mul(f.depth.checked_add(1)?));
        if params.is_none_or(|p| p > MAX_FIELD_PARAMS) {
            return Err(TrainError::config(
                "field.depth/width",
                format!(
                    "a {}×{} field has over {MAX_FIELD_PARAMS} parameters (the faithful 8×256 has 0.6M)",
                    f.depth, f.width
                ),
            ));
        }
        if !(f.head_init_scale.is_finite() && f.head_init_scale >= 0.0) {
            return Err(TrainError::config(
                "field.head_init_scale",
                format!("must be finite and ≥ 0, got {}", f.head_init_scale),
            ));
        }
        if !(f.visible_margin.is_finite() && f.visible_margin >= 0.0) {
            return Err(TrainError::config(
                "field.visible_margin",
                format!("must be ≥ 0, got {}", f.visible_margin),
            ));
        }
        let l = &self.lr;
        for (n, v) in [
            ("lr.position_init", l.position_init),
            ("lr.position_final", l.position_final),
            ("lr.spatial_scale", l.spatial_scale),
            ("lr.field_init", l.field_init),
            ("lr.field_final", l.field_final),
            ("lr.adam_eps", l.adam_eps),
        ] {
            pos(n, v)?;
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
        nonzero("lr.position_max_steps", l.position_max_steps as u64)?;
        nonzero("lr.field_max_steps", l.field_max_steps as u64)?;
        let d = &self.densify;
        nonzero("densify.interval", d.interval as u64)?;
        nonzero(
            "densify.opacity_reset_interval",
            d.opacity_reset_interval as u64,
        )?;
        pos("densify.grad_threshold", d.grad_threshold)?;
        unit("densify.percent_dense", d.percent_dense)?;
        unit("densify.min_opacity", d.min_opacity)?;
        pos("densify.screen_size", d.screen_size)?;
        pos("densify.world_size_factor", d.world_size_factor)?;
        if !(d.reset_opacity > 0.0 && d.reset_opacity < 1.0) {
            return Err(TrainError::config(
                "densify.reset_opacity",
                format!("must be in (0, 1), got {}", d.reset_opacity),
            ));
        }
        nonzero("densify.split_children", d.split_children as u64)?;
        d.mcmc
            .validate()
            .map_err(|(key, why)| TrainError::config(&format!("densify.mcmc.{key}"), why))?;
        if d.split_children > MAX_SPLIT_CHILDREN {
            return Err(TrainError::config(
                "densify.split_children",
                format!("must be ≤ {MAX_SPLIT_CHILDREN}, got {}", d.split_children),
            ));
        }
        if self.sh.max_degree > 3 {
            return Err(TrainError::config(
                "sh.max_degree",
                format!("must be ≤ 3, got {}", self.sh.max_degree),
            ));
        }
        nonzero("sh.degree_interval", self.sh.degree_interval as u64)?;
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
        unit("loss.lambda_dssim", self.loss.lambda_dssim)?;
        self.reg
            .validate()
            .map_err(|e| TrainError::config("reg", e.to_string()))?;
        self.objects
            .validate()
            .map_err(|e| TrainError::config("objects", e))?;
        Ok(())
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

    /// Found by the disk-full test: `--iters 5` rescaled `objects.start_iter` to 0.
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
