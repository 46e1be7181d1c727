//! The deformation field (Deformable-3DGS): (detached canonical mean, t) → (δx, δr, δs),
//! evaluated on a chosen subset of Gaussians (all, or those that can reach the view).

use crate::config::FieldConfig;
use crate::encoding::{encode_rows, encoded_dim};
use crate::mlp::{Mlp, MlpCache, PackedRows};
use rand::Rng;

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
    pub mlp: Mlp,
    cache: MlpCache,
    enc: Vec<f32>,
    d_out: Vec<f32>,
    /// Gaussians evaluated by the last forward.
    rows: Vec<u32>,
    /// Scratch of the backward over the rows that received a gradient.
    packed: PackedRows,
}

impl DeformField {
    pub fn new(cfg: &FieldConfig, rng: &mut impl Rng) -> Self {
        let in_dim = encoded_dim(3, cfg.pos_freqs) + encoded_dim(1, cfg.time_freqs);
        Self {
            cfg: cfg.clone(),
            mlp: Mlp::new(in_dim, cfg.width, cfg.depth, cfg.skip, HEAD, rng),
            cache: MlpCache::default(),
            enc: Vec::new(),
            d_out: Vec::new(),
            rows: Vec::new(),
            packed: PackedRows::default(),
        }
    }

    /// Evaluates the field at time `t` for the Gaussians `rows` of `means` and scatters
    /// the result into `out` (resized to N; zero elsewhere).
    pub fn forward(&mut self, means: &[f32], t: f32, rows: &[u32], out: &mut DeformOutput) {
        let n = means.len() / 3;
        out.reset(n);
        self.rows.clear();
        self.rows.extend_from_slice(rows);
        encode_rows(
            means,
            rows,
            t,
            self.cfg.pos_freqs,
            self.cfg.time_freqs,
            &mut self.enc,
        );
        self.mlp.forward(&self.enc, rows.len(), &mut self.cache);
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

    /// With `deform_scale = false`, δs is zero and a gradient on it changes nothing.
    #[test]
    fn scale_offset_can_be_switched_off() {
        let cfg = FieldConfig {
            depth: 2,
            width: 16,
            skip: 0,
            deform_scale: false,
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
