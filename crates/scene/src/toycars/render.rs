//! The toycars ray caster: primary rays against the ground mat and the posed models,
//! Lambert + Blinn-Phong shading under one sun with hard shadows, 4 rotated-grid
//! supersamples per pixel, rows in parallel (rayon).

use super::geometry::{
    add, dot, hit_box, hit_drum, hit_wheel, normalize, overlaps_box, scale, sub, Ray, V3,
};
use super::model::{albedo, Material, Model, Shape};
use super::motion::GROUND_HALF;
use super::texture;
use crate::MASK_BACKGROUND;
use rayon::prelude::*;

/// Rotated-grid 4× pattern (offsets from the pixel centre): no two samples share a row
/// or column, which resolves near-horizontal and near-vertical edges best for 4 rays.
const RGSS: [[f32; 2]; 4] = [
    [0.125, -0.375],
    [0.375, 0.125],
    [-0.125, 0.375],
    [-0.375, -0.125],
];

/// A model placed in the world at one instant by its row-major local→world matrix (the
/// one `objects.json` records): `world = R · local + pos`.
pub struct Placed<'a> {
    pub model: &'a Model,
    pub id: u8,
    /// Which part of its object this is: 0 the body, `k + 1` link `k` (the part maps).
    pub part: u8,
    pub rot: [V3; 3],
    pub pos: V3,
}

impl<'a> Placed<'a> {
    pub fn new(model: &'a Model, id: u8, m: &[[f32; 4]; 4]) -> Self {
        Self {
            model,
            id,
            part: 0,
            rot: [0, 1, 2].map(|r| [m[r][0], m[r][1], m[r][2]]),
            pos: [m[0][3], m[1][3], m[2][3]],
        }
    }

    /// `Rᵀ · v` (the inverse rotation).
    fn unrotate(&self, v: V3) -> V3 {
        let r = &self.rot;
        [0, 1, 2].map(|k| r[0][k] * v[0] + r[1][k] * v[1] + r[2][k] * v[2])
    }

    fn to_local(&self, r: &Ray) -> Ray {
        Ray {
            origin: self.unrotate(sub(r.origin, self.pos)),
            dir: self.unrotate(r.dir),
        }
    }

    fn normal_to_world(&self, n: V3) -> V3 {
        self.rot
            .map(|row| row[0] * n[0] + row[1] * n[1] + row[2] * n[2])
    }
}

/// Everything a frame needs besides the camera.
pub struct World<'a> {
    pub objects: Vec<Placed<'a>>,
    pub ground_key: u64,
    pub paint_key: u64,
    pub sun: V3,
    pub shadows: bool,
}

struct Hit {
    t: f32,
    id: u8,
    part: u8,
    normal: V3,
    color: V3,
    spec: f32,
}

/// Nearest part of one model hit by a local-frame ray: `(t, normal, part index)`.
fn hit_model(v: &Model, r: &Ray, t_max: f32) -> Option<(f32, V3, usize)> {
    if !overlaps_box(r, v.bbox_lo, v.bbox_hi, 1e-4, t_max) {
        return None;
    }
    let mut best: Option<(f32, V3, usize)> = None;
    for (i, part) in v.parts.iter().enumerate() {
        let limit = best.map_or(t_max, |b| b.0);
        let h = match part.shape {
            Shape::Box { lo, hi } => hit_box(r, lo, hi, 1e-4, limit),
            Shape::Wheel {
                center,
                radius,
                half_w,
            } => hit_wheel(r, center, radius, half_w, 1e-4, limit),
            Shape::Drum {
                center,
                radius,
                half_h,
            } => hit_drum(r, center, radius, half_h, 1e-4, limit),
        };
        if let Some((t, n)) = h {
            best = Some((t, n, i));
        }
    }
    best
}

impl World<'_> {
    fn trace(&self, ray: &Ray) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_max = f32::MAX;
        for obj in &self.objects {
            let local = obj.to_local(ray);
            if let Some((t, n, i)) = hit_model(obj.model, &local, t_max) {
                t_max = t;
                let part = &obj.model.parts[i];
                let mut p = local.at(t);
                if let (Material::Tire, Shape::Wheel { center, .. }) = (part.material, part.shape) {
                    p = sub(p, center);
                }
                let (color, spec) = albedo(&part.material, p, n, self.paint_key);
                best = Some(Hit {
                    t,
                    id: obj.id,
                    part: obj.part,
                    normal: obj.normal_to_world(n),
                    color,
                    spec,
                });
            }
        }
        if ray.dir[2] < 0.0 {
            let t = -ray.origin[2] / ray.dir[2];
            let p = ray.at(t);
            if t < t_max && p[0].abs() <= GROUND_HALF && p[1].abs() <= GROUND_HALF {
                let color = texture::ground(self.ground_key, p[0], p[1]);
                best = Some(Hit {
                    t,
                    id: MASK_BACKGROUND,
                    part: MASK_BACKGROUND,
                    normal: [0.0, 0.0, 1.0],
                    color,
                    spec: 0.04,
                });
            }
        }
        best
    }

    fn in_shadow(&self, p: V3) -> bool {
        let ray = Ray {
            origin: p,
            dir: self.sun,
        };
        self.objects
            .iter()
            .any(|o| hit_model(o.model, &o.to_local(&ray), f32::MAX).is_some())
    }

    /// Colour of a hit seen along `dir`.
    fn shade(&self, ray: &Ray, h: &Hit) -> V3 {
        let p = add(ray.at(h.t), scale(h.normal, 1e-3));
        let ndl = dot(h.normal, self.sun).max(0.0);
        let lit = if ndl > 0.0 && !(self.shadows && self.in_shadow(p)) {
            1.0
        } else {
            0.0
        };
        let half = normalize(sub(self.sun, ray.dir));
        let spec = h.spec * dot(h.normal, half).max(0.0).powi(48) * lit;
        let sky = 0.30 + 0.12 * h.normal[2];
        let k = sky + 0.78 * ndl * lit;
        [
            h.color[0] * k + spec,
            h.color[1] * k + spec,
            h.color[2] * k + spec,
        ]
    }
}

/// Pinhole camera for ray generation: centre, rotation rows (right, down, forward), intrinsics.
pub struct RayCamera {
    pub center: V3,
    pub rows: [V3; 3],
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl RayCamera {
    fn ray(&self, u: f32, v: f32) -> Ray {
        let (x, y) = ((u - self.cx) / self.fx, (v - self.cy) / self.fy);
        let r = &self.rows;
        let d = [0, 1, 2].map(|k| r[0][k] * x + r[1][k] * y + r[2][k]);
        Ray {
            origin: self.center,
            dir: normalize(d),
        }
    }
}

/// One rendered frame: straight-alpha RGBA (`H·W·4`, alpha = sample coverage), the
/// instance mask (`H·W`, majority vote over the samples, ties to the smaller ID) and the
/// part map (`H·W`: the majority part among the samples that hit the mask's object, 0 the
/// body, `k + 1` link `k`; background 255).
pub struct Rendered {
    pub rgba: Vec<u8>,
    pub ids: Vec<u8>,
    pub parts: Vec<u8>,
}

pub fn render(
    world: &World,
    cam: &RayCamera,
    width: u32,
    height: u32,
    supersample: bool,
) -> Rendered {
    let (w, h) = (width as usize, height as usize);
    let mut rgba = vec![0u8; w * h * 4];
    let mut mask = vec![MASK_BACKGROUND; w * h];
    let mut parts = vec![MASK_BACKGROUND; w * h];
    let offsets: &[[f32; 2]] = if supersample { &RGSS } else { &[[0.0, 0.0]] };
    rgba.par_chunks_mut(w * 4)
        .zip(mask.par_chunks_mut(w))
        .zip(parts.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, ((out, ids), prt))| {
            for col in 0..w {
                let (px, id, part) =
                    render_pixel(world, cam, col as f32 + 0.5, row as f32 + 0.5, offsets);
                out[col * 4..col * 4 + 4].copy_from_slice(&px);
                ids[col] = id;
                prt[col] = part;
            }
        });
    Rendered {
        rgba,
        ids: mask,
        parts,
    }
}

fn render_pixel(
    world: &World,
    cam: &RayCamera,
    u: f32,
    v: f32,
    offsets: &[[f32; 2]],
) -> ([u8; 4], u8, u8) {
    let mut sum = [0.0f32; 3];
    let mut hits = 0usize;
    let mut ids = [MASK_BACKGROUND; 4];
    let mut parts = [MASK_BACKGROUND; 4];
    for (k, o) in offsets.iter().enumerate() {
        let ray = cam.ray(u + o[0], v + o[1]);
        if let Some(h) = world.trace(&ray) {
            let c = world.shade(&ray, &h);
            for ch in 0..3 {
                sum[ch] += c[ch].min(1.0);
            }
            hits += 1;
            ids[k] = h.id;
            parts[k] = h.part;
        }
    }
    let n = offsets.len();
    let q = |x: f32| (x * 255.0 + 0.5) as u8;
    let px = if hits == 0 {
        [0; 4]
    } else {
        let inv = 1.0 / hits as f32;
        [
            q(sum[0] * inv),
            q(sum[1] * inv),
            q(sum[2] * inv),
            q(hits as f32 / n as f32),
        ]
    };
    let id = majority(&ids[..n]);
    // The part of the object the mask shows, from that object's samples only.
    let of_id: [u8; 4] = std::array::from_fn(|k| {
        if ids[k] == id {
            parts[k]
        } else {
            MASK_BACKGROUND
        }
    });
    (px, id, majority(&of_id[..n]))
}

/// Most frequent ID; ties go to the smaller value (vehicles before background).
fn majority(ids: &[u8]) -> u8 {
    let mut best = (0usize, MASK_BACKGROUND);
    for &a in ids {
        let c = ids.iter().filter(|&&b| b == a).count();
        if c > best.0 || (c == best.0 && a < best.1) {
            best = (c, a);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::majority;

    #[test]
    fn majority_prefers_objects_on_ties() {
        assert_eq!(majority(&[255, 1, 1, 255]), 1);
        assert_eq!(majority(&[255, 255, 255, 2]), 255);
        assert_eq!(majority(&[0, 2, 2, 0]), 0);
    }
}
