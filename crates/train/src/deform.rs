//! Applying the field's δ to the canonical Gaussians and the chain rule back
//! (docs/architecture.md "Deformation", Deformable-3DGS `render`): mean + δx,
//! normalize(q) + δr, exp(log_scale) + δs. The rasterizer normalizes the quaternion again
//! itself.

use crate::field::DeformOutput;
use crate::model::{GaussianModel, SH_COEFFS};
use rayon::prelude::*;
use splat::{Colors, Gaussians};

/// Deformed means, quaternions and linear scales handed to the rasterizer.
#[derive(Clone, Debug, Default)]
pub struct Deformed {
    pub means: Vec<f32>,
    pub quats: Vec<f32>,
    pub scales: Vec<f32>,
}

/// Gradients w.r.t. the canonical parameters that the deformation touches.
#[derive(Clone, Debug, Default)]
pub struct CanonicalGrads {
    pub means: Vec<f32>,
    pub quats: Vec<f32>,
    pub log_scales: Vec<f32>,
}

fn normalize4(q: &[f32]) -> ([f32; 4], f32) {
    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        .sqrt()
        .max(1e-12);
    ([q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm], norm)
}

/// Fills `out` with the deformed parameters; `delta = None` means δ = 0 (warm-up).
pub fn apply(model: &GaussianModel, delta: Option<&DeformOutput>, out: &mut Deformed) {
    rest(model, out);
    if let Some(d) = delta {
        add_delta(d, out);
    }
}

/// Fills `out` with every Gaussian at rest: mean, normalize(q), exp(log_scale). The nodes
/// then place their own rows from here.
pub fn rest(model: &GaussianModel, out: &mut Deformed) {
    let n = model.len();
    out.means.resize(n * 3, 0.0);
    out.quats.resize(n * 4, 0.0);
    out.scales.resize(n * 3, 0.0);
    // Elementwise, so parallel is bit-identical to serial (one `expf` per value; serial,
    // these two lines were a quarter of the phase on 2 threads).
    out.means
        .par_iter_mut()
        .zip(model.means.par_iter())
        .for_each(|(o, m)| *o = *m);
    out.scales
        .par_iter_mut()
        .zip(model.log_scales.par_iter())
        .for_each(|(s, l)| *s = l.exp());
    out.quats
        .par_chunks_mut(4)
        .zip(model.quats.par_chunks(4))
        .for_each(|(o, q)| o.copy_from_slice(&normalize4(q).0));
}

/// Adds the field's δ to a rest placement: mean + δx, normalize(q) + δr,
/// exp(log_scale) + δs (zero where the field was not evaluated).
pub fn add_delta(d: &DeformOutput, out: &mut Deformed) {
    for (a, b) in [
        (&mut out.means, &d.dx),
        (&mut out.quats, &d.dr),
        (&mut out.scales, &d.ds),
    ] {
        a.par_iter_mut()
            .zip(b.par_iter())
            .for_each(|(x, y)| *x += y);
    }
}

/// The rasterizer's view of canonical colours and opacities with placed geometry.
pub fn gaussians<'a>(model: &'a GaussianModel, d: &'a Deformed) -> Gaussians<'a> {
    Gaussians {
        means: &d.means,
        quats: &d.quats,
        scales: &d.scales,
        opacity_logits: &model.opacity_logits,
        colors: Colors::Sh {
            coeffs: &model.sh,
            num_coeffs: SH_COEFFS,
            degree: model.sh_degree,
        },
    }
}

/// Chains the rasterizer's gradients w.r.t. the deformed means/quats/scales back to the
/// canonical parameters as if every Gaussian were placed at rest plus δ; a node that places
/// its rows otherwise overwrites them after. `dL/dδ` equals those same gradients (δ enters
/// additively), so the field's node hands them to the field directly.
pub fn backward(
    model: &GaussianModel,
    g_means: &[f32],
    g_quats: &[f32],
    g_scales: &[f32],
    out: &mut CanonicalGrads,
) {
    let n = model.len();
    out.means.resize(n * 3, 0.0);
    out.means
        .par_iter_mut()
        .zip(g_means.par_iter())
        .for_each(|(o, g)| *o = *g);
    out.log_scales.resize(n * 3, 0.0);
    out.log_scales
        .par_iter_mut()
        .zip(model.log_scales.par_iter())
        .zip(g_scales.par_iter())
        .for_each(|((o, l), g)| *o = l.exp() * g); // d/dlog s = s·d/ds
    out.quats.resize(n * 4, 0.0);
    out.quats
        .par_chunks_mut(4)
        .zip(model.quats.par_chunks(4))
        .zip(g_quats.par_chunks(4))
        .for_each(|((o, q), g)| {
            // d normalize(q)/dq = (I − n nᵀ)/|q|
            let (u, norm) = normalize4(q);
            let dot = u[0] * g[0] + u[1] * g[1] + u[2] * g[2] + u[3] * g[3];
            for k in 0..4 {
                o[k] = (g[k] - u[k] * dot) / norm;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quat_chain_matches_finite_differences() {
        let model = GaussianModel {
            means: vec![0.0; 3],
            quats: vec![0.9, -0.3, 0.5, 0.2],
            log_scales: vec![-1.0, 0.5, 0.1],
            opacity_logits: vec![0.0],
            sh: vec![0.0; 48],
            sh_degree: 0,
        };
        let w = [0.3f32, -0.7, 0.2, 1.1];
        let ws = [0.5f32, -0.2, 0.9];
        let f = |m: &GaussianModel| -> f64 {
            let mut d = Deformed::default();
            apply(m, None, &mut d);
            let a: f64 = d.quats.iter().zip(w).map(|(a, b)| (a * b) as f64).sum();
            a + d
                .scales
                .iter()
                .zip(ws)
                .map(|(a, b)| (a * b) as f64)
                .sum::<f64>()
        };
        let mut g = CanonicalGrads::default();
        backward(&model, &[0.0; 3], &w, &ws, &mut g);
        for k in 0..4 {
            let (mut p, mut m) = (model.clone(), model.clone());
            p.quats[k] += 1e-3;
            m.quats[k] -= 1e-3;
            let fd = (f(&p) - f(&m)) / 2e-3;
            assert!(
                (fd - g.quats[k] as f64).abs() < 1e-3,
                "quat {k}: {fd} vs {}",
                g.quats[k]
            );
        }
        for k in 0..3 {
            let (mut p, mut m) = (model.clone(), model.clone());
            p.log_scales[k] += 1e-3;
            m.log_scales[k] -= 1e-3;
            let fd = (f(&p) - f(&m)) / 2e-3;
            assert!((fd - g.log_scales[k] as f64).abs() < 1e-3);
        }
    }
}
