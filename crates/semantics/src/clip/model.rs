//! A loaded CLIP model: both towers, the tokenizer, and normalized encoders.

use std::path::{Path, PathBuf};

use candle_core::Tensor;

use super::config::{Activation, ClipConfig};
use super::text::TextTower;
use super::tokenizer::Tokenizer;
use super::tower::l2_normalize;
use super::vision::VisionTower;
use super::weights::{Layout, Weights};
use super::ClipError;

/// How to load a checkpoint; all optional.
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// Model config JSON. Default: `open_clip_config.json`, else `config.json`, beside the
    /// weights; else the shapes are inferred from the weights.
    pub config: Option<PathBuf>,
    /// Forces the MLP activation (see [`super::config`] for the default rules).
    pub activation: Option<Activation>,
}

/// CLIP ViT image and text towers.
pub struct ClipModel {
    pub config: ClipConfig,
    pub layout: Layout,
    vision: VisionTower,
    text: TextTower,
    tokenizer: Tokenizer,
}

fn sibling_config(weights: &Path) -> Option<PathBuf> {
    let dir = weights.parent()?;
    ["open_clip_config.json", "config.json"]
        .iter()
        .map(|n| dir.join(n))
        .find(|p| p.is_file())
}

impl ClipModel {
    /// A model of the given architecture with random weights (seeded), for speed
    /// measurements where no checkpoint is at hand.
    pub fn random(config: &ClipConfig, seed: u64) -> Result<Self, ClipError> {
        let w = Weights::random(config, seed)?;
        Self::build(&w, config.clone())
    }

    fn build(w: &Weights, config: ClipConfig) -> Result<Self, ClipError> {
        let act = config.activation();
        Ok(Self {
            vision: VisionTower::load(w, &config.vision, config.embed_dim, act)?,
            text: TextTower::load(w, &config.text, config.embed_dim, act)?,
            tokenizer: Tokenizer::new()?,
            layout: w.layout,
            config,
        })
    }

    /// Loads `weights` (see [`super::weights::Weights::load`] for the formats).
    pub fn load(weights: &Path, options: &LoadOptions) -> Result<Self, ClipError> {
        // A candle error while reading or assembling the towers (a dtype that does not
        // convert, shapes that do not reshape) is about the weights file: say which.
        Self::load_named(weights, options).map_err(|e| match e {
            ClipError::Candle(source) => ClipError::ReadWeights {
                path: weights.to_path_buf(),
                source,
            },
            other => other,
        })
    }

    fn load_named(weights: &Path, options: &LoadOptions) -> Result<Self, ClipError> {
        let w = Weights::load(weights)?;
        let config_path = options.config.clone().or_else(|| sibling_config(weights));
        let mut config = match &config_path {
            Some(p) => ClipConfig::from_json_file(p)?,
            None => {
                let c = w.infer_config()?;
                c.validate().map_err(|reason| ClipError::Layout {
                    path: weights.to_path_buf(),
                    reason: format!("inferred architecture: {reason}"),
                })?;
                c
            }
        };
        let layout_default = match w.layout {
            Layout::HuggingFace => Activation::QuickGelu,
            Layout::OpenClip => Activation::Gelu,
        };
        let activation = options
            .activation
            .or(config.activation)
            .unwrap_or(layout_default);
        config.activation = Some(activation);
        tracing::info!(
            weights = %weights.display(),
            config = ?config_path,
            layout = ?w.layout,
            ?activation,
            "CLIP ViT-{}/{} ({} px), text width {}",
            config.vision.layers,
            config.vision.patch_size,
            config.vision.image_size,
            config.text.width
        );
        Self::build(&w, config)
    }

    /// Side length of the square images the vision tower takes.
    pub fn image_size(&self) -> usize {
        self.config.vision.image_size
    }

    /// The CLIP BPE tokenizer.
    pub fn tokenizer(&self) -> &Tokenizer {
        &self.tokenizer
    }

    /// Raw image features `(batch, embed_dim)` of preprocessed `(batch, 3, S, S)` pixels.
    pub fn image_features(&self, pixels: &Tensor) -> Result<Tensor, ClipError> {
        self.vision.forward(pixels)
    }

    /// Raw text features `(batch, embed_dim)` of token rows (`context_length` ids each).
    pub fn text_features(&self, ids: &[Vec<u32>]) -> Result<Tensor, ClipError> {
        self.text.forward(ids)
    }

    /// L2-normalized image embeddings, one `Vec` per image.
    pub fn encode_images(&self, pixels: &Tensor) -> Result<Vec<Vec<f32>>, ClipError> {
        Ok(l2_normalize(&self.vision.forward(pixels)?)?.to_vec2()?)
    }

    /// L2-normalized text embeddings, one per text.
    pub fn encode_texts(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, ClipError> {
        if texts.is_empty() {
            return Ok(Vec::new());
        }
        let n = self.config.text.context_length;
        let ids: Vec<Vec<u32>> = texts
            .iter()
            .map(|t| self.tokenizer.tokenize(t, n))
            .collect();
        Ok(l2_normalize(&self.text.forward(&ids)?)?.to_vec2()?)
    }
}
