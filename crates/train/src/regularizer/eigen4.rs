//! Eigen-decomposition of a symmetric 4×4 matrix by the cyclic Jacobi method (Golub & Van
//! Loan, *Matrix Computations*, Sec. 8.5), in f64, for Horn's quaternion rigid fit
//! ([`super::rigid_fit`]).
//!
//! Why Jacobi: it is unconditionally stable and returns orthonormal eigenvectors to working
//! precision even when eigenvalues repeat, which is exactly what the fit's degenerate inputs
//! (collinear or coincident points) produce; a 4×4 matrix converges in a few sweeps.

/// Row-major 4×4 matrix.
pub type Mat4 = [[f64; 4]; 4];

/// Eigenvalues (unsorted) and eigenvectors: column `c` of `vectors` (`vectors[r][c]`,
/// `r = 0..4`) is the unit eigenvector of `values[c]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Eigen4 {
    pub values: [f64; 4],
    pub vectors: Mat4,
}

impl Eigen4 {
    /// The unit eigenvector of the largest eigenvalue (the first one on ties, so the choice
    /// is deterministic).
    pub fn top_vector(&self) -> [f64; 4] {
        let mut best = 0;
        for c in 1..4 {
            if self.values[c] > self.values[best] {
                best = c;
            }
        }
        [0, 1, 2, 3].map(|r| self.vectors[r][best])
    }
}

/// More than enough: cyclic Jacobi converges quadratically, a 4×4 in ≤ 6 sweeps.
const MAX_SWEEPS: usize = 50;

/// Eigen-decomposition of the symmetric `a` (only its upper triangle is read). Non-finite
/// entries give non-finite output; callers check their inputs.
#[allow(
    clippy::needless_range_loop,
    reason = "mirroring a triangle reads m[j][i] while writing m[i][j]"
)]
pub fn symmetric_eigen(a: &Mat4) -> Eigen4 {
    let mut m = *a;
    for i in 0..4 {
        for j in 0..i {
            m[i][j] = m[j][i];
        }
    }
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _ in 0..MAX_SWEEPS {
        let off: f64 = (0..4)
            .flat_map(|i| (i + 1..4).map(move |j| (i, j)))
            .map(|(i, j)| m[i][j] * m[i][j])
            .sum();
        let diag: f64 = (0..4).map(|i| m[i][i] * m[i][i]).sum();
        // Converged when the off-diagonal part is below rounding of the diagonal.
        if off <= f64::EPSILON * f64::EPSILON * diag || off == 0.0 || !off.is_finite() {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                rotate(&mut m, &mut v, p, q);
            }
        }
    }
    Eigen4 {
        values: [m[0][0], m[1][1], m[2][2], m[3][3]],
        vectors: v,
    }
}

/// One Jacobi rotation `m ← Jᵀ m J`, `v ← v J`, with `J` the plane rotation in `(p, q)`
/// chosen to zero `m[p][q]` (the smaller of the two angles that do, for stability).
#[allow(
    clippy::needless_range_loop,
    reason = "a Jacobi rotation updates columns p, q of every row of m: index form is the textbook's"
)]
fn rotate(m: &mut Mat4, v: &mut Mat4, p: usize, q: usize) {
    let apq = m[p][q];
    if apq == 0.0 {
        return;
    }
    let theta = (m[q][q] - m[p][p]) / (2.0 * apq);
    // t = tan φ = sgn θ / (|θ| + √(θ² + 1)); hypot avoids overflow for huge θ.
    let t = theta.signum() / (theta.abs() + theta.hypot(1.0));
    let c = 1.0 / t.hypot(1.0);
    let s = t * c;
    for k in 0..4 {
        let (kp, kq) = (m[k][p], m[k][q]);
        m[k][p] = c * kp - s * kq;
        m[k][q] = s * kp + c * kq;
    }
    for k in 0..4 {
        let (pk, qk) = (m[p][k], m[q][k]);
        m[p][k] = c * pk - s * qk;
        m[q][k] = s * pk + c * qk;
    }
    m[p][q] = 0.0;
    m[q][p] = 0.0;
    for row in v.iter_mut() {
        let (kp, kq) = (row[p], row[q]);
        row[p] = c * kp - s * kq;
        row[q] = s * kp + c * kq;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `V diag(λ) Vᵀ` reproduces `a` (to 1e-12 of its largest entry), `V` is orthonormal.
    #[allow(
        clippy::needless_range_loop,
        reason = "entry (i, j) of two matrix products"
    )]
    fn check(a: &Mat4) -> Eigen4 {
        let e = symmetric_eigen(a);
        let scale = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        for i in 0..4 {
            for j in 0..4 {
                let rec: f64 = (0..4)
                    .map(|c| e.vectors[i][c] * e.values[c] * e.vectors[j][c])
                    .sum();
                let err = (rec - a[i][j]).abs();
                assert!(err <= 1e-12 * scale, "A[{i}][{j}] {rec} vs {}", a[i][j]);
                let dot: f64 = (0..4).map(|r| e.vectors[r][i] * e.vectors[r][j]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 1e-12, "VᵀV[{i}][{j}] = {dot}");
            }
        }
        e
    }

    #[test]
    fn dense_matrix_is_reconstructed() {
        let a = [
            [4.0, 1.0, -2.0, 0.5],
            [1.0, 3.0, 0.25, -1.0],
            [-2.0, 0.25, -1.0, 2.0],
            [0.5, -1.0, 2.0, 0.0],
        ];
        let e = check(&a);
        // The top vector's Rayleigh quotient is the largest eigenvalue.
        let top = e.top_vector();
        let max = e.values.iter().copied().fold(f64::MIN, f64::max);
        let rq: f64 = (0..4)
            .flat_map(|i| (0..4).map(move |j| (i, j)))
            .map(|(i, j)| top[i] * a[i][j] * top[j])
            .sum();
        assert!((rq - max).abs() < 1e-12);
    }

    #[test]
    fn repeated_zero_and_diagonal_matrices() {
        check(&[[0.0; 4]; 4]);
        let e = check(&[
            [2.0, 0.0, 0.0, 0.0],
            [0.0, 2.0, 0.0, 0.0],
            [0.0; 4],
            [0.0; 4],
        ]);
        assert_eq!(e.top_vector(), [1.0, 0.0, 0.0, 0.0], "first of a tie");
        // Repeated non-trivial eigenvalues (rank-one plus identity).
        let u = [0.5, 0.5, 0.5, 0.5];
        let a = [0, 1, 2, 3].map(|i| [0, 1, 2, 3].map(|j| 3.0 * u[i] * u[j] + f64::from(i == j)));
        let e = check(&a);
        let top = e.top_vector();
        let dot: f64 = (0..4).map(|i| top[i] * u[i]).sum();
        assert!((dot.abs() - 1.0).abs() < 1e-12);
        // Tiny and huge scales.
        check(&a.map(|r| r.map(|x| x * 1e-30)));
        check(&a.map(|r| r.map(|x| x * 1e30)));
    }
}
