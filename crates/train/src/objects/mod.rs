//! Rigid objects: our extension beyond the paper (docs/objects.md). Each object of the
//! object-ID maps becomes a node of the scene with a trajectory `T_o(t) ∈ SE(3)`; its
//! Gaussians are stored in the object's frame and placed by `T_o(t)`, with no time-varying
//! scale or opacity, so an object cannot be drawn as a flip-book. Everything else keeps the
//! Deformable-3DGS field. drivestudio's rigid nodes are organised the same way (a per-Gaussian
//! object column, a pose table per object, one rasterizer call for all nodes).
//!
//! Pieces, in the order a run meets them:
//! - [`config`]: `[objects]` of the training config;
//! - before `start_iter`, object pixels are kept out of the photometric gradient
//!   ([`RigidObjects::mask_background`]), so the static background does not learn them;
//! - at `start_iter`, [`start`]: the background's depth is rendered in every training view,
//!   each object is lifted from its first sighting ([`lift`]), tested for motion on its
//!   mask-lifted track, tracked through its views in time order ([`track`]), and placed
//!   by the occlusion gauge ([`gauge`]); its Gaussians join the training state with their
//!   object in the state's object column;
//! - every step: [`place`] puts object Gaussians in the world at the view's time and chains
//!   the gradients back (articulated objects' rows by their skinning weights,
//!   `parts::skin`, with `parts::arap` between neighbours), [`mask_loss`] adds the
//!   alpha-against-mask term, [`knots`] steps the trajectories; with `residual`, each
//!   object's small field adds its δ in the object's frame first ([`residual`]);
//! - densification keeps the column aligned (children inherit their parent's object).
//!
//! [`node`] is the scene model's view of all this: the rigid objects as one node kind
//! (`crate::node::Node`).
//!
//! After training, [`select`] turns named objects (and `background`) into the rows render
//! and export keep, and [`export`] writes one object in its own frame with its trajectory.

pub mod adopt;
pub mod config;
pub mod contact;
pub mod export;
pub mod gauge;
pub mod json_f32;
pub mod knots;
pub mod lift;
pub mod mask_loss;
pub mod membership;
pub mod node;
pub mod parts;
pub mod place;
pub mod regauge;
pub mod residual;
pub mod scale;
pub mod select;
pub mod smooth;
pub mod start;
pub mod store;
pub mod track;
pub mod trajectory;
pub mod truth;

pub use config::{ObjectSource, ObjectsConfig, ObjectsMode};
pub use place::NO_OBJECT;
pub use select::{SelectMode, Selection};
pub use trajectory::{Pose, Trajectory};

use crate::adam::AdamHyper;
use crate::deform::{CanonicalGrads, Deformed};
use crate::model::GaussianModel;
use knots::KnotAdam;
use trajectory::TrajectoryGrad;

/// One rigid body of the scene: its ID in the object column, the ID of the object-ID maps
/// whose pixels it is seen in (`mask`), a name, and its trajectory. A whole object has
/// `mask == id`; a part of an articulated object ([`parts`]) has a column ID of its own and
/// its object's `mask`. A static body keeps one pose and gets no pose gradient.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidObject {
    pub id: u8,
    pub mask: u8,
    pub name: String,
    pub is_static: bool,
    pub trajectory: Trajectory,
}

impl RigidObject {
    pub fn new(id: u8, name: String, trajectory: Trajectory, is_static: bool) -> Self {
        Self {
            id,
            mask: id,
            name,
            is_static,
            trajectory,
        }
    }

    /// Whether this body is a part of an articulated object other than its body.
    pub fn is_part(&self) -> bool {
        self.id != self.mask
    }
}

/// The object column with every part's ID replaced by its object's mask ID, so rows are
/// counted per object of the ID maps (evaluation, selection).
pub fn column_by_mask(objects: &[RigidObject], column: &[u8]) -> Vec<u8> {
    let mut map: [u8; 256] = std::array::from_fn(|i| i as u8);
    for o in objects {
        map[o.id as usize] = o.mask;
    }
    column.iter().map(|&c| map[c as usize]).collect()
}

/// The rigid-object node of a training run: config, the training views' ID maps, the
/// objects (empty before `start_iter`), their knot optimizers and reused buffers.
pub struct RigidObjects {
    pub cfg: ObjectsConfig,
    pub objects: Vec<RigidObject>,
    pub knot_adam: Vec<KnotAdam>,
    /// Whether [`start`] has run (objects may still be empty if none was seen).
    pub started: bool,
    /// One ID map per training frame, at the training resolution.
    pub id_maps: Vec<Vec<u8>>,
    /// Name of each object ID, from the scene (objects.json, else the segmentation's
    /// dictionary, else `object-<id>`).
    pub names: Vec<(u8, String)>,
    /// What [`start`] found per object (empty before it ran; kept in checkpoints).
    pub start_reports: Vec<start::StartReport>,
    /// Persistent top-k votes and the transfer rule (None with `transfer = false`).
    pub membership: Option<membership::Membership>,
    /// Joints between the parts of articulated objects, by column ID ([`parts::joints`]).
    pub joints: Vec<parts::Joint>,
    /// Articulated objects' blended placement and its as-rigid-as-possible term.
    pub skin: parts::skin::Skinning,
    arap: parts::arap::Arap,
    /// Each object's residual field on top of its poses (`[objects] residual`).
    pub residual: Option<residual::Residual>,
    rows: Vec<Vec<u32>>,
    /// `rows` without the skinned ones (placed and chained back by `skin`).
    rigid_rows: Vec<Vec<u32>>,
    poses: Vec<Pose>,
    grads: Vec<TrajectoryGrad>,
    mask: mask_loss::MaskLoss,
}

impl RigidObjects {
    pub fn new(cfg: ObjectsConfig, id_maps: Vec<Vec<u8>>, names: Vec<(u8, String)>) -> Self {
        let membership = cfg.transfer.then(|| {
            let maps = id_maps.iter().map(Vec::as_slice);
            membership::Membership::new(
                maps,
                cfg.votes_k,
                cfg.transfer_share,
                cfg.transfer_min_weight,
            )
        });
        Self {
            start_reports: Vec::new(),
            membership,
            cfg,
            objects: Vec::new(),
            knot_adam: Vec::new(),
            joints: Vec::new(),
            started: false,
            id_maps,
            names,
            skin: parts::skin::Skinning::default(),
            arap: parts::arap::Arap::default(),
            residual: None,
            rows: Vec::new(),
            rigid_rows: Vec::new(),
            poses: Vec::new(),
            grads: Vec::new(),
            mask: mask_loss::MaskLoss::default(),
        }
    }

    /// The node of a training run (reads the training views' ID maps). Lifted objects
    /// start no earlier than `min_start_passes` passes over those views
    /// ([`ObjectsConfig::start_for_views`]).
    pub fn for_training(
        cfg: &ObjectsConfig,
        ds: &scene::Dataset,
        iterations: u32,
    ) -> crate::error::Result<Self> {
        let maps = crate::id_maps::load(ds)?;
        let mut cfg = cfg.clone();
        if cfg.source == ObjectSource::Lift {
            let (scheduled, views) = (cfg.start_iter, maps.len());
            cfg.start_iter = cfg.start_for_views(views, iterations);
            if cfg.start_iter != scheduled {
                tracing::info!(scheduled, start = cfg.start_iter, views,
                    "objects start after {} passes over the training views (objects.min_start_passes)",
                    cfg.min_start_passes);
            }
        }
        Ok(Self::new(cfg, maps, crate::id_maps::names(ds)))
    }

    /// Before the objects start: zero `dL/dimage` on object pixels of training view `frame`,
    /// so the background is not fitted to objects it will not own.
    /// Objects taken over from the field are learned by it until then: nothing is masked.
    pub fn mask_background(&self, iteration: u32, frame: usize, dl_dimage: &mut [f32]) {
        if iteration >= self.cfg.start_iter || self.cfg.source == ObjectSource::Field {
            return;
        }
        for (p, &id) in self.id_maps[frame].iter().enumerate() {
            if id != NO_OBJECT {
                dl_dimage[p * 3..p * 3 + 3].fill(0.0);
            }
        }
    }

    /// Places the object rows at time `t` (after `deform::apply`) and keeps the poses for
    /// [`RigidObjects::backward`]: each on its body, then the rows of articulated objects
    /// by their skinning weights where the store has them (`aux`, [`parts::skin`]).
    pub fn place(
        &mut self,
        model: &GaussianModel,
        column: &[u8],
        aux: &[crate::state::AuxRows],
        t: f32,
        out: &mut Deformed,
    ) {
        place::rows_by_object(&self.objects, column, &mut self.rows);
        let shape = match &mut self.residual {
            Some(r) if !r.fields.is_empty() => r.place(&self.objects, &self.rows, model, t, out),
            _ => place::Shape::of(model),
        };
        place::place(&self.objects, &self.rows, shape, t, out, &mut self.poses);
        let (objects, poses) = (&self.objects, &self.poses);
        self.skin.place(objects, poses, shape, column, aux, out);
    }

    /// The as-rigid-as-possible term of the articulated objects for this step's placement
    /// ([`parts::arap`]); adds its gradient into `g_means` (world space).
    pub fn add_arap(
        &mut self,
        model: &GaussianModel,
        placed: &Deformed,
        g_means: &mut [f32],
    ) -> f32 {
        let w = self.cfg.arap_weight;
        self.arap.add(&self.skin, model, placed, w, g_means)
    }

    /// The alpha-against-mask term for training view `frame` (objects rendered alone, each
    /// moving object against its own mask); adds its gradient into `grads` (world space).
    pub fn add_mask_loss(
        &mut self,
        frame: usize,
        cam: &splat::Camera,
        model: &GaussianModel,
        deformed: &Deformed,
        grads: &mut splat::Gradients,
    ) -> Result<f32, splat::SplatError> {
        if self.cfg.lambda_mask == 0.0 {
            return Ok(0.0);
        }
        let inp = mask_loss::MaskInput {
            objects: &self.objects,
            rows: &self.rows,
            id_map: &self.id_maps[frame],
            cam,
            model,
            deformed,
            lambda: self.cfg.lambda_mask,
        };
        self.mask.add(&inp, grads)
    }

    /// Chains the object rows' world gradients back (see [`place::backward`]) and collects
    /// the trajectories' gradients, and the residual fields' (`g_scales`: their δs).
    pub fn backward(
        &mut self,
        model: &GaussianModel,
        world: &splat::Gradients,
        canon: &mut CanonicalGrads,
    ) {
        let (g_means, g_quats) = (&world.means[..], &world.quats[..]);
        // The shape the last placement placed: the store's, or with the residual's δ.
        let residual = self.residual.as_ref().and_then(|r| r.shape());
        let shape = residual.unwrap_or(place::Shape::of(model));
        self.grads.clear();
        self.grads.extend(
            self.objects
                .iter()
                .map(|o| TrajectoryGrad::zeros(o.trajectory.len())),
        );
        // The skinned rows are chained back by `skin` below, not by their home body.
        let rows = if self.skin.active() {
            self.rigid_rows.clone_from(&self.rows);
            for &s in self.skin.groups.iter().flatten() {
                self.rigid_rows[s].clear();
            }
            &self.rigid_rows
        } else {
            &self.rows
        };
        place::backward(
            &self.objects,
            rows,
            shape,
            &self.poses,
            place::WorldGrads {
                means: g_means,
                quats: g_quats,
            },
            canon,
            &mut self.grads,
        );
        if self.skin.active() {
            let world = place::WorldGrads {
                means: g_means,
                quats: g_quats,
            };
            let (objects, poses) = (&self.objects, &self.poses);
            self.skin
                .backward(objects, poses, shape, world, canon, &mut self.grads);
        }
        parts::joints::add(&self.joints, &self.objects, &self.poses, &mut self.grads);
        if let Some(r) = &mut self.residual {
            r.backward(model, &world.scales, canon);
        }
    }

    /// Adam on the skinning logits of this step's rows; `iteration` counts their steps
    /// from `start_iter`. Whether every logit is finite.
    pub fn step_skin(
        &self,
        iteration: u32,
        hp: AdamHyper,
        aux: &mut crate::state::AuxStore<'_>,
    ) -> bool {
        let t = iteration.saturating_sub(self.cfg.start_at()).max(1);
        self.skin.step(aux, hp, self.cfg.skin_lr, t)
    }

    /// Adam on the knots that this step's view touched.
    pub fn step(&mut self, hp: AdamHyper) {
        let lr = (self.cfg.lr_translation, self.cfg.lr_rotation);
        for ((o, a), g) in self
            .objects
            .iter_mut()
            .zip(&mut self.knot_adam)
            .zip(&self.grads)
        {
            if !o.is_static {
                a.step_touched(&mut o.trajectory, g, hp, lr);
            }
        }
    }

    /// Top-k entries per pixel the training render must record for the votes (0: none).
    pub fn topk(&self) -> usize {
        match &self.membership {
            Some(m) if self.started => m.k,
            _ => 0,
        }
    }

    /// Adds the training view's top-k votes (`ids`/`weights` with `stride` entries a pixel).
    pub fn record_votes(
        &self,
        frame: usize,
        ids: &[u32],
        weights: &[f32],
        stride: usize,
        aux: &mut crate::state::AuxStore,
    ) -> Result<(), String> {
        let Some(m) = self
            .membership
            .as_ref()
            .filter(|_| self.started && stride > 0)
        else {
            return Ok(());
        };
        let votes = aux.get_or_zeros(membership::VOTES_NAME, m.cols())?;
        m.record(ids, weights, stride, &self.id_maps[frame], votes)
    }

    /// The first non-finite knot of a trajectory, named (a few hundred floats: cheap enough
    /// to test every iteration).
    pub fn nonfinite_knot(&self) -> Option<String> {
        self.objects.iter().find_map(|o| {
            let t = &o.trajectory;
            let bad = |k: usize| {
                t.translations[k]
                    .iter()
                    .chain(&t.rotations[k])
                    .any(|x| !x.is_finite())
            };
            (0..t.translations.len()).find(|&k| bad(k)).map(|k| {
                format!(
                    "trajectory of object `{}` (knot {k}, t = {})",
                    o.name, t.times[k]
                )
            })
        })
    }

    /// Moves the Gaussians their votes elect into other objects (at densification).
    pub fn transfer(
        &self,
        state: &mut crate::state::GaussianState,
        at: &membership::StepPlacement,
    ) -> usize {
        match &self.membership {
            Some(m) if self.started => m.transfer(state, &self.objects, at),
            _ => 0,
        }
    }

    /// The name recorded for object `id`.
    pub fn name_of(&self, id: u8) -> String {
        self.names
            .iter()
            .find(|(i, _)| *i == id)
            .map_or_else(|| format!("object-{id}"), |(_, n)| n.clone())
    }
}
