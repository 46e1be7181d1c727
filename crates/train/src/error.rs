//! Typed errors of the trainer. Each variant names the file or field involved so that the
//! CLI's message says what to fix.

use std::path::PathBuf;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum TrainError {
    #[error("invalid config value `{field}`: {problem}")]
    Config { field: String, problem: String },
    /// [`TrainError::Config`] of a value read from a file.
    #[error("invalid config value `{field}` in {path}: {problem}")]
    ConfigInFile {
        path: PathBuf,
        field: String,
        problem: String,
    },
    #[error("cannot parse config {path}: {message}")]
    ConfigParse { path: PathBuf, message: String },
    #[error("I/O error on {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("bad PLY file {path}: {problem}")]
    Ply { path: PathBuf, problem: String },
    #[error("bad checkpoint {path}: {problem}")]
    Checkpoint { path: PathBuf, problem: String },
    #[error("{folder} holds no checkpoint of iteration {iteration} (it holds: {held})")]
    NoSuchCheckpoint {
        folder: PathBuf,
        iteration: u32,
        held: String,
    },
    #[error("buffer `{name}` has length {got}, expected {expected}")]
    Length {
        name: &'static str,
        got: usize,
        expected: usize,
    },
    #[error("training diverged at iteration {iteration}: {what} is not finite")]
    NonFinite { iteration: u32, what: String },
    #[error("deformation hook failed: {0}")]
    Hook(String),
    #[error("data set problem: {0}")]
    Data(String),
    #[error("this run has no rigid objects to select from: --only, --without and --per-object need a checkpoint of a run trained with --objects (baseline and SemDynReg (paper) runs store no per-Gaussian objects)")]
    NoObjects,
    #[error("this run has no object `{name}`; its objects (name or ID): {known}, and `background` (the deformable rest)")]
    UnknownObject { name: String, known: String },
    #[error("{0}")]
    EmptySelection(String),
    #[error("rasterizer: {0}")]
    Splat(#[from] splat::SplatError),
}

impl TrainError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        TrainError::Io {
            path: path.into(),
            source,
        }
    }

    /// This error, naming `path` when it is about a config value (the value came from it).
    pub(crate) fn in_config_file(self, path: &std::path::Path) -> Self {
        match self {
            TrainError::Config { field, problem } => TrainError::ConfigInFile {
                path: path.to_path_buf(),
                field,
                problem,
            },
            other => other,
        }
    }

    pub(crate) fn config(field: &str, problem: impl Into<String>) -> Self {
        TrainError::Config {
            field: field.to_string(),
            problem: problem.into(),
        }
    }
}

pub type Result<T> = std::result::Result<T, TrainError>;

/// `scene`'s file helpers (atomic writes) report I/O failures as this crate's own
/// [`TrainError::Io`], naming the file.
impl From<scene::SceneError> for TrainError {
    fn from(e: scene::SceneError) -> Self {
        match e {
            scene::SceneError::Io { path, source } => TrainError::Io { path, source },
            other => TrainError::Data(other.to_string()),
        }
    }
}

/// Checks shared by the config sections' `validate`, each naming the key it refuses.
pub(crate) mod check {
    use super::{Result, TrainError};

    /// Finite and > 0.
    pub fn positive(name: &str, v: f32) -> Result<()> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(TrainError::config(
                name,
                format!("must be finite and > 0, got {v}"),
            ))
        }
    }

    /// Finite and in [0, 1].
    pub fn unit(name: &str, v: f32) -> Result<()> {
        if v.is_finite() && (0.0..=1.0).contains(&v) {
            Ok(())
        } else {
            Err(TrainError::config(
                name,
                format!("must be in [0, 1], got {v}"),
            ))
        }
    }

    /// ≥ 1.
    pub fn at_least_one(name: &str, v: u64) -> Result<()> {
        if v > 0 {
            Ok(())
        } else {
            Err(TrainError::config(name, "must be ≥ 1"))
        }
    }
}
