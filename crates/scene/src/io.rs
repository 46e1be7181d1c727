//! Small file helpers: atomic writes (temp file in the target folder, then rename) and
//! JSON reading with errors that name the file.

use crate::SceneError;
use serde::de::DeserializeOwned;
use std::io::Write;
use std::path::Path;

/// Writes `path` atomically: the bytes go to a temporary file beside it which is then
/// renamed over `path`, so a crash never leaves a half-written file under the final name.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), SceneError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| SceneError::io(dir, e))?;
    {
        let mut buf = std::io::BufWriter::new(tmp.as_file_mut());
        write(&mut buf).map_err(|e| SceneError::io(path, e))?;
        buf.flush().map_err(|e| SceneError::io(path, e))?;
    }
    // On disk before the rename, so a power cut cannot leave a renamed but empty file.
    tmp.as_file()
        .sync_all()
        .map_err(|e| SceneError::io(path, e))?;
    tmp.persist(path)
        .map_err(|e| SceneError::io(path, e.error))?;
    Ok(())
}

/// Serializes `value` as pretty JSON into `path`, atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), SceneError> {
    let bytes = serde_json::to_vec_pretty(value).map_err(|e| SceneError::json(path, e))?;
    write_atomic(path, |w| w.write_all(&bytes))
}

/// Reads and parses a JSON file; a syntax or shape error names the file.
pub fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, SceneError> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| SceneError::json(path, e))
}
