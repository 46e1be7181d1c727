//! `[objects]`: every constant of the rigid-object mode (docs/objects.md). Off by default:
//! the baseline and the paper's SemDynReg are unchanged unless `enabled` (`train --objects`).

use super::scale::GaugeRule;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectsConfig {
    /// Turn each object of the ID maps into a rigid body with its own trajectory.
    pub enabled: bool,
    /// Iteration (1-based, of a 40k schedule; rescaled with `--iters`) at which objects are
    /// lifted from their masks and tracked: the end of the field's warm-up, when the static
    /// background is sharp enough to read depth from. Before it, object pixels do not
    /// reach the photometric gradient, so the background does not learn the objects.
    pub start_iter: u32,
    /// The lift reads depth from the background, which must have seen each training view
    /// a few times by then whatever the schedule's length: the start waits for at least
    /// this many passes over the training views (each pass draws every view once), up to
    /// half the schedule. On toycars at 1,500 iterations a start after two passes called a
    /// parked car moving, after three it did not (docs/objects.md).
    pub min_start_passes: f32,
    /// Where an object's Gaussians and motion come from. `lift` (the default): lifted from
    /// its first sighting against the static background at `start_iter`, then tracked
    /// through its masks. `field` (`adopt.rs`): the deformation field's own Gaussians inside
    /// its masks, taken over at `field_start_iter` with the parts and trajectories that the
    /// field's motion of them fits; for scenes with no static background to lift against
    /// (object-centric captures such as D-NeRF's, whose object is the whole scene).
    pub source: ObjectSource,
    /// `source = "field"`: the iteration (of a 40k schedule) at which the field's motion is
    /// read; until then the field learns the objects as it learns the rest. Half the
    /// schedule: on lego a take-over at a quarter found parts the field had not yet moved
    /// (val 2.5 dB lower, docs/objects.md).
    pub field_start_iter: u32,
    /// `source = "field"`: an object whose best fit (one rigid body, or its parts) leaves
    /// an RMS distance to the field's motion above this fraction of its size stays with
    /// the field.
    pub field_max_residual: f32,
    /// A mask smaller than this many pixels (at the training resolution) is not a sighting.
    pub min_pixels: u32,
    /// Gaussians lifted from the reference mask of each object (at most).
    pub lift_points: usize,
    /// Depth spread of the lifted points, as a fraction of the mask's width in world units at
    /// the estimated depth (0 = a flat layer facing the camera). One view cannot tell how
    /// deep an object is, and a wrong guess makes the tracked distance drift (docs/objects.md),
    /// so a moving object is tracked from each of these and the fit with the lowest loss over
    /// all its views is kept; the first also decides whether the object is static.
    pub lift_thickness: Vec<f32>,
    /// Re-set the common factor of size and distance after tracking so that the median over
    /// views of (ring background depth / object depth) is 1, instead of trusting the first
    /// view's reading alone. Off by default: on toycars it helped three scenes of four
    /// only by cancelling the rendered background's bias, and on a synthetic box with the
    /// true background depth it costs 14 points of follow (docs/objects.md).
    pub ring_gauge: bool,
    /// How a mover's common factor of size and distance is set (`objects::scale`): `lift`
    /// keeps the first view's ring depth, `cues` takes the median of that reading, the
    /// ring depth over all views and the surface contact over all views.
    pub gauge: GaugeRule,
    /// Two readings of the gauge agree within this `ln` factor (0.1: about the 10 % of a
    /// path length); the gauge's confidence is the share of readings that agree with it.
    pub gauge_tolerance: f32,
    /// A mover whose gauge has a lower confidence is left to the deformation field, with a
    /// warning saying so, rather than placed at a depth no cue backs (0: never).
    pub min_scale_confidence: f32,
    /// Width in pixels of the band around a mask where the background's depth is read.
    pub ring_px: u32,
    /// The static test (`Tracker::still_scale`, docs/objects.md): an object whose track's
    /// centroid moves, as the cameras see it, less than `static_image_motion` of its size
    /// in the image (RMS over the views, under the gauge that makes it move least), that
    /// turns less than `static_angle_deg` or so that its Gaussians move less than
    /// `static_motion` of its size, and whose still copy stands where the scene around its
    /// silhouette is (`static_ring_tolerance`), is static: one fixed pose.
    pub static_image_motion: f32,
    pub static_motion: f32,
    pub static_angle_deg: f32,
    /// And only if that still copy stands where the scene around its silhouette is: its
    /// ring ratio (background depth around the mask / its depth, median over views) within
    /// this factor of 1. A camera moving along the object's path cannot otherwise tell a
    /// moving object from a static one at another depth (docs/objects.md).
    pub static_ring_tolerance: f32,
    /// And only if one pose covers its masks about as well as its track does: a still
    /// object held still loses nothing, a slow mover the measures above missed loses its
    /// masks' overlap (median IoU, `Tracker::mask_iou`). The object stays a mover when
    /// holding it still costs more than this much IoU; 1 disables the check.
    pub static_iou_drop: f32,
    /// An object whose tracked rigid render (still or moving) covers its masks with a
    /// median IoU below this (over its views, alpha > ½ against the mask) is not a rigid
    /// body (a hand, a person, a crane swinging its boom): it is left to the deformation
    /// field, with a warning saying so. 0 keeps every object rigid.
    pub min_rigid_iou: f32,
    /// Articulated objects (`parts/`): at most this many rigid parts per object (1: every
    /// object is one rigid body). With more, each object is cut into this many spatial
    /// clusters, re-tracked with one trajectory per cluster held together at their joints,
    /// and clusters that move alike are merged; the result replaces the rigid fit when it
    /// keeps two or more parts and lowers the tracking loss by `parts_min_gain`.
    pub parts: usize,
    /// Two clusters are one part when their relative motion (RMS over views and their
    /// Gaussians of the distance between where each one's trajectory carries them) stays
    /// below this fraction of the object's size.
    pub parts_merge: f32,
    /// Relative drop of the mean tracking loss (colour + mask, over the views) the parts
    /// must bring over the rigid fit to be kept.
    pub parts_min_gain: f32,
    /// Weight of the joint term that holds neighbouring parts together (squared distance
    /// between where the two parts carry their joint point, over the object's size²), while
    /// tracking and in training.
    pub joint_weight: f32,
    /// Training of articulated objects (`parts/skin.rs`): each Gaussian is placed by a
    /// blend of its object's part poses with learned weights (linear blend skinning, softmax
    /// of one logit per part), starting from `exp(−d²/2σ²)` of its distance `d` to each
    /// part's Gaussians, `σ = skin_radius ×` their median spacing; `skin_lr` is the logits'
    /// Adam rate. false: each Gaussian moves with one part (piecewise rigid).
    pub skin: bool,
    pub skin_radius: f32,
    pub skin_lr: f32,
    /// Weight of the as-rigid-as-possible term between each skinned Gaussian and its
    /// nearest neighbours on the same part (`parts/arap.rs`): the squared change of their
    /// offset beyond the blended rotation, over the squared neighbour spacing. 0 (the
    /// default) turns it off: at 0.01 and 0.1 it lowered the crane's crop by 0.2–0.3 dB
    /// and the hand's by 0.2 dB (docs/objects.md).
    pub arap_weight: f32,
    /// A residual deformation on top of each object's rigid or articulated motion
    /// (`residual.rs`): a small Deformable-3DGS field per object, `residual_depth` ×
    /// `residual_width`, evaluated in the object's frame at the view's time and started at
    /// δ = 0 when the objects start; its learning rate follows `[lr] field_*`. false (the
    /// default): object Gaussians keep their shape and move only with their poses.
    pub residual: bool,
    pub residual_depth: usize,
    pub residual_width: usize,
    /// Tracking (time-progressive fitting): iterations of pose fitting per new frame, and of
    /// shape/appearance refinement on already tracked frames after each new frame.
    pub track_pose_iters: u32,
    pub track_shape_iters: u32,
    /// Iterations of joint refinement of shape, appearance and all poses after the last view,
    /// and again after each of `contact_rounds` corrections of its distance by contact.
    pub track_refine_iters: u32,
    pub contact_rounds: u32,
    /// After each joint refinement the knots are replaced by their Whittaker–Eilers smooth
    /// (`smooth.rs`): `gcv` chooses each track's penalty by generalized cross-validation,
    /// `period` halves a period of `track_smooth_period` of the track, `rays` does so
    /// trusting each knot along its view's ray only `(size / distance)²`, `off` keeps the
    /// knots as tracked (the default: on the benchmark smoothing shortens over-long paths
    /// but moves no count by more than the seed-to-seed spread, docs/objects.md).
    pub track_smooth: super::smooth::SmoothRule,
    pub track_smooth_period: f32,
    /// Weight of the spring that holds each view's distance to the camera at its contact
    /// target while refining (`contact.rs`).
    pub contact_weight: f32,
    /// Learning rates while tracking: pose translation (world units), pose quaternion, and
    /// the object's Gaussians' means (world units), colours, opacity logits, log-scales.
    pub track_lr_translation: f32,
    pub track_lr_rotation: f32,
    pub track_lr_means: f32,
    pub track_lr_colors: f32,
    pub track_lr_opacity: f32,
    pub track_lr_scales: f32,
    /// Weight of the mask term (object alpha against the object's mask, balanced inside and
    /// outside) against the colour term, while tracking and in training.
    pub lambda_mask: f32,
    /// Training: Adam rates of the trajectory knots (translation in world units per step,
    /// quaternion components per step).
    pub lr_translation: f32,
    pub lr_rotation: f32,
    /// Occlusion gauge: the quantile of (background depth / object depth) over the object's
    /// pixels that is set to 1, i.e. objects are placed as far away as the static scene in
    /// front of which they are seen allows (0 disables). Monocular video fixes a moving
    /// object's size and distance only up to one common factor; this fixes the factor.
    pub scale_quantile: f32,
    /// Iterations (of a 40k schedule) at which the gauge is applied again during training.
    pub rescale_at: Vec<u32>,
    /// Membership from persistent top-k votes (`membership.rs`): at each densification, a
    /// Gaussian whose votes put `transfer_share` of their weight (and `transfer_min_weight`)
    /// on one object joins it. `votes_k` top-k entries per pixel vote.
    pub transfer: bool,
    pub transfer_share: f32,
    pub transfer_min_weight: f32,
    pub votes_k: usize,
}

impl Default for ObjectsConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            start_iter: 3000,
            min_start_passes: 3.0,
            source: ObjectSource::Lift,
            field_start_iter: 20000,
            field_max_residual: 0.05,
            min_pixels: 20,
            lift_points: 3000,
            lift_thickness: vec![0.25, 0.1, 0.5],
            ring_gauge: false,
            gauge: GaugeRule::Lift,
            gauge_tolerance: 0.1,
            min_scale_confidence: 0.0,
            ring_px: 3,
            static_image_motion: 0.1,
            static_motion: 0.25,
            static_angle_deg: 10.0,
            static_ring_tolerance: 1.6,
            static_iou_drop: 0.1,
            min_rigid_iou: 0.0,
            parts: 1,
            parts_merge: 0.1,
            parts_min_gain: 0.1,
            joint_weight: 10.0,
            skin: true,
            skin_radius: 2.0,
            skin_lr: 0.01,
            arap_weight: 0.0,
            residual: false,
            residual_depth: 4,
            residual_width: 64,
            track_pose_iters: 30,
            track_shape_iters: 10,
            track_refine_iters: 1000,
            track_smooth: super::smooth::SmoothRule::Off,
            track_smooth_period: 0.4,
            contact_rounds: 0,
            contact_weight: 30.0,
            track_lr_translation: 2e-3,
            track_lr_rotation: 5e-3,
            track_lr_means: 1e-3,
            track_lr_colors: 1e-2,
            track_lr_opacity: 5e-2,
            track_lr_scales: 5e-3,
            lambda_mask: 0.5,
            lr_translation: 2e-4,
            lr_rotation: 5e-4,
            scale_quantile: 0.03,
            rescale_at: Vec::new(),
            transfer: true,
            transfer_share: 0.6,
            transfer_min_weight: 1.0,
            votes_k: 3,
        }
    }
}

/// Where the objects' Gaussians and motion come from (`[objects] source`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ObjectSource {
    /// Lifted from the first sighting and tracked through the masks (`start.rs`).
    #[default]
    Lift,
    /// Taken over from the deformation field (`adopt.rs`).
    Field,
}

/// What each object of the ID maps may become (`train --objects=MODE`). Each object's
/// start logs the evidence of the choice (its rigid fit's and its parts' mask IoU and
/// tracking loss, docs/objects.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObjectsMode {
    /// One rigid body per object (`parts = 1`).
    Rigid,
    /// Up to [`MODE_PARTS`] rigid parts held at joints where they lower the tracking loss
    /// by `parts_min_gain`; one rigid body otherwise.
    Parts,
    /// As `Parts`, and an object that neither one body nor its parts cover well (median
    /// mask IoU of the kept fit below [`AUTO_MIN_RIGID_IOU`]) goes to the deformation
    /// field: rigid, articulated or field, per object.
    Auto,
}

/// The most parts `parts` and `auto` try per object (the crane's four: docs/objects.md).
pub const MODE_PARTS: usize = 4;
/// `auto`'s `min_rigid_iou`. Rigid fits of rigid objects cover their masks with a median
/// IoU of 0.88–0.99 (toycars' vehicles 0.97–0.98; 26 of the generated benchmark's 28
/// objects; the other two are a slow mover wrongly held still, 0.60, and a still barrel,
/// 0.79); the real capture's hand, which bends, 0.71–0.74 (docs/objects.md,
/// docs/real-data.md).
pub const AUTO_MIN_RIGID_IOU: f32 = 0.8;

impl ObjectsMode {
    /// Every mode, in the order `--help` and the error list them.
    pub const ALL: [ObjectsMode; 3] = [ObjectsMode::Rigid, ObjectsMode::Parts, ObjectsMode::Auto];

    /// The mode's name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ObjectsMode::Rigid => "rigid",
            ObjectsMode::Parts => "parts",
            ObjectsMode::Auto => "auto",
        }
    }
}

impl std::str::FromStr for ObjectsMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        ObjectsMode::ALL
            .into_iter()
            .find(|m| m.name() == s.trim())
            .ok_or_else(|| {
                let names: Vec<&str> = ObjectsMode::ALL.iter().map(|m| m.name()).collect();
                format!(
                    "{s:?} is not an objects mode: use one of {}",
                    names.join(", ")
                )
            })
    }
}

impl ObjectsConfig {
    /// The iteration at which the objects start: `start_iter`, or `field_start_iter` for
    /// objects taken over from the field.
    pub fn start_at(&self) -> u32 {
        match self.source {
            ObjectSource::Lift => self.start_iter,
            ObjectSource::Field => self.field_start_iter,
        }
    }

    /// `start_iter` raised to `min_start_passes` over `views` training views, at most to
    /// half of an `iterations`-long schedule (never lowered).
    pub fn start_for_views(&self, views: usize, iterations: u32) -> u32 {
        let passes = (f64::from(self.min_start_passes) * views as f64).ceil() as u32;
        self.start_iter.max(passes.min(iterations / 2))
    }

    /// Turns the objects on in `mode`. `rigid` sets `parts = 1`; `parts` and `auto` raise
    /// `parts` to [`MODE_PARTS`] unless the config already allows more than one; `auto`
    /// also sets `min_rigid_iou` to [`AUTO_MIN_RIGID_IOU`] unless the config sets one.
    pub fn apply_mode(&mut self, mode: ObjectsMode) {
        self.enabled = true;
        match mode {
            ObjectsMode::Rigid => self.parts = 1,
            ObjectsMode::Parts | ObjectsMode::Auto => {
                if self.parts == 1 {
                    self.parts = MODE_PARTS;
                }
            }
        }
        if mode == ObjectsMode::Auto && self.min_rigid_iou == 0.0 {
            self.min_rigid_iou = AUTO_MIN_RIGID_IOU;
        }
    }

    /// The schedule's milestones rescaled from `from` to `to` iterations.
    pub fn rescaled(&self, from: u32, to: u32) -> Self {
        let at = |v: u32| (v as f64 * to as f64 / from as f64).round() as u32;
        Self {
            // ≥ 1: a very short schedule (`--iters 5`) still starts the objects.
            start_iter: at(self.start_iter).max(1),
            field_start_iter: at(self.field_start_iter).max(1),
            rescale_at: self.rescale_at.iter().map(|&v| at(v)).collect(),
            ..self.clone()
        }
    }

    /// Rejects values that would make the mode meaningless, naming the key.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("objects.lift_points", self.lift_points as f32),
            ("objects.track_lr_translation", self.track_lr_translation),
            ("objects.track_lr_rotation", self.track_lr_rotation),
            ("objects.lr_translation", self.lr_translation),
            ("objects.lr_rotation", self.lr_rotation),
            ("objects.skin_radius", self.skin_radius),
        ];
        if !(self.static_ring_tolerance.is_finite() && self.static_ring_tolerance > 1.0) {
            return Err(format!(
                "objects.static_ring_tolerance must be finite and > 1, got {}",
                self.static_ring_tolerance
            ));
        }
        if !(self.min_start_passes.is_finite() && self.min_start_passes >= 0.0) {
            return Err(format!(
                "objects.min_start_passes must be finite and ≥ 0, got {}",
                self.min_start_passes
            ));
        }
        if !(0.0..=1.0).contains(&self.min_scale_confidence) {
            return Err(format!(
                "objects.min_scale_confidence must be in [0, 1], got {}",
                self.min_scale_confidence
            ));
        }
        if !(self.gauge_tolerance.is_finite() && self.gauge_tolerance > 0.0) {
            return Err(format!(
                "objects.gauge_tolerance must be finite and > 0, got {}",
                self.gauge_tolerance
            ));
        }
        if !(self.track_smooth_period.is_finite()
            && (0.0..=1.0).contains(&self.track_smooth_period))
        {
            return Err(format!(
                "objects.track_smooth_period must be in [0, 1], got {}",
                self.track_smooth_period
            ));
        }
        if !(0.0..=1.0).contains(&self.static_iou_drop) {
            return Err(format!(
                "objects.static_iou_drop must be in [0, 1], got {}",
                self.static_iou_drop
            ));
        }
        if !(1..=16).contains(&self.parts) {
            return Err(format!(
                "objects.parts must be in 1..=16, got {}",
                self.parts
            ));
        }
        if !(0.0..1.0).contains(&self.parts_min_gain) {
            return Err(format!(
                "objects.parts_min_gain must be in [0, 1), got {}",
                self.parts_min_gain
            ));
        }
        if !(0.0..=1.0).contains(&self.min_rigid_iou) {
            return Err(format!(
                "objects.min_rigid_iou must be in [0, 1], got {}",
                self.min_rigid_iou
            ));
        }
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be finite and > 0, got {v}"));
            }
        }
        let non_negative = [
            ("objects.static_image_motion", self.static_image_motion),
            ("objects.static_motion", self.static_motion),
            ("objects.static_angle_deg", self.static_angle_deg),
            ("objects.track_lr_means", self.track_lr_means),
            ("objects.track_lr_colors", self.track_lr_colors),
            ("objects.track_lr_opacity", self.track_lr_opacity),
            ("objects.track_lr_scales", self.track_lr_scales),
            ("objects.lambda_mask", self.lambda_mask),
            ("objects.parts_merge", self.parts_merge),
            ("objects.joint_weight", self.joint_weight),
            ("objects.skin_lr", self.skin_lr),
            ("objects.arap_weight", self.arap_weight),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be finite and ≥ 0, got {v}"));
            }
        }
        if self.lift_thickness.is_empty()
            || self
                .lift_thickness
                .iter()
                .any(|t| !(t.is_finite() && *t >= 0.0))
        {
            return Err("objects.lift_thickness must list at least one finite value ≥ 0".into());
        }
        if !(0.0..0.5).contains(&self.scale_quantile) {
            return Err(format!(
                "objects.scale_quantile must be in [0, 0.5), got {}",
                self.scale_quantile
            ));
        }
        if !(self.transfer_share > 0.5 && self.transfer_share <= 1.0) {
            return Err(format!(
                "objects.transfer_share must be in (0.5, 1] (a majority), got {}",
                self.transfer_share
            ));
        }
        if !(1..=crate::regularizer::config::MAX_TOPK).contains(&self.votes_k) {
            return Err(format!(
                "objects.votes_k must be in 1..=32, got {}",
                self.votes_k
            ));
        }
        if !(1..=32).contains(&self.residual_depth) || !(1..=1024).contains(&self.residual_width) {
            return Err(format!(
                "objects.residual_depth must be in 1..=32 and objects.residual_width in 1..=1024, got {} and {}",
                self.residual_depth, self.residual_width
            ));
        }
        if self.start_iter == 0 || self.field_start_iter == 0 {
            return Err("objects.start_iter and objects.field_start_iter must be ≥ 1".into());
        }
        if !(self.field_max_residual.is_finite() && self.field_max_residual > 0.0) {
            return Err(format!(
                "objects.field_max_residual must be finite and > 0, got {}",
                self.field_max_residual
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_start_waits_for_passes_over_the_views_up_to_half_the_schedule() {
        // The 3,000-iteration schedule starts at 225, after more than three passes over
        // 72 views: unchanged. Halved, its 113 is raised to three passes (216).
        let c = ObjectsConfig::default().rescaled(40_000, 3_000);
        assert_eq!(c.start_for_views(72, 3_000), 225);
        let c = ObjectsConfig::default().rescaled(40_000, 1_500);
        assert_eq!(c.start_iter, 113);
        assert_eq!(c.start_for_views(72, 1_500), 216);
        // A schedule too short for three passes starts at its middle, never later.
        assert_eq!(c.start_for_views(400, 1_500), 750);
        // 0 passes keeps the schedule's start.
        let c = ObjectsConfig {
            min_start_passes: 0.0,
            ..c
        };
        assert_eq!(c.start_for_views(72, 1_500), 113);
        assert!(ObjectsConfig {
            min_start_passes: f32::NAN,
            ..c
        }
        .validate()
        .is_err());
    }

    #[test]
    fn modes_set_parts_and_the_field_fallback_without_overriding_the_config() {
        let mut c = ObjectsConfig::default();
        c.apply_mode(ObjectsMode::Auto);
        assert!(c.enabled);
        assert_eq!((c.parts, c.min_rigid_iou), (MODE_PARTS, AUTO_MIN_RIGID_IOU));
        // A config that already chose keeps its choice.
        let mut c = ObjectsConfig {
            parts: 8,
            min_rigid_iou: 0.6,
            ..ObjectsConfig::default()
        };
        c.apply_mode(ObjectsMode::Auto);
        assert_eq!((c.parts, c.min_rigid_iou), (8, 0.6));
        c.apply_mode(ObjectsMode::Rigid);
        assert_eq!((c.parts, c.min_rigid_iou), (1, 0.6));
        c.apply_mode(ObjectsMode::Parts);
        assert_eq!((c.parts, c.min_rigid_iou), (MODE_PARTS, 0.6));
        assert!(c.validate().is_ok());
    }

    #[test]
    fn modes_parse_by_name_and_refuse_others() {
        for m in ObjectsMode::ALL {
            assert_eq!(m.name().parse::<ObjectsMode>(), Ok(m));
        }
        let e = "field".parse::<ObjectsMode>().unwrap_err();
        assert!(
            e.contains("field") && e.contains("one of rigid, parts, auto"),
            "{e}"
        );
    }

    #[test]
    fn track_smoothing_reads_by_name_and_checks_its_period() {
        let c: ObjectsConfig = toml::from_str("track_smooth = \"gcv\"").unwrap();
        assert_eq!(c.track_smooth, super::super::smooth::SmoothRule::Gcv);
        assert!(c.validate().is_ok());
        let c: ObjectsConfig = toml::from_str("track_smooth = \"rays\"").unwrap();
        assert_eq!(c.track_smooth, super::super::smooth::SmoothRule::Rays);
        assert!(toml::from_str::<ObjectsConfig>("track_smooth = \"spline\"").is_err());
        let c = ObjectsConfig {
            track_smooth_period: 1.5,
            ..ObjectsConfig::default()
        };
        let e = c.validate().unwrap_err();
        assert!(e.contains("objects.track_smooth_period"), "{e}");
    }
}
