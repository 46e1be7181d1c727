//! Object-ID maps with no ground truth: each object is chosen once (a click, a box, or the
//! automatic mask generator on the first frame) and tracked through every frame in time order
//! with MobileSAM prompts derived from its previous mask, as box-propagation video
//! segmentation does (SAM-PT, DEVA and SAM 2 propagate likewise; we keep no memory bank, only
//! the last mask, the object's displacement and its colours). When the prompt's mask is not
//! plausible (area jump, other colours, low confidence) the object counts as lost in that
//! frame and is searched for again, wider for each frame lost (`tracker.rs`).
//!
//! `sequence.rs` runs it over frames; `scene.rs` over a scene's frames of every split, writing
//! the same `semantics/` layout as per-frame segmentation; `evaluate.rs` scores the result
//! against ground-truth masks when a scene has them.

pub mod auto;
pub mod evaluate;
pub mod region;
pub mod scene;
pub mod seed;
pub mod sequence;
pub mod tracker;

pub use auto::AutoSeeds;
pub use region::Region;
pub use seed::{FrameRef, Seed, SeedShape};
pub use sequence::{track_sequence, ObjectReport, Tracked};
pub use tracker::TrackConfig;

/// Errors of tracking.
#[derive(Debug, thiserror::Error)]
pub enum TrackError {
    /// A prompt that cannot be used, with what is wrong and how to fix it.
    #[error("{0}")]
    Prompt(String),
    #[error(transparent)]
    Sam(#[from] crate::sam::SamError),
}
