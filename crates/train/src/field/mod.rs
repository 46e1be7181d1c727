//! The deformation field (Deformable-3DGS): (detached canonical mean, t) → (δx, δr, δs),
//! evaluated on a chosen subset of Gaussians (all, or those that can reach the view).

use crate::encoding::{encode_rows, encode_time, encoded_dim};
use crate::mlp::{Mlp, MlpCache, PackedRows};
use crate::time_net::{TimeNet, TimeNetCache};
use rand::Rng;

pub mod config;
pub use config::{FieldConfig, MAX_FIELD_PARAMS};

/// Outputs of the field head: δx (3), δr (4), δs (3).
pub const HEAD: usize = 10;

/// Per-Gaussian deformation of one iteration, `N·3`, `N·4`, `N·3`; zero where the field
/// was not evaluated. The same layout carries `dL/dδ` into [`DeformField::backward`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DeformOutput {
    pub dx: Vec<f32>,
    pub dr: Vec<f32>,
    pub ds: Vec<f32>,
}

impl DeformOutput {
    /// Resizes to `n` Gaussians and zeroes.
    pub fn reset(&mut self, n: usize) {
        for (v, k) in [(&mut self.dx, 3), (&mut self.dr, 4), (&mut self.ds, 3)] {
            v.clear();
            v.resize(n * k, 0.0);
        }
    }

    pub fn len(&self) -> usize {
        self.dx.len() / 3
    }

    pub fn is_empty(&self) -> bool {
        self.dx.is_empty()
    }
}

#[derive(Clone, Debug)]
pub struct DeformField {
    pub cfg: FieldConfig,
    /// The MLP; with a time network, its parameters follow the head in `mlp.params`.
    pub mlp: Mlp,
    time_net: Option<TimeNet>,
    time_cache: TimeNetCache,
    cache: MlpCache,
    enc: Vec<f32>,
    d_out: Vec<f32>,
    /// Gaussians evaluated by the last forward.
    rows: Vec<u32>,
    /// Scratch of the backward over the rows that received a gradient.
    packed: PackedRows,
    /// Reference path: the time features written into every row of the MLP's input
    /// instead of folded into the biases (`set_time_per_row`).
    time_per_row: bool,
}

impl DeformField {
    pub fn new(cfg: &FieldConfig, rng: &mut impl Rng) -> Self {
        let in_dim = encoded_dim(3, cfg.pos_freqs) + cfg.time_input_dim();
        let mut mlp = Mlp::new(in_dim, cfg.width, cfg.depth, cfg.skip, HEAD, rng);
        let head = mlp.head_range();
        mlp.params[head]
            .iter_mut()
            .for_each(|p| *p *= cfg.head_init_scale);
        let time_net = (cfg.time_net_width > 0).then(|| {
            let t_dim = encoded_dim(1, cfg.time_freqs);
            TimeNet::append(
                &mut mlp.params,
                t_dim,
                cfg.time_net_width,
                cfg.time_net_out,
                rng,
            )
        });
        Self {
            cfg: cfg.clone(),
            mlp,
            time_net,
            time_cache: TimeNetCache::default(),
            cache: MlpCache::default(),
            enc: Vec::new(),
            d_out: Vec::new(),
            rows: Vec::new(),
            packed: PackedRows::default(),
            time_per_row: false,
        }
    }

    /// With `true`, the time features go into every row of the MLP's input, as in
    /// Deformable-3DGS, instead of being folded once into the biases of the two layers
    /// that read the input (`Mlp::forward`'s shared columns). The results are equal up to
    /// the order of the sums; the per-row path is the reference that benchmarks and tests
    /// compare against.
    pub fn set_time_per_row(&mut self, per_row: bool) {
        self.time_per_row = per_row;
    }

    /// Evaluates the field at time `t` for the Gaussians `rows` of `means` and scatters
    /// the result into `out` (resized to N; zero elsewhere).
    pub fn forward(&mut self, means: &[f32], t: f32, rows: &[u32], out: &mut DeformOutput) {
        let n = means.len() / 3;
        out.reset(n);
        self.rows.clear();
        self.rows.extend_from_slice(rows);
        let mut t_feat = encode_time(t, self.cfg.time_freqs);
        if let Some(net) = &self.time_net {
            net.forward(&self.mlp.params, &t_feat, &mut self.time_cache);
            t_feat.clone_from(&self.time_cache.out);
        }
        // Every row shares t: its features cost one bias per layer, not a column per row.
        let (in_rows, shared) = if self.time_per_row {
            (&t_feat[..], &[][..])
        } else {
            (&[][..], &t_feat[..])
        };
        encode_rows(means, rows, in_rows, self.cfg.pos_freqs, &mut self.enc);
        self.mlp
            .forward(&self.enc, rows.len(), shared, &mut self.cache);
        for (o, &i) in self.cache.out.chunks_exact(HEAD).zip(rows) {
            let i = i as usize;
            out.dx[i * 3..i * 3 + 3].copy_from_slice(&o[0..3]);
            out.dr[i * 4..i * 4 + 4].copy_from_slice(&o[3..7]);
            if self.cfg.deform_scale {
                out.ds[i * 3..i * 3 + 3].copy_from_slice(&o[7..10]);
            }
        }
    }

    /// Gradient of the field's parameters given `dL/dδ` for the last forward.
    pub fn backward(&mut self, d_delta: &DeformOutput, grad: &mut Vec<f32>) {
        self.d_out.resize(self.rows.len() * HEAD, 0.0);
        for (o, &i) in self.d_out.chunks_exact_mut(HEAD).zip(&self.rows) {
            let i = i as usize;
            o[0..3].copy_from_slice(&d_delta.dx[i * 3..i * 3 + 3]);
            o[3..7].copy_from_slice(&d_delta.dr[i * 4..i * 4 + 4]);
            if self.cfg.deform_scale {
                o[7..10].copy_from_slice(&d_delta.ds[i * 3..i * 3 + 3]);
            } else {
                o[7..10].fill(0.0); // δs is not applied: no gradient reaches its head
            }
        }
        self.mlp.backward_nonzero(
            &self.enc,
            &self.d_out,
            &mut self.cache,
            &mut self.packed,
            grad,
        );
        if let Some(net) = &self.time_net {
            // Every row shares the time features: their gradient comes from the bias
            // gradients of the layers that read the input (`Mlp::shared_input_grad`).
            let px = encoded_dim(3, self.cfg.pos_freqs);
            let d_feat = self.mlp.shared_input_grad(grad, px..px + net.out);
            net.backward(&self.mlp.params, &self.time_cache, &d_feat, grad);
        }
    }

    /// Rows the last backward pass back-propagated: those with a nonzero `dL/dδ`.
    pub fn rows_with_gradient(&self) -> usize {
        self.packed.kept()
    }

    /// Gaussians evaluated by the last forward.
    pub fn rows(&self) -> &[u32] {
        &self.rows
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// With the time network on, the gradient of its parameters (through the shared time
    /// features and both input-reading layers) matches central differences.
    #[test]
    fn time_network_gradient_matches_finite_differences() {
        let cfg = FieldConfig {
            depth: 3,
            width: 8,
            skip: 1,
            pos_freqs: 2,
            time_freqs: 2,
            time_net_width: 6,
            time_net_out: 4,
            visible_only: false,
            head_init_scale: 1.0, // a nonzero δ for the check to see
            ..FieldConfig::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let mut f = DeformField::new(&cfg, &mut rng);
        let tail = 5 * 6 + 6 + 6 * 4 + 4;
        let n = 40;
        let means: Vec<f32> = (0..n * 3).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let rows: Vec<u32> = (0..n as u32).collect();
        let mut d = DeformOutput::default();
        d.reset(n);
        for v in d.dx.iter_mut().chain(&mut d.dr).chain(&mut d.ds) {
            *v = rng.gen_range(-1.0..1.0);
        }
        let loss = |f: &mut DeformField| {
            let mut out = DeformOutput::default();
            f.forward(&means, 0.37, &rows, &mut out);
            let pairs = [(&out.dx, &d.dx), (&out.dr, &d.dr), (&out.ds, &d.ds)];
            pairs
                .iter()
                .flat_map(|(a, b)| a.iter().zip(b.iter()))
                .map(|(a, b)| *a as f64 * *b as f64)
                .sum::<f64>()
        };
        loss(&mut f);
        let mut g = Vec::new();
        f.backward(&d, &mut g);
        let p = f.mlp.num_params();
        assert_eq!(g.len(), p);
        let (rel, norm) = crate::fd_check::relative_error(
            &mut f,
            |f, i| &mut f.mlp.params[i],
            loss,
            &g,
            p - tail..p,
            1e-3,
        );
        assert!(norm > 0.0);
        assert!(rel < 2e-2, "relative gradient error {rel}");
    }

    /// The time features folded into the biases give the field's outputs and its whole
    /// gradient (time network included) of the reference path that writes them into every
    /// row, up to the order of the sums; with and without the time network.
    #[test]
    fn time_in_the_bias_equals_time_per_row() {
        for time_net_width in [0, 6] {
            let cfg = FieldConfig {
                depth: 4,
                width: 16,
                skip: 2,
                pos_freqs: 3,
                time_freqs: 2,
                time_net_width,
                time_net_out: 4,
                head_init_scale: 1.0,
                ..FieldConfig::default()
            };
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
            let mut f = DeformField::new(&cfg, &mut rng);
            let n = 3000;
            let means: Vec<f32> = (0..n * 3).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let rows: Vec<u32> = (0..n as u32).filter(|i| i % 3 != 1).collect();
            let mut d = DeformOutput::default();
            d.reset(n);
            for v in d.dx.iter_mut().chain(&mut d.dr).chain(&mut d.ds) {
                *v = rng.gen_range(-1.0..1.0);
            }
            let mut run = |per_row: bool| {
                f.set_time_per_row(per_row);
                let (mut out, mut g) = (DeformOutput::default(), Vec::new());
                f.forward(&means, 0.61, &rows, &mut out);
                f.backward(&d, &mut g);
                ([out.dx, out.dr, out.ds].concat(), g)
            };
            let (out_a, g_a) = run(true);
            let (out_b, g_b) = run(false);
            for (a, b, what) in [(&out_a, &out_b, "δ"), (&g_a, &g_b, "gradient")] {
                let norm = a.iter().map(|v| v * v).sum::<f32>().sqrt();
                let diff = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>();
                assert!(norm > 0.0);
                assert!(
                    diff.sqrt() <= 1e-5 * norm,
                    "{what}, time net {time_net_width}: {} vs {norm}",
                    diff.sqrt()
                );
            }
        }
    }

    /// `head_init_scale = 0` starts the field at δ = 0 everywhere, and it still learns:
    /// the head's weights get a gradient from the (nonzero) hidden activations.
    #[test]
    fn a_zero_head_starts_at_no_deformation_and_learns() {
        let cfg = FieldConfig {
            depth: 2,
            width: 16,
            skip: 0,
            head_init_scale: 0.0,
            ..FieldConfig::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let mut f = DeformField::new(&cfg, &mut rng);
        let means = [0.1, 0.2, 0.3, -0.4, 0.5, 0.0];
        let mut out = DeformOutput::default();
        f.forward(&means, 0.3, &[0, 1], &mut out);
        assert!(out
            .dx
            .iter()
            .chain(&out.dr)
            .chain(&out.ds)
            .all(|&v| v == 0.0));
        let mut d = DeformOutput::default();
        d.reset(2);
        d.dx.fill(0.5);
        let mut g = Vec::new();
        f.backward(&d, &mut g);
        let head = f.mlp.head_range();
        assert!(g[head].iter().any(|&v| v != 0.0));
    }

    /// With `deform_scale = false`, δs is zero and a gradient on it changes nothing.
    #[test]
    fn scale_offset_can_be_switched_off() {
        let cfg = FieldConfig {
            depth: 2,
            width: 16,
            skip: 0,
            deform_scale: false,
            head_init_scale: 1.0, // a nonzero δ for the check to see
            ..FieldConfig::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut f = DeformField::new(&cfg, &mut rng);
        let means = [0.1, 0.2, 0.3, -0.4, 0.5, 0.0];
        let mut out = DeformOutput::default();
        f.forward(&means, 0.3, &[0, 1], &mut out);
        assert!(out.dx.iter().any(|&v| v != 0.0));
        assert!(out.ds.iter().all(|&v| v == 0.0));
        let mut d = DeformOutput::default();
        d.reset(2);
        d.dx.fill(0.5);
        let (mut g0, mut g1) = (Vec::new(), Vec::new());
        f.backward(&d, &mut g0);
        d.ds.fill(7.0);
        f.backward(&d, &mut g1);
        assert_eq!(g0, g1);
        // On (the default), δs is the head's output and its gradient counts.
        f.cfg.deform_scale = true;
        f.forward(&means, 0.3, &[0, 1], &mut out);
        assert!(out.ds.iter().any(|&v| v != 0.0));
        f.backward(&d, &mut g1);
        assert_ne!(g0, g1);
    }
}
