//! Segment Anything (SAM / MobileSAM) for automatic mask generation on the CPU.
//!
//! The image encoders are our TinyViT for MobileSAM (`tiny_vit.rs`: candle's, with the exact erf
//! GELU, vectorized and multi-threaded) and, with the cargo feature `sam-vit`,
//! candle-transformers' ViT-B/L/H (left out by default: that crate alone is ~225 s of CPU in
//! every optimized build, docs/performance.md "Build time"); the prompt
//! encoder and mask decoder are re-implemented here on plain f32 buffers (see `decoder.rs` for
//! why), loading the same checkpoint keys as the official `segment_anything` code.

pub mod conv_bn;
pub mod decoder;
pub mod dense;
pub mod elementwise;
pub mod kernels;
pub mod layers;
pub mod model;
pub mod norm;
pub mod predict;
pub mod prompt;
pub mod resize;
pub mod tensor_ops;
pub mod tiny_vit;

pub use decoder::{ImageContext, MaskDecoder, Outputs, PromptMasks, Scratch};
pub use model::{Backbone, ImageEmbedding, Sam, MOBILE_SAM_HINT};
pub use predict::{Prediction, Predictor};
pub use prompt::Prompt;

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

/// Sets `RAYON_NUM_THREADS` (when unset) to this machine's available parallelism, the count
/// rayon uses by default anyway. Why: candle-core looks its thread count up on every
/// matrix product (`utils::get_num_threads`), and without that variable it asks `num_cpus`,
/// which reads files under `/proc` (and, in some candle versions, all of `/proc/cpuinfo`) each
/// time: up to ~11% of the MobileSAM encoder's samples in `perf`. With the variable set,
/// candle uses that count, as does rayon's global pool.
///
/// # Safety
/// Writes the process environment: call at program start, while no other thread can read or
/// write it (`std::env::set_var`).
pub unsafe fn set_thread_count_env() {
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        let n = std::thread::available_parallelism().map_or(1, |n| n.get());
        // SAFETY: the caller guarantees no concurrent environment access (see above).
        unsafe { std::env::set_var("RAYON_NUM_THREADS", n.to_string()) };
    }
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
