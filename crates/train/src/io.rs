//! File access for checkpoints and run folders, errors naming the file. Atomic writes are
//! `scene`'s one implementation ([`scene::io::write_atomic`]: a temporary file beside the
//! target, synced, then renamed, so a crash or Ctrl-C never leaves a half-written file
//! under the final name).

use crate::error::{Result, TrainError};
use std::path::Path;

/// Writes `bytes` to `path` atomically ([`scene::io::write_atomic`]: a temporary file
/// beside it, synced, then renamed).
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(scene::io::write_atomic(path, |w| w.write_all(bytes))?)
}

/// Reads a whole file, naming it on failure.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| TrainError::io(path, e))
}

/// Creates a folder and its parents, naming it on failure.
pub(crate) fn create_dir_all(path: &Path) -> Result<()> {
    std::fs::create_dir_all(path).map_err(|e| TrainError::io(path, e))
}
