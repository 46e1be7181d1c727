//! Real spherical harmonics (Sloan basis, as 3DGS and gsplat's `_eval_sh_bases_fast`),
//! degree 0–3, and the derivative of the basis with respect to the unit direction.
//!
//! The polynomials are written in 3DGS's `computeColorFromSH` form. They equal gsplat's
//! "fast" form on the unit sphere; off the sphere they differ, but the direction is
//! normalized first, so the gradient (projected onto the sphere's tangent plane by the
//! normalization's backward) is the same.

use crate::lanes::Lane;

/// Largest supported degree.
pub const MAX_DEGREE: usize = 3;

/// Number of coefficients of degree `d`: (d+1)².
pub const fn num_coeffs(degree: usize) -> usize {
    (degree + 1) * (degree + 1)
}

/// Floating-point type the basis is evaluated in (f32 on the hot path, f64 in the
/// reference implementation).
pub trait Real:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Neg<Output = Self>
{
    fn c(v: f64) -> Self;
}

impl Real for f32 {
    #[inline(always)]
    fn c(v: f64) -> Self {
        v as f32
    }
}

impl Real for f64 {
    #[inline(always)]
    fn c(v: f64) -> Self {
        v
    }
}

const C0: f64 = 0.282_094_791_773_878_1;
const C1: f64 = 0.488_602_511_902_919_9;
const C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
const C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Basis values at unit direction `n` for the first `num_coeffs(degree)` entries of `out`.
#[inline(always)]
pub fn basis<T: Real>(degree: usize, n: [T; 3], out: &mut [T; 16]) {
    let [x, y, z] = n;
    out[0] = T::c(C0);
    if degree == 0 {
        return;
    }
    out[1] = -(T::c(C1) * y);
    out[2] = T::c(C1) * z;
    out[3] = -(T::c(C1) * x);
    if degree == 1 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let two = T::c(2.0);
    out[4] = T::c(C2[0]) * x * y;
    out[5] = T::c(C2[1]) * y * z;
    out[6] = T::c(C2[2]) * (two * zz - xx - yy);
    out[7] = T::c(C2[3]) * x * z;
    out[8] = T::c(C2[4]) * (xx - yy);
    if degree == 2 {
        return;
    }
    let (three, four) = (T::c(3.0), T::c(4.0));
    out[9] = T::c(C3[0]) * y * (three * xx - yy);
    out[10] = T::c(C3[1]) * x * y * z;
    out[11] = T::c(C3[2]) * y * (four * zz - xx - yy);
    out[12] = T::c(C3[3]) * z * (two * zz - three * xx - three * yy);
    out[13] = T::c(C3[4]) * x * (four * zz - xx - yy);
    out[14] = T::c(C3[5]) * z * (xx - yy);
    out[15] = T::c(C3[6]) * x * (xx - three * yy);
}

/// Gradient of `Σ_k w[k]·basis_k(n)` with respect to `n` (not projected onto the sphere).
#[inline(always)]
pub(crate) fn basis_vjp<T: Lane>(degree: usize, n: [T; 3], w: &[T; 16]) -> [T; 3] {
    let [x, y, z] = n;
    let zero = T::c(0.0);
    let mut g = [zero; 3];
    if degree == 0 {
        return g;
    }
    // A function, not a closure: see `lanes::arr`.
    #[inline(always)]
    fn add<T: Lane>(g: &mut [T; 3], w: T, d: [T; 3]) {
        g[0] = g[0] + w * d[0];
        g[1] = g[1] + w * d[1];
        g[2] = g[2] + w * d[2];
    }
    let c1 = T::c(C1);
    add(&mut g, w[1], [zero, -c1, zero]);
    add(&mut g, w[2], [zero, zero, c1]);
    add(&mut g, w[3], [-c1, zero, zero]);
    if degree >= 2 {
        let c2 = [
            T::c(C2[0]),
            T::c(C2[1]),
            T::c(C2[2]),
            T::c(C2[3]),
            T::c(C2[4]),
        ];
        add(&mut g, w[4], [c2[0] * y, c2[0] * x, zero]);
        add(&mut g, w[5], [zero, c2[1] * z, c2[1] * y]);
        let d6 = [
            T::c(-2.0) * c2[2] * x,
            T::c(-2.0) * c2[2] * y,
            T::c(4.0) * c2[2] * z,
        ];
        add(&mut g, w[6], d6);
        add(&mut g, w[7], [c2[3] * z, zero, c2[3] * x]);
        add(
            &mut g,
            w[8],
            [T::c(2.0) * c2[4] * x, T::c(-2.0) * c2[4] * y, zero],
        );
    }
    if degree >= 3 {
        let c3 = [
            T::c(C3[0]),
            T::c(C3[1]),
            T::c(C3[2]),
            T::c(C3[3]),
            T::c(C3[4]),
            T::c(C3[5]),
            T::c(C3[6]),
        ];
        let (xx, yy, zz) = (x * x, y * y, z * z);
        let (two, three, four) = (T::c(2.0), T::c(3.0), T::c(4.0));
        let (six, eight) = (T::c(6.0), T::c(8.0));
        let d9 = [c3[0] * six * x * y, c3[0] * three * (xx - yy), zero];
        add(&mut g, w[9], d9);
        add(&mut g, w[10], [c3[1] * y * z, c3[1] * x * z, c3[1] * x * y]);
        let d11 = [
            c3[2] * T::c(-2.0) * x * y,
            c3[2] * (four * zz - xx - three * yy),
            c3[2] * eight * y * z,
        ];
        add(&mut g, w[11], d11);
        let d12 = [
            c3[3] * T::c(-6.0) * x * z,
            c3[3] * T::c(-6.0) * y * z,
            c3[3] * (six * zz - three * xx - three * yy),
        ];
        add(&mut g, w[12], d12);
        let d13 = [
            c3[4] * (four * zz - three * xx - yy),
            c3[4] * T::c(-2.0) * x * y,
            c3[4] * eight * x * z,
        ];
        add(&mut g, w[13], d13);
        let d14 = [
            c3[5] * two * x * z,
            c3[5] * T::c(-2.0) * y * z,
            c3[5] * (xx - yy),
        ];
        add(&mut g, w[14], d14);
        let d15 = [c3[6] * three * (xx - yy), c3[6] * T::c(-6.0) * x * y, zero];
        add(&mut g, w[15], d15);
    }
    g
}

/// Normalizes `d` as `torch.nn.functional.normalize` does (divides by max(|d|, 1e-12)).
#[inline(always)]
pub(crate) fn normalize<T: Lane>(d: [T; 3]) -> ([T; 3], T) {
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        .sqrt()
        .max(T::c(1e-12));
    ([d[0] / len, d[1] / len, d[2] / len], len)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_vjp_matches_finite_differences() {
        let n = [0.3f64, -0.5, 0.7];
        let w: [f32; 16] = std::array::from_fn(|k| (k as f32 * 0.37).sin());
        let g = basis_vjp(3, n.map(|v| v as f32), &w);
        let f = |p: [f64; 3]| {
            let mut b = [0.0f64; 16];
            basis(3, p, &mut b);
            (0..16).map(|k| w[k] as f64 * b[k]).sum::<f64>()
        };
        for a in 0..3 {
            let (mut p, mut m) = (n, n);
            p[a] += 1e-6;
            m[a] -= 1e-6;
            let fd = (f(p) - f(m)) / 2e-6;
            assert!(
                (fd - g[a] as f64).abs() < 1e-4,
                "axis {a}: fd {fd} vs {}",
                g[a]
            );
        }
    }

    #[test]
    fn matches_gsplat_fast_form_on_sphere() {
        // gsplat `_eval_sh_bases_fast` entries 6 and 12 at a unit direction.
        let (n, _) = normalize([0.2, -0.4, 0.9]);
        let mut b = [0.0f32; 16];
        basis(3, n, &mut b);
        let z = n[2];
        let b6 = 0.946_174_7 * z * z - 0.315_391_57;
        let b12 = z * (1.865_881_7 * z * z - 1.119_529);
        assert!((b[6] - b6).abs() < 1e-6 && (b[12] - b12).abs() < 1e-6);
    }
}
