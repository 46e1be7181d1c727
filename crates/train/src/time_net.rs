//! Deformable-3DGS's time network for D-NeRF scenes (`is_blender`, "better for D-NeRF
//! Dataset" in its `utils/time_utils.py`): γ(t) → Linear(·, W) → ReLU → Linear(W, K), whose
//! K outputs replace γ(t) in the field's input (and in its skip). t is the same for every
//! Gaussian of a frame, so the network runs on one row per iteration: it costs nothing
//! next to the field, and it is written out by hand here instead of on `gemm`.
//!
//! Its parameters live at the end of the field's flat parameter vector (after the MLP's
//! head, which never reads them), so one Adam state and one checkpoint tensor cover both.

use rand::Rng;

/// Layout of the network inside a parameter slice starting at `off`: W1 (`input × width`,
/// row-major as `Mlp`), b1, W2 (`width × out`), b2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimeNet {
    pub input: usize,
    pub width: usize,
    pub out: usize,
    pub off: usize,
}

/// Activations of one forward pass, kept for the backward pass.
#[derive(Clone, Debug, Default)]
pub struct TimeNetCache {
    x: Vec<f32>,
    hidden: Vec<f32>,
    pub out: Vec<f32>,
}

impl TimeNet {
    pub fn num_params(&self) -> usize {
        self.input * self.width + self.width + self.width * self.out + self.out
    }

    /// Appends freshly initialized parameters to `params` (PyTorch `nn.Linear` default:
    /// U(−1/√fan_in, 1/√fan_in) for weights and biases) and returns the layout.
    pub fn append(
        params: &mut Vec<f32>,
        input: usize,
        width: usize,
        out: usize,
        rng: &mut impl Rng,
    ) -> Self {
        let net = Self {
            input,
            width,
            out,
            off: params.len(),
        };
        for (fan_in, n) in [(input, input * width + width), (width, width * out + out)] {
            let bound = 1.0 / (fan_in as f32).sqrt();
            params.extend((0..n).map(|_| rng.gen_range(-bound..bound)));
        }
        net
    }

    /// Offsets of W1, b1, W2, b2 in the parameter vector.
    fn offsets(&self) -> [usize; 4] {
        let w1 = self.off;
        let b1 = w1 + self.input * self.width;
        let w2 = b1 + self.width;
        let b2 = w2 + self.width * self.out;
        [w1, b1, w2, b2]
    }

    /// `cache.out = W2ᵀ·relu(W1ᵀ·x + b1) + b2` for the single input row `x`.
    pub fn forward(&self, params: &[f32], x: &[f32], cache: &mut TimeNetCache) {
        assert_eq!(x.len(), self.input, "time network input size");
        let [w1, b1, w2, b2] = self.offsets();
        cache.x.clear();
        cache.x.extend_from_slice(x);
        cache.hidden.clear();
        cache.hidden.extend_from_slice(&params[b1..b1 + self.width]);
        for (i, &xi) in x.iter().enumerate() {
            let row = &params[w1 + i * self.width..][..self.width];
            for (h, w) in cache.hidden.iter_mut().zip(row) {
                *h += xi * w;
            }
        }
        cache.hidden.iter_mut().for_each(|h| *h = h.max(0.0));
        cache.out.clear();
        cache.out.extend_from_slice(&params[b2..b2 + self.out]);
        for (j, &hj) in cache.hidden.iter().enumerate() {
            let row = &params[w2 + j * self.out..][..self.out];
            for (o, w) in cache.out.iter_mut().zip(row) {
                *o += hj * w;
            }
        }
    }

    /// Writes the gradient of the network's parameters for `d_out = dL/d(out)` of the last
    /// forward into `grad` (the whole field's gradient vector; only this net's range).
    pub fn backward(&self, params: &[f32], cache: &TimeNetCache, d_out: &[f32], grad: &mut [f32]) {
        let [w1, b1, w2, b2] = self.offsets();
        grad[b2..b2 + self.out].copy_from_slice(d_out);
        let mut dh = vec![0.0f32; self.width];
        for (j, (&hj, dhj)) in cache.hidden.iter().zip(&mut dh).enumerate() {
            let row = &params[w2 + j * self.out..][..self.out];
            let g = &mut grad[w2 + j * self.out..][..self.out];
            for ((gw, &d), &w) in g.iter_mut().zip(d_out).zip(row) {
                *gw = hj * d;
                *dhj += w * d;
            }
            // ReLU: the stored output is > 0 exactly where the pre-activation was.
            if hj <= 0.0 {
                *dhj = 0.0;
            }
        }
        grad[b1..b1 + self.width].copy_from_slice(&dh);
        for (i, &xi) in cache.x.iter().enumerate() {
            let g = &mut grad[w1 + i * self.width..][..self.width];
            for (gw, &d) in g.iter_mut().zip(&dh) {
                *gw = xi * d;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn loss(net: &TimeNet, p: &[f32], x: &[f32], w: &[f32]) -> f64 {
        let mut c = TimeNetCache::default();
        net.forward(p, x, &mut c);
        c.out
            .iter()
            .zip(w)
            .map(|(a, b)| (*a as f64) * (*b as f64))
            .sum()
    }

    /// Central differences on every parameter (f32 net, f64 loss): relative error < 1%.
    #[test]
    fn backward_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut params = vec![9.0; 5]; // a prefix the net must leave alone
        let net = TimeNet::append(&mut params, 13, 16, 4, &mut rng);
        assert_eq!(params.len(), 5 + net.num_params());
        let x: Vec<f32> = (0..13).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let w: Vec<f32> = (0..4).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let mut c = TimeNetCache::default();
        net.forward(&params, &x, &mut c);
        let mut g = vec![0.0; params.len()];
        net.backward(&params, &c, &w, &mut g);
        assert!(g[..5].iter().all(|&v| v == 0.0));
        let n = params.len();
        let (rel, _) = crate::fd_check::relative_error(
            &mut params,
            |p, i| &mut p[i],
            |p| loss(&net, p, &x, &w),
            &g,
            5..n,
            1e-3,
        );
        assert!(rel < 1e-2, "relative gradient error {rel}");
    }
}
