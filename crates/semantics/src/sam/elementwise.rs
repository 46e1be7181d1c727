//! Element-wise kernels of the SAM mask decoder (LayerNorm, softmax, GELU, ReLU, additions),
//! compiled several times and picked at run time for the widest SIMD the CPU has (AVX-512F,
//! else AVX2+FMA, else the portable baseline; `simd::level`, capped by `SEMDYNREG_SIMD`). The code of each kernel is written once, as plain
//! loops the compiler auto-vectorizes: no float reductions in sequential order (they would pin
//! the loop to scalar adds; sums use 16 independent accumulators instead), no integer ops that
//! carry overflow checks in test builds (the exp bit-trick uses wrapping arithmetic).
//!
//! Why approximations: one 32×32 grid needs ~10⁹ `exp` calls (softmax over 4,096 keys or over 7
//! tokens, per head, per prompt) and ~2·10⁹ GELUs in the output upscaling; libm's scalar `expf`
//! / `erff` alone would cost seconds. Both approximations below are accurate to ~2e-7
//! (relative for exp, absolute for erf), far below the f32 noise of the matrix products.

/// Defines `pub fn $name(args)` running `$body` through the best available instruction set.
/// `$body` may only call `#[inline(always)]` helpers so that it is compiled for each target.
macro_rules! dispatch {
    ($(#[$m:meta])* fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $body:block) => {
        $(#[$m])*
        pub fn $name($($arg: $ty),*) {
            #[inline(always)]
            fn generic($($arg: $ty),*) $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f")]
                fn avx512($($arg: $ty),*) {
                    generic($($arg),*)
                }
                #[target_feature(enable = "avx2,fma")]
                fn avx2($($arg: $ty),*) {
                    generic($($arg),*)
                }
                match simd::level() {
                    // SAFETY: `simd::level` only returns levels this CPU supports.
                    simd::Simd::Avx512 => return unsafe { avx512($($arg),*) },
                    // SAFETY: as above (AVX2 and FMA).
                    simd::Simd::Avx2 => return unsafe { avx2($($arg),*) },
                    simd::Simd::Portable => {}
                }
            }
            generic($($arg),*)
        }
    };
}

pub(crate) use dispatch;

const LANES: usize = 16;

/// Sum with `LANES` independent accumulators, so the loop vectorizes.
#[inline(always)]
fn sum(x: &[f32]) -> f32 {
    let mut acc = [0.0f32; LANES];
    let chunks = x.chunks_exact(LANES);
    let tail: f32 = chunks.remainder().iter().sum();
    for c in chunks {
        for i in 0..LANES {
            acc[i] += c[i];
        }
    }
    acc.iter().sum::<f32>() + tail
}

/// Σ (x − mean)², vectorized like [`sum`].
#[inline(always)]
fn sum_sq_dev(x: &[f32], mean: f32) -> f32 {
    let mut acc = [0.0f32; LANES];
    let chunks = x.chunks_exact(LANES);
    let tail: f32 = chunks
        .remainder()
        .iter()
        .map(|v| (v - mean) * (v - mean))
        .sum();
    for c in chunks {
        for i in 0..LANES {
            let d = c[i] - mean;
            acc[i] += d * d;
        }
    }
    acc.iter().sum::<f32>() + tail
}

#[inline(always)]
fn max(x: &[f32]) -> f32 {
    let mut acc = [f32::NEG_INFINITY; LANES];
    let chunks = x.chunks_exact(LANES);
    let tail = chunks
        .remainder()
        .iter()
        .fold(f32::NEG_INFINITY, |m, &v| m.max(v));
    for c in chunks {
        for i in 0..LANES {
            acc[i] = acc[i].max(c[i]);
        }
    }
    acc.iter().fold(tail, |m, &v| m.max(v))
}

/// `e^x` for f32, Cody–Waite range reduction + degree-6 polynomial (Cephes `expf` constants),
/// written without branches so loops over it vectorize. Relative error < 2e-7 on [-87, 88].
#[inline(always)]
pub fn exp_approx(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5·2²³: adding it rounds to the nearest integer k (without SSE4.1 `round`) and leaves k
    // in the low mantissa bits, from which 2^k is built with integer ops only.
    const MAGIC: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let kf = x * LOG2E + MAGIC;
    let k = kf - MAGIC;
    let r = x - k * LN2_HI - k * LN2_LO;
    let p = 1.987_569_1e-4;
    let p = p * r + 1.398_199_9e-3;
    let p = p * r + 8.333_452e-3;
    let p = p * r + 4.166_579_6e-2;
    let p = p * r + 1.666_666_5e-1;
    let p = p * r + 5e-1;
    let e = p * r * r + r + 1.0;
    // bits(kf) = bits(MAGIC) + k with k ∈ [-126, 127], so (k + 127) << 23 is 2^k's bit pattern.
    let pow2 = (kf.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(127)) << 23;
    e * f32::from_bits(pow2)
}

/// Exact-form GELU `x·Φ(x) = ½x(1 + erf(x/√2))` (PyTorch `nn.GELU()` default, which SAM uses),
/// with erf from Abramowitz & Stegun 7.1.26 (|error| ≤ 1.5e-7).
#[inline(always)]
pub fn gelu(x: f32) -> f32 {
    let z = (x * std::f32::consts::FRAC_1_SQRT_2).abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * z);
    let poly = t
        * (0.254_829_6
            + t * (-0.284_496_74 + t * (1.421_413_8 + t * (-1.453_152_1 + t * 1.061_405_4))));
    let erf_abs = 1.0 - poly * exp_approx(-z * z);
    let erf = if x < 0.0 { -erf_abs } else { erf_abs };
    0.5 * x * (1.0 + erf)
}

dispatch! {
    /// LayerNorm over the last dimension (`dim`), in place, PyTorch semantics (biased variance).
    fn layer_norm(x: &mut [f32], dim: usize, w: &[f32], b: &[f32], eps: f32) {
        let (w, b) = (&w[..dim], &b[..dim]);
        for row in x.chunks_exact_mut(dim) {
            let mean = sum(row) / dim as f32;
            let inv = 1.0 / (sum_sq_dev(row, mean) / dim as f32 + eps).sqrt();
            for ((v, &g), &bb) in row.iter_mut().zip(w).zip(b) {
                *v = (*v - mean) * inv * g + bb;
            }
        }
    }
}

dispatch! {
    /// `x = LayerNorm(base + x)` row by row (`norm` = weight, bias, eps; the row length is the
    /// weight's), and `x_pe = x + pe`: the image side's residual + norm4 of a two-way block and
    /// the positional sum the next attention reads, fused into one pass over the 4 MB token
    /// arrays (the decoder streams them from L3).
    fn residual_norm_pe(
        x: &mut [f32],
        base: &[f32],
        pe: &[f32],
        x_pe: &mut [f32],
        norm: (&[f32], &[f32], f32),
    ) {
        let (w, b, eps) = norm;
        let dim = w.len();
        let b = &b[..dim];
        let rows = x
            .chunks_exact_mut(dim)
            .zip(base.chunks_exact(dim))
            .zip(pe.chunks_exact(dim).zip(x_pe.chunks_exact_mut(dim)));
        for ((row, base), (pe, out)) in rows {
            row.iter_mut().zip(base).for_each(|(v, &a)| *v += a);
            let mean = sum(row) / dim as f32;
            let inv = 1.0 / (sum_sq_dev(row, mean) / dim as f32 + eps).sqrt();
            let params = w.iter().zip(b).zip(pe.iter().zip(out.iter_mut()));
            for (v, ((&g, &bb), (&p, o))) in row.iter_mut().zip(params) {
                *v = (*v - mean) * inv * g + bb;
                *o = *v + p;
            }
        }
    }
}

dispatch! {
    /// Softmax of each `len`-long group of `x` after multiplying by `scale`, in place. Short
    /// groups (the 7 prompt tokens) take a three-pass form so that the `exp` runs over the
    /// whole slice at full vector width.
    fn softmax_groups(x: &mut [f32], len: usize, scale: f32) {
        if len < LANES {
            for g in x.chunks_exact_mut(len) {
                let mx = g.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
                g.iter_mut().for_each(|v| *v = (*v - mx) * scale);
            }
            x.iter_mut().for_each(|v| *v = exp_approx(*v));
            for g in x.chunks_exact_mut(len) {
                let inv = 1.0 / g.iter().sum::<f32>();
                g.iter_mut().for_each(|v| *v *= inv);
            }
            return;
        }
        for g in x.chunks_exact_mut(len) {
            let mx = max(g);
            g.iter_mut().for_each(|v| *v = exp_approx((*v - mx) * scale));
            let inv = 1.0 / sum(g);
            g.iter_mut().for_each(|v| *v *= inv);
        }
    }
}

dispatch! {
    /// Softmax of each `len`-long row of `x` after `x·scale + bias` (TinyViT's window attention:
    /// scaled scores plus the learned relative-position bias), in place; `bias` has the length
    /// of `x`.
    fn softmax_rows_biased(x: &mut [f32], bias: &[f32], len: usize, scale: f32) {
        for (g, b) in x.chunks_exact_mut(len).zip(bias.chunks_exact(len)) {
            g.iter_mut().zip(b).for_each(|(v, &b)| *v = *v * scale + b);
            let mx = max(g);
            g.iter_mut().for_each(|v| *v = exp_approx(*v - mx));
            let inv = 1.0 / sum(g);
            g.iter_mut().for_each(|v| *v *= inv);
        }
    }
}

dispatch! {
    /// Softmax down each column of a row-major matrix with `cols` columns, after multiplying
    /// by `scale`, in place. The loops run along rows, so they vectorize across columns.
    fn softmax_columns(x: &mut [f32], cols: usize, scale: f32) {
        let mut mx = vec![f32::NEG_INFINITY; cols];
        for row in x.chunks_exact(cols) {
            mx.iter_mut().zip(row).for_each(|(m, &v)| *m = m.max(v));
        }
        let mut total = vec![0.0f32; cols];
        for row in x.chunks_exact_mut(cols) {
            for ((v, &m), t) in row.iter_mut().zip(&mx).zip(total.iter_mut()) {
                *v = exp_approx((*v - m) * scale);
                *t += *v;
            }
        }
        total.iter_mut().for_each(|t| *t = 1.0 / *t);
        for row in x.chunks_exact_mut(cols) {
            row.iter_mut().zip(&total).for_each(|(v, &inv)| *v *= inv);
        }
    }
}

dispatch! {
    /// GELU over a slice, in place.
    fn gelu_inplace(x: &mut [f32]) {
        x.iter_mut().for_each(|v| *v = gelu(*v));
    }
}

dispatch! {
    /// ReLU over a slice, in place.
    fn relu_inplace(x: &mut [f32]) {
        x.iter_mut().for_each(|v| *v = v.max(0.0));
    }
}

dispatch! {
    /// `x += y` elementwise.
    fn add_assign(x: &mut [f32], y: &[f32]) {
        x.iter_mut().zip(y).for_each(|(a, b)| *a += b);
    }
}

dispatch! {
    /// `out = x + y` elementwise.
    fn add_into(out: &mut [f32], x: &[f32], y: &[f32]) {
        out.iter_mut().zip(x).zip(y).for_each(|((o, a), b)| *o = a + b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_matches_std() {
        let mut worst = 0.0f32;
        for i in -8700..8800 {
            let x = i as f32 * 0.01;
            let rel = ((exp_approx(x) - x.exp()) / x.exp()).abs();
            worst = worst.max(rel);
        }
        assert!(worst < 5e-7, "worst relative error {worst}");
        // Clamped outside the f32 range instead of overflowing.
        assert!(exp_approx(-1000.0) < 1e-37 && exp_approx(1000.0).is_finite());
    }

    #[test]
    fn gelu_matches_erf_form() {
        // x·Φ(x) from tables of the normal CDF.
        let known = [
            (0.0f32, 0.0f32),
            (1.0, 0.841_344_7),
            (-1.0, -0.158_655_3),
            (3.0, 2.995_95),
        ];
        for (x, y) in known {
            assert!(
                (gelu(x) - y).abs() < 1e-6,
                "gelu({x}) = {} want {y}",
                gelu(x)
            );
        }
        // The dispatched slice version agrees with the scalar one, tail included.
        let xs: Vec<f32> = (0..37).map(|i| i as f32 * 0.3 - 5.0).collect();
        let mut ys = xs.clone();
        gelu_inplace(&mut ys);
        for (x, y) in xs.iter().zip(&ys) {
            assert!((gelu(*x) - y).abs() < 1e-6);
        }
    }

    #[test]
    fn softmax_groups_sum_to_one() {
        let mut x = vec![1.0, 2.0, 3.0, -1.0, 0.0, 100.0];
        softmax_groups(&mut x, 3, 0.5);
        assert!((x[..3].iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert!((x[3..].iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let want = (0.5f32).exp() / (1.0 + 0.5f32.exp() + 1.0f32.exp());
        assert!((x[1] - want).abs() < 1e-6);
    }

    #[test]
    fn long_softmax_matches_naive() {
        let len = 4096 + 7; // chunked path plus a tail
        let x: Vec<f32> = (0..2 * len)
            .map(|i| ((i * 37) % 101) as f32 * 0.1)
            .collect();
        let mut y = x.clone();
        softmax_groups(&mut y, len, 0.25);
        for (g, h) in x.chunks(len).zip(y.chunks(len)) {
            let mx = g.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
            let z: f64 = g.iter().map(|&v| (((v - mx) * 0.25) as f64).exp()).sum();
            for (&a, &b) in g.iter().zip(h) {
                let want = (((a - mx) * 0.25) as f64).exp() / z;
                assert!((b as f64 - want).abs() < 1e-6 * want.max(1e-3));
            }
        }
    }

    #[test]
    fn biased_softmax_matches_naive() {
        let len = 49;
        let x: Vec<f32> = (0..len * 3)
            .map(|i| ((i * 37 % 101) as f32 - 50.0) * 0.3)
            .collect();
        let bias: Vec<f32> = (0..len * 3)
            .map(|i| ((i * 13 % 29) as f32 - 14.0) * 0.2)
            .collect();
        let mut got = x.clone();
        softmax_rows_biased(&mut got, &bias, len, 0.17);
        for r in 0..3 {
            let z: Vec<f64> = (0..len)
                .map(|j| f64::from(x[r * len + j]) * 0.17 + f64::from(bias[r * len + j]))
                .collect();
            let mx = z.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            let total: f64 = z.iter().map(|v| (v - mx).exp()).sum();
            for j in 0..len {
                let want = (z[j] - mx).exp() / total;
                assert!((f64::from(got[r * len + j]) - want).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn column_softmax_matches_row_softmax_of_transpose() {
        let (rows, cols) = (300, 21);
        let x: Vec<f32> = (0..rows * cols)
            .map(|i| ((i * 7) % 53) as f32 * 0.2)
            .collect();
        let mut by_col = x.clone();
        softmax_columns(&mut by_col, cols, 0.7);
        let mut t: Vec<f32> = (0..cols * rows)
            .map(|i| x[(i % rows) * cols + i / rows])
            .collect();
        softmax_groups(&mut t, rows, 0.7);
        for r in 0..rows {
            for c in 0..cols {
                assert!((by_col[r * cols + c] - t[c * rows + r]).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn residual_norm_pe_matches_unfused() {
        let dim = 48;
        let x: Vec<f32> = (0..4 * dim).map(|i| ((i * 11) % 23) as f32 * 0.3).collect();
        let base: Vec<f32> = (0..4 * dim).map(|i| ((i * 5) % 17) as f32 - 8.0).collect();
        let pe: Vec<f32> = (0..4 * dim).map(|i| (i as f32 * 0.1).sin()).collect();
        let (w, b) = (vec![1.5f32; dim], vec![0.25f32; dim]);
        let mut want = x.clone();
        add_assign(&mut want, &base);
        layer_norm(&mut want, dim, &w, &b, 1e-5);
        let mut want_pe = vec![0.0; want.len()];
        add_into(&mut want_pe, &want, &pe);
        let (mut got, mut got_pe) = (x.clone(), vec![0.0; x.len()]);
        residual_norm_pe(&mut got, &base, &pe, &mut got_pe, (&w, &b, 1e-5));
        for i in 0..x.len() {
            assert!((got[i] - want[i]).abs() < 1e-6 && (got_pe[i] - want_pe[i]).abs() < 1e-6);
        }
    }

    #[test]
    fn layer_norm_matches_two_pass_f64() {
        let dim = 64 + 5;
        let x: Vec<f32> = (0..3 * dim).map(|i| ((i * 13) % 29) as f32 - 9.0).collect();
        let w: Vec<f32> = (0..dim).map(|i| 1.0 + i as f32 * 0.01).collect();
        let b: Vec<f32> = (0..dim).map(|i| i as f32 * -0.02).collect();
        let mut y = x.clone();
        layer_norm(&mut y, dim, &w, &b, 1e-5);
        for (row, out) in x.chunks(dim).zip(y.chunks(dim)) {
            let mean = row.iter().map(|&v| v as f64).sum::<f64>() / dim as f64;
            let var = row.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / dim as f64;
            for i in 0..dim {
                let want = (row[i] as f64 - mean) / (var + 1e-5).sqrt() * w[i] as f64 + b[i] as f64;
                assert!((out[i] as f64 - want).abs() < 1e-5, "{} vs {want}", out[i]);
            }
        }
    }
}
