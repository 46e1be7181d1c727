//! A bounds-checked, safe front to `gemm::gemm` for strided f32 matrices. Callers split
//! rows into fixed chunks and run these single-threaded inside rayon, so results do not
//! depend on the thread count (resume must be bit-identical).

/// A strided read-only matrix view: element (i, j) is `data[i·rs + j·cs]`.
#[derive(Clone, Copy, Debug)]
pub struct Mat<'a> {
    pub data: &'a [f32],
    pub rows: usize,
    pub cols: usize,
    pub rs: usize,
    pub cs: usize,
}

impl<'a> Mat<'a> {
    pub fn row_major(data: &'a [f32], rows: usize, cols: usize) -> Self {
        Self {
            data,
            rows,
            cols,
            rs: cols,
            cs: 1,
        }
    }

    /// The transpose, by swapping strides (no copy).
    pub fn t(self) -> Self {
        Self {
            data: self.data,
            rows: self.cols,
            cols: self.rows,
            rs: self.cs,
            cs: self.rs,
        }
    }

    fn assert_in_bounds(&self) {
        if self.rows > 0 && self.cols > 0 {
            let last = (self.rows - 1) * self.rs + (self.cols - 1) * self.cs;
            assert!(last < self.data.len(), "matrix view out of bounds");
        }
    }
}

/// `c (a.rows × b.cols, row-major) = [c +] a · b`.
pub fn matmul(c: &mut [f32], a: Mat, b: Mat, accumulate: bool) {
    assert_eq!(a.cols, b.rows, "inner dimensions differ");
    assert_eq!(c.len(), a.rows * b.cols, "output size");
    a.assert_in_bounds();
    b.assert_in_bounds();
    if c.is_empty() {
        return;
    }
    if a.cols == 0 {
        if !accumulate {
            c.iter_mut().for_each(|x| *x = 0.0);
        }
        return;
    }
    // SAFETY: every index gemm touches is (i·rs + j·cs) within the views checked above and
    // within `c` (m·n elements, row stride n); `c` does not alias `a` or `b` (&mut borrow).
    unsafe {
        gemm::gemm(
            a.rows,
            b.cols,
            a.cols,
            c.as_mut_ptr(),
            1,
            b.cols as isize,
            accumulate,
            a.data.as_ptr(),
            a.cs as isize,
            a.rs as isize,
            b.data.as_ptr(),
            b.cs as isize,
            b.rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(a: Mat, b: Mat) -> Vec<f32> {
        let mut c = vec![0.0; a.rows * b.cols];
        for i in 0..a.rows {
            for j in 0..b.cols {
                for k in 0..a.cols {
                    c[i * b.cols + j] += a.data[i * a.rs + k * a.cs] * b.data[k * b.rs + j * b.cs];
                }
            }
        }
        c
    }

    #[test]
    fn matches_naive_with_transposes() {
        let a: Vec<f32> = (0..35).map(|i| (i as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..35).map(|i| (i as f32 * 0.11).cos()).collect();
        let am = Mat::row_major(&a, 5, 7);
        let bm = Mat::row_major(&b, 5, 7);
        for (x, y) in [(am, bm.t()), (am.t(), bm), (bm.t(), am)] {
            let mut c = vec![1.0; x.rows * y.cols];
            matmul(&mut c, x, y, false);
            for (u, v) in c.iter().zip(naive(x, y)) {
                assert!((u - v).abs() < 1e-5);
            }
            let before = c.clone();
            matmul(&mut c, x, y, true);
            for (u, v) in c.iter().zip(before) {
                assert!((u - 2.0 * v).abs() < 1e-4);
            }
        }
    }
}
