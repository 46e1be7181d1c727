//! Matrix products of the SAM mask decoder: a thin safe wrapper over the `gemm` crate
//! (single-threaded per call: the decoder parallelizes over prompts instead, so the two cores
//! never fight over one small matrix). The element-wise kernels are in `elementwise.rs`.

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

/// `y = x·Wt (+ bias)` with `wt` the in×out (row-major) transpose of a PyTorch `nn.Linear`
/// weight; `x` is rows×in. The transposed layout keeps `gemm` on its no-packing path (see
/// `Linear` in `layers.rs`).
pub fn linear(x: &[f32], rows: usize, wt: &[f32], bias: Option<&[f32]>, n_out: usize) -> Vec<f32> {
    let n_in = wt.len() / n_out;
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
        wt,
        (n_out, 1),
        &mut y,
        n_out,
        bias.is_some(),
    );
    y
}

/// Transpose a rows×cols row-major matrix.
pub fn transpose(x: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut t = vec![0.0f32; rows * cols];
    for (r, row) in x.chunks_exact(cols).take(rows).enumerate() {
        for (c, &v) in row.iter().enumerate() {
            t[c * rows + r] = v;
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
