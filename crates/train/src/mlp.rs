//! The deformation MLP of Deformable-3DGS (`DeformNetwork`): `depth` ReLU layers of
//! `width`, the encoded input concatenated to the output of layer `skip` (`skips=[D//2]`),
//! and a linear head (δx, δr, δs stacked, identical to three separate `nn.Linear` heads).
//! Forward and backward are hand-written on `gemm` (DESIGN.md: no ML framework on the
//! training path), parallel over fixed row chunks so results are thread-count independent.

use crate::gemm_util::{matmul, Mat};
use rand::Rng;
use rayon::prelude::*;

/// Rows per parallel work item; fixed so the summation order never changes.
const ROW_CHUNK: usize = 1024;

#[derive(Clone, Copy, Debug, PartialEq)]
struct Layer {
    w_off: usize,
    b_off: usize,
    fan_in: usize,
    fan_out: usize,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    pub in_dim: usize,
    pub width: usize,
    pub depth: usize,
    pub out_dim: usize,
    /// Layer after whose output the input is concatenated again (None = no skip).
    pub skip: Option<usize>,
    /// All weights (row-major fan_in × fan_out) and biases, layer after layer, head last.
    pub params: Vec<f32>,
    layers: Vec<Layer>,
}

/// Activations kept from the forward pass for the backward pass.
#[derive(Clone, Debug, Default)]
pub struct MlpCache {
    rows: usize,
    /// Post-ReLU output of each hidden layer, `rows × width`.
    acts: Vec<Vec<f32>>,
    /// `rows × out_dim`.
    pub out: Vec<f32>,
    scratch_a: Vec<f32>,
    scratch_b: Vec<f32>,
}

impl Mlp {
    /// PyTorch `nn.Linear` default init: weights and biases U(−1/√fan_in, 1/√fan_in).
    pub fn new(
        in_dim: usize,
        width: usize,
        depth: usize,
        skip: usize,
        out_dim: usize,
        rng: &mut impl Rng,
    ) -> Self {
        let skip = (skip + 1 < depth).then_some(skip);
        let mut layers = Vec::with_capacity(depth + 1);
        let mut off = 0;
        for l in 0..=depth {
            let fan_in = match l {
                0 => in_dim,
                l if Some(l - 1) == skip => in_dim + width,
                _ => width,
            };
            let fan_out = if l == depth { out_dim } else { width };
            layers.push(Layer {
                w_off: off,
                b_off: off + fan_in * fan_out,
                fan_in,
                fan_out,
            });
            off += fan_in * fan_out + fan_out;
        }
        let mut params = vec![0.0; off];
        for ly in &layers {
            let bound = 1.0 / (ly.fan_in as f32).sqrt();
            for p in &mut params[ly.w_off..ly.b_off + ly.fan_out] {
                *p = rng.gen_range(-bound..bound);
            }
        }
        Self {
            in_dim,
            width,
            depth,
            out_dim,
            skip,
            params,
            layers,
        }
    }

    pub fn num_params(&self) -> usize {
        self.params.len()
    }

    /// Multiply-adds per row of one forward pass (backward costs about twice this).
    pub fn macs_per_row(&self) -> usize {
        self.layers.iter().map(|l| l.fan_in * l.fan_out).sum()
    }

    fn weights(&self, l: usize) -> &[f32] {
        let ly = self.layers[l];
        &self.params[ly.w_off..ly.b_off]
    }

    fn bias(&self, l: usize) -> &[f32] {
        let ly = self.layers[l];
        &self.params[ly.b_off..ly.b_off + ly.fan_out]
    }

    /// Forward over `rows` rows of `input` (`rows × in_dim`); the result is `cache.out`.
    pub fn forward(&self, input: &[f32], rows: usize, cache: &mut MlpCache) {
        assert_eq!(input.len(), rows * self.in_dim, "MLP input size");
        cache.rows = rows;
        cache.acts.resize(self.depth, Vec::new());
        for l in 0..=self.depth {
            let (prev, rest) = cache.acts.split_at_mut(l.min(self.depth));
            let out: &mut Vec<f32> = if l == self.depth {
                &mut cache.out
            } else {
                &mut rest[0]
            };
            let h_in: &[f32] = if l == 0 { input } else { &prev[l - 1] };
            let fo = self.layers[l].fan_out;
            out.resize(rows * fo, 0.0);
            self.layer_forward(l, input, h_in, out, l < self.depth);
        }
    }

    /// `out = relu?(h_in·W_h [+ input·W_x] + b)` for layer `l`, parallel over row chunks.
    fn layer_forward(&self, l: usize, input: &[f32], h_in: &[f32], out: &mut [f32], relu: bool) {
        let ly = self.layers[l];
        let w = self.weights(l);
        let b = self.bias(l);
        let is_skip = l > 0 && Some(l - 1) == self.skip;
        let h_dim = if l == 0 { self.in_dim } else { self.width };
        let (w_x, w_h) = if is_skip {
            w.split_at(self.in_dim * ly.fan_out)
        } else {
            (&[][..], w)
        };
        out.par_chunks_mut(ROW_CHUNK * ly.fan_out)
            .enumerate()
            .for_each(|(c, o)| {
                let r0 = c * ROW_CHUNK;
                let n = o.len() / ly.fan_out;
                let hin = &h_in[r0 * h_dim..(r0 + n) * h_dim];
                matmul(
                    o,
                    Mat::row_major(hin, n, h_dim),
                    Mat::row_major(w_h, h_dim, ly.fan_out),
                    false,
                );
                if is_skip {
                    let xin = &input[r0 * self.in_dim..(r0 + n) * self.in_dim];
                    let wx = Mat::row_major(w_x, self.in_dim, ly.fan_out);
                    matmul(o, Mat::row_major(xin, n, self.in_dim), wx, true);
                }
                for row in o.chunks_exact_mut(ly.fan_out) {
                    for (v, bb) in row.iter_mut().zip(b) {
                        *v += bb;
                        if relu && *v < 0.0 {
                            *v = 0.0;
                        }
                    }
                }
            });
    }

    /// Gradient of the parameters given `d_out` (`rows × out_dim`) for the input of the
    /// last forward. `grad` is overwritten. No gradient w.r.t. the input: Deformable-3DGS
    /// feeds the field detached canonical means (DESIGN.md "Deformation").
    pub fn backward(
        &self,
        input: &[f32],
        d_out: &[f32],
        cache: &mut MlpCache,
        grad: &mut Vec<f32>,
    ) {
        let rows = cache.rows;
        assert_eq!(d_out.len(), rows * self.out_dim, "MLP d_out size");
        grad.clear();
        grad.resize(self.params.len(), 0.0);
        let mut dz = std::mem::take(&mut cache.scratch_a);
        let mut dh = std::mem::take(&mut cache.scratch_b);
        dz.clear();
        dz.extend_from_slice(d_out);
        for l in (0..=self.depth).rev() {
            if l < self.depth {
                // ReLU: the stored output is > 0 exactly where the pre-activation was.
                dz.par_chunks_mut(ROW_CHUNK * self.width)
                    .zip(cache.acts[l].par_chunks(ROW_CHUNK * self.width))
                    .for_each(|(d, a)| {
                        for (x, &y) in d.iter_mut().zip(a) {
                            if y <= 0.0 {
                                *x = 0.0;
                            }
                        }
                    });
            }
            let h_in: &[f32] = if l == 0 { input } else { &cache.acts[l - 1] };
            self.layer_param_grad(l, input, h_in, &dz, rows, grad);
            if l > 0 {
                self.layer_input_grad(l, &dz, rows, &mut dh);
                std::mem::swap(&mut dz, &mut dh);
            }
        }
        cache.scratch_a = dz;
        cache.scratch_b = dh;
    }

    /// dW = inputᵀ·dz and db = Σ_rows dz, summed over fixed row chunks in a fixed order.
    fn layer_param_grad(
        &self,
        l: usize,
        input: &[f32],
        h_in: &[f32],
        dz: &[f32],
        rows: usize,
        grad: &mut [f32],
    ) {
        let ly = self.layers[l];
        let is_skip = l > 0 && Some(l - 1) == self.skip;
        let h_dim = if l == 0 { self.in_dim } else { self.width };
        let fo = ly.fan_out;
        let n_chunks = rows.div_ceil(ROW_CHUNK * 8).max(1);
        let per = rows.div_ceil(n_chunks);
        let partials: Vec<Vec<f32>> = (0..n_chunks)
            .into_par_iter()
            .map(|c| {
                let r0 = (c * per).min(rows);
                let r1 = ((c + 1) * per).min(rows);
                let n = r1 - r0;
                let mut g = vec![0.0; ly.fan_in * fo + fo];
                let dzc = Mat::row_major(&dz[r0 * fo..r1 * fo], n, fo);
                let (gx, gh) =
                    g[..ly.fan_in * fo].split_at_mut(if is_skip { self.in_dim * fo } else { 0 });
                let hin = Mat::row_major(&h_in[r0 * h_dim..r1 * h_dim], n, h_dim);
                matmul(gh, hin.t(), dzc, false);
                if is_skip {
                    let xin =
                        Mat::row_major(&input[r0 * self.in_dim..r1 * self.in_dim], n, self.in_dim);
                    matmul(gx, xin.t(), dzc, false);
                }
                let gb = &mut g[ly.fan_in * fo..];
                for row in dz[r0 * fo..r1 * fo].chunks_exact(fo) {
                    for (b, d) in gb.iter_mut().zip(row) {
                        *b += d;
                    }
                }
                g
            })
            .collect();
        let dst = &mut grad[ly.w_off..ly.b_off + fo];
        for p in &partials {
            for (d, s) in dst.iter_mut().zip(p) {
                *d += s;
            }
        }
    }

    /// Gradient w.r.t. the hidden input of layer `l` (l ≥ 1): dh = dz·W_hᵀ.
    fn layer_input_grad(&self, l: usize, dz: &[f32], rows: usize, dh: &mut Vec<f32>) {
        let ly = self.layers[l];
        let is_skip = Some(l - 1) == self.skip;
        let w = self.weights(l);
        let w_h = if is_skip {
            &w[self.in_dim * ly.fan_out..]
        } else {
            w
        };
        let wm = Mat::row_major(w_h, self.width, ly.fan_out).t();
        dh.resize(rows * self.width, 0.0);
        dh.par_chunks_mut(ROW_CHUNK * self.width)
            .enumerate()
            .for_each(|(c, o)| {
                let r0 = c * ROW_CHUNK;
                let n = o.len() / self.width;
                let d = Mat::row_major(&dz[r0 * ly.fan_out..(r0 + n) * ly.fan_out], n, ly.fan_out);
                matmul(o, d, wm, false);
            });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn loss(mlp: &Mlp, x: &[f32], rows: usize, w: &[f32]) -> f64 {
        let mut c = MlpCache::default();
        mlp.forward(x, rows, &mut c);
        c.out
            .iter()
            .zip(w)
            .map(|(a, b)| (*a as f64) * (*b as f64))
            .sum()
    }

    /// Finite differences on every third parameter of a small MLP with a skip connection
    /// (f32 network, f64 loss). h = 1e-3 keeps ReLU-kink crossings rare (h = 1e-2 visibly
    /// biases FD here); the check is on the whole gradient vector: ‖fd − an‖/‖fd‖ < 2%.
    #[test]
    fn backward_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (ind, rows) = (5, 2100); // > 2 row chunks
        let mut mlp = Mlp::new(ind, 8, 4, 1, 3, &mut rng);
        assert_eq!(mlp.skip, Some(1));
        let x: Vec<f32> = (0..rows * ind).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let w: Vec<f32> = (0..rows * 3).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let mut c = MlpCache::default();
        mlp.forward(&x, rows, &mut c);
        let mut g = Vec::new();
        mlp.backward(&x, &w, &mut c, &mut g);
        let (mut diff, mut norm) = (0.0f64, 0.0f64);
        for i in (0..mlp.params.len()).step_by(3) {
            let p0 = mlp.params[i];
            let h = 1e-3;
            mlp.params[i] = p0 + h;
            let lp = loss(&mlp, &x, rows, &w);
            mlp.params[i] = p0 - h;
            let lm = loss(&mlp, &x, rows, &w);
            mlp.params[i] = p0;
            let fd = (lp - lm) / (2.0 * h as f64);
            diff += (fd - g[i] as f64).powi(2);
            norm += fd * fd;
        }
        let rel = (diff / norm).sqrt();
        assert!(rel < 2e-2, "relative gradient error {rel}");
    }

    #[test]
    fn forward_is_thread_count_independent_and_layout_matches() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mlp = Mlp::new(7, 16, 8, 4, 10, &mut rng);
        let n =
            7 * 16 + 16 + 4 * (16 * 16 + 16) + (23 * 16 + 16) + 2 * (16 * 16 + 16) + 16 * 10 + 10;
        assert_eq!(mlp.num_params(), n);
        let x: Vec<f32> = (0..3000 * 7).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let mut a = MlpCache::default();
        mlp.forward(&x, 3000, &mut a);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut b = MlpCache::default();
        pool.install(|| mlp.forward(&x, 3000, &mut b));
        assert_eq!(a.out, b.out);
    }
}
