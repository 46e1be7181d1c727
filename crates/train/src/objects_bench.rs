//! The objects benchmark's runner: a training run on a generated scene up to the rigid
//! objects' start, scored against the scene's ground truth (`objects::truth`). Used by
//! `examples/objects_bench.rs` and `tests/objects_bench.rs` (docs/objects.md).

use crate::error::{Result, TrainError};
use crate::objects::{truth, RigidObjects};
use crate::{TrainConfig, Trainer};
use scene::objects::ObjectsFile;
use std::path::Path;

/// Trains `cfg` with rigid objects on the toycars scene in `dir` (its `semantics/` ID maps,
/// `objects.json`), black background, up to the objects' start, and scores what the start
/// made of each object.
pub fn start_and_score(
    dir: &Path,
    mut cfg: TrainConfig,
    seed: u64,
) -> Result<Vec<truth::ObjectScore>> {
    let data = |e: scene::SceneError| TrainError::Data(e.to_string());
    cfg.objects.enabled = true;
    cfg.validate()?;
    let ds = scene::load_dataset(dir, &scene::LoadOptions::default()).map_err(data)?;
    let truth = ObjectsFile::load(&dir.join("objects.json")).map_err(data)?;
    let mut tr = Trainer::new(cfg, ds, seed)?;
    loop {
        tr.step()?;
        let node = tr
            .nodes
            .get::<RigidObjects>()
            .ok_or_else(|| TrainError::Data("the run has no rigid-objects node".into()))?;
        if node.started {
            return Ok(truth::score(node, &tr.state, &tr.dataset, &truth));
        }
    }
}
