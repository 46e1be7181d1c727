//! 2-D convolution + bias + ReLU on NHWC batches: im2col of a band of output pixels (rayon),
//! then one multithreaded `gemm` call per band (bands of ~4 MiB of im2col: 8 for AlexNet's
//! conv1 and conv2 at 480×360, 1–3 for its later layers).
//!
//! Why this shape: with NHWC input, the `k × c_in` values of one kernel row are contiguous
//! in memory (consecutive x, all channels), so im2col is `k` memcpys per output pixel; the
//! GEMM output (pixels × c_out, row-major) is NHWC again, so layers chain without
//! transposes. Banding bounds the im2col buffer (VGG16 conv1_2 at 480×360 would need
//! 0.8 GB at once) and keeps it in cache while `gemm` packs it. The batch (both images of an
//! LPIPS pair) is part of the pixel dimension, so one pass serves both.

use super::tensor::Nhwc;
use rayon::prelude::*;

/// im2col band size in floats (4 MiB). In A/B runs on AlexNet at 480×360 (docs/performance.md)
/// 1–4 MiB bands were fastest, 16–256 MiB ones 20–40 % slower (the band is re-read while
/// gemm packs it, from cache only when small), and per-thread bands with one
/// single-threaded gemm each were ~20 % slower (each re-packs the whole weight matrix).
const BAND_FLOATS: usize = 1024 * 1024;
/// At least this many pixels per band, so that gemm's weight packing is amortized.
const MIN_BAND_ROWS: usize = 128;
/// Pixels per rayon task for im2col, bias and ReLU.
const TASK_ROWS: usize = 64;

/// A convolution with square kernel, symmetric zero padding and equal strides.
#[derive(Clone, Debug)]
pub(crate) struct Conv2d {
    pub c_in: usize,
    pub c_out: usize,
    pub k: usize,
    pub pad: usize,
    pub stride: usize,
    /// `(k·k·c_in) × c_out` row-major, row index `(ky·k + kx)·c_in + c` (im2col order).
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl Conv2d {
    /// Builds from PyTorch's OIHW weight `(c_out, c_in, k, k)` and bias `(c_out)`.
    pub fn from_oihw(
        oihw: &[f32],
        bias: Vec<f32>,
        c_in: usize,
        k: usize,
        pad: usize,
        stride: usize,
    ) -> Self {
        let c_out = bias.len();
        assert_eq!(oihw.len(), c_out * c_in * k * k, "OIHW weight size");
        let mut weight = vec![0.0f32; oihw.len()];
        for o in 0..c_out {
            for c in 0..c_in {
                for ky in 0..k {
                    for kx in 0..k {
                        let src = ((o * c_in + c) * k + ky) * k + kx;
                        weight[((ky * k + kx) * c_in + c) * c_out + o] = oihw[src];
                    }
                }
            }
        }
        Self {
            c_in,
            c_out,
            k,
            pad,
            stride,
            weight,
            bias,
        }
    }

    fn out_size(&self, side: usize) -> usize {
        (side + 2 * self.pad - self.k) / self.stride + 1
    }

    /// `relu(conv(x) + bias)`. `x.c` must equal `c_in` and each side must be ≥ `k − 2·pad`.
    pub fn forward_relu(&self, x: &Nhwc) -> Nhwc {
        assert_eq!(x.c, self.c_in, "conv input channels");
        let (ho, wo) = (self.out_size(x.h), self.out_size(x.w));
        let kdim = self.k * self.k * self.c_in;
        let n = self.c_out;
        let band = (BAND_FLOATS / kdim).max(MIN_BAND_ROWS);
        let mut data = vec![0.0f32; x.n * ho * wo * n];
        let mut cols = Vec::new();
        for (b, out) in data.chunks_mut(band * n).enumerate() {
            let rows = out.len() / n;
            cols.resize(rows * kdim, 0.0);
            cols.par_chunks_mut(kdim * TASK_ROWS)
                .enumerate()
                .for_each(|(j, c)| self.im2col(x, ho, wo, b * band + j * TASK_ROWS, c));
            gemm_set(out, &cols, &self.weight, rows, kdim, n);
            // Bias and ReLU in one pass while the band is still in cache.
            out.par_chunks_mut(n * TASK_ROWS).for_each(|o| {
                for px in o.chunks_exact_mut(n) {
                    for (v, &b) in px.iter_mut().zip(&self.bias) {
                        *v = (*v + b).max(0.0);
                    }
                }
            });
        }
        Nhwc {
            n: x.n,
            h: ho,
            w: wo,
            c: n,
            data,
        }
    }

    /// Fills `cols` (rows × k·k·c_in) with the receptive fields of output pixels
    /// `first..first + rows` (flat over image, y, x); zero padding where outside.
    fn im2col(&self, x: &Nhwc, ho: usize, wo: usize, first: usize, cols: &mut [f32]) {
        let (k, c, s, p) = (self.k, self.c_in, self.stride, self.pad as isize);
        for (r, row) in cols.chunks_exact_mut(k * k * c).enumerate() {
            let pix = first + r;
            let (i, oy, ox) = (pix / (ho * wo), pix / wo % ho, pix % wo);
            // Valid kx: 0 ≤ ox·s + kx − p < w, a contiguous range [lo, hi).
            let x0 = (ox * s) as isize - p;
            let lo = (-x0).clamp(0, k as isize) as usize;
            let hi = (x.w as isize - x0).clamp(0, k as isize) as usize;
            for (ky, krow) in row.chunks_exact_mut(k * c).enumerate() {
                let iy = (oy * s) as isize + ky as isize - p;
                if iy < 0 || iy >= x.h as isize || lo >= hi {
                    krow.fill(0.0);
                    continue;
                }
                krow[..lo * c].fill(0.0);
                krow[hi * c..].fill(0.0);
                let start = ((i * x.h + iy as usize) * x.w + (x0 + lo as isize) as usize) * c;
                krow[lo * c..hi * c].copy_from_slice(&x.data[start..start + (hi - lo) * c]);
            }
        }
    }
}

/// `c (m × n) = a (m × k) · b (k × n)`, all row-major and dense, on all rayon threads
/// (gemm splits m and n, never k, so each sum's order does not depend on the thread count).
fn gemm_set(c: &mut [f32], a: &[f32], b: &[f32], m: usize, k: usize, n: usize) {
    assert!(
        c.len() == m * n && a.len() == m * k && b.len() == k * n,
        "gemm sizes"
    );
    // SAFETY: the three slices hold exactly the m×n, m×k and k×n row-major matrices
    // described by the strides below (checked above), and `c` is a unique borrow.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            c.as_mut_ptr(),
            1,
            n as isize,
            false,
            a.as_ptr(),
            1,
            k as isize,
            b.as_ptr(),
            1,
            n as isize,
            0.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::Rayon(0),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct NCHW-free definition: out[i,y,x,o] = b[o] + Σ w[o,c,ky,kx]·in[i, y·s+ky−p, …].
    fn naive(x: &Nhwc, oihw: &[f32], bias: &[f32], k: usize, p: usize, s: usize) -> Nhwc {
        let (ho, wo) = ((x.h + 2 * p - k) / s + 1, (x.w + 2 * p - k) / s + 1);
        let co = bias.len();
        let mut data = Vec::new();
        for i in 0..x.n {
            for y in 0..ho {
                for xx in 0..wo {
                    for o in 0..co {
                        let mut acc = bias[o];
                        for ky in 0..k {
                            for kx in 0..k {
                                let iy = (y * s + ky) as isize - p as isize;
                                let ix = (xx * s + kx) as isize - p as isize;
                                if iy < 0 || ix < 0 || iy >= x.h as isize || ix >= x.w as isize {
                                    continue;
                                }
                                let px = x.pixel(i, iy as usize, ix as usize);
                                for (c, &v) in px.iter().enumerate() {
                                    acc += oihw[((o * x.c + c) * k + ky) * k + kx] * v;
                                }
                            }
                        }
                        data.push(acc.max(0.0));
                    }
                }
            }
        }
        Nhwc {
            n: x.n,
            h: ho,
            w: wo,
            c: co,
            data,
        }
    }

    fn pseudo(len: usize, seed: f32) -> Vec<f32> {
        (0..len).map(|i| (i as f32 * seed).sin()).collect()
    }

    #[test]
    fn matches_direct_convolution_with_padding_and_stride() {
        // (c_in, c_out, k, pad, stride, h, w): AlexNet-like conv1, 3×3 same, 5×5 same,
        // and an image whose width is not a multiple of the stride.
        for (ci, co, k, p, s, h, w) in [
            (3, 8, 11, 2, 4, 31, 37),
            (5, 7, 3, 1, 1, 9, 13),
            (4, 6, 5, 2, 1, 6, 7),
            (2, 3, 3, 0, 2, 8, 9),
        ] {
            let x = Nhwc {
                n: 2,
                h,
                w,
                c: ci,
                data: pseudo(2 * h * w * ci, 0.37),
            };
            let wt = pseudo(co * ci * k * k, 0.11);
            let bias = pseudo(co, 1.3);
            let conv = Conv2d::from_oihw(&wt, bias.clone(), ci, k, p, s);
            let got = conv.forward_relu(&x);
            let want = naive(&x, &wt, &bias, k, p, s);
            assert_eq!(
                (got.n, got.h, got.w, got.c),
                (want.n, want.h, want.w, want.c)
            );
            for (g, e) in got.data.iter().zip(&want.data) {
                assert!((g - e).abs() < 1e-4 * (1.0 + e.abs()), "{g} vs {e}");
            }
        }
    }

    #[test]
    fn bands_cover_many_gemm_calls() {
        // 3×3, c_in = 1024 → kdim 9216 → band of 128 rows; 2×20×20 = 800 pixels → 7 bands,
        // the last partial, and 2 im2col tasks per band.
        let (ci, co) = (1024, 4);
        let x = Nhwc {
            n: 2,
            h: 20,
            w: 20,
            c: ci,
            data: pseudo(2 * 400 * ci, 0.013),
        };
        let wt = pseudo(co * ci * 9, 0.07);
        let bias = vec![0.1; co];
        let got = Conv2d::from_oihw(&wt, bias.clone(), ci, 3, 1, 1).forward_relu(&x);
        let want = naive(&x, &wt, &bias, 3, 1, 1);
        for (g, e) in got.data.iter().zip(&want.data) {
            assert!((g - e).abs() < 1e-3 * (1.0 + e.abs()), "{g} vs {e}");
        }
    }
}
