//! Smoothing a tracked trajectory as one solve, outside the knots' own optimizer.
//!
//! Tracking fits one pose per view; a monocular view fixes an object's distance only to a
//! few percent of the depth, so the knots wobble along the rays from view to view, which
//! lengthens a slow mover's path and makes a still object look as if it moved. A penalty
//! added to each knot's gradient does not help: each knot's Adam state scales it to a full
//! step and the knots oscillate about the smooth path. Here the whole track is replaced
//! by the Whittaker–Eilers smoother of its knots (Eilers 2003, "A perfect smoother"):
//! `z = argmin Σ_k |z_k − y_k|² + λ Σ_k |Δ²z_k|²`, i.e. `(I + λ DᵀD) z = y` with `D` the
//! second-difference matrix, solved in O(K) by one banded Cholesky factorization
//! ([`banded_cholesky_solve`], shared with [`smooth_along_rays`]).
//!
//! The smoother's gain is `1 / (1 + λ (2 − 2 cos ω)²)`: it halves a period of
//! `2π λ^{1/4}` knots. [`smooth`] takes that period as a fraction of the track's knots, so
//! the same setting means the same thing at any frame count. [`smooth_along_rays`] weighs
//! each knot's data term by how well its view fixes it: across the ray fully, along it
//! (the distance) by `(size / distance)²`.

use super::trajectory::Trajectory;

/// `λ` whose half-gain period is `fraction` of `knots − 1` knot intervals.
pub fn lambda_for(fraction: f32, knots: usize) -> f64 {
    let period = f64::from(fraction) * (knots.saturating_sub(1)) as f64;
    (period / std::f64::consts::TAU).powi(4)
}

/// Replaces `y` by its Whittaker–Eilers smooth with penalty `lambda` (no change for
/// `lambda ≤ 0` or fewer than three values: a line is never changed).
pub fn whittaker(y: &mut [f64], lambda: f64) {
    let n = y.len();
    if n < 3 || lambda <= 0.0 {
        return;
    }
    // A = I + λ DᵀD is pentadiagonal: its lower band has two diagonals below the main one.
    let mut a = vec![[1.0, 0.0, 0.0]; n];
    add_second_differences(&mut a, n, 1, lambda);
    banded_cholesky_solve(&mut a, y);
}

/// Adds `λ DᵀD ⊗ I_stride` to the lower band `a` (`a[u][d] = A[u][u − d]`) of a system over
/// `knots` knots of `stride` unknowns each: row r of `D` is (1, −2, 1) at knots r, r+1, r+2,
/// so `DᵀD`'s rows are the stencil (1, −4, 6, −4, 1) clipped at both ends.
fn add_second_differences<const W: usize>(
    a: &mut [[f64; W]],
    knots: usize,
    stride: usize,
    lambda: f64,
) {
    let stencil = [1.0, -2.0, 1.0];
    for r in 0..knots.saturating_sub(2) {
        for i in 0..3 {
            for j in 0..=i {
                let v = lambda * stencil[i] * stencil[j];
                for c in 0..stride {
                    a[stride * (r + i) + c][stride * (i - j)] += v;
                }
            }
        }
    }
}

/// The trace of the smoother's hat matrix `(I + λ DᵀD)⁻¹` for `n` knots, from the
/// eigenvalues `(2 − 2 cos(πj/n))²` of `DᵀD` (exact for a periodic track, within a few
/// knots' worth at the ends otherwise): the smooth's effective number of parameters.
fn hat_trace(n: usize, lambda: f64) -> f64 {
    (0..n)
        .map(|j| {
            let e = 2.0 - 2.0 * (std::f64::consts::PI * j as f64 / n as f64).cos();
            1.0 / (1.0 + lambda * e * e)
        })
        .sum()
}

/// The penalty that minimizes the generalized cross-validation score
/// `GCV(λ) = (RSS/m) / (1 − tr H/n)²` (Craven & Wahba 1979; Eilers 2003 §5) of the
/// series smoothed together (each of length `n`, `m` values in all), over half-gain
/// periods from 2 knots to the whole track. The wobble of a track is what changes from one
/// view to the next; the motion is what the neighbouring views agree on.
pub fn gcv_lambda(series: &[Vec<f64>]) -> f64 {
    let n = series.first().map_or(0, Vec::len);
    if n < 4 {
        return 0.0;
    }
    let m = (n * series.len()) as f64;
    let mut best = (f64::INFINITY, 0.0);
    const STEPS: usize = 32;
    for i in 0..=STEPS {
        // Periods 2 … n knots, log-spaced.
        let period = 2.0 * (n as f64 / 2.0).powf(i as f64 / STEPS as f64);
        let lambda = (period / std::f64::consts::TAU).powi(4);
        let mut rss = 0.0;
        for y in series {
            let mut z = y.clone();
            whittaker(&mut z, lambda);
            rss += y.iter().zip(&z).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        }
        let free = 1.0 - hat_trace(n, lambda) / n as f64;
        let score = (rss / m) / (free * free).max(1e-12);
        if score < best.0 {
            best = (score, lambda);
        }
    }
    best.1
}

/// How tracked knots are smoothed (`[objects] track_smooth`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SmoothRule {
    /// The knots as tracked.
    #[default]
    Off,
    /// Each track's penalty by generalized cross-validation ([`gcv_lambda`]).
    Gcv,
    /// A half-gain period of `track_smooth_period` of the track.
    Period,
    /// As `Period`, but each knot's position is trusted across its view's ray and hardly
    /// along it ([`smooth_along_rays`]): the distance is what one view fixes least.
    Rays,
}

/// How much [`smooth`] smooths.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Amount {
    /// A half-gain period of this fraction of the track, for translations and rotations.
    Period(f32),
    /// Translations and rotations each by their own generalized cross-validation choice.
    Gcv,
}

/// The penalties used, translation and rotation.
pub type Lambdas = (f64, f64);

/// Smooths every coordinate of the translations and the rotations of `tr` (quaternions
/// brought to one hemisphere along the track first, renormalized after). A period of 0
/// leaves it as it is.
pub fn smooth(tr: &mut Trajectory, amount: Amount) -> Lambdas {
    let k = tr.len();
    if k < 3 {
        return (0.0, 0.0);
    }
    let mut p: Vec<Vec<f64>> = (0..3)
        .map(|c| tr.translations.iter().map(|p| f64::from(p[c])).collect())
        .collect();
    let lt = match amount {
        Amount::Period(f) => lambda_for(f, k),
        Amount::Gcv => gcv_lambda(&p),
    };
    if lt > 0.0 {
        for (c, y) in p.iter_mut().enumerate() {
            whittaker(y, lt);
            for (t, v) in tr.translations.iter_mut().zip(y.iter()) {
                t[c] = *v as f32;
            }
        }
    }
    let lr = smooth_rotations(tr, amount);
    (lt, lr)
}

/// The translations smoothed with a data term that trusts each knot across the ray from
/// its view's camera centre and only `(extent / distance)²` of that along it:
/// `z = argmin Σ_k (z_k − y_k)ᵀ W_k (z_k − y_k) + λ Σ_k |Δ²z_k|²` with
/// `W_k = I − (1 − ε_k) r_k r_kᵀ`. One view places an object across the image to about a
/// pixel but its distance only through its apparent size, about a pixel of its size in
/// pixels: the variance ratio is `(size / distance)²`, the same for any focal length. Along
/// the rays the smoothness prior then decides. Rotations as [`smooth`] with the same
/// period. Returns λ.
pub fn smooth_along_rays(
    tr: &mut Trajectory,
    centres: &[[f32; 3]],
    extent: f32,
    fraction: f32,
) -> f64 {
    let k = tr.len();
    let lambda = lambda_for(fraction, k);
    if k < 3 || lambda <= 0.0 || centres.len() != k {
        return 0.0;
    }
    let n = 3 * k;
    // Band of A below the diagonal: a[u][d] = A[u][u − d], d ≤ 8 (two knots of 3 rows).
    const B: usize = 8;
    let mut a = vec![[0.0f64; B + 1]; n];
    let mut rhs = vec![0.0f64; n];
    for (i, (p, c)) in tr.translations.iter().zip(centres).enumerate() {
        let v: [f64; 3] = std::array::from_fn(|j| f64::from(p[j] - c[j]));
        let dist = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-9);
        let r = v.map(|x| x / dist);
        let eps = (f64::from(extent) / dist).powi(2).min(1.0);
        for row in 0..3 {
            for col in 0..=row {
                let w = f64::from(u8::from(row == col)) - (1.0 - eps) * r[row] * r[col];
                a[3 * i + row][row - col] += w;
                rhs[3 * i + row] += w * f64::from(p[col]);
                if row != col {
                    rhs[3 * i + col] += w * f64::from(p[row]);
                }
            }
        }
    }
    add_second_differences(&mut a, k, 3, lambda);
    banded_cholesky_solve(&mut a, &mut rhs);
    for (i, p) in tr.translations.iter_mut().enumerate() {
        *p = std::array::from_fn(|j| rhs[3 * i + j] as f32);
    }
    smooth_rotations(tr, Amount::Period(fraction));
    lambda
}

/// Solves `A x = b` in place for a symmetric positive definite `A` given by its lower band
/// (`a[u][d] = A[u][u − d]`), by the banded Cholesky factorization `A = LLᵀ`.
fn banded_cholesky_solve<const W: usize>(a: &mut [[f64; W]], b: &mut [f64]) {
    let n = b.len();
    let bw = W - 1;
    for u in 0..n {
        for d in (0..=bw.min(u)).rev() {
            let v = u - d;
            // L[u][v] = (A[u][v] − Σ_{w<v} L[u][w] L[v][w]) / L[v][v]
            // (w = u − e; L[v][w] = a[v][e − d], inside the band since e − d ≤ bw.)
            let mut sum = a[u][d];
            for e in d + 1..=bw.min(u) {
                sum -= a[u][e] * a[v][e - d];
            }
            a[u][d] = if d == 0 {
                sum.max(1e-300).sqrt()
            } else {
                sum / a[v][0]
            };
        }
    }
    for u in 0..n {
        let mut s = b[u];
        for d in 1..=bw.min(u) {
            s -= a[u][d] * b[u - d];
        }
        b[u] = s / a[u][0];
    }
    for u in (0..n).rev() {
        let mut s = b[u];
        for d in 1..=bw.min(n - 1 - u) {
            s -= a[u + d][d] * b[u + d];
        }
        b[u] = s / a[u][0];
    }
}

fn smooth_rotations(tr: &mut Trajectory, amount: Amount) -> f64 {
    let k = tr.len();
    let mut q: Vec<[f64; 4]> = Vec::with_capacity(k);
    for r in &tr.rotations {
        let mut x = r.map(f64::from);
        let norm = x.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
        x.iter_mut().for_each(|v| *v /= norm);
        if let Some(prev) = q.last() {
            let dot: f64 = (0..4).map(|i| prev[i] * x[i]).sum();
            if dot < 0.0 {
                x.iter_mut().for_each(|v| *v = -*v);
            }
        }
        q.push(x);
    }
    let mut series: Vec<Vec<f64>> = (0..4).map(|c| q.iter().map(|x| x[c]).collect()).collect();
    let lambda = match amount {
        Amount::Period(f) => lambda_for(f, k),
        Amount::Gcv => gcv_lambda(&series),
    };
    if lambda <= 0.0 {
        return 0.0;
    }
    for (c, y) in series.iter_mut().enumerate() {
        whittaker(y, lambda);
        for (x, v) in q.iter_mut().zip(y.iter()) {
            x[c] = *v;
        }
    }
    for (r, x) in tr.rotations.iter_mut().zip(q) {
        let norm = x.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
        *r = x.map(|v| (v / norm) as f32);
    }
    lambda
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dense solve of `(I + λ DᵀD) z = y`, for checking the banded one.
    fn dense(y: &[f64], lambda: f64) -> Vec<f64> {
        let n = y.len();
        let mut a = vec![vec![0.0; n]; n];
        for (i, row) in a.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        for r in 0..n - 2 {
            let c = [1.0, -2.0, 1.0];
            for i in 0..3 {
                for j in 0..3 {
                    a[r + i][r + j] += lambda * c[i] * c[j];
                }
            }
        }
        // Gaussian elimination (A is SPD: no pivoting needed).
        let mut b = y.to_vec();
        for i in 0..n {
            let pivot = a[i].clone();
            for r in i + 1..n {
                let f = a[r][i] / pivot[i];
                for (x, p) in a[r][i..].iter_mut().zip(&pivot[i..]) {
                    *x -= f * p;
                }
                b[r] -= f * b[i];
            }
        }
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|c| a[i][c] * b[c]).sum();
            b[i] = (b[i] - s) / a[i][i];
        }
        b
    }

    #[test]
    fn the_banded_solve_matches_the_dense_one() {
        for n in [3, 4, 5, 17] {
            let y: Vec<f64> = (0..n).map(|i| ((i * 7919) % 13) as f64 - 6.0).collect();
            for lambda in [0.5, 30.0, 1e4] {
                let mut z = y.clone();
                whittaker(&mut z, lambda);
                for (a, b) in z.iter().zip(dense(&y, lambda)) {
                    assert!((a - b).abs() < 1e-9 * (1.0 + b.abs()), "n {n} λ {lambda}");
                }
            }
        }
    }

    #[test]
    fn a_straight_constant_speed_path_is_unchanged_and_noise_shrinks() {
        let n = 60;
        let line: Vec<f64> = (0..n).map(|i| 0.3 + 0.05 * i as f64).collect();
        let mut z = line.clone();
        whittaker(&mut z, lambda_for(0.2, n));
        for (a, b) in z.iter().zip(&line) {
            assert!((a - b).abs() < 1e-9);
        }
        // Alternating wobble (the highest frequency) on the line: all but the ends' share goes.
        let noisy: Vec<f64> = line
            .iter()
            .enumerate()
            .map(|(i, v)| v + if i % 2 == 0 { 0.1 } else { -0.1 })
            .collect();
        let mut z = noisy.clone();
        whittaker(&mut z, lambda_for(0.2, n));
        let rms = |v: &[f64]| {
            (v.iter()
                .zip(&line)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                / n as f64)
                .sqrt()
        };
        assert!(
            rms(&z) < 0.1 * rms(&noisy),
            "{} vs {}",
            rms(&z),
            rms(&noisy)
        );
    }

    #[test]
    fn rotations_stay_unit_and_a_sign_flip_is_not_a_turn() {
        let k = 10;
        let mut tr = Trajectory {
            times: (0..k).map(|i| i as f32 / (k - 1) as f32).collect(),
            translations: vec![[0.0; 3]; k],
            rotations: (0..k)
                .map(|i| {
                    let h = 0.05 * i as f32;
                    let q = [h.cos(), 0.0, h.sin(), 0.0];
                    // Every other knot stored with the opposite sign (the same rotation).
                    if i % 2 == 1 {
                        q.map(|v| -v)
                    } else {
                        q
                    }
                })
                .collect(),
        };
        smooth(&mut tr, Amount::Period(0.3));
        for (i, q) in tr.rotations.iter().enumerate() {
            let norm: f32 = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!((norm - 1.0).abs() < 1e-5);
            // A constant-rate turn about y is a line in angle: kept (up to the chord error).
            let h = 0.05 * i as f32;
            let dot = (q[0] * h.cos() + q[2] * h.sin()).abs();
            assert!(dot > 0.9999, "knot {i}: {q:?}");
        }
    }

    #[test]
    fn cross_validation_keeps_a_slow_motion_and_drops_view_to_view_noise() {
        // A slow curve (one bend over the track) under deterministic pseudo-random wobble.
        let n = 80;
        let truth: Vec<f64> = (0..n)
            .map(|i| (std::f64::consts::PI * i as f64 / n as f64).sin())
            .collect();
        let mut state = 12345u64;
        let noisy: Vec<f64> = truth
            .iter()
            .map(|v| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                v + 0.05 * (((state >> 33) as f64 / (1u64 << 31) as f64) - 0.5)
            })
            .collect();
        let lambda = gcv_lambda(std::slice::from_ref(&noisy));
        let mut z = noisy.clone();
        whittaker(&mut z, lambda);
        let err = |v: &[f64]| {
            v.iter()
                .zip(&truth)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
        };
        assert!(
            err(&z) < 0.3 * err(&noisy),
            "{} vs {}",
            err(&z),
            err(&noisy)
        );
        // A fast motion without noise is left nearly as it is (the smallest penalty wins).
        let fast: Vec<f64> = (0..n).map(|i| (1.3 * i as f64).sin()).collect();
        let mut z = fast.clone();
        whittaker(&mut z, gcv_lambda(std::slice::from_ref(&fast)));
        let moved: f64 = z
            .iter()
            .zip(&fast)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(moved < 0.2, "{moved}");
    }

    #[test]
    fn along_the_rays_the_prior_decides_and_across_them_the_data() {
        // Cameras on a line looking at a still object; its knots wobble along the rays
        // (towards and away from each camera) and a little across them.
        let k = 30;
        let truth = [0.0f32, 0.0, 5.0];
        let centres: Vec<[f32; 3]> = (0..k).map(|i| [i as f32 * 0.1 - 1.5, 0.0, 0.0]).collect();
        let translations: Vec<[f32; 3]> = centres
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let v: [f32; 3] = std::array::from_fn(|j| truth[j] - c[j]);
                let d = v.iter().map(|x| x * x).sum::<f32>().sqrt();
                let along = if i % 2 == 0 { 0.3 } else { -0.3 };
                std::array::from_fn(|j| truth[j] + along * v[j] / d)
            })
            .collect();
        let mut tr = Trajectory {
            times: (0..k).map(|i| i as f32).collect(),
            translations: translations.clone(),
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; k],
        };
        let mut iso = tr.clone();
        smooth_along_rays(&mut tr, &centres, 0.3, 0.1);
        smooth(&mut iso, Amount::Period(0.1));
        let err = |t: &Trajectory| -> f32 {
            t.translations
                .iter()
                .map(|p| (0..3).map(|j| (p[j] - truth[j]).powi(2)).sum::<f32>())
                .sum::<f32>()
        };
        let before = err(&Trajectory {
            translations,
            ..tr.clone()
        });
        assert!(err(&tr) < 0.05 * before, "{} vs {before}", err(&tr));
        assert!(err(&tr) < 0.5 * err(&iso), "{} vs {}", err(&tr), err(&iso));
    }

    #[test]
    fn zero_leaves_the_track_as_it_is() {
        let mut tr = Trajectory {
            times: vec![0.0, 0.5, 1.0],
            translations: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0; 3]],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; 3],
        };
        let before = tr.clone();
        smooth(&mut tr, Amount::Period(0.0));
        assert_eq!(tr, before);
    }
}
