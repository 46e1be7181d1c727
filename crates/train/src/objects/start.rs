//! Bringing the objects in at `start_iter`: read the static background's depth in every
//! training view, then for each object of the ID maps: its sightings in time order, its
//! first Gaussians lifted from its first sighting's mask, and the time-progressive fit
//! through the others ([`super::track`]), which also decides whether it is static.

use super::lift::{self, DepthMap, LiftInput};
use super::parts;
use super::track::{self, TrackView};
use super::{knots::KnotAdam, RigidObject, RigidObjects, NO_OBJECT};
use crate::deform::{self, Deformed};
use crate::model::GaussianModel;
use crate::state::GaussianState;
use rand::{Rng, SeedableRng};
use scene::Dataset;
use splat::Rasterizer;

/// What [`start`] found, per object, for the log.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StartReport {
    pub id: u8,
    pub name: String,
    pub sightings: usize,
    pub is_static: bool,
    /// RMS motion of the tracked trajectory under the gauge that makes it move least, and
    /// the object's size (world units, after the gauge).
    #[serde(with = "super::json_f32")]
    pub residual_motion: f32,
    #[serde(with = "super::json_f32")]
    pub size: f32,
    /// The static test's measures ([`track::StillEvidence`]).
    pub still: track::StillEvidence,
    pub gaussians: usize,
    /// The gauge applied to the lifted guess of its size and distance.
    #[serde(with = "super::json_f32")]
    pub scale: f32,
    /// Median IoU of its rigid render with its masks (`Tracker::mask_iou`).
    #[serde(with = "super::json_f32")]
    pub mask_iou: f32,
    /// Not a rigid body by `objects.min_rigid_iou`: left to the deformation field (no
    /// Gaussians, no trajectory of its own).
    pub left_to_field: bool,
    /// The readings of its gauge (`scale.rs`) and the choice made from them, for a moving
    /// object.
    pub cues: Option<super::scale::ScaleCues>,
    pub gauge: Option<super::scale::GaugeChoice>,
    /// What the split into parts measured (`objects.parts` > 1), and whether it was kept.
    #[serde(default)]
    pub parts: Option<super::parts::PartsEvidence>,
}

/// The static background's camera depth in every training view (δ = 0: the background
/// has been trained static until now).
fn background_depths(
    model: &GaussianModel,
    ds: &Dataset,
) -> Result<Vec<DepthMap>, splat::SplatError> {
    let mut d = Deformed::default();
    deform::apply(model, None, &mut d);
    let mut raster = Rasterizer::new();
    ds.train
        .iter()
        .map(|f| {
            lift::render_depth(
                &mut raster,
                &d.means,
                &d.quats,
                &d.scales,
                &model.opacity_logits,
                &f.camera,
            )
        })
        .collect()
}

/// A sighting: a training view where the object's mask is large enough, with the depth of
/// its surroundings and its size (the mask's diagonal) in world units at that depth.
struct Sighting {
    frame: usize,
    depth: f32,
    size: f32,
}

fn sightings(node: &RigidObjects, ds: &Dataset, depths: &[DepthMap], id: u8) -> Vec<Sighting> {
    let mut out = Vec::new();
    for (f, frame) in ds.train.iter().enumerate() {
        let map = &node.id_maps[f];
        let (px, bb) = lift::mask_pixels(map, frame.camera.width, id);
        if px.len() < node.cfg.min_pixels as usize {
            continue;
        }
        let Some(depth) = lift::ring_depth(&depths[f], map, id, node.cfg.ring_px) else {
            continue;
        };
        let diag = ((bb[2] - bb[0]) as f32).hypot((bb[3] - bb[1]) as f32);
        out.push(Sighting {
            frame: f,
            depth,
            size: diag * depth / frame.camera.fx,
        });
    }
    out.sort_by(|a, b| ds.train[a.frame].time.total_cmp(&ds.train[b.frame].time));
    out
}

fn lift_at(
    node: &RigidObjects,
    ds: &Dataset,
    s: &Sighting,
    id: u8,
    thickness: f32,
    rng: &mut impl Rng,
) -> GaussianModel {
    let frame = &ds.train[s.frame];
    let image = frame.image.to_f32();
    let inp = LiftInput {
        cam: &frame.camera,
        image: &image,
        id_map: &node.id_maps[s.frame],
        id,
        depth: s.depth,
    };
    lift::lift(&inp, node.cfg.lift_points, thickness, rng)
}

/// The tracking views of an object's sightings.
fn views<'a>(
    node: &'a RigidObjects,
    ds: &'a Dataset,
    depths: &'a [DepthMap],
    seen: &[Sighting],
) -> Vec<TrackView<'a>> {
    seen.iter()
        .map(|s| TrackView {
            cam: &ds.train[s.frame].camera,
            time: ds.train[s.frame].time,
            image: &ds.train[s.frame].image,
            id_map: &node.id_maps[s.frame],
            background: Some(&depths[s.frame]),
        })
        .collect()
}

/// Object IDs present in the ID maps, ascending.
pub(super) fn object_ids(maps: &[Vec<u8>]) -> Vec<u8> {
    let mut seen = [false; 256];
    for m in maps {
        for &v in m {
            seen[v as usize] = true;
        }
    }
    (0..NO_OBJECT).filter(|&i| seen[i as usize]).collect()
}

/// Lifts, tests, tracks and places every object, appends their Gaussians to `state` (with
/// their object in the column) and fills `node.objects`.
pub fn start(
    node: &mut RigidObjects,
    state: &mut GaussianState,
    ds: &Dataset,
    rng: &mut impl Rng,
) -> Result<Vec<StartReport>, splat::SplatError> {
    let depths = background_depths(&state.model, ds)?;
    let ids: Vec<(u8, Vec<Sighting>)> = object_ids(&node.id_maps)
        .into_iter()
        .map(|id| (id, sightings(node, ds, &depths, id)))
        .filter(|(_, seen)| !seen.is_empty())
        .collect();
    let mut done = Vec::new();
    for (id, seen) in &ids {
        let v = views(node, ds, &depths, seen);
        // The lifts draw from their own stream, seeded from the run's, so runs repeat.
        let mut lift_rng = rand_chacha::ChaCha8Rng::seed_from_u64(rng.gen());
        let mut lift = |th: f32| lift_at(node, ds, &seen[0], *id, th, &mut lift_rng);
        let name = node.name_of(*id);
        let fit = track::fit(&v, *id, &name, &mut lift, &node.cfg, rng)?;
        let split = parts::split(&v, *id, &name, &fit, &node.cfg, rng)?;
        done.push((fit, split));
    }
    let mut free = free_ids(&node.id_maps);
    let mut reports = Vec::new();
    for ((f, split), (id, seen)) in done.into_iter().zip(&ids) {
        let id = *id;
        let name = node.name_of(id);
        let size = median(seen.iter().map(|s| s.size).collect()) * f.scale;
        let (parts_evidence, articulated) = match split {
            Some((e, a)) => (Some(e), a),
            None => (None, None),
        };
        let iou = parts_evidence
            .filter(|e| e.kept)
            .map_or(f.mask_iou, |e| e.iou_parts);
        // Still or moving: a still pose that covers the masks badly is a body whose parts
        // move (a crane's boom, an arm) as surely as a moving fit that does.
        let not_rigid = iou < node.cfg.min_rigid_iou;
        let confidence = f.gauge.map_or(1.0, |g| g.confidence);
        let unplaced = !f.is_static && confidence < node.cfg.min_scale_confidence;
        let left_to_field = not_rigid || unplaced;
        if not_rigid {
            tracing::warn!(object = %name, mask_iou = iou, rigid_mask_iou = f.mask_iou,
                is_static = f.is_static, min_rigid_iou = node.cfg.min_rigid_iou,
                "not a rigid body: its fit (one rigid shape, or its parts where they were kept) \
                 covers its masks with a median IoU below objects.min_rigid_iou, so the \
                 deformation field keeps it");
        } else if unplaced {
            tracing::warn!(object = %name, confidence,
                min_scale_confidence = node.cfg.min_scale_confidence,
                "no trustworthy depth: too few of its gauge's cues agree \
                 (objects.min_scale_confidence), so the deformation field keeps it");
        } else if articulated.is_none() {
            state.append_object(&f.model, id);
            tracing::info!(object = %name, sightings = seen.len(), is_static = f.is_static,
                residual_motion = f.residual_motion, size, scale = f.scale,
                mask_iou = f.mask_iou, gaussians = f.model.len(), "object started");
        }
        reports.push(StartReport {
            id,
            name: name.clone(),
            sightings: seen.len(),
            is_static: f.is_static,
            residual_motion: f.residual_motion,
            size,
            still: f.still,
            gaussians: if left_to_field { 0 } else { f.model.len() },
            scale: f.scale,
            mask_iou: f.mask_iou,
            left_to_field,
            cues: f.cues,
            gauge: f.gauge,
            parts: parts_evidence,
        });
        if left_to_field {
            continue;
        }
        if let Some(a) = articulated {
            add_parts(node, state, (id, &name), a, &mut free);
            continue;
        }
        node.knot_adam.push(KnotAdam::zeros(f.trajectory.len()));
        node.objects
            .push(RigidObject::new(id, name, f.trajectory, f.is_static));
    }
    node.started = true;
    node.start_reports = reports.clone();
    Ok(reports)
}

/// Column IDs no object of the ID maps uses, highest first: the parts' own IDs.
pub(super) fn free_ids(maps: &[Vec<u8>]) -> Vec<u8> {
    let used = object_ids(maps);
    (0..NO_OBJECT).filter(|i| !used.contains(i)).collect()
}

/// Appends an articulated object's parts: the body under the object's ID, every other part
/// under a free column ID, all seen in the object's mask; the joints follow the IDs.
fn add_parts(
    node: &mut RigidObjects,
    state: &mut GaussianState,
    (id, name): (u8, &str),
    a: parts::Articulated,
    free: &mut Vec<u8>,
) {
    let mut ids = Vec::with_capacity(a.parts.len());
    for (p, part) in a.parts.into_iter().enumerate() {
        let Some(col) = (if p == 0 { Some(id) } else { free.pop() }) else {
            tracing::warn!(
                object = name,
                "no free object IDs left for its parts: the rest \
                stay with the body"
            );
            break;
        };
        state.append_object(&part.model, col);
        tracing::info!(
            object = name,
            part = p,
            id = col,
            gaussians = part.model.len(),
            "part started"
        );
        let label = if p == 0 {
            name.to_string()
        } else {
            format!("{name}/part-{p}")
        };
        let mut body = RigidObject::new(col, label, part.trajectory, part.is_static);
        body.mask = id;
        node.knot_adam.push(KnotAdam::zeros(body.trajectory.len()));
        node.objects.push(body);
        ids.push(col);
    }
    for j in a.joints {
        if let (Some(&ja), Some(&jb)) = (ids.get(j.a as usize), ids.get(j.b as usize)) {
            node.joints.push(parts::Joint { a: ja, b: jb, ..j });
        }
    }
}

pub(super) fn median(mut v: Vec<f32>) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    v.select_nth_unstable_by(mid, f32::total_cmp);
    v[mid]
}
