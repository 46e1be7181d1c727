//! Segment Anything (SAM / MobileSAM) for automatic mask generation on the CPU.
//!
//! The image encoders (TinyViT for MobileSAM, ViT-B/L/H) are candle-transformers'; the prompt
//! encoder and mask decoder are re-implemented here on plain f32 buffers (see `decoder.rs` for
//! why), loading the same checkpoint keys as the official `segment_anything` code.

pub mod decoder;
pub mod kernels;
pub mod layers;
pub mod model;
pub mod prompt;
pub mod resize;

pub use decoder::{ImageContext, MaskDecoder, PromptMasks, Scratch};
pub use model::{Backbone, ImageEmbedding, Sam, MOBILE_SAM_HINT};

use std::path::PathBuf;

/// Errors from loading or running SAM.
#[derive(Debug, thiserror::Error)]
pub enum SamError {
    #[error("SAM checkpoint {path} not found. {hint}")]
    MissingWeights { path: PathBuf, hint: String },
    #[error("cannot load SAM checkpoint {path}: {source}")]
    Load {
        path: PathBuf,
        source: candle_core::Error,
    },
    #[error("SAM: {0}")]
    Candle(#[from] candle_core::Error),
    #[error("SAM input: {0}")]
    Input(String),
}

/// The weights folder: `$SEMDYNREG_WEIGHTS`, else `./weights`.
pub fn weights_dir() -> PathBuf {
    std::env::var_os("SEMDYNREG_WEIGHTS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("weights"))
}

/// The default checkpoint, `<weights_dir>/mobile_sam.pt`.
pub fn default_checkpoint() -> PathBuf {
    weights_dir().join("mobile_sam.pt")
}
