//! A run folder: `run.json` says which scene (and how it was loaded) the run trains on, so
//! `render`, `eval`, `export` and `--resume` need only the folder.

use crate::error::{Result, TrainError};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub const RUN_FILE: &str = "run.json";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunInfo {
    /// Scene folder, absolute.
    pub scene: PathBuf,
    pub downscale: u32,
    pub background: [f32; 3],
    pub seed: u64,
}

impl RunInfo {
    pub fn save(&self, run: &Path) -> Result<()> {
        crate::io::create_dir_all(run)?;
        let text = serde_json::to_string_pretty(self).expect("plain data serializes");
        crate::io::write_atomic(&run.join(RUN_FILE), text.as_bytes())
    }

    pub fn load(run: &Path) -> Result<Self> {
        let p = run.join(RUN_FILE);
        let text = std::fs::read_to_string(&p).map_err(|e| TrainError::io(&p, e))?;
        serde_json::from_str(&text).map_err(|e| TrainError::Checkpoint {
            path: p,
            problem: e.to_string(),
        })
    }

    /// Loads the scene the way the run was trained on it.
    pub fn dataset(&self) -> Result<scene::Dataset> {
        let opts = scene::LoadOptions {
            background: self.background,
            downscale: self.downscale,
        };
        scene::load_dataset(&self.scene, &opts).map_err(|e| TrainError::Data(e.to_string()))
    }
}
