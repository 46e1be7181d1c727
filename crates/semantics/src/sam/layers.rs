//! Decoder building blocks holding plain `f32` weights copied out of the checkpoint once, and
//! the attention variants of SAM's two-way transformer (`segment_anything/modeling/transformer.py`).
//!
//! The image side of the transformer has 4,096 tokens and the prompt side 7, so the cost of a
//! prompt is in the projections of the image tokens. The "folded" forms below move each
//! projection to the 7-token side by associativity — `(X·Wₖᵀ)·qᵀ = X·(Wₖᵀ·qᵀ)` — which turns
//! 4096×256×128 products into 4096×256×(8 heads × 7 tokens), 2.3× fewer operations. Adding a
//! query-side bias term that is constant along the softmax axis is dropped (softmax is invariant
//! to it); value biases pass through because attention rows sum to one.

use candle_nn::VarBuilder;

use super::elementwise::{layer_norm, residual_norm_pe, softmax_columns, softmax_groups};
use super::kernels::{linear, matmul, transpose};

/// Read a weight as a flat f32 vector of the given shape.
pub fn get_vec(vb: &VarBuilder, shape: &[usize], name: &str) -> candle_core::Result<Vec<f32>> {
    vb.get(shape, name)?
        .to_dtype(candle_core::DType::F32)?
        .flatten_all()?
        .to_vec1::<f32>()
}

/// `nn.Linear` with bias: `w` is out×in row-major (PyTorch), `wt` its in×out transpose. The
/// products use `wt`: `gemm` computes a row-major product as its transpose and would otherwise
/// repack the strided weight element by element on every call (measured: ~15% of the decoder).
#[derive(Debug, Clone)]
pub struct Linear {
    pub w: Vec<f32>,
    pub wt: Vec<f32>,
    pub b: Vec<f32>,
    pub n_in: usize,
    pub n_out: usize,
}

impl Linear {
    pub fn load(vb: &VarBuilder, n_in: usize, n_out: usize) -> candle_core::Result<Self> {
        let w = get_vec(vb, &[n_out, n_in], "weight")?;
        Ok(Self {
            wt: transpose(&w, n_out, n_in),
            w,
            b: get_vec(vb, &[n_out], "bias")?,
            n_in,
            n_out,
        })
    }

    pub fn forward(&self, x: &[f32], rows: usize) -> Vec<f32> {
        linear(x, rows, &self.wt, Some(&self.b), self.n_out)
    }
}

/// `nn.LayerNorm` over the last dimension.
#[derive(Debug, Clone)]
pub struct Norm {
    pub w: Vec<f32>,
    pub b: Vec<f32>,
    pub eps: f32,
}

impl Norm {
    pub fn load(vb: &VarBuilder, dim: usize, eps: f32) -> candle_core::Result<Self> {
        Ok(Self {
            w: get_vec(vb, &[dim], "weight")?,
            b: get_vec(vb, &[dim], "bias")?,
            eps,
        })
    }

    pub fn apply(&self, x: &mut [f32]) {
        layer_norm(x, self.w.len(), &self.w, &self.b, self.eps);
    }

    /// `x = norm(base + x)` and `x_pe = x + pe` in one pass (see `residual_norm_pe`).
    pub fn residual_pe(&self, x: &mut [f32], base: &[f32], pe: &[f32], x_pe: &mut [f32]) {
        residual_norm_pe(x, base, pe, x_pe, (&self.w, &self.b, self.eps));
    }
}

/// SAM's `Attention` (projections to `internal = dim / downsample` channels split over heads).
#[derive(Debug, Clone)]
pub struct Attention {
    pub q: Linear,
    pub k: Linear,
    pub v: Linear,
    pub out: Linear,
    pub heads: usize,
}

impl Attention {
    pub fn load(
        vb: &VarBuilder,
        dim: usize,
        heads: usize,
        downsample: usize,
    ) -> candle_core::Result<Self> {
        let internal = dim / downsample;
        Ok(Self {
            q: Linear::load(&vb.pp("q_proj"), dim, internal)?,
            k: Linear::load(&vb.pp("k_proj"), dim, internal)?,
            v: Linear::load(&vb.pp("v_proj"), dim, internal)?,
            out: Linear::load(&vb.pp("out_proj"), internal, dim)?,
            heads,
        })
    }

    fn internal(&self) -> usize {
        self.q.n_out
    }

    fn head_dim(&self) -> usize {
        self.internal() / self.heads
    }

    fn dim(&self) -> usize {
        self.q.n_in
    }

    /// Plain attention between two small token sets (the prompt tokens' self-attention).
    pub fn forward_small(&self, q: &[f32], k: &[f32], v: &[f32], n: usize) -> Vec<f32> {
        let (qp, kp, vp) = (
            self.q.forward(q, n),
            self.k.forward(k, n),
            self.v.forward(v, n),
        );
        let (inner, d) = (self.internal(), self.head_dim());
        let mut o = vec![0.0f32; n * inner];
        let mut s = vec![0.0f32; n * n];
        for h in 0..self.heads {
            matmul(
                n,
                n,
                d,
                &qp[h * d..],
                (inner, 1),
                &kp[h * d..],
                (1, inner),
                &mut s,
                n,
                false,
            );
            softmax_groups(&mut s, n, 1.0 / (d as f32).sqrt());
            matmul(
                n,
                d,
                n,
                &s,
                (n, 1),
                &vp[h * d..],
                (inner, 1),
                &mut o[h * d..],
                inner,
                false,
            );
        }
        self.out.forward(&o, n)
    }

    /// Tokens attend to image tokens whose key/value projections were computed once per image
    /// (first block, before the image side changes): `k_img_t` holds each head's keys
    /// transposed (heads × head_dim × N, so the score product reads a row-major operand),
    /// `v_img` the values (N×internal).
    pub fn tokens_to_precomputed(
        &self,
        q: &[f32],
        nq: usize,
        k_img_t: &[f32],
        v_img: &[f32],
    ) -> Vec<f32> {
        let (inner, d) = (self.internal(), self.head_dim());
        let n_img = v_img.len() / inner;
        let qp = self.q.forward(q, nq);
        let mut s = vec![0.0f32; nq * n_img];
        let mut o = vec![0.0f32; nq * inner];
        for h in 0..self.heads {
            matmul(
                nq,
                n_img,
                d,
                &qp[h * d..],
                (inner, 1),
                &k_img_t[h * d * n_img..],
                (n_img, 1),
                &mut s,
                n_img,
                false,
            );
            softmax_groups(&mut s, n_img, 1.0 / (d as f32).sqrt());
            matmul(
                nq,
                d,
                n_img,
                &s,
                (n_img, 1),
                &v_img[h * d..],
                (inner, 1),
                &mut o[h * d..],
                inner,
                false,
            );
        }
        self.out.forward(&o, nq)
    }

    /// Tokens attend to image tokens `img` (N×dim, values) with keys `img_pe` (N×dim), without
    /// projecting the N image tokens: the key projection moves onto the queries and the value
    /// projection after the attention-weighted sum (see the module comment).
    pub fn tokens_to_image_folded(
        &self,
        q: &[f32],
        nq: usize,
        img: &[f32],
        img_pe: &[f32],
        s: &mut Vec<f32>,
    ) -> Vec<f32> {
        let (dim, inner, d, heads) = (self.dim(), self.internal(), self.head_dim(), self.heads);
        let n_img = img.len() / dim;
        let qp = self.q.forward(q, nq);
        // qt[(h, i), :] = qp_h[i] · Wk_h  (heads·nq × dim)
        let mut qt = vec![0.0f32; heads * nq * dim];
        for h in 0..heads {
            let wk_h = &self.k.w[h * d * dim..];
            matmul(
                nq,
                dim,
                d,
                &qp[h * d..],
                (inner, 1),
                wk_h,
                (dim, 1),
                &mut qt[h * nq * dim..],
                dim,
                false,
            );
        }
        // Scores transposed, sᵀ = img_pe · qtᵀ (N × heads·nq): both operands row-major, so
        // `gemm` streams the 4096×256 image side without repacking it.
        let g = heads * nq;
        let qt_t = transpose(&qt, g, dim);
        s.resize(n_img * g, 0.0);
        matmul(n_img, g, dim, img_pe, (dim, 1), &qt_t, (g, 1), s, g, false);
        softmax_columns(s, g, 1.0 / (d as f32).sqrt());
        let mut ak = vec![0.0f32; g * dim];
        matmul(g, dim, n_img, s, (1, g), img, (dim, 1), &mut ak, dim, false);
        // o_h = ak_h · Wv_hᵀ + bv_h
        let mut o = vec![0.0f32; nq * inner];
        for row in o.chunks_exact_mut(inner) {
            row.copy_from_slice(&self.v.b);
        }
        for h in 0..heads {
            matmul(
                nq,
                d,
                dim,
                &ak[h * nq * dim..],
                (dim, 1),
                &self.v.wt[h * d..],
                (inner, 1),
                &mut o[h * d..],
                inner,
                true,
            );
        }
        self.out.forward(&o, nq)
    }

    /// Image tokens attend to the `nq` prompt tokens (keys `tk`, values `tv`, each nq×dim) and
    /// the projected result is written to `out` (N×dim). The image-side query projection is
    /// either given (`q_img`, N×internal, computed once per image) or folded onto the tokens
    /// and applied to `img_pe` (N×dim). `s` is scratch.
    #[allow(clippy::too_many_arguments)]
    pub fn image_to_tokens(
        &self,
        q_img: Option<&[f32]>,
        img_pe: &[f32],
        tk: &[f32],
        tv: &[f32],
        nq: usize,
        s: &mut Vec<f32>,
        out: &mut [f32],
    ) {
        let (dim, inner, d, heads) = (self.dim(), self.internal(), self.head_dim(), self.heads);
        let n_img = img_pe.len() / dim;
        let kp = self.k.forward(tk, nq);
        let vp = self.v.forward(tv, nq);
        let g = heads * nq;
        s.resize(n_img * g, 0.0);
        match q_img {
            Some(q_img) => {
                for h in 0..heads {
                    matmul(
                        n_img,
                        nq,
                        d,
                        &q_img[h * d..],
                        (inner, 1),
                        &kp[h * d..],
                        (1, inner),
                        &mut s[h * nq..],
                        g,
                        false,
                    );
                }
            }
            None => {
                // m[:, (h, j)] = Wq_hᵀ · kp_h[j]; c[(h, j)] = bq_h · kp_h[j]
                let mut m = vec![0.0f32; dim * g];
                let mut c = vec![0.0f32; g];
                for h in 0..heads {
                    matmul(
                        dim,
                        nq,
                        d,
                        &self.q.wt[h * d..],
                        (inner, 1),
                        &kp[h * d..],
                        (1, inner),
                        &mut m[h * nq..],
                        g,
                        false,
                    );
                    for j in 0..nq {
                        c[h * nq + j] = (0..d)
                            .map(|i| self.q.b[h * d + i] * kp[j * inner + h * d + i])
                            .sum();
                    }
                }
                for row in s.chunks_exact_mut(g) {
                    row.copy_from_slice(&c);
                }
                matmul(n_img, g, dim, img_pe, (dim, 1), &m, (g, 1), s, g, true);
            }
        }
        softmax_groups(s, nq, 1.0 / (d as f32).sqrt());
        // vw[(h, j), :] = vp_h[j] · Wo_hᵀ, so out = s · vw + bo in one product.
        let mut vw = vec![0.0f32; g * dim];
        for h in 0..heads {
            matmul(
                nq,
                dim,
                d,
                &vp[h * d..],
                (inner, 1),
                &self.out.wt[h * d * dim..],
                (dim, 1),
                &mut vw[h * nq * dim..],
                dim,
                false,
            );
        }
        for row in out.chunks_exact_mut(dim) {
            row.copy_from_slice(&self.out.b);
        }
        matmul(n_img, dim, g, s, (g, 1), &vw, (dim, 1), out, dim, true);
    }
}
