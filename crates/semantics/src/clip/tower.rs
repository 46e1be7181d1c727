//! The pre-norm residual transformer shared by both CLIP towers: OpenCLIP's
//! `ResidualAttentionBlock` (`x + attn(ln_1(x))`, then `x + mlp(ln_2(x))`) with PyTorch's
//! `nn.MultiheadAttention` (packed `in_proj`, scale `1/√head_dim` on the queries).

use candle_core::{Module, Tensor, D};
use candle_nn::LayerNorm;

use crate::sam::dense::{Dense, Then};

use super::config::Activation;
use super::weights::Weights;
use super::ClipError;

/// PyTorch `nn.LayerNorm`'s default epsilon, used by every CLIP checkpoint.
const LN_EPS: f64 = 1e-5;

/// `nn.LayerNorm(width)` named `prefix`.
pub fn layer_norm(w: &Weights, prefix: &str, width: usize) -> Result<LayerNorm, ClipError> {
    Ok(LayerNorm::new(
        w.get(&format!("{prefix}.weight"), &[width])?,
        w.get(&format!("{prefix}.bias"), &[width])?,
        LN_EPS,
    ))
}

/// `nn.Linear(inp, out)` named `prefix`, run as one multi-threaded pass with its bias (and
/// GELU or residual where the block has one; `sam/dense.rs`).
fn linear(w: &Weights, prefix: &str, out: usize, inp: usize) -> Result<Dense, ClipError> {
    Ok(Dense::from_tensors(
        &w.get(&format!("{prefix}.weight"), &[out, inp])?,
        &w.get(&format!("{prefix}.bias"), &[out])?,
    )?)
}

struct Block {
    ln_1: LayerNorm,
    in_proj: Dense,
    out_proj: Dense,
    ln_2: LayerNorm,
    c_fc: Dense,
    c_proj: Dense,
}

/// A stack of residual attention blocks.
pub struct Transformer {
    blocks: Vec<Block>,
    width: usize,
    heads: usize,
    activation: Activation,
}

impl Transformer {
    /// Reads `{prefix}.resblocks.{0..layers}`.
    pub fn load(
        w: &Weights,
        prefix: &str,
        (width, layers, heads, mlp_width): (usize, usize, usize, usize),
        activation: Activation,
    ) -> Result<Self, ClipError> {
        if heads == 0 || width % heads != 0 {
            return Err(ClipError::Layout {
                path: w.path.clone(),
                reason: format!("{prefix}: width {width} is not divisible by {heads} heads"),
            });
        }
        let blocks = (0..layers)
            .map(|i| {
                let p = format!("{prefix}.resblocks.{i}");
                Ok(Block {
                    ln_1: layer_norm(w, &format!("{p}.ln_1"), width)?,
                    in_proj: Dense::from_tensors(
                        &w.get(&format!("{p}.attn.in_proj_weight"), &[3 * width, width])?,
                        &w.get(&format!("{p}.attn.in_proj_bias"), &[3 * width])?,
                    )?,
                    out_proj: linear(w, &format!("{p}.attn.out_proj"), width, width)?,
                    ln_2: layer_norm(w, &format!("{p}.ln_2"), width)?,
                    c_fc: linear(w, &format!("{p}.mlp.c_fc"), mlp_width, width)?,
                    c_proj: linear(w, &format!("{p}.mlp.c_proj"), width, mlp_width)?,
                })
            })
            .collect::<Result<_, ClipError>>()?;
        Ok(Self {
            blocks,
            width,
            heads,
            activation,
        })
    }

    /// `x`: `(batch, tokens, width)`; `mask`: additive `(tokens, tokens)` (causal for text).
    pub fn forward(&self, x: &Tensor, mask: Option<&Tensor>) -> Result<Tensor, ClipError> {
        let mut x = x.clone();
        for b in &self.blocks {
            x = self.attention(b, &b.ln_1.forward(&x)?, mask, &x)?;
            let n = b.ln_2.forward(&x)?;
            let h = match self.activation {
                Activation::Gelu => b.c_fc.forward(&n, Then::Gelu)?,
                Activation::QuickGelu => {
                    let h = b.c_fc.forward(&n, Then::Nothing)?;
                    (&h * candle_nn::ops::sigmoid(&(&h * 1.702)?)?)?
                }
            };
            x = b.c_proj.forward_add(&h, &x)?;
        }
        Ok(x)
    }

    /// `residual + attn(x)`.
    fn attention(
        &self,
        b: &Block,
        x: &Tensor,
        mask: Option<&Tensor>,
        residual: &Tensor,
    ) -> Result<Tensor, ClipError> {
        let (batch, tokens, _) = x.dims3()?;
        let head_dim = self.width / self.heads;
        let qkv = b
            .in_proj
            .forward(x, Then::Nothing)?
            .reshape((batch, tokens, 3, self.heads, head_dim))?;
        // (3, batch, heads, tokens, head_dim)
        let qkv = qkv.permute((2, 0, 3, 1, 4))?;
        let q = (qkv.get(0)?.contiguous()? * (head_dim as f64).powf(-0.5))?;
        let k = qkv.get(1)?.contiguous()?;
        let v = qkv.get(2)?.contiguous()?;
        let mut scores = q.matmul(&k.t()?)?;
        if let Some(m) = mask {
            scores = scores.broadcast_add(m)?;
        }
        let attn = candle_nn::ops::softmax_last_dim(&scores)?;
        let out = attn
            .matmul(&v)?
            .transpose(1, 2)?
            .reshape((batch, tokens, self.width))?;
        Ok(b.out_proj.forward_add(&out, residual)?)
    }
}

/// `x / ‖x‖₂` along the last dimension (`F.normalize`, eps 1e-12).
pub fn l2_normalize(x: &Tensor) -> Result<Tensor, ClipError> {
    let norm = x
        .sqr()?
        .sum_keepdim(D::Minus1)?
        .sqrt()?
        .clamp(1e-12, f64::INFINITY)?;
    Ok(x.broadcast_div(&norm)?)
}
