//! Tracking an object as several rigid parts: the rigid tracker's time-progressive fit
//! (`objects/track.rs`) with one trajectory per part, the parts rendered together against
//! the object's one mask and colour, and the joint term between neighbouring parts. Each
//! part's pose in a new view is predicted at constant velocity from its own last two, so a
//! part that turns away from the rest (a boom, a forearm) is followed while the others hold.

use super::super::knots::KnotAdam;
use super::super::place;
use super::super::track::{self, TrackView, HP};
use super::super::trajectory::{Pose, Trajectory, TrajectoryGrad};
use super::super::{ObjectsConfig, RigidObject};
use super::joints::{self, Joint};
use super::merge;
use crate::adam::Adam;
use crate::deform::{self, CanonicalGrads, Deformed};
use crate::model::{GaussianModel, ROWS};
use rand::Rng;
use splat::{Gradients, Rasterizer, RenderOptions};

pub struct PartsTracker<'a> {
    views: &'a [TrackView<'a>],
    cfg: &'a ObjectsConfig,
    /// The object's ID in the maps.
    id: u8,
    /// One body per part, with column IDs `0..k` (internal to the tracker) and one knot
    /// per view.
    pub parts: Vec<RigidObject>,
    /// The part of each Gaussian.
    pub labels: Vec<u32>,
    pub joints: Vec<Joint>,
    /// The object's Gaussians in its frame at the first view.
    pub model: GaussianModel,
    size: f32,
    /// The rigid fit's trajectory, one knot per view.
    rigid: Trajectory,
    rows: Vec<Vec<u32>>,
    adam: [Adam; 5],
    knots: Vec<KnotAdam>,
    raster: Rasterizer,
    deformed: Deformed,
    grads: Gradients,
    canon: CanonicalGrads,
    gt: Vec<f32>,
}

impl<'a> PartsTracker<'a> {
    /// Parts `labels` of the rigid fit (`model` in the object's frame, `rigid` its
    /// trajectory), each starting on the rigid trajectory at every view.
    pub fn new(
        views: &'a [TrackView<'a>],
        id: u8,
        cfg: &'a ObjectsConfig,
        model: GaussianModel,
        rigid: &Trajectory,
        labels: Vec<u32>,
    ) -> Self {
        let times: Vec<f32> = views.iter().map(|v| v.time).collect();
        let poses: Vec<Pose> = times.iter().map(|&t| rigid.pose(t)).collect();
        let per_view = Trajectory {
            times,
            translations: poses.iter().map(|p| p.p).collect(),
            rotations: poses.iter().map(|p| p.q).collect(),
        };
        let k = labels.iter().copied().max().map_or(1, |m| m as usize + 1);
        let parts = (0..k)
            .map(|p| {
                let tr = per_view.clone();
                let mut b = RigidObject::new(p as u8, format!("part-{p}"), tr, false);
                b.mask = id;
                b
            })
            .collect();
        let n = model.len();
        let mut t = Self {
            views,
            cfg,
            id,
            parts,
            labels,
            joints: Vec::new(),
            size: track::extent(&model.means),
            rigid: per_view,
            model,
            rows: Vec::new(),
            adam: ROWS.map(|r| Adam::zeros(n * r)),
            knots: Vec::new(),
            raster: Rasterizer::new(),
            deformed: Deformed::default(),
            grads: Gradients::default(),
            canon: CanonicalGrads::default(),
            gt: Vec::new(),
        };
        t.relabel();
        t
    }

    /// Holds the body (part 0, the largest) still at its pose in the first view, where the
    /// object was lifted, with the object scaled about the cameras by `gauge` (the factor
    /// under which the rigid track stood still): the hypothesis of an articulated object on
    /// a fixed base (a crane, a robot arm, a lamp), tracked beside the one where every part
    /// moves.
    pub fn hold_body(&mut self, gauge: f32) {
        let centres: Vec<[f32; 3]> = self.views.iter().map(|v| v.cam.center()).collect();
        // The Gaussians scale once; every part's trajectory scales (an empty model with it).
        let mut none = self.model.gather(&[]);
        super::super::gauge::apply_scale(&mut none, &mut self.rigid, &centres, gauge);
        for (p, b) in self.parts.iter_mut().enumerate() {
            let m = if p == 0 { &mut self.model } else { &mut none };
            super::super::gauge::apply_scale(m, &mut b.trajectory, &centres, gauge);
        }
        self.size = track::extent(&self.model.means);
        let b = &mut self.parts[0];
        let tr = &b.trajectory;
        b.trajectory = Trajectory::constant(tr.times[0], tr.translations[0], tr.rotations[0]);
        b.is_static = true;
        self.relabel();
    }

    /// Rows, joints and fresh knot optimizers for the current labels.
    fn relabel(&mut self) {
        let k = self.parts.len();
        self.rows = vec![Vec::new(); k];
        for (i, &l) in self.labels.iter().enumerate() {
            self.rows[l as usize].push(i as u32);
        }
        let reach = 3.0 * joints::spacing(&self.model.means);
        let w = self.cfg.joint_weight / (self.size * self.size).max(1e-12);
        self.joints = joints::find(&self.model.means, &self.labels, reach)
            .into_iter()
            .map(|(a, b, point)| Joint {
                a: a as u8,
                b: b as u8,
                point,
                weight: w,
            })
            .collect();
        self.knots = (0..k).map(|_| KnotAdam::zeros(self.views.len())).collect();
    }

    /// The parts placed in the world at `time` (into `self.deformed`), and their poses.
    fn place_at(&mut self, time: f32) -> Vec<Pose> {
        deform::apply(&self.model, None, &mut self.deformed);
        let mut poses = Vec::new();
        let (parts, rows, model) = (&self.parts, &self.rows, &self.model);
        place::place(
            parts,
            rows,
            place::Shape::of(model),
            time,
            &mut self.deformed,
            &mut poses,
        );
        poses
    }

    /// One forward/backward on view `v` (returns the view's colour + mask loss); steps the
    /// view's knots and/or the Gaussians.
    fn step(&mut self, v: usize, pose: bool, shape: bool) -> Result<f32, splat::SplatError> {
        let view = &self.views[v];
        let poses = self.place_at(view.time);
        let g = deform::gaussians(&self.model, &self.deformed);
        let opts = RenderOptions::default();
        let out = self.raster.forward(&g, view.cam, &opts)?;
        view.image.to_f32_into(&mut self.gt);
        let loss = track::view_loss(
            view,
            &self.gt,
            self.id,
            out.image,
            out.alpha,
            self.cfg.lambda_mask,
        );
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
        let mut tg: Vec<TrajectoryGrad> = self
            .parts
            .iter()
            .map(|_| TrajectoryGrad::zeros(self.views.len()))
            .collect();
        let world = place::WorldGrads {
            means: &gr.means,
            quats: &gr.quats,
        };
        place::backward(
            &self.parts,
            &self.rows,
            place::Shape::of(&self.model),
            &poses,
            world,
            &mut self.canon,
            &mut tg,
        );
        joints::add(&self.joints, &self.parts, &poses, &mut tg);
        if pose {
            let lr = (self.cfg.track_lr_translation, self.cfg.track_lr_rotation);
            for ((b, k), g) in self.parts.iter_mut().zip(&mut self.knots).zip(&tg) {
                if !b.is_static {
                    k.step_knot(&mut b.trajectory, g, v, HP, lr);
                }
            }
        }
        if shape {
            track::step_shape(
                self.cfg,
                &mut self.adam,
                &mut self.model,
                &self.canon,
                &self.grads,
            );
        }
        Ok(loss.value)
    }

    /// The time-progressive pass through the views (each part predicted to keep its offset
    /// from the rigid fit, then fitted), then the joint refinement.
    pub fn sequential(&mut self, rng: &mut impl Rng) -> Result<(), splat::SplatError> {
        for v in 0..self.views.len() {
            if v > 0 {
                for b in self.parts.iter_mut().filter(|b| !b.is_static) {
                    follow_rigid(&mut b.trajectory, &self.rigid, v);
                }
                for _ in 0..self.cfg.track_pose_iters {
                    self.step(v, true, false)?;
                }
            }
            for _ in 0..self.cfg.track_shape_iters {
                let lo = if rng.gen::<bool>() {
                    v.saturating_sub(4)
                } else {
                    0
                };
                let j = rng.gen_range(lo..=v);
                self.step(j, true, true)?;
            }
        }
        self.refine(rng, self.cfg.track_refine_iters)
    }

    /// Joint refinement of shape, appearance and every pose on views drawn uniformly.
    pub fn refine(&mut self, rng: &mut impl Rng, iters: u32) -> Result<(), splat::SplatError> {
        for _ in 0..iters {
            let j = rng.gen_range(0..self.views.len());
            self.step(j, true, true)?;
        }
        Ok(())
    }

    /// The mean tracking loss of the rigid fit this tracker started from (every part on
    /// the rigid trajectory, so the joint term is zero), before any step.
    pub fn mean_loss_rigid(&mut self) -> Result<f32, splat::SplatError> {
        let saved: Vec<Trajectory> = self.parts.iter().map(|b| b.trajectory.clone()).collect();
        for b in &mut self.parts {
            b.trajectory = self.rigid.clone();
        }
        let loss = self.mean_loss();
        for (b, t) in self.parts.iter_mut().zip(saved) {
            b.trajectory = t;
        }
        loss
    }

    /// [`Self::refine`] for `objects.track_refine_iters`.
    pub fn refine_default(&mut self, rng: &mut impl Rng) -> Result<(), splat::SplatError> {
        self.refine(rng, self.cfg.track_refine_iters)
    }

    /// Mean tracking loss (colour + mask, as the rigid tracker's) over every view, no step.
    pub fn mean_loss(&mut self) -> Result<f32, splat::SplatError> {
        let mut sum = 0.0;
        for v in 0..self.views.len() {
            sum += self.step(v, false, false)?;
        }
        Ok(sum / self.views.len().max(1) as f32)
    }

    /// Median mask IoU of the parts rendered together (as `Tracker::mask_iou`).
    pub fn mask_iou(&mut self) -> Result<f32, splat::SplatError> {
        let mut ious = Vec::with_capacity(self.views.len());
        for view in self.views {
            self.place_at(view.time);
            let g = deform::gaussians(&self.model, &self.deformed);
            let out = self
                .raster
                .forward(&g, view.cam, &RenderOptions::default())?;
            ious.push(track::iou(out.alpha, view.id_map, self.id));
        }
        if ious.is_empty() {
            return Ok(1.0);
        }
        let mid = ious.len() / 2;
        ious.select_nth_unstable_by(mid, f32::total_cmp);
        Ok(ious[mid])
    }

    /// Merges the parts that move alike (`objects.parts_merge`), gives every Gaussian the
    /// part whose motion best explains it (`merge::reassign`), and numbers the parts by size
    /// with a still base first (0 is the body). Returns the number of parts left.
    pub fn merge(&mut self) -> usize {
        let groups = self.groups_by_motion();
        // A group moves as its largest cluster.
        let lead = lead_clusters(&groups, &self.labels);
        let mut labels: Vec<u32> = self.labels.iter().map(|&l| groups[l as usize]).collect();
        let trajs: Vec<Trajectory> = lead
            .iter()
            .map(|&c| self.parts[c].trajectory.clone())
            .collect();
        let still: Vec<bool> = lead.iter().map(|&c| self.parts[c].is_static).collect();
        if lead.len() > 1 {
            let views: Vec<merge::MaskView> = self
                .views
                .iter()
                .map(|v| merge::MaskView {
                    cam: v.cam,
                    time: v.time,
                    id_map: v.id_map,
                    image: v.image.to_f32(),
                })
                .collect();
            let refs: Vec<&Trajectory> = trajs.iter().collect();
            merge::reassign(&self.model, &mut labels, &refs, &views, self.id);
        }
        // Number by size, a still base first (it is the body); a part the reassignment
        // emptied is dropped.
        let mut sized = labels.clone();
        super::cluster::by_size(&mut sized);
        if let Some(base) = labels.iter().zip(&sized).find(|(&l, _)| still[l as usize]) {
            let base = *base.1;
            for l in &mut sized {
                // The base to 0, the parts before it one down the list.
                *l = match (*l).cmp(&base) {
                    std::cmp::Ordering::Equal => 0,
                    std::cmp::Ordering::Less => *l + 1,
                    std::cmp::Ordering::Greater => *l,
                };
            }
        }
        let mut order = vec![usize::MAX; lead.len()];
        for (&old, &new) in labels.iter().zip(&sized) {
            order[new as usize] = old as usize;
        }
        let kept = order.into_iter().take_while(|&o| o != usize::MAX);
        self.parts = kept
            .enumerate()
            .map(|(p, old)| {
                let tr = trajs[old].clone();
                let mut b = RigidObject::new(p as u8, format!("part-{p}"), tr, still[old]);
                b.mask = self.id;
                b
            })
            .collect();
        self.labels = sized;
        self.relabel();
        self.parts.len()
    }

    /// Each cluster's group: clusters whose relative motion stays below `parts_merge` of
    /// the object's size are one.
    fn groups_by_motion(&self) -> Vec<u32> {
        let k = self.parts.len();
        let traj: Vec<&Trajectory> = self.parts.iter().map(|b| &b.trajectory).collect();
        let times: Vec<f32> = self.views.iter().map(|v| v.time).collect();
        let (means, labels) = (&self.model.means, &self.labels);
        let mut rel = vec![0.0f32; k * k];
        for a in 0..k {
            for b in a + 1..k {
                let pair = (a as u32, b as u32);
                let at = (&times[..], self.size);
                rel[a * k + b] =
                    merge::relative_motion(means, labels, pair, (traj[a], traj[b]), at);
            }
        }
        let limit = self.cfg.parts_merge;
        tracing::debug!(
            ?rel,
            limit,
            "relative motion of the clusters (over the object's size)"
        );
        merge::group(k, |a, b| rel[a * k + b] < limit)
    }

    /// The Gaussians of part `p` (object frame).
    pub fn part_model(&self, p: usize) -> GaussianModel {
        let idx: Vec<usize> = self.rows[p].iter().map(|&r| r as usize).collect();
        self.model.gather(&idx)
    }
}

/// The largest cluster of each group (ties: the lower index), given each cluster's group
/// and each Gaussian's cluster.
fn lead_clusters(groups: &[u32], labels: &[u32]) -> Vec<usize> {
    let k = groups.len();
    let g = groups.iter().copied().max().map_or(1, |m| m as usize + 1);
    let mut count = vec![0usize; k];
    for &l in labels {
        count[l as usize] += 1;
    }
    (0..g)
        .map(|grp| {
            (0..k)
                .filter(|&c| groups[c] as usize == grp)
                .max_by_key(|&c| (count[c], std::cmp::Reverse(c)))
                .expect("every group has a cluster")
        })
        .collect()
}

/// Predicts knot `v` of a part from its knot `v − 1`: the part keeps the offset it had
/// from the rigid fit there, `T_part(v) = T_rigid(v)·T_rigid(v−1)⁻¹·T_part(v−1)`. The rigid
/// fit already follows the object's gross motion; a part learns only how it departs from it.
fn follow_rigid(part: &mut Trajectory, rigid: &Trajectory, v: usize) {
    let (r0, r1) = (rigid.pose(rigid.times[v - 1]), rigid.pose(rigid.times[v]));
    let q_p = crate::quat::normalize(&part.rotations[v - 1]).0;
    let p_p = part.translations[v - 1];
    // The offset D = T_rigid(v−1)⁻¹·T_part(v−1).
    let q_d = crate::quat::mul(crate::quat::conj(r0.q), q_p);
    let p_d = r0.invert(p_p);
    part.rotations[v] = crate::quat::mul(r1.q, q_d);
    part.translations[v] = r1.apply(p_d);
}
