//! The two primitives of MCMC density control: drawing Gaussians in proportion to their
//! opacity, and Eq. 9 of 3DGS-MCMC (Kheradmand et al. 2024), the opacity and scale that
//! N copies of a Gaussian need so that together they render like the one they replace.

use rand::Rng;

/// Copies per Gaussian that Eq. 9 is evaluated for; more are clamped (gsplat: `n_max` 51).
/// The alternating binomial sum loses precision beyond that even in f64.
pub const MAX_COPIES: usize = 51;

/// Opacity and scale factor of each of `copies` Gaussians replacing one of opacity
/// `opacity` (Eq. 9): `o' = 1 − (1 − o)^(1/N)`, so N copies stacked at the centre are as
/// opaque as the original, and scales × `o / Σ_{i=1}^{N} Σ_{k<i} C(i−1,k)(−1)^k
/// o'^{k+1}/√(k+1)`, so the stacked profile `1 − (1 − o'·g)^N` integrates (along a line
/// through the centre) to what `o·g` did. `copies` counts the original: relocating one
/// dead Gaussian onto a live one gives N = 2. Computed in f64: the alternating sum cancels.
pub fn relocated(opacity: f32, copies: usize) -> (f32, f32) {
    let n = copies.clamp(1, MAX_COPIES);
    let o = f64::from(opacity);
    let o_new = 1.0 - (1.0 - o).powf(1.0 / n as f64);
    let mut denom = 0.0f64;
    for i in 1..=n {
        // C(i−1, k) by the running product, exact in f64 for i ≤ 51.
        let mut binom = 1.0f64;
        for k in 0..i {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            denom += binom * sign * o_new.powi(k as i32 + 1) / ((k + 1) as f64).sqrt();
            binom = binom * (i - 1 - k) as f64 / (k + 1) as f64;
        }
    }
    let coeff = if denom > 0.0 { o / denom } else { 1.0 };
    (o_new as f32, coeff as f32)
}

/// `n` indices drawn with replacement, index `i` with probability `weights[i] / Σ weights`
/// (`torch.multinomial(weights, n, replacement=True)`); empty when every weight is 0.
pub fn sample_weighted(weights: &[f32], n: usize, rng: &mut impl Rng) -> Vec<usize> {
    let mut cdf = Vec::with_capacity(weights.len());
    let mut total = 0.0f64;
    for &w in weights {
        total += f64::from(w.max(0.0));
        cdf.push(total);
    }
    if total <= 0.0 {
        return Vec::new();
    }
    (0..n)
        .map(|_| {
            let u = rng.gen::<f64>() * total;
            // First index whose cumulative weight exceeds u: never a zero-weight one.
            cdf.partition_point(|&c| c <= u).min(weights.len() - 1)
        })
        .collect()
}

/// How often each index occurs in `idx` (a table over `0..len`).
pub fn counts(idx: &[usize], len: usize) -> Vec<u32> {
    let mut c = vec![0u32; len];
    for &i in idx {
        c[i] += 1;
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn one_copy_changes_nothing() {
        for o in [0.01f32, 0.3, 0.9, 0.999] {
            let (o1, c) = relocated(o, 1);
            assert!(
                (o1 - o).abs() < 1e-6 && (c - 1.0).abs() < 1e-5,
                "{o}: {o1} {c}"
            );
        }
    }

    /// The two properties Eq. 9 is built on, checked by quadrature instead of by its
    /// algebra: N copies are as opaque at the centre as the original, and their stacked
    /// profile along a line integrates to the original's.
    #[test]
    fn copies_render_like_the_original() {
        let g = |x: f64, s: f64| (-0.5 * (x / s) * (x / s)).exp();
        for &o in &[0.05f32, 0.4, 0.8, 0.97] {
            for &n in &[2usize, 3, 5, 12, 40] {
                let (on, c) = relocated(o, n);
                let (o, on, c) = (f64::from(o), f64::from(on), f64::from(c));
                let centre = 1.0 - (1.0 - on).powi(n as i32);
                assert!((centre - o).abs() < 1e-5, "o {o} n {n}: centre {centre}");
                let (s, dx) = (1.0, 1e-3);
                let xs = (-12_000..=12_000).map(|k| k as f64 * dx);
                let (mut before, mut after) = (0.0, 0.0);
                for x in xs {
                    before += o * g(x, s) * dx;
                    after += (1.0 - (1.0 - on * g(x, c * s)).powi(n as i32)) * dx;
                }
                assert!(
                    (after / before - 1.0).abs() < 1e-3,
                    "o {o} n {n}: {after} vs {before}"
                );
                assert!(c <= 1.0 + 1e-9, "o {o} n {n}: copies grew ({c})");
            }
        }
    }

    #[test]
    fn too_many_copies_are_clamped() {
        assert_eq!(relocated(0.5, 500), relocated(0.5, MAX_COPIES));
        let (o, c) = relocated(0.5, MAX_COPIES);
        assert!(o.is_finite() && c.is_finite() && c > 0.0);
    }

    #[test]
    fn sampling_follows_the_weights_and_skips_zeros() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let w = [0.0, 1.0, 0.0, 3.0, 0.0];
        let idx = sample_weighted(&w, 40_000, &mut rng);
        let c = counts(&idx, w.len());
        assert_eq!((c[0], c[2], c[4]), (0, 0, 0));
        let share = f64::from(c[3]) / 40_000.0;
        assert!((share - 0.75).abs() < 0.01, "{share}");
        assert!(sample_weighted(&[0.0, 0.0], 5, &mut rng).is_empty());
        assert!(sample_weighted(&w, 0, &mut rng).is_empty());
    }
}
