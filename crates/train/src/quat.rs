//! Quaternion and rotation helpers shared by the deformation, densification and the rigid
//! objects (DESIGN.md: quaternions are stored w, x, y, z and unnormalized; they are
//! normalized where used). Products follow Hamilton's convention, as 3DGS does.

/// `q / |q|` and `|q|` (the norm floored at 1e-12 so a zero quaternion does not divide by 0).
pub fn normalize(q: &[f32]) -> ([f32; 4], f32) {
    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        .sqrt()
        .max(1e-12);
    ([q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm], norm)
}

/// Chain rule through [`normalize`]: `dL/dq = (I − u uᵀ)·dL/du / |q|` for `u = q/|q|`.
pub fn normalize_vjp(u: [f32; 4], norm: f32, g: [f32; 4]) -> [f32; 4] {
    let dot = u[0] * g[0] + u[1] * g[1] + u[2] * g[2] + u[3] * g[3];
    std::array::from_fn(|k| (g[k] - u[k] * dot) / norm)
}

/// Hamilton product `a ⊗ b`.
pub fn mul(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// The conjugate `(w, −x, −y, −z)`: the inverse of a unit quaternion.
pub fn conj(q: [f32; 4]) -> [f32; 4] {
    [q[0], -q[1], -q[2], -q[3]]
}

/// Rotation matrix (row-major) of a unit quaternion.
pub fn to_matrix(q: [f32; 4]) -> [[f32; 3]; 3] {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Rotation matrix of any non-zero quaternion (normalized first).
pub fn matrix_of(q: &[f32]) -> [[f32; 3]; 3] {
    to_matrix(normalize(q).0)
}

/// Gradient w.r.t. the (unit) quaternion components of a loss with gradient `g` w.r.t. the
/// matrix [`to_matrix`] returns: the partial derivatives of its polynomial entries. Callers
/// chain [`normalize_vjp`] to reach the stored, unnormalized quaternion.
pub fn to_matrix_vjp(q: [f32; 4], g: &[[f64; 3]; 3]) -> [f64; 4] {
    let [w, x, y, z] = q.map(f64::from);
    let d_w = -z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1];
    let d_x = y * g[0][1] + z * g[0][2] + y * g[1][0] - 2.0 * x * g[1][1] - w * g[1][2]
        + z * g[2][0]
        + w * g[2][1]
        - 2.0 * x * g[2][2];
    let d_y = -2.0 * y * g[0][0] + x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2]
        - w * g[2][0]
        + z * g[2][1]
        - 2.0 * y * g[2][2];
    let d_z = -2.0 * z * g[0][0] - w * g[0][1] + x * g[0][2] + w * g[1][0] - 2.0 * z * g[1][1]
        + y * g[1][2]
        + x * g[2][0]
        + y * g[2][1];
    [2.0 * d_w, 2.0 * d_x, 2.0 * d_y, 2.0 * d_z]
}

/// `r · v`.
pub fn rotate(r: &[[f32; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    r.map(|row| row[0] * v[0] + row[1] * v[1] + row[2] * v[2])
}

/// `rᵀ · v` (the inverse rotation).
pub fn rotate_inv(r: &[[f32; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|k| r[0][k] * v[0] + r[1][k] * v[1] + r[2][k] * v[2])
}

/// Unit quaternion of a rotation vector (axis · angle in radians).
pub fn from_rotvec(v: [f32; 3]) -> [f32; 4] {
    let angle = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if angle < 1e-8 {
        return [1.0, 0.5 * v[0], 0.5 * v[1], 0.5 * v[2]];
    }
    let s = (0.5 * angle).sin() / angle;
    [(0.5 * angle).cos(), v[0] * s, v[1] * s, v[2] * s]
}

/// Rotation vector of a unit quaternion (the shorter way round).
pub fn to_rotvec(q: [f32; 4]) -> [f32; 3] {
    let q = if q[0] < 0.0 { q.map(|v| -v) } else { q };
    let s = (q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if s < 1e-8 {
        return [2.0 * q[1], 2.0 * q[2], 2.0 * q[3]];
    }
    let angle = 2.0 * s.atan2(q[0]);
    [q[1] / s * angle, q[2] / s * angle, q[3] / s * angle]
}

/// Unit quaternion (w ≥ 0) of a row-major rotation matrix, by the largest of the four
/// diagonal combinations (Shepperd 1978), which keeps the division well away from zero.
pub fn from_matrix(r: &[[f64; 3]; 3]) -> [f32; 4] {
    let tr = r[0][0] + r[1][1] + r[2][2];
    let q = if tr > r[0][0].max(r[1][1]).max(r[2][2]) {
        let s = 2.0 * (1.0 + tr).sqrt();
        [
            0.25 * s,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] >= r[1][1] && r[0][0] >= r[2][2] {
        let s = 2.0 * (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt();
        [
            (r[2][1] - r[1][2]) / s,
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] >= r[2][2] {
        let s = 2.0 * (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt();
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt();
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
        ]
    };
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    let q = q.map(|v| (sign * v) as f32);
    normalize(&q).0
}

/// Angle in radians of the rotation between two unit quaternions.
pub fn angle_between(a: [f32; 4], b: [f32; 4]) -> f32 {
    let d = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]).abs();
    2.0 * d.min(1.0).acos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrix_round_trips_through_the_quaternion() {
        // Near the identity, half-turns about each axis (each branch of Shepperd's rule).
        let cases = [
            [0.9, 0.1, -0.3, 0.2],
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.05, 0.1, 0.2, 0.97],
        ];
        for q in cases {
            let q = normalize(&q).0;
            let m = to_matrix(q).map(|row| row.map(f64::from));
            let back = from_matrix(&m);
            let d = (0..4).map(|k| (back[k] - q[k]).abs()).fold(0.0, f32::max);
            let d_neg = (0..4).map(|k| (back[k] + q[k]).abs()).fold(0.0, f32::max);
            assert!(d.min(d_neg) < 1e-5, "{q:?} → {back:?}");
            assert!(back[0] >= 0.0);
        }
    }

    #[test]
    fn product_composes_rotations() {
        let a = normalize(&[0.9, 0.1, -0.3, 0.2]).0;
        let b = normalize(&[0.4, -0.6, 0.2, 0.5]).0;
        let v = [0.3, -1.2, 0.7];
        let ab = rotate(&to_matrix(mul(a, b)), v);
        let a_b = rotate(&to_matrix(a), rotate(&to_matrix(b), v));
        for k in 0..3 {
            assert!((ab[k] - a_b[k]).abs() < 1e-5);
        }
        let back = rotate_inv(&to_matrix(a), rotate(&to_matrix(a), v));
        for k in 0..3 {
            assert!((back[k] - v[k]).abs() < 1e-5);
        }
        let id = mul(a, conj(a));
        assert!((id[0] - 1.0).abs() < 1e-6 && id[1..].iter().all(|x| x.abs() < 1e-6));
    }

    #[test]
    fn rotvec_round_trips() {
        for v in [[0.3f32, -0.2, 1.1], [0.0, 0.0, 3.0], [1e-9, 0.0, 0.0]] {
            let back = to_rotvec(from_rotvec(v));
            for k in 0..3 {
                assert!((back[k] - v[k]).abs() < 1e-5, "{v:?} → {back:?}");
            }
        }
        let q = from_rotvec([0.0, 0.0, 0.5]);
        assert!((angle_between(q, [1.0, 0.0, 0.0, 0.0]) - 0.5).abs() < 1e-5);
    }

    /// `to_matrix_vjp` then `normalize_vjp` is the gradient of `Σ G ⊙ R(q/|q|)` w.r.t. q.
    #[test]
    fn matrix_gradient_matches_finite_differences() {
        let g = [[0.3, -1.0, 0.2], [0.7, 0.1, -0.4], [-0.5, 0.9, 0.6]];
        let f = |q: &[f32]| -> f64 {
            let r = matrix_of(q);
            (0..9)
                .map(|k| g[k / 3][k % 3] * r[k / 3][k % 3] as f64)
                .sum()
        };
        let q = [1.1f32, -0.2, 0.4, 0.3];
        let (u, norm) = normalize(&q);
        let du = to_matrix_vjp(u, &g).map(|v| v as f32);
        let dq = normalize_vjp(u, norm, du);
        for k in 0..4 {
            let (mut p, mut m) = (q, q);
            p[k] += 1e-3;
            m[k] -= 1e-3;
            let fd = (f(&p) - f(&m)) / 2e-3;
            assert!((fd - dq[k] as f64).abs() < 1e-3, "{k}: {fd} vs {}", dq[k]);
        }
    }
}
