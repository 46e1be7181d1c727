//! Rigid props that are not vehicles (`--add`): a wooden toy crate and an upright toy
//! barrel. Every face carries strong texture and the markings differ per side, so a
//! tracker can tell a 180° turn from none.

use super::geometry::V3;
use super::model::{Material, Model, Part, Shape};
use super::texture::{checker, lines, mix, noise};
use std::f32::consts::{PI, TAU};

/// Half extents of the crate's body (x, y) and its height: about a vehicle's cabin.
const CRATE: V3 = [0.15, 0.11, 0.2];
/// Plank width on the crate's faces.
const PLANK: f32 = 0.04;

fn wood_box(lo: V3, hi: V3, base: V3, marks: bool) -> Part {
    Part {
        shape: Shape::Box { lo, hi },
        material: Material::Wood { base, marks },
    }
}

/// A slab along one edge: `[lo, hi]` per axis, given as (a, b) in either order.
fn slab(x: [f32; 2], y: [f32; 2], z: [f32; 2]) -> Part {
    let r = |a: [f32; 2]| [a[0].min(a[1]), a[0].max(a[1])];
    let (x, y, z) = (r(x), r(y), r(z));
    wood_box(
        [x[0], y[0], z[0]],
        [x[1], y[1], z[1]],
        [0.50, 0.33, 0.19],
        false,
    )
}

/// A plank crate framed by darker corner posts and top and bottom rails standing 6 mm
/// proud (relief the shading shows at any angle).
pub fn toy_crate(name: String) -> Model {
    let [hx, hy, h] = CRATE;
    let (w, o) = (0.025, 0.006);
    let mut parts = vec![wood_box(
        [-hx, -hy, 0.0],
        [hx, hy, h],
        [0.80, 0.62, 0.40],
        true,
    )];
    for s in [-1.0f32, 1.0] {
        for t in [-1.0f32, 1.0] {
            let (x, y) = ([s * (hx - w), s * (hx + o)], [t * (hy - w), t * (hy + o)]);
            parts.push(slab(x, y, [0.0, h]));
        }
        for z in [[0.0, 0.02], [h - w, h + o]] {
            parts.push(slab([-hx - o, hx + o], [s * (hy - w), s * (hy + o)], z));
            parts.push(slab([s * (hx - w), s * (hx + o)], [-hy - o, hy + o], z));
        }
    }
    Model::new(name, "wooden crate", parts)
}

/// An upright red barrel with two dark hoops.
pub fn toy_barrel(name: String) -> Model {
    let drum = |z: f32, radius: f32, half_h: f32, material| Part {
        shape: Shape::Drum {
            center: [0.0, 0.0, z],
            radius,
            half_h,
        },
        material,
    };
    let hoop = Material::Solid([0.20, 0.20, 0.22]);
    let parts = vec![
        drum(0.12, 0.09, 0.12, Material::Barrel),
        drum(0.04, 0.095, 0.008, hoop),
        drum(0.20, 0.095, 0.008, hoop),
    ];
    Model::new(name, "red striped barrel", parts)
}

/// Face index (+x, −x, +y, −y, +z, −z) and in-face coordinates: `u` along the planks
/// (horizontal), `v` across them.
fn face(p: V3, n: V3) -> (u64, f32, f32) {
    if n[0].abs() > 0.5 {
        (u64::from(n[0] < 0.0), p[1], p[2])
    } else if n[1].abs() > 0.5 {
        (2 + u64::from(n[1] < 0.0), p[0], p[2])
    } else {
        (4 + u64::from(n[2] < 0.0), p[0], p[1])
    }
}

/// Planks with their own tone each, grain along them and dark gaps; the crate's body
/// adds its printed markings.
pub fn wood(base: V3, marks: bool, p: V3, n: V3, key: u64) -> V3 {
    let (f, u, v) = face(p, n);
    let plank = (v / PLANK).floor();
    let tone = noise(key ^ 0x70 ^ (f << 8), plank * 5.0, 0.0);
    let grain = noise(key ^ 0x71 ^ (f << 8), u * 14.0 + plank * 7.0, v * 170.0);
    let mut c = mix(
        [base[0] * 0.7, base[1] * 0.7, base[2] * 0.7],
        base,
        0.45 * tone + 0.55 * grain,
    );
    if lines(v, PLANK, 0.003) {
        c = [0.22, 0.15, 0.09];
    }
    if marks {
        c = crate_marking(f, u, v).unwrap_or(c);
    }
    c
}

/// Ink printed on face `f` at (u, v), different on every side: a red arrow on the front,
/// a black ring on the back, a braced X and a barcode label on the left, hazard stripes
/// and a number block on the right, a cross and a red corner patch on the lid.
fn crate_marking(f: u64, u: f32, v: f32) -> Option<V3> {
    let (red, black) = ([0.78, 0.10, 0.08], [0.08, 0.07, 0.06]);
    let b = v - 0.5 * CRATE[2];
    match f {
        0 => {
            let shaft = u.abs() < 0.015 && (-0.07..0.01).contains(&b);
            let head = (0.01..0.07).contains(&b) && u.abs() < (0.07 - b) * 0.9;
            (shaft || head).then_some(red)
        }
        1 => {
            let r = u.hypot(b);
            ((0.045..0.06).contains(&r) || r < 0.015).then_some(black)
        }
        2 => {
            let slope = CRATE[2] / (2.0 * CRATE[0]);
            let brace = (b - slope * u).abs() < 0.01 || (b + slope * u).abs() < 0.01;
            let label = (0.04..0.11).contains(&u) && (0.035..0.075).contains(&b);
            if label {
                Some(if lines(u, 0.012, 0.005) {
                    black
                } else {
                    [0.95, 0.94, 0.90]
                })
            } else {
                brace.then_some([0.12, 0.20, 0.55])
            }
        }
        3 => {
            if b.abs() < 0.03 {
                Some(if lines(u + b, 0.03, 0.015) {
                    red
                } else {
                    [0.95, 0.90, 0.75]
                })
            } else {
                let block = (-0.11..-0.05).contains(&u) && (-0.08..-0.05).contains(&b);
                (block && checker(u, b, 0.015)).then_some(black)
            }
        }
        4 => {
            let slope = CRATE[1] / CRATE[0];
            let cross = (v - slope * u).abs() < 0.01 || (v + slope * u).abs() < 0.01;
            let patch = (0.05..0.10).contains(&u) && (0.03..0.075).contains(&v);
            if patch {
                Some(red)
            } else {
                cross.then_some(black)
            }
        }
        _ => None,
    }
}

/// The barrel's paint at local `p` with normal `n`: red staves with a white band, a
/// yellow barcode label facing +x, a black diamond facing −x; a grey lid with an
/// off-centre bung (on the +x side) and a ring of ticks.
pub fn barrel(p: V3, n: V3, key: u64) -> V3 {
    let r = p[0].hypot(p[1]);
    let a = p[1].atan2(p[0]);
    if n[2] > 0.5 {
        return if (p[0] - 0.045).hypot(p[1]) < 0.015 {
            [0.10, 0.10, 0.10]
        } else if (0.055..0.07).contains(&r) && lines(a, TAU / 12.0, 0.12) {
            [0.95, 0.95, 0.95]
        } else {
            [0.55, 0.55, 0.58]
        };
    }
    if n[2] < -0.5 {
        return [0.15, 0.05, 0.05];
    }
    let z = p[2];
    let back = a.rem_euclid(TAU) - PI; // angle from −x, in [−π, π)
    if a.abs() < 0.5 && (0.14..0.185).contains(&z) {
        if (0.15..0.175).contains(&z) && lines(a, 0.12, 0.05) {
            return [0.05, 0.05, 0.05];
        }
        return [0.95, 0.80, 0.15];
    }
    if (back * 0.09).abs() + (z - 0.09).abs() < 0.035 {
        return [0.05, 0.05, 0.05];
    }
    if (0.105..0.125).contains(&z) {
        return [0.96, 0.96, 0.94];
    }
    let stave = lines(a, TAU / 16.0, 0.03);
    let grime = noise(key ^ 0x80, a * 6.0, z * 40.0);
    let base = mix([0.60, 0.08, 0.07], [0.82, 0.16, 0.12], grime);
    if stave {
        mix(base, [0.0; 3], 0.5)
    } else {
        base
    }
}
