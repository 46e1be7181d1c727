//! The little linear algebra the loaders and the generator need (f64 for inversions).

pub type Mat4 = [[f64; 4]; 4];

pub const IDENTITY: Mat4 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// `a · b`.
pub fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut out = [[0.0; 4]; 4];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[r][k] * b[k][c]).sum();
        }
    }
    out
}

/// General 4×4 inverse by Gauss-Jordan elimination with partial pivoting; `None` when
/// singular (a pivot below 1e-12 relative to the matrix scale).
pub fn invert(m: &Mat4) -> Option<Mat4> {
    let scale = m.iter().flatten().fold(0.0f64, |a, &v| a.max(v.abs()));
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    let mut a = *m;
    let mut inv = IDENTITY;
    for col in 0..4 {
        let pivot = (col..4).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 * scale {
            return None;
        }
        a.swap(col, pivot);
        inv.swap(col, pivot);
        let p = a[col][col];
        for k in 0..4 {
            a[col][k] /= p;
            inv[col][k] /= p;
        }
        for r in 0..4 {
            if r != col {
                let f = a[r][col];
                for k in 0..4 {
                    a[r][k] -= f * a[col][k];
                    inv[r][k] -= f * inv[col][k];
                }
            }
        }
    }
    Some(inv)
}

/// Rotation about +z by `yaw` radians, then translation by `t`.
pub fn yaw_translate(yaw: f64, t: [f64; 3]) -> Mat4 {
    let (s, c) = yaw.sin_cos();
    [
        [c, -s, 0.0, t[0]],
        [s, c, 0.0, t[1]],
        [0.0, 0.0, 1.0, t[2]],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// `m · [p, 1]`, the affine part only.
pub fn transform_point(m: &Mat4, p: [f64; 3]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (r, o) in out.iter_mut().enumerate() {
        *o = m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3];
    }
    out
}

/// Converts to the f32 row-major matrix `splat::Camera` stores; `None` if any entry is
/// not finite in f32.
pub fn to_f32(m: &Mat4) -> Option<[[f32; 4]; 4]> {
    let mut out = [[0.0f32; 4]; 4];
    for r in 0..4 {
        for c in 0..4 {
            let v = m[r][c] as f32;
            if !v.is_finite() {
                return None;
            }
            out[r][c] = v;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_times_matrix_is_identity() {
        let m = mul(
            &yaw_translate(0.7, [1.0, -2.0, 0.5]),
            &[
                [2.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.3, 0.0],
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        );
        let p = mul(&m, &invert(&m).unwrap());
        for r in 0..4 {
            for c in 0..4 {
                assert!((p[r][c] - IDENTITY[r][c]).abs() < 1e-12);
            }
        }
        assert!(invert(&[[0.0; 4]; 4]).is_none());
    }
}
