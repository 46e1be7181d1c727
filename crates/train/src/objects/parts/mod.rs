//! Articulated objects: an object of the ID maps that one rigid body cannot explain (a
//! crane swinging its boom, an arm, a hand closing) becomes several rigid **parts**, each a
//! body of the rigid-object node with its own trajectory and column ID, all seen in the
//! object's mask, held together at their joints. `objects.parts` sets the most parts an
//! object may get (1: rigid only).
//!
//! How the parts are found, from the images and ID maps alone (the rigid fit of `track.rs`
//! comes first and is the fallback):
//! 1. [`cluster`]: the rigid fit's Gaussians cut into `parts` spatial clusters (k-means on
//!    their object-frame means);
//! 2. [`track`]: the clusters re-tracked through the views in time order, one trajectory
//!    each, rendered together against the mask and colour, neighbours held by [`joints`];
//! 3. [`merge`]: clusters whose trajectories carry their Gaussians alike (relative motion
//!    below `parts_merge` of the object's size) become one part, and each Gaussian joins
//!    the part whose motion keeps it on its own colour inside the mask over the views; a
//!    still base, else the largest part, is the body, which keeps the object's ID;
//! 4. the parts are kept when two or more remain and they lower the mean tracking loss by
//!    `parts_min_gain` against the rigid fit; otherwise the rigid fit stands unchanged, so
//!    an object that moves as one comes out exactly as the rigid mode makes it.
//!
//! In training the parts are bodies of the rigid node (knots, checkpoints), their mask
//! term renders them together (`mask_loss.rs`), and the joint term keeps adding its
//! gradient to their knots (`RigidObjects::backward`). With `objects.skin` (the default)
//! each Gaussian of the object is placed by a blend of all its parts' poses with learned
//! weights ([`skin`], linear blend skinning as SC-GS binds Gaussians to its control
//! points), starting from its distance to each part; [`arap`] (off unless
//! `arap_weight > 0`) keeps neighbouring Gaussians of a part rigid where the weights
//! blend; `skin = false` keeps each Gaussian on one part (piecewise rigid). The evidence of every split is kept in the start report
//! ([`PartsEvidence`]).

pub mod arap;
pub mod cluster;
pub mod from_tracks;
pub mod joints;
pub mod merge;
pub mod skin;
pub mod track;

use super::json_f32;
use super::track::{TrackView, Tracked};
use super::ObjectsConfig;
use crate::model::GaussianModel;
use rand::Rng;
use serde::{Deserialize, Serialize};

pub use joints::Joint;

/// Lloyd iterations of the clustering.
const KMEANS_ITERS: usize = 20;

/// What the split measured, for the log and the start report.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PartsEvidence {
    /// Clusters tracked, and parts left after merging.
    pub clusters: usize,
    pub parts: usize,
    /// Whether the kept hypothesis holds the body still.
    pub body_still: bool,
    /// Mean tracking loss over the views of the rigid fit and of the parts.
    #[serde(with = "json_f32")]
    pub loss_rigid: f32,
    #[serde(with = "json_f32")]
    pub loss_parts: f32,
    /// Median mask IoU of the parts rendered together.
    #[serde(with = "json_f32")]
    pub iou_parts: f32,
    /// Whether the parts replaced the rigid fit.
    pub kept: bool,
}

/// One part: its Gaussians (object frame at the first view) and its trajectory.
pub struct Part {
    pub model: GaussianModel,
    pub trajectory: super::Trajectory,
    pub is_static: bool,
}

/// The parts of an object (the body first) and the joints between them, by part index.
pub struct Articulated {
    pub parts: Vec<Part>,
    pub joints: Vec<Joint>,
}

/// Tries to split the rigid fit `rigid` of object `id` into parts (see the module's
/// steps), under two hypotheses: every part moving, and (where the rigid track's motion
/// measures called the object still) the body held still under that still gauge; the one
/// with the lower tracking loss is kept. None when `objects.parts` is 1 or
/// the object has fewer than three views.
pub fn split(
    views: &[TrackView],
    id: u8,
    name: &str,
    rigid: &Tracked,
    cfg: &ObjectsConfig,
    rng: &mut impl Rng,
) -> Result<Option<(PartsEvidence, Option<Articulated>)>, splat::SplatError> {
    if cfg.parts < 2 || views.len() < 3 {
        return Ok(None);
    }
    let mut labels = cluster::kmeans(&rigid.model.means, cfg.parts, KMEANS_ITERS);
    cluster::by_size(&mut labels);
    let fresh = || {
        let (model, l) = (rigid.model.clone(), labels.clone());
        track::PartsTracker::new(views, id, cfg, model, &rigid.trajectory, l)
    };
    let mut moving = fresh();
    let loss_rigid = moving.mean_loss_rigid()?;
    let e = attempt(&mut moving, name, loss_rigid, rng)?;
    let mut best = (e, moving);
    // A still base is tried where the rigid track's motion measures called it still.
    if let Some(s) = rigid.still_gauge {
        let mut held = fresh();
        held.hold_body(s / rigid.scale);
        let e = attempt(&mut held, name, loss_rigid, rng)?;
        if e.loss_parts < best.0.loss_parts {
            best = (e, held);
        }
    }
    let (mut e, t) = best;
    e.kept = e.parts > 1 && e.loss_parts <= (1.0 - cfg.parts_min_gain) * e.loss_rigid;
    tracing::info!(
        object = name,
        clusters = e.clusters,
        parts = e.parts,
        body_still = e.body_still,
        loss_rigid = e.loss_rigid,
        loss_parts = e.loss_parts,
        iou_parts = e.iou_parts,
        rigid_iou = rigid.mask_iou,
        kept = e.kept,
        "parts tried (objects.parts)"
    );
    let out = e.kept.then(|| Articulated {
        parts: (0..e.parts)
            .map(|p| Part {
                model: t.part_model(p),
                trajectory: t.parts[p].trajectory.clone(),
                is_static: t.parts[p].is_static,
            })
            .collect(),
        joints: t.joints.clone(),
    });
    Ok(Some((e, out)))
}

/// One hypothesis: track the clusters, merge them into parts, refine; what it measured.
fn attempt(
    t: &mut track::PartsTracker,
    name: &str,
    loss_rigid: f32,
    rng: &mut impl Rng,
) -> Result<PartsEvidence, splat::SplatError> {
    let body_still = t.parts[0].is_static;
    t.sequential(rng)?;
    let clusters = t.parts.len();
    let parts = t.merge();
    if parts > 1 {
        t.refine_default(rng)?;
    }
    for (p, b) in t.parts.iter().enumerate() {
        let (dist, angle) = b.trajectory.motion_extent();
        let n = t.labels.iter().filter(|&&l| l as usize == p).count();
        tracing::debug!(
            object = name,
            body_still,
            part = p,
            gaussians = n,
            dist,
            angle_deg = angle.to_degrees(),
            "part"
        );
    }
    Ok(PartsEvidence {
        clusters,
        parts,
        body_still,
        loss_rigid,
        loss_parts: t.mean_loss()?,
        iou_parts: t.mask_iou()?,
        kept: false,
    })
}
