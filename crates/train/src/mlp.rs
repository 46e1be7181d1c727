//! The deformation MLP of Deformable-3DGS (`DeformNetwork`): `depth` ReLU layers of
//! `width`, the encoded input concatenated to the output of layer `skip` (`skips=[D//2]`),
//! and a linear head (δx, δr, δs stacked, identical to three separate `nn.Linear` heads).
//! Forward and backward are hand-written on `gemm` (docs/architecture.md, "Crates": no ML
//! framework on the training path), parallel over fixed row chunks so results are
//! thread-count independent.

use crate::gemm_util::{matmul, Mat};
use rand::Rng;
use rayon::prelude::*;
use std::ops::Range;

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
    /// A caller may append parameters of its own after the head (the field's time network,
    /// `crate::time_net`): no layer reads them, and their gradient here is zero.
    pub params: Vec<f32>,
    layers: Vec<Layer>,
}

/// Activations kept from the forward pass for the backward pass.
#[derive(Clone, Debug, Default)]
pub struct MlpCache {
    rows: usize,
    /// Input columns shared by every row (see [`Mlp::forward`]), kept for the backward.
    shared: Vec<f32>,
    /// Each layer's bias with the shared columns' contribution folded in, layer after
    /// layer (`fan_out` values each).
    bias: Vec<f32>,
    /// Post-ReLU outputs of the hidden layers, chunk-major: row chunk `c` (ROW_CHUNK rows,
    /// `n` in the last) holds `depth` blocks of `n × width`, layer after layer, so that one
    /// chunk's whole pass stays in cache.
    acts: Vec<f32>,
    /// `rows × out_dim`.
    pub out: Vec<f32>,
    /// Backward jobs' buffers, reused across calls: partial parameter gradient and two
    /// chunk-sized scratch buffers for dL/dz and dL/dh.
    jobs: Vec<JobBuffers>,
}

/// Scratch of [`Mlp::backward_nonzero`]: the rows it kept, packed.
#[derive(Clone, Debug, Default)]
pub struct PackedRows {
    keep: Vec<usize>,
    input: Vec<f32>,
    d_out: Vec<f32>,
    cache: MlpCache,
}

impl PackedRows {
    /// Rows the last [`Mlp::backward_nonzero`] back-propagated (all when it did not pack).
    pub fn kept(&self) -> usize {
        self.keep.len()
    }
}

#[derive(Clone, Debug, Default)]
struct JobBuffers {
    grad: Vec<f32>,
    dz: Vec<f32>,
    dh: Vec<f32>,
}

/// Row chunks per backward job: each job owns one partial parameter gradient, summed in
/// job order at the end (fixed by the row count, so thread-count independent).
const CHUNKS_PER_JOB: usize = 8;

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

    /// Where the head's weights and bias lie in `params`.
    pub fn head_range(&self) -> std::ops::Range<usize> {
        let ly = self.layers[self.depth];
        ly.w_off..ly.b_off + ly.fan_out
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

    /// Forward over `rows` rows; the result is `cache.out`. The input's last
    /// `shared.len()` columns hold the same values in every row (the field's time
    /// features): they are passed once in `shared` and folded into the biases of the
    /// layers that read the input (`b + shared·W_shared`), so `input` holds only the
    /// other columns (`rows × (in_dim − shared.len())`). With `shared` empty every column
    /// is per row. Equal to feeding the shared values in every row up to the order of the
    /// sums.
    /// Chunk-major: each chunk of ROW_CHUNK rows goes through every layer before the next
    /// (its activations stay in L2 instead of streaming `rows × width` per layer).
    pub fn forward(&self, input: &[f32], rows: usize, shared: &[f32], cache: &mut MlpCache) {
        let per_row = self.per_row_dim(shared.len());
        assert_eq!(input.len(), rows * per_row, "MLP input size");
        cache.rows = rows;
        cache.shared.clear();
        cache.shared.extend_from_slice(shared);
        self.fold_shared(shared, &mut cache.bias);
        let (w, depth) = (self.width, self.depth);
        cache.acts.resize(rows * w * depth, 0.0);
        cache.out.resize(rows * self.out_dim, 0.0);
        let bias = &cache.bias;
        cache
            .out
            .par_chunks_mut(ROW_CHUNK * self.out_dim)
            .zip(cache.acts.par_chunks_mut(ROW_CHUNK * w * depth))
            .enumerate()
            .for_each(|(c, (out, acts))| {
                let n = out.len() / self.out_dim;
                let x = &input[c * ROW_CHUNK * per_row..][..n * per_row];
                for l in 0..=depth {
                    let (prev, rest) = acts.split_at_mut(l.min(depth) * n * w);
                    let h_in = if l == 0 { x } else { &prev[(l - 1) * n * w..] };
                    let o = if l == depth {
                        &mut *out
                    } else {
                        &mut rest[..n * w]
                    };
                    let b = &bias[self.bias_offset(l)..][..self.layers[l].fan_out];
                    self.layer_forward(l, per_row, x, h_in, n, o, b, l < depth);
                }
            });
    }

    /// Columns of the input given per row when `shared` of them are shared.
    fn per_row_dim(&self, shared: usize) -> usize {
        assert!(shared <= self.in_dim, "more shared columns than inputs");
        self.in_dim - shared
    }

    /// Whether layer `l` reads the encoded input: the first, and the one after the skip.
    fn reads_input(&self, l: usize) -> bool {
        l == 0 || Some(l - 1) == self.skip
    }

    /// Where layer `l`'s bias starts in [`MlpCache::bias`].
    fn bias_offset(&self, l: usize) -> usize {
        self.layers[..l].iter().map(|ly| ly.fan_out).sum()
    }

    /// `out` = every layer's bias, plus `Σ_c shared[c]·W[per_row + c, ·]` for the layers
    /// that read the input (the weight rows of the shared columns follow the per-row ones
    /// in both the first and the skip layer).
    fn fold_shared(&self, shared: &[f32], out: &mut Vec<f32>) {
        let per_row = self.per_row_dim(shared.len());
        out.clear();
        for (l, ly) in self.layers.iter().enumerate() {
            let start = out.len();
            out.extend_from_slice(self.bias(l));
            if !self.reads_input(l) {
                continue;
            }
            let b = &mut out[start..];
            for (c, &s) in shared.iter().enumerate() {
                let w = &self.params[ly.w_off + (per_row + c) * ly.fan_out..][..ly.fan_out];
                for (b, &w) in b.iter_mut().zip(w) {
                    *b += s * w;
                }
            }
        }
    }

    /// `out = relu?(h_in·W_h [+ x·W_x] + b)` for layer `l` over `n` rows, `x` holding
    /// `per_row` columns and `b` the bias with the shared columns folded in.
    #[allow(clippy::too_many_arguments)]
    fn layer_forward(
        &self,
        l: usize,
        per_row: usize,
        x: &[f32],
        h_in: &[f32],
        n: usize,
        o: &mut [f32],
        b: &[f32],
        relu: bool,
    ) {
        let fo = self.layers[l].fan_out;
        let (w_x, w_h) = self.split_weights(l, per_row);
        let h_dim = if l == 0 { per_row } else { self.width };
        let hin = Mat::row_major(&h_in[..n * h_dim], n, h_dim);
        matmul(o, hin, Mat::row_major(w_h, h_dim, fo), false);
        if !w_x.is_empty() {
            let wx = Mat::row_major(w_x, per_row, fo);
            matmul(o, Mat::row_major(x, n, per_row), wx, true);
        }
        for row in o.chunks_exact_mut(fo) {
            for (v, bb) in row.iter_mut().zip(b) {
                let s = *v + bb;
                *v = if relu && s < 0.0 { 0.0 } else { s };
            }
        }
    }

    /// Layer `l`'s weight rows that multiply per-row values, as ranges of its weights:
    /// those of the re-fed input (skip layer only, else empty) and those of the layer's
    /// main input (the previous layer's output; for layer 0 the input itself). The rows
    /// of shared columns (`per_row..in_dim` of the input's rows) are in neither: they are
    /// folded into the bias. The first range ends before the second starts.
    fn weight_rows(&self, l: usize, per_row: usize) -> (Range<usize>, Range<usize>) {
        let ly = self.layers[l];
        let (fo, all) = (ly.fan_out, ly.fan_in * ly.fan_out);
        if l == 0 {
            (0..0, 0..per_row * fo)
        } else if self.reads_input(l) {
            (0..per_row * fo, self.in_dim * fo..all)
        } else {
            (0..0, 0..all)
        }
    }

    /// Layer `l`'s weights at [`Self::weight_rows`].
    fn split_weights(&self, l: usize, per_row: usize) -> (&[f32], &[f32]) {
        let w = self.weights(l);
        let (x, h) = self.weight_rows(l, per_row);
        (&w[x], &w[h])
    }

    /// Gradient of the parameters given `d_out` (`rows × out_dim`) for the input of the
    /// last forward (its per-row columns in `input`, as given to it). `grad` is
    /// overwritten. The weight rows of shared columns get `shared[c]·Σ_rows dz`, i.e.
    /// `shared[c]` times the layer's bias gradient. No gradient w.r.t. the input: Deformable-3DGS
    /// feeds the field detached canonical means (docs/architecture.md "Deformation").
    /// Chunk-major like the forward pass; each job of CHUNKS_PER_JOB chunks sums into its
    /// own partial gradient, and the partials are added in job order.
    pub fn backward(
        &self,
        input: &[f32],
        d_out: &[f32],
        cache: &mut MlpCache,
        grad: &mut Vec<f32>,
    ) {
        let rows = cache.rows;
        assert_eq!(d_out.len(), rows * self.out_dim, "MLP d_out size");
        let per_row = self.per_row_dim(cache.shared.len());
        assert_eq!(input.len(), rows * per_row, "MLP input size");
        let job_rows = ROW_CHUNK * CHUNKS_PER_JOB;
        let jobs = rows.div_ceil(job_rows).max(1);
        let MlpCache {
            acts,
            jobs: bufs,
            shared,
            ..
        } = cache;
        bufs.resize_with(jobs, JobBuffers::default);
        bufs.par_iter_mut().enumerate().for_each(|(j, b)| {
            b.grad.clear();
            b.grad.resize(self.params.len(), 0.0);
            let (r0, r1) = (j * job_rows, ((j + 1) * job_rows).min(rows));
            for c0 in (r0..r1).step_by(ROW_CHUNK) {
                let n = (r1 - c0).min(ROW_CHUNK);
                self.chunk_backward(per_row, input, d_out, acts, c0, n, b);
            }
        });
        grad.clear();
        grad.resize(self.params.len(), 0.0);
        for b in bufs.iter() {
            for (d, s) in grad.iter_mut().zip(&b.grad) {
                *d += s;
            }
        }
        self.shared_weight_grad(shared, grad);
    }

    /// dW of the shared columns' weight rows: `Σ_rows shared[c]·dz = shared[c]·db`.
    fn shared_weight_grad(&self, shared: &[f32], grad: &mut [f32]) {
        let per_row = self.per_row_dim(shared.len());
        for (l, ly) in self.layers.iter().enumerate() {
            if !self.reads_input(l) {
                continue;
            }
            let fo = ly.fan_out;
            let (gw, gb) = grad[ly.w_off..ly.b_off + fo].split_at_mut(ly.fan_in * fo);
            for (c, &s) in shared.iter().enumerate() {
                let row = &mut gw[(per_row + c) * fo..][..fo];
                for (g, &d) in row.iter_mut().zip(gb.iter()) {
                    *g = s * d;
                }
            }
        }
    }

    /// [`Self::backward`] over only the rows whose `d_out` is not all zero, packed into
    /// `packed` (scratch reused across calls). A zero row adds exactly nothing to any
    /// parameter's gradient (its dL/dz is zero through every layer), and in training most
    /// rows are zero: Gaussians the field moved that no pixel composited (hidden behind
    /// others, transparent, or outside every tile they were binned to). Equal to the full
    /// backward up to the order of the sums (packed rows fall in other chunks), and
    /// thread-count independent like it.
    pub fn backward_nonzero(
        &self,
        input: &[f32],
        d_out: &[f32],
        cache: &mut MlpCache,
        packed: &mut PackedRows,
        grad: &mut Vec<f32>,
    ) {
        let rows = cache.rows;
        let per_row = self.per_row_dim(cache.shared.len());
        packed.keep.clear();
        packed.keep.extend(
            d_out
                .chunks_exact(self.out_dim)
                .enumerate()
                .filter(|(_, d)| d.iter().any(|&v| v != 0.0))
                .map(|(r, _)| r),
        );
        // Packing costs a copy of each kept row's activations: not worth it when few drop.
        if packed.keep.len() * 10 >= rows * 9 {
            return self.backward(input, d_out, cache, grad);
        }
        let PackedRows {
            keep,
            input: p_in,
            d_out: p_dout,
            cache: p_cache,
        } = packed;
        p_in.clear();
        p_dout.clear();
        for &r in keep.iter() {
            p_in.extend_from_slice(&input[r * per_row..(r + 1) * per_row]);
            p_dout.extend_from_slice(&d_out[r * self.out_dim..(r + 1) * self.out_dim]);
        }
        self.gather_acts(cache, keep, p_cache);
        self.backward(p_in, p_dout, p_cache, grad);
    }

    /// dL/d(input column c) for the columns `cols` when every row holds the same value in
    /// them (the field's time features): `Σ_rows dz·Wᵀ = (Σ_rows dz)·Wᵀ`, and `Σ_rows dz`
    /// of a layer is its bias gradient. So it is read from `grad` (the last backward's
    /// result) and the rows of the two layers that see the input (the first and the skip),
    /// at no cost per row.
    pub fn shared_input_grad(&self, grad: &[f32], cols: std::ops::Range<usize>) -> Vec<f32> {
        let mut out = vec![0.0f32; cols.len()];
        for l in (0..=self.depth).filter(|&l| self.reads_input(l)) {
            let ly = self.layers[l];
            let gb = &grad[ly.b_off..ly.b_off + ly.fan_out];
            for (o, c) in out.iter_mut().zip(cols.clone()) {
                let w = &self.params[ly.w_off + c * ly.fan_out..][..ly.fan_out];
                *o += w.iter().zip(gb).map(|(a, b)| a * b).sum::<f32>();
            }
        }
        out
    }

    /// `out` = the activations of rows `keep` (ascending) of `cache`, in the chunk-major
    /// layout a forward pass over those rows alone would have written.
    fn gather_acts(&self, cache: &MlpCache, keep: &[usize], out: &mut MlpCache) {
        let (w, depth, rows, m) = (self.width, self.depth, cache.rows, keep.len());
        // Offset of (row r of a pass over `total` rows, layer l) in the chunk-major layout.
        let at = |r: usize, l: usize, total: usize| {
            let c = r / ROW_CHUNK;
            let n = (total - c * ROW_CHUNK).min(ROW_CHUNK);
            c * ROW_CHUNK * w * depth + l * n * w + (r % ROW_CHUNK) * w
        };
        out.rows = m;
        out.shared.clone_from(&cache.shared);
        out.acts.resize(m * w * depth, 0.0);
        out.acts
            .par_chunks_mut(ROW_CHUNK * w * depth)
            .enumerate()
            .for_each(|(c, chunk)| {
                let base = c * ROW_CHUNK * w * depth;
                let k1 = ((c + 1) * ROW_CHUNK).min(m);
                for (k, &r) in keep.iter().enumerate().take(k1).skip(c * ROW_CHUNK) {
                    for l in 0..depth {
                        let (d, s) = (at(k, l, m) - base, at(r, l, rows));
                        chunk[d..d + w].copy_from_slice(&cache.acts[s..s + w]);
                    }
                }
            });
    }

    /// Backward of the `n` rows starting at `c0` (one forward chunk) into `b.grad`.
    #[allow(clippy::too_many_arguments)]
    fn chunk_backward(
        &self,
        per_row: usize,
        input: &[f32],
        d_out: &[f32],
        acts: &[f32],
        c0: usize,
        n: usize,
        b: &mut JobBuffers,
    ) {
        let JobBuffers { grad: g, dz, dh } = b;
        let (w, depth) = (self.width, self.depth);
        let acts = &acts[c0 * w * depth..][..n * w * depth];
        let x = &input[c0 * per_row..][..n * per_row];
        dz.clear();
        dz.extend_from_slice(&d_out[c0 * self.out_dim..][..n * self.out_dim]);
        for l in (0..=depth).rev() {
            if l < depth {
                // ReLU: the stored output is > 0 exactly where the pre-activation was.
                // A select with an unconditional store, not `if a <= 0 { *d = 0 }`: the
                // conditional store compiled to a branch on the sign pattern, which
                // mispredicts about half the time (7 % of a trained-state iteration;
                // docs/performance.md, "v7").
                for (d, &a) in dz.iter_mut().zip(&acts[l * n * w..][..n * w]) {
                    *d = if a <= 0.0 { 0.0 } else { *d };
                }
            }
            let h_in = if l == 0 {
                x
            } else {
                &acts[(l - 1) * n * w..][..n * w]
            };
            self.layer_param_grad(l, per_row, x, h_in, dz, n, g);
            if l > 0 {
                let ly = self.layers[l];
                let (_, w_h) = self.split_weights(l, per_row);
                dh.resize(n * w, 0.0);
                let d = Mat::row_major(dz, n, ly.fan_out);
                matmul(dh, d, Mat::row_major(w_h, w, ly.fan_out).t(), false);
                std::mem::swap(dz, dh);
            }
        }
    }

    /// Adds dW = inputᵀ·dz (the per-row input rows; shared ones are done once by
    /// [`Self::shared_weight_grad`]) and db = Σ_rows dz of layer `l` over `n` rows into `g`.
    #[allow(clippy::too_many_arguments)]
    fn layer_param_grad(
        &self,
        l: usize,
        per_row: usize,
        x: &[f32],
        h_in: &[f32],
        dz: &[f32],
        n: usize,
        g: &mut [f32],
    ) {
        let ly = self.layers[l];
        let fo = ly.fan_out;
        let h_dim = if l == 0 { per_row } else { self.width };
        let dzm = Mat::row_major(dz, n, fo);
        let (gw, gb) = g[ly.w_off..ly.b_off + fo].split_at_mut(ly.fan_in * fo);
        let (x_rows, h_rows) = self.weight_rows(l, per_row);
        let (x_part, h_part) = gw.split_at_mut(h_rows.start);
        let (gx, gh) = (&mut x_part[x_rows], &mut h_part[..h_rows.len()]);
        matmul(gh, Mat::row_major(h_in, n, h_dim).t(), dzm, true);
        if !gx.is_empty() {
            matmul(gx, Mat::row_major(x, n, per_row).t(), dzm, true);
        }
        for row in dz.chunks_exact(fo) {
            for (b, d) in gb.iter_mut().zip(row) {
                *b += d;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn loss(mlp: &Mlp, x: &[f32], rows: usize, w: &[f32]) -> f64 {
        let mut c = MlpCache::default();
        mlp.forward(x, rows, &[], &mut c);
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
        mlp.forward(&x, rows, &[], &mut c);
        let mut g = Vec::new();
        mlp.backward(&x, &w, &mut c, &mut g);
        let n = mlp.params.len();
        let (rel, _) = crate::fd_check::relative_error(
            &mut mlp,
            |m, i| &mut m.params[i],
            |m| loss(m, &x, rows, &w),
            &g,
            (0..n).step_by(3),
            1e-3,
        );
        assert!(rel < 2e-2, "relative gradient error {rel}");
    }

    /// The input gradient of columns that hold one value in every row, from the bias
    /// gradients, against central differences of that shared value.
    #[test]
    fn shared_input_grad_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (ind, rows) = (6, 700);
        let mlp = Mlp::new(ind, 12, 4, 1, 3, &mut rng);
        let mut x: Vec<f32> = (0..rows * ind).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let shared = [0.3f32, -0.6];
        for r in x.chunks_exact_mut(ind) {
            r[4..].copy_from_slice(&shared);
        }
        let w: Vec<f32> = (0..rows * 3).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let mut c = MlpCache::default();
        mlp.forward(&x, rows, &[], &mut c);
        let mut g = Vec::new();
        mlp.backward(&x, &w, &mut c, &mut g);
        let an = mlp.shared_input_grad(&g, 4..6);
        for (k, &a) in an.iter().enumerate() {
            let at = |v: f32| {
                let mut y = x.clone();
                y.chunks_exact_mut(ind).for_each(|r| r[4 + k] = v);
                loss(&mlp, &y, rows, &w)
            };
            let fd = (at(shared[k] + 1e-3) - at(shared[k] - 1e-3)) / 2e-3;
            assert!(
                (fd - a as f64).abs() < 2e-2 * fd.abs().max(1.0),
                "column {k}: {fd} vs {a}"
            );
        }
    }

    /// Shared columns folded into the biases: outputs and every parameter gradient (the
    /// shared columns' weight rows included, full and packed backward) equal those of
    /// the same columns given in every row, up to the order of the sums.
    #[test]
    fn shared_columns_equal_the_same_columns_per_row() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let (ind, n_shared, rows) = (9, 3, ROW_CHUNK * CHUNKS_PER_JOB + 500);
        let mlp = Mlp::new(ind, 16, 4, 1, 10, &mut rng);
        let shared: Vec<f32> = (0..n_shared).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let own: Vec<f32> = (0..rows * (ind - n_shared))
            .map(|_| rng.gen_range(-1.0..1.0))
            .collect();
        let full: Vec<f32> = own
            .chunks_exact(ind - n_shared)
            .flat_map(|r| r.iter().chain(&shared).copied())
            .collect();
        // Half the rows without gradient, so that the packed path runs too.
        let d: Vec<f32> = (0..rows * 10)
            .map(|i| {
                if (i / 10) % 2 == 0 {
                    0.0
                } else {
                    rng.gen_range(-1.0..1.0)
                }
            })
            .collect();
        let close = |a: &[f32], b: &[f32], what: &str| {
            assert_eq!(a.len(), b.len());
            let norm = a.iter().map(|v| v * v).sum::<f32>().sqrt();
            let diff = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>();
            assert!(
                diff.sqrt() <= 1e-5 * norm,
                "{what}: {} vs {norm}",
                diff.sqrt()
            );
            assert!(norm > 0.0, "{what} is zero");
        };
        let (mut a, mut b) = (MlpCache::default(), MlpCache::default());
        mlp.forward(&full, rows, &[], &mut a);
        mlp.forward(&own, rows, &shared, &mut b);
        close(&a.out, &b.out, "output");
        let (mut ga, mut gb) = (Vec::new(), Vec::new());
        mlp.backward(&full, &d, &mut a, &mut ga);
        mlp.backward(&own, &d, &mut b, &mut gb);
        close(&ga, &gb, "gradient");
        let (mut pa, mut pb) = (PackedRows::default(), PackedRows::default());
        mlp.backward_nonzero(&full, &d, &mut a, &mut pa, &mut ga);
        mlp.backward_nonzero(&own, &d, &mut b, &mut pb, &mut gb);
        assert_eq!(pb.kept(), rows / 2);
        close(&ga, &gb, "packed gradient");
        // The shared columns' weight rows of both input-reading layers are nonzero.
        for l in [0, 2] {
            let ly = mlp.layers[l];
            let rows_c = &gb[ly.w_off + (ind - n_shared) * ly.fan_out..][..n_shared * ly.fan_out];
            assert!(rows_c.iter().all(|&v| v != 0.0), "layer {l}");
        }
    }

    /// Zero rows of dL/dout dropped: the gradient equals the full backward's up to
    /// summation order, at every share of zero rows (packed and not).
    #[test]
    fn backward_over_nonzero_rows_equals_the_full_one() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (ind, rows) = (6, 2 * ROW_CHUNK * CHUNKS_PER_JOB + 300);
        let mlp = Mlp::new(ind, 16, 4, 1, 10, &mut rng);
        let x: Vec<f32> = (0..rows * ind).map(|_| rng.gen_range(-1.0..1.0)).collect();
        for zero_share in [0.0, 0.5, 0.97] {
            let d: Vec<f32> = (0..rows)
                .flat_map(|_| {
                    let zero = rng.gen::<f64>() < zero_share;
                    (0..10)
                        .map(|_| if zero { 0.0 } else { rng.gen_range(-1.0..1.0) })
                        .collect::<Vec<f32>>()
                })
                .collect();
            let mut c = MlpCache::default();
            mlp.forward(&x, rows, &[], &mut c);
            let (mut full, mut part) = (Vec::new(), Vec::new());
            mlp.backward(&x, &d, &mut c, &mut full);
            let mut packed = PackedRows::default();
            mlp.backward_nonzero(&x, &d, &mut c, &mut packed, &mut part);
            let live = d.chunks(10).filter(|r| r.iter().any(|&v| v != 0.0)).count();
            assert_eq!(packed.kept(), live);
            let norm = full.iter().map(|v| v * v).sum::<f32>().sqrt();
            let diff = full
                .iter()
                .zip(&part)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f32>()
                .sqrt();
            assert!(diff <= 1e-5 * norm, "share {zero_share}: {diff} vs {norm}");
        }
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
        mlp.forward(&x, 3000, &[], &mut a);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut b = MlpCache::default();
        pool.install(|| mlp.forward(&x, 3000, &[], &mut b));
        assert_eq!(a.out, b.out);
        // The backward too: 3000 rows are several chunks but one job, so also check a
        // multi-job size.
        let rows = 2 * ROW_CHUNK * CHUNKS_PER_JOB + 77;
        let x: Vec<f32> = (0..rows * 7).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let d: Vec<f32> = (0..rows * 10).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let grads = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let (mut c, mut g) = (MlpCache::default(), Vec::new());
                mlp.forward(&x, rows, &[], &mut c);
                mlp.backward(&x, &d, &mut c, &mut g);
                g
            })
        };
        let g1 = grads(1);
        assert!(g1.iter().any(|&v| v != 0.0));
        assert_eq!(g1, grads(3));
    }
}
