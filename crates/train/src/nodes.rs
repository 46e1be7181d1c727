//! The scene model's node kinds, registered in [`KINDS`], and the list a run holds.
//! Adding a kind: its module implements [`Node`]; here, a constructor from the config and
//! one entry in [`KINDS`]. The trainer, the renderer and checkpoints go through the list
//! and need no change.

use crate::config::TrainConfig;
use crate::error::Result;
use crate::field_node::FieldNode;
use crate::node::{At, Node, Rows};
use crate::objects::RigidObjects;
use crate::timing::StepTimings;
use rand_chacha::ChaCha8Rng;
use std::ops::{Deref, DerefMut};

/// What a kind's constructor sees.
pub struct NodeInit<'a> {
    pub cfg: &'a TrainConfig,
    /// The training data; None when a checkpoint is opened for rendering.
    pub dataset: Option<&'a scene::Dataset>,
    /// The run's random stream (a throwaway one when the state comes from a checkpoint).
    pub rng: &'a mut ChaCha8Rng,
}

/// A node kind's constructor: its node when the config asks for one.
type Build = fn(&mut NodeInit<'_>) -> Result<Option<Box<dyn Node>>>;

/// Every node kind, in placement order: the deformation field's first (it adds δ to the
/// rest placement of every row it owns), then kinds that overwrite their own rows.
const KINDS: [Build; 2] = [field, rigid_objects];

/// Every run has the deformation field's node.
fn field(init: &mut NodeInit<'_>) -> Result<Option<Box<dyn Node>>> {
    let c = init.cfg;
    Ok(Some(Box::new(FieldNode::new(&c.field, &c.lr, init.rng))))
}

/// The rigid objects' node, when `[objects] enabled`.
fn rigid_objects(init: &mut NodeInit<'_>) -> Result<Option<Box<dyn Node>>> {
    let c = &init.cfg.objects;
    let Some(mut node) = RigidObjects::for_run(c, init.dataset, init.cfg.iterations)? else {
        return Ok(None);
    };
    if c.residual {
        let field = crate::objects::residual::field_config(c.residual_depth, c.residual_width);
        let l = &init.cfg.lr;
        let lr = (l.field_init, l.field_final, l.field_max_steps);
        node.residual = Some(crate::objects::residual::Residual::new(field, lr));
    }
    Ok(Some(Box::new(node)))
}

/// The nodes of a run or of a loaded checkpoint, in [`KINDS`] order.
pub struct Nodes(Vec<Box<dyn Node>>);

impl Nodes {
    /// Every kind the config asks for.
    pub fn build(mut init: NodeInit<'_>) -> Result<Self> {
        let mut list = Vec::new();
        for kind in KINDS {
            list.extend(kind(&mut init)?);
        }
        Ok(Self(list))
    }

    /// The node of kind `T`, if the run has one.
    pub fn get<T: Node>(&self) -> Option<&T> {
        self.0.iter().find_map(|n| n.as_any().downcast_ref())
    }

    pub fn get_mut<T: Node>(&mut self) -> Option<&mut T> {
        self.0
            .iter_mut()
            .find_map(|n| n.as_any_mut().downcast_mut())
    }

    /// Places every row at `at` ([`crate::node::place`]).
    pub fn place(
        &mut self,
        rows: Rows<'_>,
        at: &At<'_>,
        out: &mut crate::deform::Deformed,
        tm: &mut StepTimings,
    ) {
        crate::node::place(&mut self.0, rows, at, out, tm);
    }

    /// The first non-finite value of any node's own parameters, named.
    pub fn nonfinite(&self) -> Option<String> {
        self.0.iter().find_map(|n| n.nonfinite())
    }

    /// Whether some node owns the rows of object ID `id`.
    pub fn owns(&self, id: u8) -> bool {
        self.0.iter().any(|n| n.owns(id))
    }
}

impl Deref for Nodes {
    type Target = [Box<dyn Node>];

    fn deref(&self) -> &Self::Target {
        &self.0
    }
}

impl DerefMut for Nodes {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut self.0
    }
}
