//! Time-progressive fitting of one object (Dynamic 3D Gaussians' online fitting, on one
//! camera): its Gaussians, lifted from its first sighting, are tracked through the views in
//! time order. Each new view's pose is predicted at constant velocity from the two before
//! it, then fitted to that view alone; then the object's shape and appearance, and the poses
//! of the views seen so far, are refined on randomly chosen views among those. The loss of
//! a view looks only at the object: its colour inside its mask, and its alpha against its
//! mask, balanced (missing and spilled area count alike, both relative to the mask's area).
//! Rendering error alone cannot find a large motion in a monocular video (DreamScene4D);
//! the mask term can, because it has a gradient wherever the render and the mask overlap,
//! and a constant-velocity prediction keeps them overlapping from one view to the next.

use super::contact;
use super::gauge;
use super::knots::KnotAdam;
use super::lift::{self, DepthMap};
use super::place::{self, NO_OBJECT};
use super::scale::{self, GaugeChoice, ScaleCues};
use super::trajectory::{Pose, Trajectory, TrajectoryGrad};
use super::{ObjectsConfig, RigidObject};
use crate::adam::{Adam, AdamHyper};
use crate::deform::{self, CanonicalGrads, Deformed};
use crate::model::{GaussianModel, ROWS};
use crate::quat;
use rand::Rng;
use splat::{Camera, Gradients, Rasterizer, RenderOptions};

/// One view of the object: a training frame where its mask was seen.
pub struct TrackView<'a> {
    pub cam: &'a Camera,
    pub time: f32,
    pub image: &'a scene::ImageU8,
    /// The static background's depth in this view, when known (for the contact).
    pub background: Option<&'a DepthMap>,
    /// The frame's object-ID map at the training resolution.
    pub id_map: &'a [u8],
}

/// Loss of one view and its gradients w.r.t. the object-only render.
pub(super) struct ViewLoss {
    pub value: f32,
    pub dl_dimage: Vec<f32>,
    pub dl_dalpha: Vec<f32>,
}

/// `L = mean_M |C − I| + λ·(Σ_M (1 − α) + Σ_out α) / |M|`, where `out` excludes the
/// pixels of other objects (they may occlude this one).
pub(super) fn view_loss(
    view: &TrackView,
    gt: &[f32],
    id: u8,
    image: &[f32],
    alpha: &[f32],
    lambda: f32,
) -> ViewLoss {
    let n = alpha.len();
    let area = view.id_map.iter().filter(|&&v| v == id).count().max(1) as f32;
    let mut out = ViewLoss {
        value: 0.0,
        dl_dimage: vec![0.0; n * 3],
        dl_dalpha: vec![0.0; n],
    };
    let (wc, wm) = (1.0 / (3.0 * area), lambda / area);
    for p in 0..n {
        let v = view.id_map[p];
        if v == id {
            for c in 0..3 {
                let d = image[p * 3 + c] - gt[p * 3 + c];
                out.value += wc * d.abs();
                out.dl_dimage[p * 3 + c] = wc * d.signum();
            }
            out.value += wm * (1.0 - alpha[p]);
            out.dl_dalpha[p] = -wm;
        } else if v == NO_OBJECT {
            out.value += wm * alpha[p];
            out.dl_dalpha[p] = wm;
        }
    }
    out
}

/// The object being tracked: its Gaussians (object frame), one knot per view, optimizers.
pub struct Tracker<'a> {
    views: &'a [TrackView<'a>],
    cfg: &'a ObjectsConfig,
    object: RigidObject,
    model: GaussianModel,
    adam: [Adam; 5],
    knots: KnotAdam,
    raster: Rasterizer,
    deformed: Deformed,
    grads: Gradients,
    canon: CanonicalGrads,
    rows: Vec<Vec<u32>>,
    gt: Vec<f32>,
    /// Per view: the distance from its camera that the contact correction asks for.
    springs: Vec<Option<f32>>,
    /// The gauge applied so far to the first guess of size and distance.
    scale: f32,
    residual_motion: f32,
    still: StillEvidence,
    /// The least-motion gauge of the first track when its motion measures called it still
    /// (relative to the lifted guess), kept even when the object stays a mover.
    still_gauge: Option<f32>,
    /// The readings of the gauge and the choice made from them, for a moving object
    /// ([`Self::scale_cues`], [`scale::choose`]).
    cues: Option<ScaleCues>,
    gauge: Option<GaugeChoice>,
}

/// What the static test measured ([`Tracker::still_scale`]), logged and kept in the start
/// report so a wrong decision can be traced to the criterion that made it.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StillEvidence {
    /// RMS motion of its centroid under the least-motion gauge as the cameras see it,
    /// across the image, over its size there (`Tracker::image_motion`; static below
    /// `static_image_motion`).
    #[serde(with = "super::json_f32")]
    pub motion: f32,
    /// Largest rotation from the first knot, degrees.
    #[serde(with = "super::json_f32")]
    pub angle_deg: f32,
    /// RMS displacement of its Gaussians by the rotation alone, over its extent (a turn
    /// counts when both this reaches `static_motion` and the angle `static_angle_deg`).
    #[serde(with = "super::json_f32")]
    pub turn: f32,
    /// `|ln(ring ratio / gauge)|`: how far in front of or behind the scene around its
    /// silhouette the still copy would stand (static below `ln static_ring_tolerance`);
    /// None when no view sees a background around it.
    #[serde(with = "super::json_f32::option")]
    pub ring_offset: Option<f32>,
    /// Median mask IoU of its track, and of one pose held still, when the measures above
    /// called it still (`static_iou_drop`).
    #[serde(default, with = "super::json_f32::option")]
    pub iou_tracked: Option<f32>,
    #[serde(default, with = "super::json_f32::option")]
    pub iou_still: Option<f32>,
}

pub(super) const HP: AdamHyper = AdamHyper {
    beta1: 0.9,
    beta2: 0.999,
    eps: 1e-15,
};

impl<'a> Tracker<'a> {
    /// The object's Gaussians placed in the world at `time` (into `self.deformed`), and
    /// the pose used, for the backward.
    fn place_at(&mut self, time: f32) -> Vec<Pose> {
        deform::apply(&self.model, None, &mut self.deformed);
        let mut poses = Vec::new();
        place::place(
            std::slice::from_ref(&self.object),
            &self.rows,
            place::Shape::of(&self.model),
            time,
            &mut self.deformed,
            &mut poses,
        );
        poses
    }

    /// One forward/backward on view `v`; steps the view's knot and/or the Gaussians.
    fn step(&mut self, v: usize, pose: bool, shape: bool) -> Result<f32, splat::SplatError> {
        let view = &self.views[v];
        let poses = self.place_at(view.time);
        let objects = std::slice::from_ref(&self.object);
        let g = crate::deform::gaussians(&self.model, &self.deformed);
        let opts = RenderOptions::default();
        let out = self.raster.forward(&g, view.cam, &opts)?;
        view.image.to_f32_into(&mut self.gt);
        let lambda = self.cfg.lambda_mask;
        let loss = view_loss(view, &self.gt, self.object.id, out.image, out.alpha, lambda);
        self.raster.backward(
            &g,
            view.cam,
            &opts,
            &loss.dl_dimage,
            Some(&loss.dl_dalpha),
            &mut self.grads,
        )?;
        let gr = &self.grads;
        deform::backward(
            &self.model,
            &gr.means,
            &gr.quats,
            &gr.scales,
            &mut self.canon,
        );
        let mut tg = vec![TrajectoryGrad::zeros(self.object.trajectory.len())];
        place::backward(
            objects,
            &self.rows,
            place::Shape::of(&self.model),
            &poses,
            place::WorldGrads {
                means: &gr.means,
                quats: &gr.quats,
            },
            &mut self.canon,
            &mut tg,
        );
        if let Some(target) = self.springs.get(v).copied().flatten() {
            let p = self.object.trajectory.translations[v];
            let g = contact::spring_grad(p, view.cam.center(), target, self.cfg.contact_weight);
            for (t, g) in tg[0].translations[v].iter_mut().zip(g) {
                *t += g;
            }
        }
        if pose {
            let lr = (self.cfg.track_lr_translation, self.cfg.track_lr_rotation);
            self.knots
                .step_knot(&mut self.object.trajectory, &tg[0], v, HP, lr);
        }
        if shape {
            self.step_shape();
        }
        Ok(loss.value)
    }

    fn step_shape(&mut self) {
        step_shape(
            self.cfg,
            &mut self.adam,
            &mut self.model,
            &self.canon,
            &self.grads,
        );
    }

    /// The contact ratio of every view that sees the background behind the object
    /// (`contact.rs`), as `(time, ln q)`.
    fn contact_profile(&mut self) -> Result<Vec<(usize, f32, f32)>, splat::SplatError> {
        let mut out = Vec::new();
        for (k, v) in self.views.iter().enumerate() {
            let Some(bg) = v.background else { continue };
            let q = self.cfg.scale_quantile;
            let ring = self.cfg.ring_px;
            let r = contact::view_ratio(
                &mut self.raster,
                &self.object,
                &self.model,
                v.cam,
                v.time,
                v.id_map,
                bg,
                q,
                ring,
                10,
            )?;
            if let Some(r) = r.filter(|r| *r > 0.0) {
                out.push((k, v.time, r.ln()));
            }
        }
        Ok(out)
    }

    /// One contact correction (`contact.rs`): the profile's robust level applied as the
    /// gauge, its slope as spring targets for the views' distances. Returns the gauge factor
    /// and the slope (None when no view sees a background behind the object).
    fn correct_contact(&mut self, target: f32) -> Result<Option<(f32, f32)>, splat::SplatError> {
        let profile = self.contact_profile()?;
        let pts: Vec<(f32, f32)> = profile.iter().map(|p| (p.1, p.2)).collect();
        let Some((level, slope, t_mean)) = contact::robust_line(&pts) else {
            return Ok(None);
        };
        let s = (level.exp() / target).clamp(0.5, 2.0);
        let centres: Vec<[f32; 3]> = self.views.iter().map(|v| v.cam.center()).collect();
        gauge::apply_scale(&mut self.model, &mut self.object.trajectory, &centres, s);
        let tr = &self.object.trajectory;
        self.springs = (0..tr.len())
            .map(|k| {
                let c = centres[k];
                let p = tr.translations[k];
                let d =
                    ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
                Some(d * (slope * (tr.times[k] - t_mean)).exp())
            })
            .collect();
        Ok(Some((s, slope)))
    }

    /// Joint refinement of shape, appearance and every pose on views drawn uniformly, then
    /// the knots smoothed (`objects.track_smooth`).
    fn refine(&mut self, rng: &mut impl Rng) -> Result<(), splat::SplatError> {
        for _ in 0..self.cfg.track_refine_iters {
            let j = rng.gen_range(0..self.views.len());
            self.step(j, true, true)?;
        }
        self.smooth_knots();
        Ok(())
    }

    /// The knots replaced by their smooth (`objects.track_smooth`, `smooth.rs`).
    fn smooth_knots(&mut self) {
        use super::smooth::{smooth, smooth_along_rays, Amount, SmoothRule};
        let tr = &mut self.object.trajectory;
        let period = self.cfg.track_smooth_period;
        let lambdas = match self.cfg.track_smooth {
            SmoothRule::Off => return,
            SmoothRule::Gcv => smooth(tr, Amount::Gcv),
            SmoothRule::Period => smooth(tr, Amount::Period(period)),
            SmoothRule::Rays => {
                let centres: Vec<[f32; 3]> = self.views.iter().map(|v| v.cam.center()).collect();
                let size = extent(&self.model.means);
                let l = smooth_along_rays(tr, &centres, size, period);
                (l, l)
            }
        };
        tracing::debug!(object = %self.object.name, ?lambdas, "track smoothed");
    }

    fn predict(&mut self, k: usize) {
        predict_knot(&mut self.object.trajectory, k);
    }
}

impl<'a> Tracker<'a> {
    /// A tracker for the object `id` whose first Gaussians are `lifted` (world space, at
    /// the first view); the views are in time order, one knot each.
    pub fn new(
        views: &'a [TrackView<'a>],
        id: u8,
        name: &str,
        lifted: GaussianModel,
        cfg: &'a ObjectsConfig,
    ) -> Self {
        let n = lifted.len();
        let origin = centroid(&lifted.means);
        let mut model = lifted;
        for m in model.means.chunks_exact_mut(3) {
            for c in 0..3 {
                m[c] -= origin[c];
            }
        }
        let times: Vec<f32> = views.iter().map(|v| v.time).collect();
        let k = times.len();
        let trajectory = Trajectory {
            times,
            translations: vec![origin; k],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; k],
        };
        Self {
            views,
            cfg,
            object: RigidObject::new(id, name.into(), trajectory, false),
            model,
            adam: ROWS.map(|r| Adam::zeros(n * r)),
            knots: KnotAdam::zeros(k),
            raster: Rasterizer::new(),
            deformed: Deformed::default(),
            grads: Gradients::default(),
            canon: CanonicalGrads::default(),
            rows: vec![(0..n as u32).collect()],
            gt: Vec::new(),
            springs: Vec::new(),
            scale: 1.0,
            residual_motion: 0.0,
            still: StillEvidence::default(),
            still_gauge: None,
            cues: None,
            gauge: None,
        }
    }

    /// The time-progressive pass through the views, then a joint refinement; returns the
    /// pose loss of the last view.
    pub fn sequential(&mut self, rng: &mut impl Rng) -> Result<f32, splat::SplatError> {
        let mut last = 0.0;
        for v in 0..self.views.len() {
            if v > 0 {
                self.predict(v);
                for _ in 0..self.cfg.track_pose_iters {
                    last = self.step(v, true, false)?;
                }
            }
            for _ in 0..self.cfg.track_shape_iters {
                // Half the refinement on the newest views, half on any view seen so far.
                let lo = if rng.gen::<bool>() {
                    v.saturating_sub(4)
                } else {
                    0
                };
                let j = rng.gen_range(lo..=v);
                self.step(j, true, true)?;
            }
        }
        self.refine(rng)?;
        Ok(last)
    }

    /// The factor under which the trajectory stands (nearly) still, if one does: a static
    /// object tracked at the wrong depth seems to move with the camera
    /// (`gauge::least_motion_scale`).
    pub fn still_scale(&mut self) -> Option<f32> {
        let centres: Vec<[f32; 3]> = self.views.iter().map(|v| v.cam.center()).collect();
        let size = extent(&self.model.means);
        let tr = &self.object.trajectory;
        // The path of the Gaussians' centroid rather than of the frame's origin: a spin
        // about an axis through the centroid (a still barrel's, which the track cannot pin
        // down) swings an off-centre origin around but leaves the centroid in place.
        let path = centroid_path(tr, &self.model.means);
        let (s, rms) = gauge::least_motion_scale(&path, &centres);
        self.residual_motion = rms;
        let motion = self.image_motion(&path, s, size);
        let (_, angle) = tr.motion_extent();
        let c = self.cfg;
        // A camera moving along an object's path sees the same images from the object
        // moving and from a static copy at another depth: the least-motion gauge cannot tell
        // them apart. What is around the silhouette can: the static copy must stand where
        // that scene is (its ring ratio near 1), not far in front of it or behind it.
        let ring_offset = self.ring_ratio().map(|r| (r / s).ln().abs());
        let turn = self.turn_motion() / size.max(1e-12);
        self.still = StillEvidence {
            motion,
            angle_deg: angle.to_degrees(),
            turn,
            ring_offset,
            ..Default::default()
        };
        let placed = ring_offset.is_none_or(|off| off <= c.static_ring_tolerance.ln());
        // A turn counts by how far it moves the object's Gaussians, the yardstick of the
        // translation: a still object symmetric about an axis (a barrel, a ball) can seem
        // to spin about it in the track, which moves nothing one can see.
        let turned = angle.to_degrees() >= c.static_angle_deg && turn >= c.static_motion;
        let still = tr.len() < 2 || (motion < c.static_image_motion && !turned && placed);
        still.then_some(s)
    }

    /// RMS over the views of how far the gauged centroid `path` strays from its mean
    /// position as each camera sees it: across the image over the object's size there, and
    /// along the ray as the relative change of its apparent size. One view fixes a small
    /// object's distance only to a few percent of the depth (its apparent size, to a pixel
    /// or so), which can be more than the object's size: measured in world units, a still
    /// prop's track wobbles in depth by a third of its size; measured as the camera sees
    /// it, by a few percent.
    fn image_motion(&self, path: &Trajectory, s: f32, size: f32) -> f32 {
        let n = path.len().min(self.views.len());
        let gauged: Vec<[f32; 3]> = (0..n)
            .map(|k| {
                let (c, p) = (self.views[k].cam.center(), path.translations[k]);
                std::array::from_fn(|i| c[i] + s * (p[i] - c[i]))
            })
            .collect();
        let mean = centroid(gauged.as_flattened());
        let (mut sum, mut m) = (0.0f64, 0usize);
        for (v, x) in self.views.iter().zip(&gauged) {
            let (Some((a, depth)), Some((b, depth_mean))) =
                (v.cam.project(*x), v.cam.project(mean))
            else {
                continue;
            };
            let pixels = v.cam.fx * size * s / depth;
            let across = (a[0] - b[0]).hypot(a[1] - b[1]) / pixels.max(1e-6);
            // Along the ray, as the change of its apparent size.
            let along = (depth - depth_mean) / depth_mean;
            sum += f64::from(across * across + along * along);
            m += 1;
        }
        if m == 0 {
            // No view sees the still copy in front of it (a gauge that shrinks the path
            // into the cameras): nothing shows that the object stands still.
            return f32::INFINITY;
        }
        (sum / m as f64).sqrt() as f32
    }

    /// RMS over the knots and the object's Gaussians of how far the rotation since the
    /// first knot moves them about their centroid (object units, before any gauge).
    fn turn_motion(&self) -> f32 {
        let tr = &self.object.trajectory;
        let c = centroid(&self.model.means);
        let r0 = quat::matrix_of(&tr.rotations[0]);
        let (mut sum, mut n) = (0.0f64, 0usize);
        for q in &tr.rotations {
            let r = quat::matrix_of(q);
            for m in self.model.means.chunks_exact(3) {
                let x = [m[0] - c[0], m[1] - c[1], m[2] - c[2]];
                let (a, b) = (quat::rotate(&r, x), quat::rotate(&r0, x));
                sum += (0..3).map(|k| f64::from(a[k] - b[k]).powi(2)).sum::<f64>();
                n += 1;
            }
        }
        (sum / n.max(1) as f64).sqrt() as f32
    }

    /// The median over views of (median background depth around the mask) / (the origin's
    /// camera depth): 1 when the object stands where the scene around its silhouette is.
    /// None when no view sees a background around it.
    fn ring_ratio(&self) -> Option<f32> {
        let tr = &self.object.trajectory;
        let mut r: Vec<f32> = Vec::new();
        for (k, v) in self.views.iter().enumerate() {
            let Some(bg) = v.background else { continue };
            let Some(d) = lift::ring_depth(bg, v.id_map, self.object.id, self.cfg.ring_px) else {
                continue;
            };
            let z = v.cam.to_camera(tr.translations[k.min(tr.len() - 1)])[2];
            if z > 0.0 {
                r.push(d / z);
            }
        }
        if r.is_empty() {
            return None;
        }
        let mid = r.len() / 2;
        r.select_nth_unstable_by(mid, f32::total_cmp);
        Some(r[mid])
    }

    /// The first guess of the object's distance, read in every view instead of the first
    /// alone: [`Self::ring_ratio`] applied as the gauge. The lift put the origin at the first
    /// view's reading; one view's surroundings are a noisy measure, all views' less so.
    pub fn ring_gauge(&mut self) {
        let Some(r) = self.ring_ratio() else { return };
        self.apply_gauge(r.clamp(0.5, 2.0));
    }

    /// Every view's readings of the gauge (`scale.rs`), the object rendered alone in each
    /// view that sees a background, reduced over the views.
    pub fn scale_cues(&mut self) -> Result<ScaleCues, splat::SplatError> {
        let views = self.views;
        let c = centroid(&self.model.means);
        let mut out = Vec::with_capacity(views.len());
        for v in views {
            let Some(bg) = v.background else { continue };
            self.place_at(v.time);
            let d = &self.deformed;
            let object = lift::render_depth(
                &mut self.raster,
                &d.means,
                &d.quats,
                &d.scales,
                &self.model.opacity_logits,
                v.cam,
            )?;
            let at = self.object.trajectory.pose(v.time).apply(c);
            let depths = scale::ViewDepths {
                time: v.time,
                object: &object,
                background: bg,
                id_map: v.id_map,
                centroid_depth: v.cam.to_camera(at)[2],
            };
            let (q, ring) = (self.cfg.scale_quantile, self.cfg.ring_px);
            out.push(scale::view_cues(&depths, self.object.id, q, ring));
        }
        Ok(ScaleCues::gather(&out))
    }

    /// Scales the object about its views' cameras by `s` (its images do not change).
    pub fn apply_gauge(&mut self, s: f32) {
        let centres: Vec<[f32; 3]> = self.views.iter().map(|v| v.cam.center()).collect();
        gauge::apply_scale(&mut self.model, &mut self.object.trajectory, &centres, s);
        self.scale *= s;
    }

    /// Makes the object static under the gauge `s`: one pose, from the middle view.
    pub fn hold_still(&mut self, s: f32) {
        let centres: Vec<[f32; 3]> = self.views.iter().map(|v| v.cam.center()).collect();
        gauge::apply_scale(&mut self.model, &mut self.object.trajectory, &centres, s);
        let tr = &self.object.trajectory;
        let mid = tr.len() / 2;
        self.object.trajectory =
            Trajectory::constant(tr.times[mid], tr.translations[mid], tr.rotations[mid]);
        self.object.is_static = true;
        self.scale *= s;
    }

    /// Holds the object still under the gauge `s` (as [`Self::hold_still`]) unless one
    /// pose covers its masks worse than its track by more than `static_iou_drop`; then the
    /// track is kept and the object stays a mover. Both IoUs go into the static test's
    /// evidence either way. Whether it was held.
    pub fn hold_still_if_it_fits(&mut self, s: f32) -> Result<bool, splat::SplatError> {
        let tracked = self.mask_iou()?;
        let saved = (
            self.model.clone(),
            self.object.trajectory.clone(),
            self.scale,
        );
        self.hold_still(s);
        let still = self.mask_iou()?;
        (self.still.iou_tracked, self.still.iou_still) = (Some(tracked), Some(still));
        if tracked - still <= self.cfg.static_iou_drop {
            return Ok(true);
        }
        tracing::info!(object = %self.object.name, iou_tracked = tracked, iou_still = still,
            "still by its motion, but one pose covers its masks worse than its track \
             (objects.static_iou_drop): a mover");
        (self.model, self.object.trajectory, self.scale) = saved;
        self.object.is_static = false;
        Ok(false)
    }

    /// The median contact ratio over the views (how the static scene reads behind an
    /// object that touches it; `contact.rs`), None without a background behind it.
    pub fn contact_ratio(&mut self) -> Result<Option<f32>, splat::SplatError> {
        let mut logs: Vec<f32> = self.contact_profile()?.iter().map(|p| p.2).collect();
        if logs.is_empty() {
            return Ok(None);
        }
        let mid = logs.len() / 2;
        logs.select_nth_unstable_by(mid, f32::total_cmp);
        Ok(Some(logs[mid].exp()))
    }

    /// `contact_rounds` contact corrections towards the ratio `target`, each followed by a
    /// joint refinement (`contact.rs`).
    pub fn settle_contact(
        &mut self,
        target: f32,
        rng: &mut impl Rng,
    ) -> Result<(), splat::SplatError> {
        for _ in 0..self.cfg.contact_rounds {
            let Some((s, slope)) = self.correct_contact(target)? else {
                break;
            };
            self.scale *= s;
            tracing::debug!(object = %self.object.name, gauge = s, slope, "contact correction");
            self.refine(rng)?;
        }
        Ok(())
    }

    /// Mean loss over every view with the current shape and poses (no step taken).
    pub fn mean_loss(&mut self) -> Result<f32, splat::SplatError> {
        let mut sum = 0.0;
        for v in 0..self.views.len() {
            sum += self.step(v, false, false)?;
        }
        Ok(sum / self.views.len().max(1) as f32)
    }

    /// Median over the views of the IoU between the object's render alone (alpha > ½) and
    /// its mask: how well one rigid shape under the tracked poses explains the masks. A
    /// body that bends (a hand) leaves part of its masks uncovered, or spills around them,
    /// in the views where its shape differs from the fitted one.
    pub fn mask_iou(&mut self) -> Result<f32, splat::SplatError> {
        let mut ious = Vec::with_capacity(self.views.len());
        for v in 0..self.views.len() {
            let view = &self.views[v];
            self.place_at(view.time);
            let g = crate::deform::gaussians(&self.model, &self.deformed);
            let out = self
                .raster
                .forward(&g, view.cam, &RenderOptions::default())?;
            ious.push(iou(out.alpha, view.id_map, self.object.id));
        }
        if ious.is_empty() {
            return Ok(1.0);
        }
        let mid = ious.len() / 2;
        ious.select_nth_unstable_by(mid, f32::total_cmp);
        Ok(ious[mid])
    }

    pub fn is_static(&self) -> bool {
        self.object.is_static
    }

    pub fn finish(mut self) -> Result<Tracked, splat::SplatError> {
        let mask_iou = self.mask_iou()?;
        let o = self.object;
        tracing::info!(object = %o.name, views = self.views.len(), is_static = o.is_static, scale = self.scale, mask_iou, "tracked");
        Ok(Tracked {
            id: o.id,
            model: self.model,
            is_static: o.is_static,
            trajectory: o.trajectory,
            scale: self.scale,
            residual_motion: self.residual_motion,
            still: self.still,
            still_gauge: self.still_gauge,
            mask_iou,
            cues: self.cues,
            gauge: self.gauge,
        })
    }
}

/// Adam on the object's Gaussians while tracking: means, log-scales, opacity and the SH DC
/// colour; rotations are left to training.
pub(super) fn step_shape(
    c: &ObjectsConfig,
    adam: &mut [Adam; 5],
    m: &mut GaussianModel,
    canon: &CanonicalGrads,
    g: &Gradients,
) {
    let [a_means, _, a_scales, a_opacity, a_sh] = adam;
    a_means.step(&mut m.means, &canon.means, HP, c.track_lr_means);
    a_scales.step(&mut m.log_scales, &canon.log_scales, HP, c.track_lr_scales);
    a_opacity.step(
        &mut m.opacity_logits,
        &g.opacity_logits,
        HP,
        c.track_lr_opacity,
    );
    let lr_dc = c.track_lr_colors;
    a_sh.step_rows(&mut m.sh, &g.colors, HP, ROWS[4], |k| {
        if k < 3 {
            lr_dc
        } else {
            0.0
        }
    });
}

/// Constant-velocity prediction of knot `k` from knots `k−1` and `k−2` (a copy of knot
/// `k−1` when it is the second view).
pub(super) fn predict_knot(tr: &mut Trajectory, k: usize) {
    let (p1, q1) = (
        tr.translations[k - 1],
        quat::normalize(&tr.rotations[k - 1]).0,
    );
    if k < 2 {
        tr.translations[k] = p1;
        tr.rotations[k] = q1;
        return;
    }
    let (p0, q0) = (
        tr.translations[k - 2],
        quat::normalize(&tr.rotations[k - 2]).0,
    );
    let dt0 = tr.times[k - 1] - tr.times[k - 2];
    let f = if dt0 > 0.0 {
        (tr.times[k] - tr.times[k - 1]) / dt0
    } else {
        0.0
    };
    tr.translations[k] = std::array::from_fn(|c| p1[c] + f * (p1[c] - p0[c]));
    // Angular velocity: the step q1·q0⁻¹ (world frame), repeated f times.
    let step = quat::to_rotvec(quat::mul(q1, quat::conj(q0))).map(|v| v * f);
    tr.rotations[k] = quat::mul(quat::from_rotvec(step), q1);
}

/// IoU of `alpha > ½` with the pixels of `id` in `id_map` (1 when both are empty).
pub(super) fn iou(alpha: &[f32], id_map: &[u8], id: u8) -> f32 {
    let (mut both, mut either) = (0u32, 0u32);
    for (&a, &m) in alpha.iter().zip(id_map) {
        let (r, k) = (a > 0.5, m == id);
        both += u32::from(r && k);
        either += u32::from(r || k);
    }
    if either == 0 {
        1.0
    } else {
        both as f32 / either as f32
    }
}

/// The object's Gaussians in its own frame and its trajectory (one knot per view) from the
/// views in time order. `lift(thickness)` gives its first Gaussians (world space, at the
/// first view) lifted with that depth spread. Tracked from the first of
/// `cfg.lift_thickness`, an object that stands still under its own gauge is static (one
/// pose); a moving one is tracked from every thickness, the fit with the lowest mean loss
/// over its views is kept, and its distance is corrected by contact (`contact_rounds`).
pub fn fit(
    views: &[TrackView],
    id: u8,
    name: &str,
    lift: &mut dyn FnMut(f32) -> GaussianModel,
    cfg: &ObjectsConfig,
    rng: &mut impl Rng,
) -> Result<Tracked, splat::SplatError> {
    let mut best: Option<(f32, Tracker)> = None;
    let mut evidence = (0.0, StillEvidence::default(), None);
    for (i, &th) in cfg.lift_thickness.iter().enumerate() {
        let mut t = Tracker::new(views, id, name, lift(th), cfg);
        t.sequential(rng)?;
        if i == 0 {
            let still = t.still_scale();
            t.still_gauge = still;
            tracing::debug!(object = name, evidence = ?t.still, is_static = still.is_some(), "static test");
            if let Some(s) = still {
                if t.hold_still_if_it_fits(s)? {
                    return t.finish();
                }
            }
            evidence = (t.residual_motion, t.still, still);
        }
        let loss = t.mean_loss()?;
        tracing::debug!(
            object = name,
            thickness = th,
            loss,
            "tracked from a lifted thickness"
        );
        if best.as_ref().is_none_or(|b| loss < b.0) {
            best = Some((loss, t));
        }
    }
    let (_, mut t) = best.expect("at least one thickness (validated)");
    let cues = t.scale_cues()?;
    let choice = scale::choose(&cues, cfg.gauge, cfg.gauge_tolerance);
    tracing::debug!(object = name, ?cues, ?choice, "scale cues");
    if choice.ln_factor != 0.0 {
        t.apply_gauge(choice.ln_factor.exp()); // (s = 1 would round the poses)
    }
    (t.cues, t.gauge) = (Some(cues), Some(choice));
    if cfg.ring_gauge {
        t.ring_gauge();
    }
    t.settle_contact(1.0, rng)?;
    // The static test ran on the first thickness's track; report what it measured there.
    (t.residual_motion, t.still, t.still_gauge) = evidence;
    t.finish()
}

/// What [`fit`] found.
pub struct Tracked {
    pub id: u8,
    /// Gaussians in the object's frame.
    pub model: GaussianModel,
    pub trajectory: Trajectory,
    /// No motion under the gauge that makes it move least (one pose then).
    pub is_static: bool,
    /// The gauge applied to the first guess of its size and distance.
    pub scale: f32,
    /// RMS motion of its origin under the least-motion gauge (world units).
    pub residual_motion: f32,
    /// What the static test measured.
    pub still: StillEvidence,
    /// The gauge (relative to the lifted guess) under which its first track stood still,
    /// when the motion measures called it still: where a still base of its parts stands.
    pub still_gauge: Option<f32>,
    /// How well the rigid fit covers its masks ([`Tracker::mask_iou`]).
    pub mask_iou: f32,
    /// The readings of its gauge and the choice made from them (a moving object).
    pub cues: Option<ScaleCues>,
    pub gauge: Option<GaugeChoice>,
}

/// Largest side of the bounding box of `N·3` points.
pub(super) fn extent(means: &[f32]) -> f32 {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for m in means.chunks_exact(3) {
        for k in 0..3 {
            lo[k] = lo[k].min(m[k]);
            hi[k] = hi[k].max(m[k]);
        }
    }
    (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f32::max)
}

/// `tr` with each knot's translation moved to where it carries the centroid of `means`.
fn centroid_path(tr: &Trajectory, means: &[f32]) -> Trajectory {
    let c = centroid(means);
    let mut out = tr.clone();
    for (p, q) in out.translations.iter_mut().zip(&tr.rotations) {
        let v = quat::rotate(&quat::matrix_of(q), c);
        *p = [p[0] + v[0], p[1] + v[1], p[2] + v[2]];
    }
    out
}

/// Mean of `N·3` points.
pub fn centroid(means: &[f32]) -> [f32; 3] {
    let n = (means.len() / 3).max(1) as f64;
    let mut s = [0.0f64; 3];
    for m in means.chunks_exact(3) {
        for c in 0..3 {
            s[c] += f64::from(m[c]);
        }
    }
    s.map(|v| (v / n) as f32)
}

#[cfg(test)]
mod tests {
    use super::iou;

    #[test]
    fn iou_counts_covered_missed_and_spilled_pixels() {
        // Mask: pixels 0..4 are object 2; the render covers 2..6 (two hits, two misses,
        // two spills) and ignores alpha at exactly ½.
        let map = [2, 2, 2, 2, 255, 255, 7, 255];
        let alpha = [0.0, 0.5, 0.9, 0.6, 0.7, 0.8, 0.0, 0.0];
        assert!((iou(&alpha, &map, 2) - 2.0 / 6.0).abs() < 1e-6);
        assert_eq!(
            iou(&[0.0; 8], &[255; 8], 2),
            1.0,
            "nothing to cover, nothing drawn"
        );
        assert_eq!(iou(&[1.0; 8], &[255; 8], 2), 0.0, "all spill");
    }
}
