//! 3DGS as Markov Chain Monte Carlo (Kheradmand et al., NeurIPS 2024), as gsplat's
//! `MCMCStrategy` and its `simple_trainer` run it:
//!
//! - every `interval` iterations in the refinement window, Gaussians with opacity ≤
//!   `min_opacity` ("dead") are moved onto live ones drawn in proportion to opacity, and
//!   `growth` × N new Gaussians are drawn the same way, up to the hard `cap`; a drawn
//!   Gaussian and its copies share its opacity and size by Eq. 9 ([`super::relocation`]);
//! - every iteration, the means of near-transparent Gaussians get noise shaped by their
//!   covariance (the SGLD term, Eq. 11: `Σ·ε·σ(−100(o − 0.005))·lr_means·noise_lr`);
//! - the loss gains `opacity_reg·mean(o) + scale_reg·mean(s)` (simple_trainer's MCMC
//!   settings), which lets unused Gaussians fade out and be relocated;
//! - the initial Gaussians start as gsplat's MCMC recipe starts them (`--init_opa 0.5
//!   --init_scale 0.1`): opaque enough to be drawn, and a tenth of the nearest-neighbour
//!   size. This is not cosmetic: the noise is `Σ·ε`, quadratic in size, and from the
//!   3DGS-sized init (0.04 on toycars' 0.56-unit scene) it moved dead Gaussians 0.16
//!   units per step, 25 units in 300 steps, until a run diverged (docs/performance.md).
//!
//! One deviation from gsplat: the moments of the row a dead Gaussian is moved into are
//! zeroed as well as its source's (gsplat zeroes only the source's and keeps the dead
//! row's, which described a Gaussian somewhere else).

use super::relocation::{counts, relocated, sample_weighted};
use super::DensifyReport;
use crate::model::{inverse_sigmoid, sigmoid, GaussianModel};
use crate::state::GaussianState;
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// `[densify.mcmc]`. Defaults: gsplat's `MCMCStrategy` and `simple_trainer` MCMC settings,
/// except `cap`, chosen by measurement on this CPU (docs/performance.md, "Time to quality").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct McmcConfig {
    /// Most Gaussians the run may hold (gsplat: 1M, sized for a GPU).
    pub cap: usize,
    /// Each refinement adds this fraction of the current count, up to `cap` (gsplat: 5 %).
    pub growth: f32,
    /// Refinement stops at this iteration (gsplat: 25k of 30k; rescaled by `--iters`).
    pub until: u32,
    /// Position-noise rate, multiplied by the means' learning rate (gsplat: 5e5).
    pub noise_lr: f32,
    /// Weights of the L1 penalties on opacity and on scale (gsplat's MCMC: 0.01 each).
    pub opacity_reg: f32,
    pub scale_reg: f32,
    /// Opacity of every initial Gaussian (gsplat's MCMC recipe: `init_opa` 0.5); replaces
    /// `[init] opacity` under this strategy.
    pub init_opacity: f32,
    /// Initial sizes as this fraction of the nearest-neighbour size 3DGS starts from
    /// (gsplat's MCMC recipe: `init_scale` 0.1).
    pub init_scale: f32,
}

impl Default for McmcConfig {
    fn default() -> Self {
        Self {
            cap: 300_000,
            growth: 0.05,
            until: 25_000,
            noise_lr: 5e5,
            opacity_reg: 0.01,
            scale_reg: 0.01,
            init_opacity: 0.5,
            init_scale: 0.1,
        }
    }
}

impl McmcConfig {
    /// Rejects values that would break a run; `(key, problem)`.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if self.cap == 0 || self.cap > crate::init::MAX_RANDOM_POINTS {
            return Err((
                "cap",
                format!(
                    "must be in 1..={}, got {}",
                    crate::init::MAX_RANDOM_POINTS,
                    self.cap
                ),
            ));
        }
        for (key, v) in [
            ("growth", self.growth),
            ("noise_lr", self.noise_lr),
            ("opacity_reg", self.opacity_reg),
            ("scale_reg", self.scale_reg),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err((key, format!("must be finite and ≥ 0, got {v}")));
            }
        }
        if !(self.init_opacity > 0.0 && self.init_opacity < 1.0) {
            return Err((
                "init_opacity",
                format!("must be in (0, 1), got {}", self.init_opacity),
            ));
        }
        if !(self.init_scale.is_finite() && self.init_scale > 0.0) {
            return Err((
                "init_scale",
                format!("must be finite and > 0, got {}", self.init_scale),
            ));
        }
        Ok(())
    }
}

/// Starts the initial Gaussians as the MCMC recipe does: opacity `init_opacity`, sizes ×
/// `init_scale` (the trainer calls this once, on a fresh run's initialization).
pub fn prepare_init(model: &mut GaussianModel, cfg: &McmcConfig) {
    let logit = inverse_sigmoid(cfg.init_opacity);
    model.opacity_logits.iter_mut().for_each(|l| *l = logit);
    let ln = cfg.init_scale.ln();
    model.log_scales.iter_mut().for_each(|s| *s += ln);
}

/// One refinement: relocate the dead, then grow towards the cap.
pub fn refine(
    st: &mut GaussianState,
    cfg: &McmcConfig,
    min_opacity: f32,
    rng: &mut impl Rng,
) -> DensifyReport {
    let relocated = relocate_dead(st, min_opacity, rng);
    let added = add_new(st, cfg, min_opacity, rng);
    DensifyReport {
        relocated,
        added,
        ..Default::default()
    }
}

/// Gives each drawn Gaussian the opacity and scale of one of `count + 1` copies (Eq. 9),
/// opacity clamped to `[min_opacity, 1 − ε]` as gsplat does, and zeroes its moments.
fn share_among_copies(st: &mut GaussianState, drawn: &[usize], min_opacity: f32) {
    let times = counts(drawn, st.len());
    for (i, &c) in times.iter().enumerate().filter(|(_, &c)| c > 0) {
        let m = &mut st.model;
        let (o, coeff) = relocated(sigmoid(m.opacity_logits[i]), c as usize + 1);
        m.opacity_logits[i] = inverse_sigmoid(o.clamp(min_opacity, 1.0 - f32::EPSILON));
        let ln = coeff.ln();
        m.log_scales[i * 3..i * 3 + 3]
            .iter_mut()
            .for_each(|s| *s += ln);
        st.zero_moments(i);
    }
}

/// Moves every dead Gaussian (opacity ≤ `min_opacity`) onto a live one drawn by opacity;
/// returns how many moved (0 when none is dead or none is alive).
pub fn relocate_dead(st: &mut GaussianState, min_opacity: f32, rng: &mut impl Rng) -> usize {
    let opacity: Vec<f32> = st
        .model
        .opacity_logits
        .iter()
        .map(|&l| sigmoid(l))
        .collect();
    let dead: Vec<usize> = (0..st.len())
        .filter(|&i| opacity[i] <= min_opacity)
        .collect();
    let alive_weight: Vec<f32> = opacity
        .iter()
        .map(|&o| if o > min_opacity { o } else { 0.0 })
        .collect();
    let sources = sample_weighted(&alive_weight, dead.len(), rng);
    if sources.is_empty() {
        return 0;
    }
    share_among_copies(st, &sources, min_opacity);
    for (&d, &s) in dead.iter().zip(&sources) {
        st.copy_row(s, d);
    }
    dead.len()
}

/// Adds `growth`·N Gaussians (at most up to `cap`), each a copy of one drawn by opacity.
pub fn add_new(
    st: &mut GaussianState,
    cfg: &McmcConfig,
    min_opacity: f32,
    rng: &mut impl Rng,
) -> usize {
    let n = st.len();
    let target = cfg
        .cap
        .min((n as f64 * (1.0 + f64::from(cfg.growth))) as usize);
    let k = target.saturating_sub(n);
    if k == 0 {
        return 0;
    }
    let opacity: Vec<f32> = st
        .model
        .opacity_logits
        .iter()
        .map(|&l| sigmoid(l))
        .collect();
    let sources = sample_weighted(&opacity, k, rng);
    if sources.is_empty() {
        return 0;
    }
    share_among_copies(st, &sources, min_opacity);
    let copies = st.model.gather(&sources);
    st.append(&copies, &sources);
    sources.len()
}

/// Adds the gradients of `opacity_reg·mean(sigmoid(logit)) + scale_reg·mean(exp(log_s))`
/// (means over Gaussians and over their 3N scales) and returns that loss.
pub fn add_penalty_grads(
    model: &GaussianModel,
    cfg: &McmcConfig,
    dlogits: &mut [f32],
    dlog_scales: &mut [f32],
) -> f32 {
    let n = model.len();
    if n == 0 {
        return 0.0;
    }
    let (wo, ws) = (cfg.opacity_reg / n as f32, cfg.scale_reg / (3 * n) as f32);
    let mut sum_o = 0.0f64;
    for (g, &l) in dlogits.iter_mut().zip(&model.opacity_logits) {
        let o = sigmoid(l);
        sum_o += f64::from(o);
        *g += wo * o * (1.0 - o);
    }
    let mut sum_s = 0.0f64;
    for (g, &ls) in dlog_scales.iter_mut().zip(&model.log_scales) {
        let s = ls.exp();
        sum_s += f64::from(s);
        *g += ws * s;
    }
    (f64::from(cfg.opacity_reg) * sum_o / n as f64
        + f64::from(cfg.scale_reg) * sum_s / (3 * n) as f64) as f32
}

/// The gate `1/(1 + e^{−100((1 − o) − 0.995)})` below which noise is not drawn: at 1e-6
/// (opacity above ~0.13) a step moves a mean by under 1e-6 of what it moves a dead one.
const NOISE_GATE_MIN: f32 = 1e-6;

/// Adds `Σᵢ·εᵢ·gate(oᵢ)·scale` to every mean (`Σ = R·diag(s²)·Rᵀ`, ε standard normal).
/// ε comes from a counter-based generator keyed by `key` and the row, so the result does
/// not depend on the thread count; the trainer draws `key` from the run's RNG.
pub fn inject_noise(model: &mut GaussianModel, scale: f32, key: u64) {
    let GaussianModel {
        means,
        quats,
        log_scales,
        opacity_logits,
        ..
    } = model;
    means.par_chunks_mut(3).enumerate().for_each(|(i, mean)| {
        let o = sigmoid(opacity_logits[i]);
        let gate = 1.0 / (1.0 + (-100.0 * ((1.0 - o) - 0.995)).exp());
        if gate < NOISE_GATE_MIN {
            return;
        }
        let r = super::rotation(&quats[i * 4..i * 4 + 4]);
        let s2: [f32; 3] = std::array::from_fn(|a| (2.0 * log_scales[i * 3 + a]).exp());
        let e: [f32; 3] = std::array::from_fn(|a| gate * scale * hashed_normal(key, i, a));
        // Σ·e = R·diag(s²)·(Rᵀ·e).
        let rt_e: [f32; 3] =
            std::array::from_fn(|b| (0..3).map(|a| r[a][b] * e[a]).sum::<f32>() * s2[b]);
        for (a, m) in mean.iter_mut().enumerate() {
            *m += (0..3).map(|b| r[a][b] * rt_e[b]).sum::<f32>();
        }
    });
}

/// SplitMix64 finalizer: a well-mixed 64-bit hash of one input.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A standard normal for (key, row, axis) by Box–Muller on two hashed uniforms.
fn hashed_normal(key: u64, row: usize, axis: usize) -> f32 {
    let c = mix(key ^ mix((row as u64) << 2 | axis as u64));
    let u1 = ((c >> 40) as f32 + 0.5) / (1u64 << 24) as f32;
    let u2 = ((c & 0xff_ffff) as f32) / (1u64 << 24) as f32;
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::SH_FLOATS;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// N Gaussians, row i tagged with i in its SH and its moments; opacity per `opac`.
    fn state(opac: &[f32]) -> GaussianState {
        let n = opac.len();
        let model = GaussianModel {
            means: (0..n * 3).map(|k| (k / 3) as f32).collect(),
            quats: (0..n).flat_map(|_| [1.0, 0.0, 0.0, 0.0]).collect(),
            log_scales: vec![-2.0; n * 3],
            opacity_logits: opac.iter().map(|&o| inverse_sigmoid(o)).collect(),
            sh: (0..n * SH_FLOATS).map(|k| (k / SH_FLOATS) as f32).collect(),
            sh_degree: 0,
        };
        let mut st = GaussianState::new(model);
        for a in st.adam.iter_mut() {
            a.m.fill(1.0);
            a.v.fill(1.0);
        }
        st.object = (0..n).map(|i| i as u8).collect();
        st
    }

    #[test]
    fn dead_gaussians_become_copies_of_live_ones() {
        let mut st = state(&[0.9, 0.001, 0.5, 0.004, 0.2]);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        assert_eq!(relocate_dead(&mut st, 0.005, &mut rng), 2);
        assert!(st.is_aligned());
        assert_eq!(st.len(), 5);
        for d in [1usize, 3] {
            let src = st.model.sh[d * SH_FLOATS] as usize;
            assert!([0, 2, 4].contains(&src), "row {d} copies live row {src}");
            assert_eq!(st.model.means[d * 3], src as f32);
            assert_eq!(st.object[d], src as u8);
            assert_eq!(st.model.opacity_logits[d], st.model.opacity_logits[src]);
            assert_eq!(st.model.log_scales[d * 3], st.model.log_scales[src * 3]);
            // Source and copy share the source's opacity and shrink (Eq. 9), fresh moments.
            assert!(sigmoid(st.model.opacity_logits[d]) < [0.9, 0.0, 0.5, 0.0, 0.2][src]);
            assert!(st.model.log_scales[d * 3] <= -2.0);
            for r in [d, src] {
                assert_eq!((st.adam[3].m[r], st.adam[0].v[r * 3]), (0.0, 0.0));
            }
        }
        // Nothing dead: nothing moves; everything dead: nothing to move onto.
        let mut st = state(&[0.9, 0.5]);
        assert_eq!(relocate_dead(&mut st, 0.005, &mut rng), 0);
        let mut st = state(&[0.001, 0.002]);
        assert_eq!(relocate_dead(&mut st, 0.005, &mut rng), 0);
    }

    #[test]
    fn growth_stops_at_the_cap() {
        let mut st = state(&[0.5; 100]);
        let cfg = McmcConfig {
            cap: 112,
            ..Default::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        assert_eq!(add_new(&mut st, &cfg, 0.005, &mut rng), 5);
        assert_eq!(add_new(&mut st, &cfg, 0.005, &mut rng), 5);
        assert_eq!(add_new(&mut st, &cfg, 0.005, &mut rng), 2);
        assert_eq!(add_new(&mut st, &cfg, 0.005, &mut rng), 0);
        assert_eq!(st.len(), 112);
        assert!(st.is_aligned());
        // New rows copy their source (the SH tag) with zero moments.
        for r in 100..112 {
            let src = st.model.sh[r * SH_FLOATS] as usize;
            assert_eq!(st.model.means[r * 3], src as f32);
            assert_eq!(st.object[r], src as u8);
            assert_eq!(st.adam[4].m[r * SH_FLOATS], 0.0);
        }
    }

    #[test]
    fn penalty_gradients_match_finite_differences() {
        let mut st = state(&[0.3, 0.7, 0.05]);
        st.model.log_scales = vec![-1.0, -2.0, -3.0, 0.1, -0.5, -4.0, -2.2, -1.1, -0.3];
        let cfg = McmcConfig {
            opacity_reg: 0.5,
            scale_reg: 0.25,
            ..Default::default()
        };
        let mut dl = vec![0.0; 3];
        let mut ds = vec![0.0; 9];
        let loss = add_penalty_grads(&st.model, &cfg, &mut dl, &mut ds);
        let eval = |m: &GaussianModel| {
            let (mut a, mut b) = (vec![0.0; 3], vec![0.0; 9]);
            f64::from(add_penalty_grads(m, &cfg, &mut a, &mut b))
        };
        assert!((f64::from(loss) - eval(&st.model)).abs() < 1e-7);
        let h = 1e-3f32;
        // Central differences of the penalty in one parameter group against its gradient.
        let check = |name: &str, grads: &[f32], group: fn(&mut GaussianModel) -> &mut [f32]| {
            for (i, &g) in grads.iter().enumerate() {
                let (mut p, mut q) = (st.model.clone(), st.model.clone());
                group(&mut p)[i] += h;
                group(&mut q)[i] -= h;
                let fd = (eval(&p) - eval(&q)) / (2.0 * f64::from(h));
                assert!((fd - f64::from(g)).abs() < 1e-5, "{name} {i}: {fd} {g}");
            }
        };
        check("opacity", &dl, |m| &mut m.opacity_logits);
        check("scale", &ds, |m| &mut m.log_scales);
    }

    #[test]
    fn init_follows_the_mcmc_recipe() {
        let mut st = state(&[0.1, 0.1]);
        let cfg = McmcConfig::default();
        prepare_init(&mut st.model, &cfg);
        for (i, &l) in st.model.opacity_logits.iter().enumerate() {
            assert!((sigmoid(l) - 0.5).abs() < 1e-6, "opacity {i}");
        }
        for &s in &st.model.log_scales {
            assert!((s.exp() - 0.1 * (-2.0f32).exp()).abs() < 1e-6);
        }
        let bad = McmcConfig {
            init_opacity: 1.0,
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().0, "init_opacity");
        let bad = McmcConfig {
            init_scale: 0.0,
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().0, "init_scale");
    }

    #[test]
    fn noise_moves_only_faint_gaussians_along_their_shape() {
        let mut st = state(&[0.001, 0.9]);
        // Gaussian 0: a needle along x (scales 1, 1e-3, 1e-3).
        st.model.log_scales[..3].copy_from_slice(&[0.0, -6.9, -6.9]);
        let before = st.model.means.clone();
        inject_noise(&mut st.model, 0.1, 42);
        let d: Vec<f32> = (0..3).map(|a| st.model.means[a] - before[a]).collect();
        assert!(d[0].abs() > 1e-4, "the faint needle moves: {d:?}");
        assert!(
            d[1].abs() < 1e-5 && d[2].abs() < 1e-5,
            "along x only: {d:?}"
        );
        assert_eq!(&st.model.means[3..], &before[3..], "the opaque one stays");
        // The same key gives the same noise; another key another.
        let mut a = state(&[0.001; 64]);
        let mut b = a.clone();
        inject_noise(&mut a.model, 0.1, 7);
        inject_noise(&mut b.model, 0.1, 7);
        assert_eq!(a.model.means, b.model.means);
        inject_noise(&mut b.model, 0.1, 8);
        assert_ne!(a.model.means, b.model.means);
    }

    #[test]
    fn hashed_normals_are_standard() {
        let xs: Vec<f64> = (0..200_000)
            .map(|i| f64::from(hashed_normal(99, i / 3, i % 3)))
            .collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.02,
            "{mean} {var}"
        );
    }

    #[test]
    fn bad_values_name_the_key() {
        let c = McmcConfig {
            cap: 0,
            ..Default::default()
        };
        assert_eq!(c.validate().unwrap_err().0, "cap");
        let c = McmcConfig {
            noise_lr: f32::NAN,
            ..Default::default()
        };
        assert_eq!(c.validate().unwrap_err().0, "noise_lr");
    }
}
