//! Where the rasterizer reference cases live: `crates/splat/tests/fixtures/reference/cases`
//! (their README says what they are and where they come from; FORMAT.md their keys).
//!
//! The one place that names the folder: splat's tests and examples reach it through
//! `common`, the CLI's `render_case` test includes this file with `#[path]`. The path is
//! built from the including crate's manifest folder, which is `crates/<name>` for every
//! crate of the workspace, so `../splat` is this crate from any of them.

use std::path::PathBuf;

/// The reference cases folder (`NN_name.npz`, `NN_name.expected.npz`, `oracle_meta.json`).
pub fn cases_dir() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../splat/tests/fixtures/reference/cases"
    ))
}
