//! A rigid object as the ray caster sees it (a vehicle or a prop): parts (boxes and
//! cylinders) with materials, its local bounding box, and the surface colour of each
//! material. Local frame: x forward, y left, z up, origin on the ground under the centre.
//! An articulated model adds links (`joints`): parts that turn about joints over time.

use super::geometry::V3;
use super::joints::Link;
use super::props::{barrel, wood};
use super::vehicles::{livery_color, tire, Livery};

#[derive(Clone, Copy, Debug)]
pub enum Shape {
    Box {
        lo: V3,
        hi: V3,
    },
    /// Cylinder around the local y axis.
    Wheel {
        center: V3,
        radius: f32,
        half_w: f32,
    },
    /// Cylinder around the local z axis (standing upright).
    Drum {
        center: V3,
        radius: f32,
        half_h: f32,
    },
}

#[derive(Clone, Copy, Debug)]
pub enum Material {
    Paint {
        base: V3,
        livery: Livery,
    },
    Glass,
    Tire,
    Solid(V3),
    /// Wooden planks; `marks` prints the crate's face markings over them.
    Wood {
        base: V3,
        marks: bool,
    },
    /// The barrel's painted staves, hoops and lid.
    Barrel,
}

#[derive(Clone, Copy, Debug)]
pub struct Part {
    pub shape: Shape,
    pub material: Material,
}

#[derive(Clone, Debug)]
pub struct Model {
    /// The name in `objects.json` (and in `--route NAME=`).
    pub name: String,
    pub prompt: &'static str,
    pub parts: Vec<Part>,
    /// The box of `parts` (the body; links have their own).
    pub bbox_lo: V3,
    pub bbox_hi: V3,
    /// Links hinged to the body or to each other; empty for a rigid model.
    pub links: Vec<Link>,
}

impl Model {
    /// A model of these parts, its bounding box computed from them.
    pub fn new(name: impl Into<String>, prompt: &'static str, parts: Vec<Part>) -> Self {
        let (bbox_lo, bbox_hi) = bounds(&parts);
        Self {
            name: name.into(),
            prompt,
            parts,
            bbox_lo,
            bbox_hi,
            links: Vec::new(),
        }
    }

    /// Corner `c` (bit k picks the high side of axis k) of the local bounding box.
    pub fn corner(&self, c: usize) -> V3 {
        [0, 1, 2].map(|k| {
            if c >> k & 1 == 0 {
                self.bbox_lo[k]
            } else {
                self.bbox_hi[k]
            }
        })
    }
}

fn bounds(parts: &[Part]) -> (V3, V3) {
    let mut lo = [f32::MAX; 3];
    let mut hi = [f32::MIN; 3];
    for p in parts {
        let (a, b) = match p.shape {
            Shape::Box { lo, hi } => (lo, hi),
            Shape::Wheel {
                center: c,
                radius: r,
                half_w: w,
            } => (
                [c[0] - r, c[1] - w, c[2] - r],
                [c[0] + r, c[1] + w, c[2] + r],
            ),
            Shape::Drum {
                center: c,
                radius: r,
                half_h: h,
            } => (
                [c[0] - r, c[1] - r, c[2] - h],
                [c[0] + r, c[1] + r, c[2] + h],
            ),
        };
        for k in 0..3 {
            lo[k] = lo[k].min(a[k]);
            hi[k] = hi[k].max(b[k]);
        }
    }
    (lo, hi)
}

/// Albedo and specular weight of a surface at local point `p` (relative to the wheel
/// centre for tyres) with local normal `n`.
pub fn albedo(m: &Material, p: V3, n: V3, key: u64) -> (V3, f32) {
    match *m {
        Material::Paint { base, livery } => (livery_color(base, livery, p, n, key), 0.35),
        Material::Glass => ([0.10, 0.14, 0.20], 0.8),
        Material::Solid(c) => (c, 0.2),
        Material::Tire => (tire(p, n), 0.05),
        Material::Wood { base, marks } => (wood(base, marks, p, n, key), 0.06),
        Material::Barrel => (barrel(p, n, key), 0.3),
    }
}
