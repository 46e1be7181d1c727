//! SAM's mask decoder (`segment_anything/modeling/mask_decoder.py` + the two-way transformer),
//! rewritten on plain f32 buffers for batched automatic-mask generation on a CPU.
//!
//! Per image, everything that does not depend on the prompt is computed once
//! ([`MaskDecoder::prepare`]): the image tokens plus the "no mask" embedding, their positional
//! sum, and the first block's image-side key / value / query projections (the image tokens only
//! change after the first block's image-to-token attention). Per prompt ([`MaskDecoder::decode`])
//! only the folded attention products remain (see `layers.rs`), and the output upscaling runs
//! only when a mask can pass the predicted-IoU filter — the IoU head reads the transformer's
//! IoU token, which is ready before any upscaling — and only over the embedding cells that the
//! un-padded image covers (the upscaling is pixel-local: 2×2 stride-2 transposed convolutions,
//! a per-pixel LayerNorm and GELUs). Both shortcuts are exact.

use candle_nn::VarBuilder;

use super::elementwise::{add_assign, add_into, gelu_inplace, relu_inplace};
use super::kernels::{matmul, transpose};
use super::layers::{get_vec, Attention, Linear, Norm};
use super::prompt::{EMBED_DIM, GRID};

const HEADS: usize = 8;
const MLP_DIM: usize = 2048;
const NUM_MASK_TOKENS: usize = 4;
const UP1: usize = EMBED_DIM / 4;
const UP2: usize = EMBED_DIM / 8;
/// Output tokens ahead of a prompt's sparse tokens: the IoU token and 4 mask tokens.
const N_OUTPUT_TOKENS: usize = 1 + NUM_MASK_TOKENS;
/// Side of the low-resolution mask grid (4× the embedding grid).
pub const LOW_RES: usize = 4 * GRID;

#[derive(Debug, Clone)]
struct Block {
    self_attn: Attention,
    norm1: Norm,
    t2i: Attention,
    norm2: Norm,
    lin1: Linear,
    lin2: Linear,
    norm3: Norm,
    norm4: Norm,
    i2t: Attention,
}

impl Block {
    fn load(vb: &VarBuilder) -> candle_core::Result<Self> {
        Ok(Self {
            self_attn: Attention::load(&vb.pp("self_attn"), EMBED_DIM, HEADS, 1)?,
            norm1: Norm::load(&vb.pp("norm1"), EMBED_DIM, 1e-5)?,
            t2i: Attention::load(&vb.pp("cross_attn_token_to_image"), EMBED_DIM, HEADS, 2)?,
            norm2: Norm::load(&vb.pp("norm2"), EMBED_DIM, 1e-5)?,
            lin1: Linear::load(&vb.pp("mlp.lin1"), EMBED_DIM, MLP_DIM)?,
            lin2: Linear::load(&vb.pp("mlp.lin2"), MLP_DIM, EMBED_DIM)?,
            norm3: Norm::load(&vb.pp("norm3"), EMBED_DIM, 1e-5)?,
            norm4: Norm::load(&vb.pp("norm4"), EMBED_DIM, 1e-5)?,
            i2t: Attention::load(&vb.pp("cross_attn_image_to_token"), EMBED_DIM, HEADS, 2)?,
        })
    }

    /// Token-side MLP with residual and norm3.
    fn mlp(&self, queries: &mut [f32]) {
        let n = queries.len() / EMBED_DIM;
        let mut h = self.lin1.forward(queries, n);
        relu_inplace(&mut h);
        add_assign(queries, &self.lin2.forward(&h, n));
        self.norm3.apply(queries);
    }
}

/// Prompt-independent decoder state for one image embedding.
#[derive(Debug, Clone)]
pub struct ImageContext {
    /// Image tokens + no-mask embedding (4096×256).
    keys0: Vec<f32>,
    /// Dense positional encoding (4096×256).
    pe: Vec<f32>,
    /// First block, token-to-image keys, per head transposed (8 × 16 × 4096), and values
    /// (4096×128).
    k0: Vec<f32>,
    v0: Vec<f32>,
    /// First block, image-to-token queries (4096×128).
    q0: Vec<f32>,
}

/// Reusable per-thread buffers (each 4096×256 or smaller), so decoding allocates no large
/// blocks per prompt.
#[derive(Debug, Default)]
pub struct Scratch {
    keys: Vec<f32>,
    keys_pe: Vec<f32>,
    attn: Vec<f32>,
    s: Vec<f32>,
    up_x: Vec<f32>,
    up_y1: Vec<f32>,
    up_y2: Vec<f32>,
    up_m: Vec<f32>,
}

/// Which of the decoder's masks a prompt returns (`multimask_output` in SAM's predictor).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outputs {
    /// Mask tokens 1–3: three nested masks for an ambiguous prompt (one point).
    Multimask,
    /// Mask token 0 alone: SAM's single output for an unambiguous prompt (a box, several
    /// points).
    Single,
}

impl Outputs {
    fn tokens(self) -> std::ops::Range<usize> {
        match self {
            Outputs::Multimask => 1..NUM_MASK_TOKENS,
            Outputs::Single => 0..1,
        }
    }
}

/// Decoder output for one prompt: SAM's three multimask outputs, or its single one.
#[derive(Debug, Clone)]
pub struct PromptMasks {
    pub iou_pred: Vec<f32>,
    /// Low-resolution mask logits, `iou_pred.len()` × `rows` × `cols`, covering the top-left `rows`×`cols`
    /// of the 256×256 padded low-res frame; `None` when no output passed the IoU gate.
    pub logits: Option<Vec<f32>>,
    pub rows: usize,
    pub cols: usize,
}

#[derive(Debug, Clone)]
pub struct MaskDecoder {
    output_tokens: Vec<f32>,
    blocks: Vec<Block>,
    final_attn: Attention,
    norm_final: Norm,
    iou_head: Vec<Linear>,
    hyper: Vec<Vec<Linear>>,
    /// ConvTranspose2d(256→64, 2, 2) as a 256×(4·64) matrix with columns ordered (dy, dx, c).
    up1_w: Vec<f32>,
    up1_b: Vec<f32>,
    up_ln: Norm,
    /// ConvTranspose2d(64→32, 2, 2) as a 64×(4·32) matrix, columns (dy, dx, c).
    up2_w: Vec<f32>,
    up2_b: Vec<f32>,
}

/// Reorder a PyTorch ConvTranspose2d weight (in, out, 2, 2) into in × (dy, dx, out).
fn conv_t_matrix(w: &[f32], n_in: usize, n_out: usize) -> Vec<f32> {
    let mut m = vec![0.0f32; n_in * 4 * n_out];
    for i in 0..n_in {
        for o in 0..n_out {
            for s in 0..4 {
                m[i * 4 * n_out + s * n_out + o] = w[(i * n_out + o) * 4 + s];
            }
        }
    }
    m
}

fn mlp3(layers: &[Linear], x: &[f32]) -> Vec<f32> {
    let mut h = x.to_vec();
    for (i, l) in layers.iter().enumerate() {
        h = l.forward(&h, 1);
        if i + 1 < layers.len() {
            relu_inplace(&mut h);
        }
    }
    h
}

impl MaskDecoder {
    /// Load from the `mask_decoder.` prefix of a SAM checkpoint.
    pub fn load(vb: &VarBuilder) -> candle_core::Result<Self> {
        let mlp = |vb: VarBuilder, out: usize| -> candle_core::Result<Vec<Linear>> {
            (0..3)
                .map(|i| {
                    Linear::load(
                        &vb.pp("layers").pp(i),
                        EMBED_DIM,
                        if i == 2 { out } else { EMBED_DIM },
                    )
                })
                .collect()
        };
        let mut output_tokens = get_vec(&vb.pp("iou_token"), &[1, EMBED_DIM], "weight")?;
        output_tokens.extend(get_vec(
            &vb.pp("mask_tokens"),
            &[NUM_MASK_TOKENS, EMBED_DIM],
            "weight",
        )?);
        let t = vb.pp("transformer");
        let up = vb.pp("output_upscaling");
        Ok(Self {
            output_tokens,
            blocks: (0..2)
                .map(|i| Block::load(&t.pp("layers").pp(i)))
                .collect::<candle_core::Result<_>>()?,
            final_attn: Attention::load(&t.pp("final_attn_token_to_image"), EMBED_DIM, HEADS, 2)?,
            norm_final: Norm::load(&t.pp("norm_final_attn"), EMBED_DIM, 1e-5)?,
            iou_head: mlp(vb.pp("iou_prediction_head"), NUM_MASK_TOKENS)?,
            hyper: (0..NUM_MASK_TOKENS)
                .map(|i| mlp(vb.pp("output_hypernetworks_mlps").pp(i), UP2))
                .collect::<candle_core::Result<_>>()?,
            up1_w: conv_t_matrix(
                &get_vec(&up.pp("0"), &[EMBED_DIM, UP1, 2, 2], "weight")?,
                EMBED_DIM,
                UP1,
            ),
            up1_b: get_vec(&up.pp("0"), &[UP1], "bias")?,
            up_ln: Norm::load(&up.pp("1"), UP1, 1e-6)?,
            up2_w: conv_t_matrix(
                &get_vec(&up.pp("3"), &[UP1, UP2, 2, 2], "weight")?,
                UP1,
                UP2,
            ),
            up2_b: get_vec(&up.pp("3"), &[UP2], "bias")?,
        })
    }

    /// Prompt-independent work for one image. `embedding` is the encoder output (256×64×64,
    /// channel-major as PyTorch), `pe` the dense positional encoding as tokens, `no_mask` the
    /// dense prompt embedding used when no mask prompt is given.
    pub fn prepare(&self, embedding: &[f32], pe: &[f32], no_mask: &[f32]) -> ImageContext {
        let n = GRID * GRID;
        let mut keys0 = vec![0.0f32; n * EMBED_DIM];
        for (c, plane) in embedding.chunks_exact(n).enumerate() {
            for (t, &v) in plane.iter().enumerate() {
                keys0[t * EMBED_DIM + c] = v + no_mask[c];
            }
        }
        let mut keys0_pe = vec![0.0f32; n * EMBED_DIM];
        add_into(&mut keys0_pe, &keys0, pe);
        let b0 = &self.blocks[0];
        ImageContext {
            // Transposed, row h·16 + i is channel i of head h: heads × 16 × N.
            k0: transpose(&b0.t2i.k.forward(&keys0_pe, n), n, EMBED_DIM / 2),
            v0: b0.t2i.v.forward(&keys0, n),
            q0: b0.i2t.q.forward(&keys0_pe, n),
            keys0,
            pe: pe.to_vec(),
        }
    }

    /// Run the two-way transformer for one prompt; returns the output tokens ((5 + sparse
    /// tokens)×256) and leaves the final image tokens in `sc.keys`.
    fn transformer(&self, ctx: &ImageContext, sparse: &[f32], sc: &mut Scratch) -> Vec<f32> {
        let n = GRID * GRID;
        let nt = N_OUTPUT_TOKENS + sparse.len() / EMBED_DIM;
        let mut point_embedding = self.output_tokens.clone();
        point_embedding.extend_from_slice(sparse);
        let qpe = &point_embedding;
        let with_pe = |q: &[f32]| -> Vec<f32> { q.iter().zip(qpe).map(|(a, b)| a + b).collect() };
        sc.keys.resize(n * EMBED_DIM, 0.0);
        sc.keys_pe.resize(n * EMBED_DIM, 0.0);
        sc.attn.resize(n * EMBED_DIM, 0.0);

        // Block 0 (skip_first_layer_pe: self-attention without residual).
        let b = &self.blocks[0];
        let mut queries = b.self_attn.forward_small(qpe, qpe, qpe, nt);
        b.norm1.apply(&mut queries);
        let out = b
            .t2i
            .tokens_to_precomputed(&with_pe(&queries), nt, &ctx.k0, &ctx.v0);
        add_assign(&mut queries, &out);
        b.norm2.apply(&mut queries);
        b.mlp(&mut queries);
        b.i2t.image_to_tokens(
            Some(&ctx.q0),
            &ctx.keys0,
            &with_pe(&queries),
            &queries,
            nt,
            &mut sc.s,
            &mut sc.attn,
        );
        // keys = norm4(keys0 + attn), keys_pe = keys + pe; `attn` becomes the next scratch.
        b.norm4
            .residual_pe(&mut sc.attn, &ctx.keys0, &ctx.pe, &mut sc.keys_pe);
        std::mem::swap(&mut sc.keys, &mut sc.attn);

        // Block 1.
        let b = &self.blocks[1];
        let q = with_pe(&queries);
        let out = b.self_attn.forward_small(&q, &q, &queries, nt);
        add_assign(&mut queries, &out);
        b.norm1.apply(&mut queries);
        let out =
            b.t2i
                .tokens_to_image_folded(&with_pe(&queries), nt, &sc.keys, &sc.keys_pe, &mut sc.s);
        add_assign(&mut queries, &out);
        b.norm2.apply(&mut queries);
        b.mlp(&mut queries);
        b.i2t.image_to_tokens(
            None,
            &sc.keys_pe,
            &with_pe(&queries),
            &queries,
            nt,
            &mut sc.s,
            &mut sc.attn,
        );
        b.norm4
            .residual_pe(&mut sc.attn, &sc.keys, &ctx.pe, &mut sc.keys_pe);
        std::mem::swap(&mut sc.keys, &mut sc.attn);

        // Final token-to-image attention.
        let out = self.final_attn.tokens_to_image_folded(
            &with_pe(&queries),
            nt,
            &sc.keys,
            &sc.keys_pe,
            &mut sc.s,
        );
        add_assign(&mut queries, &out);
        self.norm_final.apply(&mut queries);
        queries
    }

    /// Decode one point prompt into SAM's three multimask outputs. `sparse` are its two
    /// sparse tokens (see `PromptEncoder::point_tokens`); low-res logits are produced for the
    /// top-left `tok_rows`×`tok_cols` embedding cells (×4 in each direction) when any of the
    /// three IoU predictions exceeds `iou_gate` (use `f32::NEG_INFINITY` to always get them).
    pub fn decode(
        &self,
        ctx: &ImageContext,
        sparse: &[f32],
        tokens: (usize, usize),
        iou_gate: f32,
        sc: &mut Scratch,
    ) -> PromptMasks {
        self.decode_prompt(ctx, sparse, Outputs::Multimask, tokens, iou_gate, sc)
    }

    /// Decode any prompt (`sparse` from `PromptEncoder::tokens`) into the chosen outputs;
    /// otherwise as [`MaskDecoder::decode`].
    pub fn decode_prompt(
        &self,
        ctx: &ImageContext,
        sparse: &[f32],
        outputs: Outputs,
        (tok_rows, tok_cols): (usize, usize),
        iou_gate: f32,
        sc: &mut Scratch,
    ) -> PromptMasks {
        assert!(
            !sparse.is_empty() && sparse.len().is_multiple_of(EMBED_DIM),
            "sparse tokens must be whole {EMBED_DIM}-wide rows"
        );
        let hs = self.transformer(ctx, sparse, sc);
        let iou = mlp3(&self.iou_head, &hs[..EMBED_DIM]);
        let iou_pred: Vec<f32> = outputs.tokens().map(|m| iou[m]).collect();
        let (rows, cols) = (4 * tok_rows, 4 * tok_cols);
        if iou_pred.iter().all(|&p| p <= iou_gate) {
            return PromptMasks {
                iou_pred,
                logits: None,
                rows,
                cols,
            };
        }
        // Hypernetwork weights of the chosen mask tokens: outputs × 32.
        let mut hyper = Vec::with_capacity(iou_pred.len() * UP2);
        for m in outputs.tokens() {
            hyper.extend(mlp3(
                &self.hyper[m],
                &hs[(1 + m) * EMBED_DIM..(2 + m) * EMBED_DIM],
            ));
        }
        let logits = self.upscale(sc, &hyper, tok_rows, tok_cols);
        PromptMasks {
            iou_pred,
            logits: Some(logits),
            rows,
            cols,
        }
    }

    /// Output upscaling + hypernetwork products over the top-left tok_rows×tok_cols cells of
    /// the final image tokens (`sc.keys`), into `sc.up_*` buffers reused across prompts.
    fn upscale(
        &self,
        sc: &mut Scratch,
        hyper: &[f32],
        tok_rows: usize,
        tok_cols: usize,
    ) -> Vec<f32> {
        let nt = tok_rows * tok_cols;
        // Whole token rows are contiguous already (landscape images cover all 64 columns).
        let x: &[f32] = if tok_cols == GRID {
            &sc.keys[..nt * EMBED_DIM]
        } else {
            sc.up_x.clear();
            for ty in 0..tok_rows {
                let row = ty * GRID * EMBED_DIM;
                sc.up_x
                    .extend_from_slice(&sc.keys[row..row + tok_cols * EMBED_DIM]);
            }
            &sc.up_x
        };
        // Stage 1: 256 → 4 sub-pixels × 64, LayerNorm2d over the 64 channels, GELU.
        let y1 = &mut sc.up_y1;
        y1.resize(nt * 4 * UP1, 0.0);
        for row in y1.chunks_exact_mut(UP1) {
            row.copy_from_slice(&self.up1_b);
        }
        let n1 = 4 * UP1;
        matmul(
            nt,
            n1,
            EMBED_DIM,
            x,
            (EMBED_DIM, 1),
            &self.up1_w,
            (n1, 1),
            y1,
            n1,
            true,
        );
        self.up_ln.apply(y1);
        gelu_inplace(y1);
        // Stage 2: 64 → 4 sub-pixels × 32, GELU.
        let y2 = &mut sc.up_y2;
        y2.resize(nt * 16 * UP2, 0.0);
        for row in y2.chunks_exact_mut(UP2) {
            row.copy_from_slice(&self.up2_b);
        }
        let n2 = 4 * UP2;
        matmul(
            nt * 4,
            n2,
            UP1,
            y1,
            (UP1, 1),
            &self.up2_w,
            (n2, 1),
            y2,
            n2,
            true,
        );
        gelu_inplace(y2);
        // Masks: each 32-channel pixel dotted with the hypernetwork vectors (3, or 1).
        let k = hyper.len() / UP2;
        let m = &mut sc.up_m;
        m.resize(nt * 16 * k, 0.0);
        matmul(nt * 16, k, UP2, y2, (UP2, 1), hyper, (1, UP2), m, k, false);
        scatter_subpixels(m, k, tok_rows, tok_cols)
    }
}

/// Rearrange the upscaler's rows, ordered (token, s1, s2) with s = dy·2 + dx at each 2×2
/// stage and `k` mask values each, into `k` planes of (4·tok_rows)×(4·tok_cols) pixels.
fn scatter_subpixels(m: &[f32], k: usize, tok_rows: usize, tok_cols: usize) -> Vec<f32> {
    let (rows, cols) = (4 * tok_rows, 4 * tok_cols);
    let mut out = vec![0.0f32; k * rows * cols];
    for (token, cell) in m.chunks_exact(16 * k).enumerate() {
        let (y0, x0) = (4 * (token / tok_cols), 4 * (token % tok_cols));
        for (s, px) in cell.chunks_exact(k).enumerate() {
            let (s1, s2) = (s / 4, s % 4);
            let y = y0 + 2 * (s1 / 2) + s2 / 2;
            let x = x0 + 2 * (s1 % 2) + s2 % 2;
            for (k, &v) in px.iter().enumerate() {
                out[(k * rows + y) * cols + x] = v;
            }
        }
    }
    out
}
