//! CLIP image and text towers for dictionary matching (paper Sec. 3.1, docs/architecture.md
//! item 2), inference only, on candle.
//!
//! Supported checkpoints: OpenCLIP ViT models (the paper's ViT-B/16 laion2b,
//! `open_clip_model.safetensors` / `open_clip_pytorch_model.bin`) and OpenAI ViT models in the
//! Hugging Face `CLIPModel` layout (`model.safetensors` of `openai/clip-vit-base-patch32`).
//! See [`config`] for how the architecture and activation are chosen.

pub mod config;
mod encode;
pub mod model;
pub mod preprocess;
mod resize;
mod text;
pub mod tokenizer;
mod tower;
mod vision;
mod weights;

use std::path::PathBuf;

use thiserror::Error;

pub use config::{Activation, ClipConfig, TextConfig, VisionConfig};
pub use encode::MASK_BATCH;
pub use model::{ClipModel, LoadOptions};
pub use preprocess::{batch_pixels, masked_crop, CLIP_MEAN, CLIP_STD};
pub use tokenizer::{Tokenizer, CONTEXT_LENGTH};
pub use weights::Layout;

/// Where users get CLIP weights; printed when a file is missing.
pub const WEIGHTS_HELP: &str =
    "the paper's model is OpenCLIP ViT-B-16 (laion2b_s34b_b88k): download \
`open_clip_model.safetensors` (and `open_clip_config.json`) from the Hugging Face repository \
`laion/CLIP-ViT-B-16-laion2B-s34B-b88K`; OpenAI ViT-B/32 works too: `model.safetensors` and \
`config.json` of `openai/clip-vit-base-patch32`. Without CLIP weights use `--labels gt`.";

/// Errors of loading and running CLIP.
#[derive(Debug, Error)]
pub enum ClipError {
    #[error("CLIP weights not found at {path}: {WEIGHTS_HELP}")]
    MissingWeights { path: PathBuf },
    #[error("cannot read CLIP weights {path}: {source}")]
    ReadWeights {
        path: PathBuf,
        #[source]
        source: candle_core::Error,
    },
    #[error("cannot read CLIP config {path}: {reason}")]
    Config { path: PathBuf, reason: String },
    #[error("CLIP weights {path}: {reason}")]
    Layout { path: PathBuf, reason: String },
    #[error("CLIP tokenizer: {0}")]
    Tokenizer(String),
    #[error("CLIP input: {0}")]
    Input(String),
    #[error("CLIP computation failed: {0}")]
    Candle(#[from] candle_core::Error),
}
