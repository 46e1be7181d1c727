//! TinyViT's `Conv2d_BN` (`tiny_vit_sam.py`): a convolution without bias followed by an
//! eval-mode batch norm, with the norm folded into the weights at load time
//! (`w' = w·γ/√(σ²+ε)`, `b' = β − μ·γ/√(σ²+ε)`) and an optional exact GELU applied as each
//! output block is written.
//!
//! Why our own: candle-core runs a grouped convolution as one convolution per group
//! (`Tensor::conv2d` chunks the input by channel, convolves each chunk through its im2col +
//! GEMM path, and concatenates), so TinyViT's depthwise 3×3 layers (up to 256
//! channels of 256² pixels) became thousands of tiny GEMMs with scalar gathers around them
//! — about a third of the encoder's time (docs/performance.md "Tracking"). Here:
//! - depthwise 3×3 (stride 1 or 2, padding 1): one channel plane per rayon task, each output
//!   row a sum of nine shifted input rows, written as plain loops that auto-vectorize and are
//!   compiled per instruction set (`elementwise::dispatch`);
//! - pointwise 1×1: `W·X` on the NCHW planes through `kernels::matmul`, split over blocks of
//!   pixel columns, each block's output filled with the bias first;
//! - other kernels (the patch embedding's dense 3×3 convolutions) stay candle's.
//!
//! `conv_bn_reference` below is the unfused candle computation (convolution, then the batch
//! norm), which the tests hold the fast paths to.

use candle_core::{CpuStorage, CustomOp1, Layout, Result, Shape, Tensor};
use candle_nn::{Conv2dConfig, Module, VarBuilder};
use rayon::prelude::*;

use super::elementwise::{dispatch, gelu_inplace};
use super::kernels::matmul;
use super::tensor_ops::f32_slice;

const BN_EPS: f64 = 1e-5;

/// A convolution with its batch norm folded in.
#[derive(Debug)]
pub struct Conv2dBN {
    kind: Kind,
    /// Folded bias, one per output channel.
    bias: Vec<f32>,
    cin: usize,
    cout: usize,
}

#[derive(Debug)]
enum Kind {
    /// Weights `cout × cin`, row-major.
    Pointwise(Vec<f32>),
    /// Weights `channels × 9`; stride 1 or 2, padding 1.
    Depthwise3x3 { w: Vec<f32>, stride: usize },
    /// Any other kernel: candle's convolution with the folded weights.
    Dense {
        w: Tensor,
        cfg: Conv2dConfig,
        bias: Tensor,
    },
}

/// Per-channel scale and shift of an eval-mode batch norm under `vb` (`bn.*`).
fn bn_affine(out: usize, vb: &VarBuilder) -> Result<(Vec<f32>, Vec<f32>)> {
    let get = |name| vb.get(out, name)?.to_vec1::<f32>();
    let (gamma, beta) = (get("weight")?, get("bias")?);
    let (mean, var) = (get("running_mean")?, get("running_var")?);
    let mut scale = Vec::with_capacity(out);
    let mut shift = Vec::with_capacity(out);
    for c in 0..out {
        let s = f64::from(gamma[c]) / (f64::from(var[c]) + BN_EPS).sqrt();
        scale.push(s as f32);
        shift.push((f64::from(beta[c]) - f64::from(mean[c]) * s) as f32);
    }
    Ok((scale, shift))
}

impl Conv2dBN {
    /// Loads `c.weight` and `bn.*` under `vb` (the checkpoint's `Conv2d_BN` keys).
    pub fn new(
        cin: usize,
        cout: usize,
        ks: usize,
        cfg: Conv2dConfig,
        vb: VarBuilder,
    ) -> Result<Self> {
        let w = vb.get((cout, cin / cfg.groups, ks, ks), "c.weight")?;
        let (scale, bias) = bn_affine(cout, &vb.pp("bn"))?;
        let folded =
            w.broadcast_mul(&Tensor::new(scale.as_slice(), w.device())?.reshape((cout, 1, 1, 1))?)?;
        let plain = cfg.dilation == 1 && cfg.groups == 1 && cfg.padding == 0 && cfg.stride == 1;
        let kind = if ks == 1 && plain {
            Kind::Pointwise(folded.flatten_all()?.to_vec1()?)
        } else if ks == 3
            && cfg.groups == cin
            && cin == cout
            && cfg.padding == 1
            && cfg.dilation == 1
            && (cfg.stride == 1 || cfg.stride == 2)
        {
            Kind::Depthwise3x3 {
                w: folded.flatten_all()?.to_vec1()?,
                stride: cfg.stride,
            }
        } else {
            let b = Tensor::new(bias.as_slice(), w.device())?.reshape((1, cout, 1, 1))?;
            Kind::Dense {
                w: folded,
                cfg,
                bias: b,
            }
        };
        Ok(Self {
            kind,
            bias,
            cin,
            cout,
        })
    }

    /// The convolution and norm, then GELU when `gelu`.
    pub fn forward_gelu(&self, xs: &Tensor, gelu: bool) -> Result<Tensor> {
        match &self.kind {
            Kind::Dense { w, cfg, bias } => {
                let y = xs
                    .conv2d(w, cfg.padding, cfg.stride, cfg.dilation, cfg.groups)?
                    .broadcast_add(bias)?;
                if gelu {
                    super::tensor_ops::gelu(&y)
                } else {
                    Ok(y)
                }
            }
            _ => xs.contiguous()?.apply_op1_no_bwd(&Op { conv: self, gelu }),
        }
    }
}

impl Module for Conv2dBN {
    fn forward(&self, xs: &Tensor) -> Result<Tensor> {
        self.forward_gelu(xs, false)
    }
}

struct Op<'a> {
    conv: &'a Conv2dBN,
    gelu: bool,
}

impl CustomOp1 for Op<'_> {
    fn name(&self) -> &'static str {
        "conv-bn"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = f32_slice(storage, layout, "conv-bn")?;
        let (b, c, h, w) = layout.shape().dims4()?;
        let conv = self.conv;
        if c != conv.cin {
            candle_core::bail!("conv-bn: {c} input channels, the weights take {}", conv.cin);
        }
        let (out, oh, ow) = match &conv.kind {
            Kind::Pointwise(wt) => (pointwise(x, b, h * w, wt, conv, self.gelu), h, w),
            Kind::Depthwise3x3 { w: k, stride } => {
                depthwise(x, (b, c, h, w), k, &conv.bias, *stride, self.gelu)
            }
            Kind::Dense { .. } => candle_core::bail!("conv-bn: dense kernels run through candle"),
        };
        Ok((CpuStorage::F32(out), Shape::from((b, conv.cout, oh, ow))))
    }
}

/// `y[co, p] = b'[co] + Σ_ci w'[co, ci]·x[ci, p]` per image, over blocks of pixel columns.
fn pointwise(x: &[f32], b: usize, hw: usize, wt: &[f32], conv: &Conv2dBN, gelu: bool) -> Vec<f32> {
    let (cin, cout) = (conv.cin, conv.cout);
    let mut out = vec![0.0f32; b * cout * hw];
    // Column blocks small enough to stay in L2 across the output rows, at least a few per thread.
    let block = (hw / (4 * rayon::current_num_threads())).clamp(64, 1024);
    let blocks = hw.div_ceil(block);
    // Each task owns the columns [j0, j0 + n) of every output row of one image.
    let out_ptr = SendPtr(out.as_mut_ptr());
    (0..b * blocks).into_par_iter().for_each(|task| {
        let (img, j0) = (task / blocks, (task % blocks) * block);
        let n = block.min(hw - j0);
        let base = img * cout * hw + j0;
        // SAFETY: tasks write disjoint column ranges of `out`, and `base + (cout−1)·hw + n`
        // ≤ its length; no other reference to `out` exists while they run.
        let c =
            unsafe { std::slice::from_raw_parts_mut(out_ptr.get().add(base), (cout - 1) * hw + n) };
        for (co, &bias) in conv.bias.iter().enumerate() {
            c[co * hw..co * hw + n].fill(bias);
        }
        let xb = &x[img * cin * hw + j0..];
        matmul(cout, n, cin, wt, (cin, 1), xb, (hw, 1), c, hw, true);
        if gelu {
            for co in 0..cout {
                gelu_inplace(&mut c[co * hw..co * hw + n]);
            }
        }
    });
    out
}

/// A raw pointer that rayon tasks may share; each task writes only its own ranges.
#[derive(Clone, Copy)]
struct SendPtr(*mut f32);
// SAFETY: used only for disjoint writes (see `pointwise`).
unsafe impl Send for SendPtr {}
// SAFETY: as above.
unsafe impl Sync for SendPtr {}

impl SendPtr {
    fn get(self) -> *mut f32 {
        self.0
    }
}

/// Depthwise 3×3, padding 1, stride `s`: one (image, channel) plane per task.
fn depthwise(
    x: &[f32],
    (b, c, h, w): (usize, usize, usize, usize),
    k: &[f32],
    bias: &[f32],
    s: usize,
    gelu: bool,
) -> (Vec<f32>, usize, usize) {
    let (oh, ow) = ((h - 1) / s + 1, (w - 1) / s + 1);
    let mut out = vec![0.0f32; b * c * oh * ow];
    out.par_chunks_mut(oh * ow)
        .zip(x.par_chunks(h * w))
        .enumerate()
        .for_each(|(plane, (o, xi))| {
            let ch = plane % c;
            let kc: &[f32; 9] = k[ch * 9..ch * 9 + 9].try_into().expect("nine taps");
            depthwise_plane(xi, h, w, kc, bias[ch], s, o, ow);
            if gelu {
                gelu_inplace(o);
            }
        });
    (out, oh, ow)
}

dispatch! {
    /// One channel plane (`h×w` in, `oh×ow` out): each output row starts at the bias and adds
    /// the three taps of each of the (up to) three input rows it covers.
    #[allow(clippy::too_many_arguments)]
    fn depthwise_plane(
        x: &[f32],
        h: usize,
        w: usize,
        k: &[f32; 9],
        bias: f32,
        s: usize,
        out: &mut [f32],
        ow: usize,
    ) {
        for (oy, orow) in out.chunks_exact_mut(ow).enumerate() {
            orow.fill(bias);
            for ky in 0..3 {
                let iy = (oy * s + ky) as isize - 1;
                if iy < 0 || iy >= h as isize {
                    continue;
                }
                let row = &x[iy as usize * w..(iy as usize + 1) * w];
                let taps = [k[ky * 3], k[ky * 3 + 1], k[ky * 3 + 2]];
                if s == 1 {
                    add_row_stride1(orow, row, taps);
                } else {
                    add_row_strided(orow, row, taps, s);
                }
            }
        }
    }
}

/// `o[x] += t0·r[x−1] + t1·r[x] + t2·r[x+1]` with zero padding, as three shifted whole-row
/// passes the compiler vectorizes.
#[inline(always)]
fn add_row_stride1(o: &mut [f32], r: &[f32], [t0, t1, t2]: [f32; 3]) {
    let w = r.len();
    if w == 1 {
        o[0] += t1 * r[0];
        return;
    }
    o[0] += t1 * r[0] + t2 * r[1];
    o[w - 1] += t0 * r[w - 2] + t1 * r[w - 1];
    for (((o, &a), &b), &c) in o[1..w - 1]
        .iter_mut()
        .zip(&r[..w - 2])
        .zip(&r[1..w - 1])
        .zip(&r[2..])
    {
        *o += t0 * a + t1 * b + t2 * c;
    }
}

/// The same at stride `s`: `o[x] += Σ_k t_k·r[s·x + k − 1]`, taps outside the row skipped.
#[inline(always)]
fn add_row_strided(o: &mut [f32], r: &[f32], t: [f32; 3], s: usize) {
    let w = r.len() as isize;
    for (ox, o) in o.iter_mut().enumerate() {
        let x0 = (ox * s) as isize - 1;
        let mut acc = 0.0f32;
        for (kx, &tk) in t.iter().enumerate() {
            let ix = x0 + kx as isize;
            if ix >= 0 && ix < w {
                acc += tk * r[ix as usize];
            }
        }
        *o += acc;
    }
}

/// The unfused computation, candle's: convolution, then the eval-mode batch norm (tests only).
#[cfg(test)]
pub fn conv_bn_reference(
    xs: &Tensor,
    cout: usize,
    ks: usize,
    cfg: Conv2dConfig,
    vb: VarBuilder,
) -> Result<Tensor> {
    let cin = xs.dim(1)?;
    let conv = candle_nn::conv2d_no_bias(cin, cout, ks, cfg, vb.pp("c"))?;
    let bn = candle_nn::batch_norm(cout, BN_EPS, vb.pp("bn"))?;
    xs.apply(&conv)?.apply_t(&bn, false)
}

#[cfg(test)]
mod tests {
    use super::super::tensor_ops::testing::{max_abs_diff, tensor};
    use super::*;
    use candle_core::{DType, Device};
    use std::collections::HashMap;

    /// Random weights and batch-norm statistics for a `Conv2d_BN` under a fresh `VarBuilder`.
    fn random_vb(
        cin: usize,
        cout: usize,
        ks: usize,
        groups: usize,
        seed: u64,
    ) -> VarBuilder<'static> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut t = |shape: &[usize], lo: f32, hi: f32| {
            let n: usize = shape.iter().product();
            let v: Vec<f32> = (0..n).map(|_| rng.gen_range(lo..hi)).collect();
            Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
        };
        let mut m = HashMap::new();
        m.insert(
            "c.weight".to_string(),
            t(&[cout, cin / groups, ks, ks], -0.5, 0.5),
        );
        m.insert("bn.weight".to_string(), t(&[cout], 0.5, 1.5));
        m.insert("bn.bias".to_string(), t(&[cout], -0.3, 0.3));
        m.insert("bn.running_mean".to_string(), t(&[cout], -0.2, 0.2));
        m.insert("bn.running_var".to_string(), t(&[cout], 0.2, 2.0));
        VarBuilder::from_tensors(m, DType::F32, &Device::Cpu)
    }

    fn input((b, c, h, w): (usize, usize, usize, usize), seed: usize) -> Tensor {
        tensor(&[b, c, h, w], seed)
    }

    fn check(
        cin: usize,
        cout: usize,
        ks: usize,
        cfg: Conv2dConfig,
        shape: (usize, usize, usize, usize),
    ) {
        let vb = random_vb(cin, cout, ks, cfg.groups, 7);
        let x = input(shape, 3);
        let fast = Conv2dBN::new(cin, cout, ks, cfg, vb.clone()).unwrap();
        let want = conv_bn_reference(&x, cout, ks, cfg, vb).unwrap();
        let got = fast.forward(&x).unwrap();
        let d = max_abs_diff(&got, &want);
        assert!(
            d < 2e-5,
            "{cin}→{cout} k{ks} {cfg:?} on {shape:?}: max |Δ| = {d}"
        );
        let with_gelu = fast.forward_gelu(&x, true).unwrap();
        let want_gelu = super::super::tensor_ops::gelu(&want).unwrap();
        let d = max_abs_diff(&with_gelu, &want_gelu);
        assert!(d < 2e-5, "with GELU: max |Δ| = {d}");
    }

    #[test]
    fn pointwise_matches_candle_conv_then_batch_norm() {
        check(5, 7, 1, Conv2dConfig::default(), (2, 5, 9, 13));
        // More columns than one block, and a partial last block.
        check(16, 24, 1, Conv2dConfig::default(), (1, 16, 33, 41));
    }

    #[test]
    fn depthwise_matches_candle_grouped_conv_then_batch_norm() {
        for stride in [1, 2] {
            let cfg = Conv2dConfig {
                padding: 1,
                stride,
                groups: 6,
                ..Default::default()
            };
            for (h, w) in [(1, 1), (1, 5), (7, 2), (8, 11), (9, 10)] {
                check(6, 6, 3, cfg, (2, 6, h, w));
            }
        }
    }

    #[test]
    fn dense_kernels_keep_candle_with_the_norm_folded() {
        let cfg = Conv2dConfig {
            padding: 1,
            stride: 2,
            ..Default::default()
        };
        check(3, 4, 3, cfg, (1, 3, 10, 9));
    }

    #[test]
    fn wrong_channel_count_is_an_error_not_a_panic() {
        let vb = random_vb(4, 4, 1, 1, 1);
        let conv = Conv2dBN::new(4, 4, 1, Conv2dConfig::default(), vb).unwrap();
        assert!(conv.forward(&input((1, 3, 4, 4), 0)).is_err());
    }
}
