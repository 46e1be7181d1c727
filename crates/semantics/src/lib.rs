//! `semantics` (see docs/architecture.md).
pub mod automask;
pub mod clip;
pub mod idmap;
mod pth;
pub mod relevance;
pub mod sam;
pub mod segment;
pub mod track;
