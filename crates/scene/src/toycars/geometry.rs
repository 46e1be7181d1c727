//! Ray–primitive intersections for the toycars ray caster: axis-aligned boxes (slab
//! test, Kay & Kajiya) and finite cylinders: wheels around the local y axis, drums around z.

pub type V3 = [f32; 3];

#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
#[inline]
pub fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub fn normalize(a: V3) -> V3 {
    scale(a, 1.0 / dot(a, a).sqrt())
}

#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: V3,
    pub dir: V3,
}

impl Ray {
    pub fn at(&self, t: f32) -> V3 {
        add(self.origin, scale(self.dir, t))
    }
}

/// Nearest entry `(t, outward normal)` of `ray` into the box `[lo, hi]` with `t` in
/// `(t_min, t_max)`; rays starting inside report no hit (nothing renders from inside).
#[inline]
pub fn hit_box(ray: &Ray, lo: V3, hi: V3, t_min: f32, t_max: f32) -> Option<(f32, V3)> {
    let mut t0 = t_min;
    let mut t1 = t_max;
    let mut axis = usize::MAX;
    let mut sign = 0.0;
    for k in 0..3 {
        let inv = 1.0 / ray.dir[k];
        let (mut a, mut b) = ((lo[k] - ray.origin[k]) * inv, (hi[k] - ray.origin[k]) * inv);
        let mut s = -1.0;
        if a > b {
            std::mem::swap(&mut a, &mut b);
            s = 1.0;
        }
        if a > t0 {
            t0 = a;
            axis = k;
            sign = s;
        }
        t1 = t1.min(b);
        if t0 > t1 {
            return None;
        }
    }
    if axis == usize::MAX {
        return None;
    }
    let mut n = [0.0; 3];
    n[axis] = sign;
    Some((t0, n))
}

/// Whether `ray` meets the box anywhere in `(t_min, t_max)` (inside counts).
#[inline]
pub fn overlaps_box(ray: &Ray, lo: V3, hi: V3, t_min: f32, t_max: f32) -> bool {
    let mut t0 = t_min;
    let mut t1 = t_max;
    for k in 0..3 {
        let inv = 1.0 / ray.dir[k];
        let (a, b) = ((lo[k] - ray.origin[k]) * inv, (hi[k] - ray.origin[k]) * inv);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    t0 <= t1
}

/// Nearest hit of `ray` with the closed cylinder of axis y through `center`, `radius`,
/// half-length `half_w` along y: side or end caps. Returns `(t, normal)`.
pub fn hit_wheel(
    ray: &Ray,
    center: V3,
    radius: f32,
    half_w: f32,
    t_min: f32,
    t_max: f32,
) -> Option<(f32, V3)> {
    let o = sub(ray.origin, center);
    let d = ray.dir;
    let mut best: Option<(f32, V3)> = None;
    // Side: (ox + t dx)² + (oz + t dz)² = r².
    let a = d[0] * d[0] + d[2] * d[2];
    if a > 1e-12 {
        let b = o[0] * d[0] + o[2] * d[2];
        let c = o[0] * o[0] + o[2] * o[2] - radius * radius;
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let t = (-b - disc.sqrt()) / a;
            let y = o[1] + t * d[1];
            if t > t_min && t < t_max && y.abs() <= half_w {
                let p = [o[0] + t * d[0], 0.0, o[2] + t * d[2]];
                best = Some((t, scale(p, 1.0 / radius)));
            }
        }
    }
    // Caps at y = ±half_w.
    if d[1].abs() > 1e-12 {
        for s in [-1.0f32, 1.0] {
            let t = (s * half_w - o[1]) / d[1];
            let limit = best.map_or(t_max, |b| b.0);
            if t > t_min && t < limit {
                let (x, z) = (o[0] + t * d[0], o[2] + t * d[2]);
                if x * x + z * z <= radius * radius {
                    best = Some((t, [0.0, s, 0.0]));
                }
            }
        }
    }
    best
}

/// [`hit_wheel`] for a cylinder around the z axis (`half_h` along z): the same test with
/// y and z swapped.
pub fn hit_drum(
    ray: &Ray,
    center: V3,
    radius: f32,
    half_h: f32,
    t_min: f32,
    t_max: f32,
) -> Option<(f32, V3)> {
    let swap = |v: V3| [v[0], v[2], v[1]];
    let r = Ray {
        origin: swap(ray.origin),
        dir: swap(ray.dir),
    };
    hit_wheel(&r, swap(center), radius, half_h, t_min, t_max).map(|(t, n)| (t, swap(n)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_and_wheel_hits() {
        let ray = Ray {
            origin: [0.0, 0.0, 5.0],
            dir: [0.0, 0.0, -1.0],
        };
        let (t, n) = hit_box(&ray, [-1.0; 3], [1.0; 3], 0.0, f32::MAX).unwrap();
        assert_eq!((t, n), (4.0, [0.0, 0.0, 1.0]));
        assert!(hit_box(&ray, [2.0, 2.0, -1.0], [3.0, 3.0, 1.0], 0.0, f32::MAX).is_none());
        let (t, n) = hit_wheel(&ray, [0.0; 3], 0.5, 0.1, 0.0, f32::MAX).unwrap();
        assert!((t - 4.5).abs() < 1e-6 && (n[2] - 1.0).abs() < 1e-6);
        let side = Ray {
            origin: [0.0, 5.0, 0.0],
            dir: [0.0, -1.0, 0.0],
        };
        let (t, n) = hit_wheel(&side, [0.0; 3], 0.5, 0.1, 0.0, f32::MAX).unwrap();
        assert!((t - 4.9).abs() < 1e-6 && n == [0.0, 1.0, 0.0]);
        let (t, n) = hit_drum(&ray, [0.0; 3], 0.5, 0.1, 0.0, f32::MAX).unwrap();
        assert!((t - 4.9).abs() < 1e-6 && n == [0.0, 0.0, 1.0]);
        let (t, n) = hit_drum(&side, [0.0; 3], 0.5, 0.1, 0.0, f32::MAX).unwrap();
        assert!((t - 4.5).abs() < 1e-6 && (n[1] - 1.0).abs() < 1e-6);
    }
}
