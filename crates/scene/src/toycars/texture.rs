//! Procedural surface colours: a seeded value noise and the printed patterns of the
//! vehicles and the ground mat. Fine detail (periods of a few pixels at 480×360) is
//! deliberate: it is what a blurry dynamic reconstruction loses.

use super::geometry::V3;

/// splitmix64 finalizer of the key and lattice coordinates, as a value in [0, 1).
#[inline]
fn hash(key: u64, ix: i32, iy: i32) -> f32 {
    let mut z = key
        ^ (ix as u32 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (iy as u32 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 24) as f32
}

/// Bilinear value noise with a smoothstep fade, in [0, 1].
pub fn noise(key: u64, x: f32, y: f32) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as i32, fy as i32);
    let (u, v) = (x - fx, y - fy);
    let (u, v) = (u * u * (3.0 - 2.0 * u), v * v * (3.0 - 2.0 * v));
    let a = hash(key, ix, iy) + (hash(key, ix + 1, iy) - hash(key, ix, iy)) * u;
    let b = hash(key, ix, iy + 1) + (hash(key, ix + 1, iy + 1) - hash(key, ix, iy + 1)) * u;
    a + (b - a) * v
}

/// Three octaves of [`noise`], in [0, 1].
pub fn fbm(key: u64, x: f32, y: f32) -> f32 {
    (noise(key, x, y) * 4.0
        + noise(key ^ 1, 2.0 * x, 2.0 * y) * 2.0
        + noise(key ^ 2, 4.0 * x, 4.0 * y))
        / 7.0
}

pub fn mix(a: V3, b: V3, t: f32) -> V3 {
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

/// 1 on thin lines of width `w` repeating every `period` along `x`, else 0.
#[inline]
pub fn lines(x: f32, period: f32, w: f32) -> bool {
    (x / period).rem_euclid(1.0) * period < w
}

/// Checkerboard parity of cell size `period`.
#[inline]
pub fn checker(x: f32, y: f32, period: f32) -> bool {
    ((x / period).floor() as i32 + (y / period).floor() as i32) & 1 == 0
}

/// The ground mat at world (x, y): light wood with a fine grain, a printed grid of road
/// lines, and seeded coloured blotches.
pub fn ground(key: u64, x: f32, y: f32) -> V3 {
    let grain =
        noise(key ^ 0x10, x * 6.0, y * 90.0) * 0.6 + fbm(key ^ 0x20, x * 3.0, y * 3.0) * 0.4;
    let mut c = mix([0.55, 0.42, 0.30], [0.80, 0.68, 0.52], grain);
    let blot = fbm(key ^ 0x30, x * 2.2, y * 2.2);
    if blot > 0.66 {
        c = mix(c, [0.35, 0.50, 0.62], ((blot - 0.66) * 8.0).min(0.7));
    }
    // Printed grid: thin dark lines every 0.25 with a finer dashed line at mid-cells.
    if lines(x + 0.004, 0.25, 0.008) || lines(y + 0.004, 0.25, 0.008) {
        c = [0.18, 0.16, 0.15];
    } else if (lines(x + 0.128, 0.25, 0.004) && lines(y, 0.04, 0.02))
        || (lines(y + 0.128, 0.25, 0.004) && lines(x, 0.04, 0.02))
    {
        c = [0.92, 0.90, 0.85];
    }
    c
}
