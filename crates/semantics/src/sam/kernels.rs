//! Hand-written numeric kernels for the SAM mask decoder: a thin safe wrapper over the `gemm`
//! crate (single-threaded per call: the decoder parallelizes over prompts instead, so the two
//! cores never fight over one small matrix), LayerNorm, row softmax, and branch-free `exp` /
//! GELU approximations that the compiler vectorizes with whatever SIMD the baseline target has.
//!
//! Why approximations: one 32×32 grid needs ~10⁹ `exp` calls (softmax over 4,096 keys or over 7
//! tokens, per head, per prompt) and ~2·10⁹ GELUs in the output upscaling; libm's scalar `expf`
//! / `erff` alone would cost seconds. Both approximations below are accurate to ~2e-7
//! (relative for exp, absolute for erf), far below the f32 noise of the matrix products.

/// `c = a·b` (or `c += a·b` when `accumulate`), with `a` m×k and `b` k×n given by (row, column)
/// strides and `c` row-major m×n with row stride `c_rs` (≥ n). Panics only on caller bugs
/// (slice too short).
#[allow(clippy::too_many_arguments)]
pub fn matmul(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    (a_rs, a_cs): (usize, usize),
    b: &[f32],
    (b_rs, b_cs): (usize, usize),
    c: &mut [f32],
    c_rs: usize,
    accumulate: bool,
) {
    if m == 0 || n == 0 {
        return;
    }
    assert!(
        c_rs >= n && c.len() >= (m - 1) * c_rs + n,
        "matmul: output too short"
    );
    if k > 0 {
        assert!(
            a.len() > (m - 1) * a_rs + (k - 1) * a_cs,
            "matmul: lhs too short"
        );
        assert!(
            b.len() > (k - 1) * b_rs + (n - 1) * b_cs,
            "matmul: rhs too short"
        );
    } else {
        if !accumulate {
            for row in 0..m {
                c[row * c_rs..row * c_rs + n].fill(0.0);
            }
        }
        return;
    }
    // SAFETY: the asserts above guarantee every index the kernel touches is inside the slices;
    // `c` is exclusively borrowed and cannot alias `a` or `b`.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            c.as_mut_ptr(),
            1,
            c_rs as isize,
            accumulate,
            a.as_ptr(),
            a_cs as isize,
            a_rs as isize,
            b.as_ptr(),
            b_cs as isize,
            b_rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// `y = x·Wᵀ (+ bias)` for PyTorch `nn.Linear` weights `w` (out×in, row-major); `x` is rows×in.
pub fn linear(x: &[f32], rows: usize, w: &[f32], bias: Option<&[f32]>, n_out: usize) -> Vec<f32> {
    let n_in = w.len() / n_out;
    let mut y = vec![0.0f32; rows * n_out];
    if let Some(b) = bias {
        for row in y.chunks_exact_mut(n_out) {
            row.copy_from_slice(b);
        }
    }
    matmul(
        rows,
        n_out,
        n_in,
        x,
        (n_in, 1),
        w,
        (1, n_in),
        &mut y,
        n_out,
        bias.is_some(),
    );
    y
}

/// LayerNorm over the last dimension (`dim`), in place, PyTorch semantics (biased variance).
pub fn layer_norm(x: &mut [f32], dim: usize, w: &[f32], b: &[f32], eps: f32) {
    for row in x.chunks_exact_mut(dim) {
        let mean = row.iter().sum::<f32>() / dim as f32;
        let var = row.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / dim as f32;
        let inv = 1.0 / (var + eps).sqrt();
        for ((v, &g), &bb) in row.iter_mut().zip(w).zip(b) {
            *v = (*v - mean) * inv * g + bb;
        }
    }
}

/// `x += y` elementwise.
pub fn add_assign(x: &mut [f32], y: &[f32]) {
    for (a, b) in x.iter_mut().zip(y) {
        *a += b;
    }
}

/// `out = x + y` elementwise.
pub fn add_into(out: &mut [f32], x: &[f32], y: &[f32]) {
    for ((o, a), b) in out.iter_mut().zip(x).zip(y) {
        *o = a + b;
    }
}

/// Softmax of each `len`-long group of `x` after multiplying by `scale`, in place.
pub fn softmax_groups(x: &mut [f32], len: usize, scale: f32) {
    for g in x.chunks_exact_mut(len) {
        let mut mx = f32::NEG_INFINITY;
        for &v in g.iter() {
            mx = mx.max(v);
        }
        let mut sum = 0.0;
        for v in g.iter_mut() {
            *v = exp_approx((*v - mx) * scale);
            sum += *v;
        }
        let inv = 1.0 / sum;
        for v in g.iter_mut() {
            *v *= inv;
        }
    }
}

/// `e^x` for f32, Cody–Waite range reduction + degree-6 polynomial (Cephes `expf` constants),
/// written without branches so loops over it vectorize. Relative error < 2e-7 on [-87, 88].
#[inline(always)]
pub fn exp_approx(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // 1.5·2²³: adding and subtracting it rounds to the nearest integer without SSE4.1 `round`.
    const MAGIC: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let k = (x * LOG2E + MAGIC) - MAGIC;
    let r = x - k * LN2_HI - k * LN2_LO;
    let p = 1.987_569_1e-4;
    let p = p * r + 1.398_199_9e-3;
    let p = p * r + 8.333_452e-3;
    let p = p * r + 4.166_579_6e-2;
    let p = p * r + 1.666_666_5e-1;
    let p = p * r + 5e-1;
    let e = p * r * r + r + 1.0;
    e * f32::from_bits(((k as i32 + 127) << 23) as u32)
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

/// GELU over a slice, in place.
pub fn gelu_inplace(x: &mut [f32]) {
    for v in x.iter_mut() {
        *v = gelu(*v);
    }
}

/// ReLU over a slice, in place.
pub fn relu_inplace(x: &mut [f32]) {
    for v in x.iter_mut() {
        *v = v.max(0.0);
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
    }

    #[test]
    fn matmul_strided_matches_naive() {
        let (m, n, k) = (5, 7, 3);
        let a: Vec<f32> = (0..m * k).map(|i| i as f32 * 0.1 - 0.4).collect();
        let bt: Vec<f32> = (0..n * k).map(|i| (i as f32 * 0.37).sin()).collect(); // n×k
        let mut c = vec![1.0f32; m * n];
        matmul(m, n, k, &a, (k, 1), &bt, (1, k), &mut c, n, true);
        for i in 0..m {
            for j in 0..n {
                let want: f32 = 1.0 + (0..k).map(|l| a[i * k + l] * bt[j * k + l]).sum::<f32>();
                assert!((c[i * n + j] - want).abs() < 1e-5);
            }
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
}
