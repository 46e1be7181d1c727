//! The text tower (OpenCLIP `CLIP.encode_text`): token + positional embeddings, causal
//! transformer, `ln_final`, the feature at the end-of-text token (the argmax id,
//! `pool_type='argmax'`), `@ text_projection`.

use candle_core::{Device, Module, Tensor};
use candle_nn::LayerNorm;

use super::config::{Activation, TextConfig};
use super::tower::{layer_norm, Transformer};
use super::weights::Weights;
use super::ClipError;

pub struct TextTower {
    cfg: TextConfig,
    token_embedding: Tensor,
    positional_embedding: Tensor,
    transformer: Transformer,
    ln_final: LayerNorm,
    projection: Tensor,
    causal_mask: Tensor,
}

/// Additive mask: `-inf` above the diagonal (`build_causal_mask`).
fn causal_mask(n: usize) -> Result<Tensor, ClipError> {
    let data: Vec<f32> = (0..n * n)
        .map(|k| {
            if k % n > k / n {
                f32::NEG_INFINITY
            } else {
                0.0
            }
        })
        .collect();
    Ok(Tensor::from_vec(data, (n, n), &Device::Cpu)?)
}

impl TextTower {
    pub fn load(
        w: &Weights,
        cfg: &TextConfig,
        embed_dim: usize,
        act: Activation,
    ) -> Result<Self, ClipError> {
        let width = cfg.width;
        Ok(Self {
            token_embedding: w.get("token_embedding.weight", &[cfg.vocab_size, width])?,
            positional_embedding: w.get("positional_embedding", &[cfg.context_length, width])?,
            transformer: Transformer::load(
                w,
                "transformer",
                (width, cfg.layers, cfg.heads, cfg.mlp_width),
                act,
            )?,
            ln_final: layer_norm(w, "ln_final", width)?,
            projection: w.get("text_projection", &[width, embed_dim])?,
            causal_mask: causal_mask(cfg.context_length)?,
            cfg: cfg.clone(),
        })
    }

    /// `ids`: one row of `context_length` token ids per text. Returns `(batch, embed_dim)`
    /// unnormalized features.
    pub fn forward(&self, ids: &[Vec<u32>]) -> Result<Tensor, ClipError> {
        let n = self.cfg.context_length;
        let mut flat = Vec::with_capacity(ids.len() * n);
        let mut eot = Vec::with_capacity(ids.len());
        for row in ids {
            if row.len() != n || row.iter().any(|&t| t as usize >= self.cfg.vocab_size) {
                return Err(ClipError::Input(format!(
                    "token row must have {n} ids below {}",
                    self.cfg.vocab_size
                )));
            }
            // First maximum, as torch.argmax.
            let pos = row
                .iter()
                .enumerate()
                .fold(0, |best, (i, &t)| if t > row[best] { i } else { best });
            eot.push((flat.len() + pos) as u32);
            flat.extend_from_slice(row);
        }
        let b = ids.len();
        let flat = Tensor::from_vec(flat, b * n, &Device::Cpu)?;
        let x = self
            .token_embedding
            .embedding(&flat)?
            .reshape((b, n, self.cfg.width))?;
        let x = x.broadcast_add(&self.positional_embedding)?;
        let x = self.transformer.forward(&x, Some(&self.causal_mask))?;
        let x = x
            .reshape((b * n, self.cfg.width))?
            .index_select(&Tensor::new(eot, &Device::Cpu)?, 0)?;
        Ok(self.ln_final.forward(&x)?.matmul(&self.projection)?)
    }
}
