//! Every constant of the SemDynReg regularizer (paper Sec. 3.3–3.4), as a TOML/serde section.
//!
//! The paper leaves k, λ, λx, λr, λs and τ_d open; the defaults here are starting points to
//! be replaced by our ablation (README table). The schedule follows the paper's
//! "activated after an initial training phase (e.g. after 10k iterations)" and
//! docs/architecture.md item 6 (active to the end of a 40k schedule), and is rescaled with
//! `--iters` by [`RegConfig::rescaled`].

use serde::{Deserialize, Serialize};

use super::error::RegError;

/// Length of the schedule the iteration constants below refer to (Deformable 3DGS: 40k).
pub const REFERENCE_ITERS: u64 = 40_000;

/// Largest per-pixel top-k accepted (the rasterizer keeps k entries per pixel in registers).
pub const MAX_TOPK: usize = 32;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegConfig {
    /// `--reg / --no-reg`: whether the loss is added at all.
    pub enabled: bool,
    /// Top-k contributors per pixel used for the groups `G_o` (Sec. 3.3).
    pub k: usize,
    /// Weight of `L_reg` in `L = L_rgb + λ·L_reg` (Sec. 3.4).
    pub lambda: f32,
    /// Weight of the translation term `‖δx_i − δx̄_o‖²`.
    pub lambda_x: f32,
    /// Weight of the rotation term `‖δr_i − δr̄_o‖²` (δr is our 4-vector quaternion offset).
    pub lambda_r: f32,
    /// Weight of the scale term `‖δs_i − δs̄_o‖²`.
    pub lambda_s: f32,
    /// Objects with `‖δx̄_o‖ ≤ tau_d` (world units) count as static and are skipped.
    pub tau_d: f32,
    /// First iteration (1-based, inclusive) at which the loss is applied, for a 40k schedule.
    pub start_iter: u64,
    /// Last iteration (inclusive) at which the loss is applied, for a 40k schedule.
    pub end_iter: u64,
    /// How `G_o` is formed: from this view's top-k alone (the paper), or also from the
    /// Gaussians that belonged to `o` in earlier views ([`Membership::Persistent`]).
    pub membership: Membership,
    /// Persistent membership: a Gaussian belongs to object `o` when `o` holds at least this
    /// share of its accumulated top-k weight (over all objects and the background).
    pub persist_share: f32,
    /// Persistent membership: and when that weight is at least this much (Σ of `T·α`
    /// over the pixels where it was in the top-k of `o`).
    pub persist_min_weight: f32,
    /// Which per-object consistency loss: the paper's spread of δ around its mean
    /// ([`ConsistencyMode::Paper`]) or the residual of the best rigid fit
    /// ([`ConsistencyMode::Rigid`], beyond the paper).
    pub consistency: ConsistencyMode,
}

/// Where the members of an object's group come from (docs/architecture.md, "SemDynReg" item 5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Membership {
    /// Paper Sec. 3.3: `G_o` = the top-k of this view's pixels with ID `o`.
    #[default]
    View,
    /// Our extension: this view's group ∪ every Gaussian (evaluated by the field this
    /// iteration) whose top-k weight, accumulated over all earlier active iterations, is
    /// mostly on `o`. Pulls along Gaussians that left the object's mask (trailing ghosts).
    Persistent,
}

/// The per-object loss `L_reg^(o)` (docs/regularizer.md, "Rigid-aware consistency").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", try_from = "String")]
pub enum ConsistencyMode {
    /// Paper Sec. 3.4: `λx·mean‖δx_i − δx̄_o‖² + λr·… + λs·…` over non-static objects.
    #[default]
    Paper,
    /// Our extension: `λx·min_{R,t} mean‖(x_i + δx_i) − (R x_i + t)‖²` over every object
    /// (`rigid_loss`), zero for any rigid motion of the group, a turn included.
    Rigid,
}

impl TryFrom<String> for ConsistencyMode {
    type Error = String;

    /// Names the key, so that a bad value in a `[reg]` section says where it is.
    fn try_from(s: String) -> Result<Self, String> {
        match s.as_str() {
            "paper" => Ok(Self::Paper),
            "rigid" => Ok(Self::Rigid),
            _ => Err(format!(
                "`consistency` must be \"paper\" or \"rigid\", got \"{s}\""
            )),
        }
    }
}

impl Default for RegConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            k: 3,
            lambda: 0.1,
            lambda_x: 1.0,
            lambda_r: 1.0,
            lambda_s: 1.0,
            // toycars lives in [−1.3, 1.3]³; 0.01 is ~0.4 % of that span, above the jitter of
            // a static object's mean offset and far below a moving vehicle's travel.
            tau_d: 0.01,
            start_iter: 10_000,
            end_iter: REFERENCE_ITERS,
            membership: Membership::View,
            persist_share: 0.5,
            persist_min_weight: 1.0,
            consistency: ConsistencyMode::Paper,
        }
    }
}

impl RegConfig {
    /// Check every field; the error names the field and what is wrong with it.
    pub fn validate(&self) -> Result<(), RegError> {
        if self.k == 0 || self.k > MAX_TOPK {
            return Err(invalid(
                "k",
                format!("must be in 1..={MAX_TOPK}, got {}", self.k),
            ));
        }
        let weights = [
            ("lambda", self.lambda),
            ("lambda_x", self.lambda_x),
            ("lambda_r", self.lambda_r),
            ("lambda_s", self.lambda_s),
            ("tau_d", self.tau_d),
            ("persist_min_weight", self.persist_min_weight),
        ];
        for (field, v) in weights {
            if !v.is_finite() || v < 0.0 {
                return Err(invalid(field, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        if !(self.persist_share > 0.0 && self.persist_share <= 1.0) {
            return Err(invalid(
                "persist_share",
                format!("must be in (0, 1], got {}", self.persist_share),
            ));
        }
        if self.start_iter > self.end_iter {
            return Err(invalid(
                "start_iter",
                format!("{} is after end_iter {}", self.start_iter, self.end_iter),
            ));
        }
        Ok(())
    }

    /// The schedule scaled from [`REFERENCE_ITERS`] to a run of `total_iters` iterations
    /// (same fractions of training, rounded to the nearest iteration).
    pub fn rescaled(&self, total_iters: u64) -> Self {
        let scale = |it: u64| {
            let v = (it as f64 * total_iters as f64 / REFERENCE_ITERS as f64).round() as u64;
            v.max(1)
        };
        Self {
            start_iter: scale(self.start_iter),
            end_iter: scale(self.end_iter),
            ..self.clone()
        }
    }

    /// The last iteration at which this regularizer is still off (`start_iter − 1`); `None`
    /// when it is on from the first iteration. Runs keep their checkpoint there, so a
    /// `[reg]` variant can start from it (`crate::fork`).
    pub fn fork_point(&self) -> Option<u32> {
        u32::try_from(self.start_iter)
            .ok()
            .and_then(|s| s.checked_sub(1))
            .filter(|&p| p >= 1)
    }

    /// Whether the loss applies at 1-based iteration `iter`.
    pub fn active_at(&self, iter: u64) -> bool {
        self.enabled && (self.start_iter..=self.end_iter).contains(&iter)
    }
}

fn invalid(field: &'static str, problem: String) -> RegError {
    RegError::InvalidConfig { field, problem }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_follow_the_paper_schedule() {
        let c = RegConfig::default();
        c.validate().unwrap();
        assert!(!c.active_at(9_999));
        assert!(c.active_at(10_000));
        assert!(c.active_at(40_000));
        assert!(!c.active_at(40_001));
    }

    #[test]
    fn rescaling_keeps_fractions() {
        let c = RegConfig::default().rescaled(2_000);
        assert_eq!((c.start_iter, c.end_iter), (500, 2_000));
        let off = RegConfig {
            enabled: false,
            ..c
        };
        assert!(!off.active_at(1_000));
    }

    #[test]
    fn invalid_fields_are_named() {
        let bad = RegConfig {
            lambda_r: f32::NAN,
            ..RegConfig::default()
        };
        let msg = bad.validate().unwrap_err().to_string();
        assert!(msg.contains("lambda_r"), "{msg}");
        let bad = RegConfig {
            k: 0,
            ..RegConfig::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("`k`"));
        let bad = RegConfig {
            start_iter: 5,
            end_iter: 4,
            ..RegConfig::default()
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn toml_round_trip_and_unknown_field_rejected() {
        let c: RegConfig = toml::from_str("k = 8\nlambda = 0.5").unwrap();
        assert_eq!((c.k, c.lambda, c.lambda_x), (8, 0.5, 1.0));
        let text = toml::to_string(&c).unwrap();
        assert_eq!(toml::from_str::<RegConfig>(&text).unwrap(), c);
        let err = toml::from_str::<RegConfig>("lamda = 1").unwrap_err();
        assert!(err.to_string().contains("lamda"), "{err}");
        let c: RegConfig = toml::from_str("membership = \"persistent\"").unwrap();
        assert_eq!(c.membership, Membership::Persistent);
        assert!(toml::from_str::<RegConfig>("membership = \"always\"").is_err());
        let bad = RegConfig {
            persist_share: 0.0,
            ..RegConfig::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("persist_share"));
    }

    #[test]
    fn consistency_mode_round_trips_and_bad_values_name_the_key() {
        assert_eq!(RegConfig::default().consistency, ConsistencyMode::Paper);
        let c: RegConfig = toml::from_str("consistency = \"rigid\"").unwrap();
        assert_eq!(c.consistency, ConsistencyMode::Rigid);
        let text = toml::to_string(&c).unwrap();
        assert!(text.contains("consistency = \"rigid\""), "{text}");
        assert_eq!(toml::from_str::<RegConfig>(&text).unwrap(), c);
        let paper = toml::to_string(&RegConfig::default()).unwrap();
        assert!(paper.contains("consistency = \"paper\""), "{paper}");
        let err = toml::from_str::<RegConfig>("consistency = \"Rigid\"").unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("`consistency` must be"), "{msg}");
        assert!(msg.contains("\"Rigid\""), "{msg}");
        assert!(toml::from_str::<RegConfig>("consistency = 3").is_err());
    }
}
