//! The ViT image tower (OpenCLIP `VisionTransformer`, `pool_type='tok'`): patchify
//! (`conv1`, no bias), prepend the class token, add positions, `ln_pre`, transformer,
//! `ln_post` on the class token, `@ proj`.

use candle_core::{Module, Tensor};
use candle_nn::LayerNorm;

use super::config::{Activation, VisionConfig};
use super::tower::{layer_norm, Transformer};
use super::weights::Weights;
use super::ClipError;

pub struct VisionTower {
    cfg: VisionConfig,
    /// `conv1.weight` reshaped to `(3·p·p, width)`: the stride-p convolution is a matmul
    /// over non-overlapping patches.
    patch_proj: Tensor,
    class_embedding: Tensor,
    positional_embedding: Tensor,
    ln_pre: LayerNorm,
    transformer: Transformer,
    ln_post: LayerNorm,
    proj: Tensor,
}

impl VisionTower {
    pub fn load(
        w: &Weights,
        cfg: &VisionConfig,
        embed_dim: usize,
        act: Activation,
    ) -> Result<Self, ClipError> {
        let (p, width) = (cfg.patch_size, cfg.width);
        if p == 0 || !cfg.image_size.is_multiple_of(p) {
            let reason = format!(
                "image size {} is not a multiple of patch size {p}",
                cfg.image_size
            );
            return Err(ClipError::Layout {
                path: w.path.clone(),
                reason,
            });
        }
        let grid = cfg.image_size / p;
        let conv = w.get("visual.conv1.weight", &[width, 3, p, p])?;
        Ok(Self {
            patch_proj: conv.reshape((width, 3 * p * p))?.t()?.contiguous()?,
            class_embedding: w
                .get("visual.class_embedding", &[width])?
                .reshape((1, 1, width))?,
            positional_embedding: w
                .get("visual.positional_embedding", &[grid * grid + 1, width])?,
            ln_pre: layer_norm(w, "visual.ln_pre", width)?,
            transformer: Transformer::load(
                w,
                "visual.transformer",
                (width, cfg.layers, cfg.heads, cfg.mlp_width),
                act,
            )?,
            ln_post: layer_norm(w, "visual.ln_post", width)?,
            proj: w.get("visual.proj", &[width, embed_dim])?,
            cfg: cfg.clone(),
        })
    }

    /// `pixels`: `(batch, 3, S, S)` normalized, `S = image_size`. Returns `(batch, embed_dim)`
    /// unnormalized features.
    pub fn forward(&self, pixels: &Tensor) -> Result<Tensor, ClipError> {
        let (b, c, h, w) = pixels.dims4()?;
        let s = self.cfg.image_size;
        if (c, h, w) != (3, s, s) {
            return Err(ClipError::Input(format!(
                "image batch has shape {:?}, the model expects (_, 3, {s}, {s})",
                pixels.dims()
            )));
        }
        let p = self.cfg.patch_size;
        let g = s / p;
        // (b, 3, g, p, g, p) → (b, g, g, 3, p, p): one row per patch, in conv1's (c, kh, kw) order.
        let patches = pixels
            .reshape((b, 3, g, p, g, p))?
            .permute((0, 2, 4, 1, 3, 5))?
            .reshape((b * g * g, 3 * p * p))?;
        let tokens = patches
            .matmul(&self.patch_proj)?
            .reshape((b, g * g, self.cfg.width))?;
        let cls = self.class_embedding.broadcast_as((b, 1, self.cfg.width))?;
        let x = Tensor::cat(&[&cls, &tokens], 1)?.broadcast_add(&self.positional_embedding)?;
        let x = self.transformer.forward(&self.ln_pre.forward(&x)?, None)?;
        let pooled = self.ln_post.forward(&x.narrow(1, 0, 1)?.squeeze(1)?)?;
        Ok(pooled.matmul(&self.proj)?)
    }
}
