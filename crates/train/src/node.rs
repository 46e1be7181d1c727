//! The scene model's node interface. Every Gaussian lives in one row-aligned store
//! ([`GaussianState`]: parameters, Adam moments, densification statistics, hook rows and the
//! object column); the column says which node owns a row. A node owns its rows' motion
//! model, the parameters and optimizer state beside the store (a network's weights, pose
//! tracks), its losses and its rules at densification, and yields its rows as world-space
//! Gaussians at time t. The trainer composes the nodes ([`place`]: every row at rest, then
//! each node over its own rows), makes one rasterizer call, and hands each node the
//! gradients back; it has no branch on a node's kind. drivestudio's scene graph
//! (OmniRe, `models/trainers/scene_graph.py`) organises its nodes the same way.
//!
//! One training iteration, in the order `Trainer::step` calls the hooks:
//! [`Node::begin_step`] (milestones) → [`Node::topk`] → [`place`] → rasterizer forward →
//! loss → [`Node::after_render`] → the trainer's [`crate::hook::DeformHook`] on
//! [`Node::deformation`] → rasterizer backward → [`Node::add_loss`] →
//! [`crate::deform::backward`] (every row at rest) → [`Node::backward`] → Adam on the store
//! and [`Node::step`] → [`Node::mark_unplaced`] and [`Node::before_refine`] → the density
//! control strategy on the store.

use crate::adam::AdamHyper;
use crate::deform::{CanonicalGrads, Deformed};
use crate::error::{Result, TrainError};
use crate::field::DeformOutput;
use crate::model::GaussianModel;
use crate::state::{AuxRows, AuxStore, GaussianState};
use crate::timing::StepTimings;
use rand_chacha::ChaCha8Rng;
use splat::{Camera, Gradients};
use std::any::Any;
use std::path::PathBuf;

/// The store as the nodes see it: parameters, the object column and the per-Gaussian
/// rows nodes and hooks keep beside them ([`AuxRows`], e.g. skinning weights).
#[derive(Clone, Copy)]
pub struct Rows<'a> {
    pub model: &'a GaussianModel,
    pub column: &'a [u8],
    pub aux: &'a [AuxRows],
}

/// Where and when the nodes place their rows.
#[derive(Clone, Copy)]
pub struct At<'a> {
    /// Time t ∈ [0, 1].
    pub time: f32,
    /// The view, when there is one: a node may leave rows that cannot reach it at rest
    /// (the field's `visible_only`). None: every row is placed.
    pub camera: Option<&'a Camera>,
    /// The iteration being trained (1-based), or a checkpoint's completed iterations:
    /// schedules such as the field's warm-up read it.
    pub iteration: u32,
}

/// What [`Node::begin_step`] may touch: the store, the data, the run's random stream, and
/// the nodes registered before this one (to place the rest of the scene, [`place`]).
pub struct Milestone<'a> {
    pub iteration: u32,
    pub state: &'a mut GaussianState,
    pub dataset: &'a scene::Dataset,
    pub rng: &'a mut ChaCha8Rng,
    pub earlier: &'a mut [Box<dyn Node>],
}

/// The training render, as [`Node::after_render`] sees it.
pub struct Rendered<'a> {
    pub iteration: u32,
    /// Index of the view in `dataset.train`.
    pub frame: usize,
    /// Per-pixel top-k (`H·W·topk`), as large as the largest [`Node::topk`] asked.
    pub topk: usize,
    pub topk_ids: &'a [u32],
    pub topk_weights: &'a [f32],
    /// `dL/dimage` of the photometric loss, which a node may mask.
    pub dl_dimage: &'a mut [f32],
}

/// A node's deformation δ, for a [`crate::hook::DeformHook`]: this step's δ, the rows it
/// was evaluated on, and where the hook's `dL/dδ` goes (zeroed at placement).
pub struct Deformation<'a> {
    pub active: bool,
    pub delta: &'a DeformOutput,
    pub rows: &'a [u32],
    pub grad: &'a mut DeformOutput,
}

/// The placed scene of a training step, for image-space losses of a node.
pub struct Placed<'a> {
    pub iteration: u32,
    pub frame: usize,
    pub camera: &'a Camera,
    pub time: f32,
    pub model: &'a GaussianModel,
    pub deformed: &'a Deformed,
}

/// This step's placement at a densification step, for a node's rule before it.
pub struct Refining<'a> {
    pub iteration: u32,
    pub time: f32,
    pub deformed: &'a Deformed,
    /// Whether each row was placed at `time` (false: left at rest, [`Node::mark_unplaced`]).
    pub placed: &'a [bool],
}

/// Receives a node's checkpoint section: f32 tensors and metadata strings, by name.
pub trait SectionWriter {
    fn tensor(&mut self, name: String, shape: Vec<usize>, values: &[f32]);
    fn meta(&mut self, key: &str, value: String);
}

/// Reads a node's checkpoint section back.
pub trait SectionReader {
    /// An f32 tensor of `len` values, all finite; an error names it otherwise.
    fn f32s(&self, name: &str, len: usize) -> Result<Vec<f32>>;
    /// The number of values tensor `name` holds (None: absent).
    fn len_of(&self, name: &str) -> Option<usize>;
    fn meta(&self, key: &str) -> Option<&str>;
    /// An error about this checkpoint's state file.
    fn problem(&self, what: String) -> TrainError;
    /// The checkpoint's config file, for messages where either file may be the wrong one.
    fn config_file(&self) -> PathBuf;
}

/// One kind of content of the scene (see the module docs). The defaults do nothing, so a
/// kind implements what it has.
pub trait Node: Any + Send + Sync {
    /// Short name, for logs and errors.
    fn kind(&self) -> &'static str;

    /// Whether rows with this object ID (the store's column) belong to this node.
    fn owns(&self, id: u8) -> bool;

    /// Work at the start of an iteration, before anything is placed (milestones that add
    /// rows to the store or change them).
    fn begin_step(&mut self, _m: Milestone<'_>) -> Result<()> {
        Ok(())
    }

    /// Per-pixel top-k entries the training render must record for this node (0: none).
    fn topk(&self) -> usize {
        0
    }

    /// Writes this node's rows of `out`, which holds every row at rest
    /// ([`crate::deform::rest`]), placed at `at`.
    fn place(&mut self, rows: Rows<'_>, at: &At<'_>, out: &mut Deformed, tm: &mut StepTimings);

    /// Reads the training render (top-k, `dL/dimage`) after the photometric loss.
    fn after_render(&mut self, _r: Rendered<'_>, _aux: &mut AuxStore) -> Result<()> {
        Ok(())
    }

    /// The node's δ, when its motion is a deformation a hook may regularize.
    fn deformation(&mut self) -> Option<Deformation<'_>> {
        None
    }

    /// Adds the node's own image-space loss terms' gradients into the rasterizer's
    /// world-space `grads`; returns their loss.
    fn add_loss(
        &mut self,
        _at: &Placed<'_>,
        _grads: &mut Gradients,
        _tm: &mut StepTimings,
    ) -> Result<f32> {
        Ok(0.0)
    }

    /// Chains `grads` (world space) back through this node's placement of its rows:
    /// overwrites `canon` on rows it did not place at rest and collects the gradients of
    /// its own parameters.
    fn backward(
        &mut self,
        rows: Rows<'_>,
        grads: &Gradients,
        canon: &mut CanonicalGrads,
        tm: &mut StepTimings,
    );

    /// Adam on the node's own parameters at iteration `iteration` (including those it keeps
    /// in the store's per-Gaussian rows, `aux`); whether every value written is finite.
    fn step(&mut self, iteration: u32, hp: AdamHyper, aux: &mut AuxStore<'_>) -> bool;

    /// Clears `placed[i]` for this node's rows that this step's placement left at rest
    /// (rows culled from the view): their placed geometry is not where they draw.
    fn mark_unplaced(&self, _column: &[u8], _placed: &mut [bool]) {}

    /// The node's rule at a densification step, before the strategy refines the store
    /// (rows changing owner, say).
    fn before_refine(&self, _state: &mut GaussianState, _step: &Refining<'_>) {}

    /// The first non-finite value of the node's own parameters or optimizer state, named.
    fn nonfinite(&self) -> Option<String>;

    /// The node's checkpoint section.
    fn save(&self, out: &mut dyn SectionWriter);

    /// Reads what rendering needs back from a checkpoint section.
    fn load(&mut self, sec: &dyn SectionReader) -> Result<()>;

    /// Reads what resuming training adds (optimizer state).
    fn load_optimizer(&mut self, _sec: &dyn SectionReader) -> Result<()> {
        Ok(())
    }

    fn as_any(&self) -> &dyn Any;
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

/// Every row of `state` placed by `nodes` at `time`, for every view (no camera): what a
/// milestone reads of the scene the nodes before it make (the objects' regauge and their
/// take-over from the field).
pub fn place_state(
    nodes: &mut [Box<dyn Node>],
    state: &GaussianState,
    (time, iteration): (f32, u32),
    out: &mut Deformed,
) {
    let rows = Rows {
        model: &state.model,
        column: &state.object,
        aux: &state.aux,
    };
    let at = At {
        time,
        camera: None,
        iteration,
    };
    place(nodes, rows, &at, out, &mut StepTimings::default());
}

/// Places the scene: every row at rest, then each node over its rows, in order.
pub fn place(
    nodes: &mut [Box<dyn Node>],
    rows: Rows<'_>,
    at: &At<'_>,
    out: &mut Deformed,
    tm: &mut StepTimings,
) {
    let t0 = std::time::Instant::now();
    crate::deform::rest(rows.model, out);
    tm.record(crate::timing::Phase::Deform, t0);
    for n in nodes {
        n.place(rows, at, out, tm);
    }
}
