//! The three toy vehicles of the paper's setup (Sec. 4.1), built from boxes, wheels and
//! window panels with printed liveries. Local frame: x forward, y left, z up, origin on
//! the ground under the vehicle's centre.

use super::geometry::V3;
use super::model::{Material, Model, Part, Shape};
use super::texture::{checker, lines, mix, noise};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Livery {
    /// White SUV: black checker rally band on the sides, dotted roof, hood roundel.
    Rally,
    /// Yellow sedan: red roof stripe with white edges, black side pinstripes, hood checks.
    Pinstripe,
    /// Green SUV: mottled camouflage and diagonal door hatching.
    Camo,
}

/// Body proportions shared by both body styles.
struct Dims {
    half_len: f32,
    half_wid: f32,
    body_z: [f32; 2],
    cabin_x: [f32; 2],
    cabin_top: f32,
    wheel_x: f32,
    wheel_r: f32,
}

pub fn white_suv() -> Model {
    let d = Dims {
        half_len: 0.28,
        half_wid: 0.12,
        body_z: [0.045, 0.15],
        cabin_x: [-0.26, 0.12],
        cabin_top: 0.26,
        wheel_x: 0.17,
        wheel_r: 0.05,
    };
    build(
        "white-suv",
        "white SUV",
        &d,
        [0.93, 0.93, 0.91],
        Livery::Rally,
    )
}

pub fn yellow_sedan() -> Model {
    let d = Dims {
        half_len: 0.26,
        half_wid: 0.115,
        body_z: [0.04, 0.125],
        cabin_x: [-0.13, 0.11],
        cabin_top: 0.2,
        wheel_x: 0.16,
        wheel_r: 0.045,
    };
    build(
        "yellow-sedan",
        "yellow sedan with a red stripe on its roof",
        &d,
        [0.95, 0.78, 0.12],
        Livery::Pinstripe,
    )
}

pub fn green_suv() -> Model {
    let d = Dims {
        half_len: 0.28,
        half_wid: 0.12,
        body_z: [0.045, 0.15],
        cabin_x: [-0.26, 0.12],
        cabin_top: 0.26,
        wheel_x: 0.17,
        wheel_r: 0.05,
    };
    build(
        "green-suv",
        "green SUV",
        &d,
        [0.16, 0.52, 0.24],
        Livery::Camo,
    )
}

fn build(name: &'static str, prompt: &'static str, d: &Dims, base: V3, livery: Livery) -> Model {
    let paint = Material::Paint { base, livery };
    let (hl, hw) = (d.half_len, d.half_wid);
    let cw = hw - 0.015;
    let mut parts = vec![
        Part {
            shape: Shape::Box {
                lo: [-hl, -hw, d.body_z[0]],
                hi: [hl, hw, d.body_z[1]],
            },
            material: paint,
        },
        Part {
            shape: Shape::Box {
                lo: [d.cabin_x[0], -cw, d.body_z[1] - 0.001],
                hi: [d.cabin_x[1], cw, d.cabin_top],
            },
            material: paint,
        },
    ];
    parts.extend(windows(d, cw));
    parts.extend(trim(d));
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            let center = [sx * d.wheel_x, sy * (hw - 0.005), d.wheel_r];
            parts.push(Part {
                shape: Shape::Wheel {
                    center,
                    radius: d.wheel_r,
                    half_w: 0.022,
                },
                material: Material::Tire,
            });
        }
    }
    Model::new(name, prompt, parts)
}

/// Thin glass panels standing 6 mm proud of the cabin: windshield, rear, two per side.
fn windows(d: &Dims, cw: f32) -> Vec<Part> {
    let z = [d.body_z[1] + 0.018, d.cabin_top - 0.014];
    let (x0, x1) = (d.cabin_x[0], d.cabin_x[1]);
    let xm = 0.5 * (x0 + x1);
    let g = |lo: V3, hi: V3| Part {
        shape: Shape::Box { lo, hi },
        material: Material::Glass,
    };
    let mut v = vec![
        g([x1, -cw + 0.014, z[0]], [x1 + 0.006, cw - 0.014, z[1]]),
        g(
            [x0 - 0.006, -cw + 0.018, z[0] + 0.01],
            [x0, cw - 0.018, z[1]],
        ),
    ];
    for y in [cw, -cw - 0.006] {
        v.push(g([x0 + 0.02, y, z[0]], [xm - 0.01, y + 0.006, z[1]]));
        v.push(g([xm + 0.01, y, z[0]], [x1 - 0.02, y + 0.006, z[1]]));
    }
    v
}

/// Bumpers, head lamps and tail lamps.
fn trim(d: &Dims) -> Vec<Part> {
    let (hl, hw) = (d.half_len, d.half_wid);
    let z0 = d.body_z[0];
    let zl = [d.body_z[1] - 0.045, d.body_z[1] - 0.02];
    let b = |lo: V3, hi: V3, c: V3| Part {
        shape: Shape::Box { lo, hi },
        material: Material::Solid(c),
    };
    let mut v = vec![
        b(
            [hl, -hw + 0.005, z0],
            [hl + 0.014, hw - 0.005, z0 + 0.03],
            [0.22, 0.22, 0.24],
        ),
        b(
            [-hl - 0.014, -hw + 0.005, z0],
            [-hl, hw - 0.005, z0 + 0.03],
            [0.22, 0.22, 0.24],
        ),
    ];
    for sy in [-1.0, 1.0] {
        let (ya, yb) = if sy > 0.0 {
            (hw - 0.055, hw - 0.015)
        } else {
            (-hw + 0.015, -hw + 0.055)
        };
        v.push(b(
            [hl, ya, zl[0]],
            [hl + 0.005, yb, zl[1]],
            [1.0, 0.97, 0.78],
        ));
        v.push(b(
            [-hl - 0.005, ya, zl[0]],
            [-hl, yb, zl[1]],
            [0.85, 0.08, 0.06],
        ));
    }
    v
}

/// Tyre colour at `q`, relative to the wheel centre: a light hub with five spokes on the
/// flanks, fine grooves on the tread.
pub fn tire(q: V3, n: V3) -> V3 {
    let ang = q[2].atan2(q[0]);
    if n[1].abs() > 0.5 {
        let r = (q[0] * q[0] + q[2] * q[2]).sqrt();
        let spoke_gap = r > 0.008 && lines(ang, std::f32::consts::TAU / 5.0, 0.45);
        if r < 0.024 && !spoke_gap {
            [0.72, 0.72, 0.74]
        } else {
            [0.08, 0.08, 0.09]
        }
    } else if lines(ang, 0.2, 0.06) {
        [0.03, 0.03, 0.03]
    } else {
        [0.12, 0.12, 0.13]
    }
}

pub fn livery_color(base: V3, livery: Livery, p: V3, n: V3, key: u64) -> V3 {
    let top = n[2] > 0.5;
    let side = n[1].abs() > 0.5;
    let front = n[0] > 0.5;
    match livery {
        Livery::Rally => {
            if side && p[2] > 0.085 && p[2] < 0.115 && checker(p[0], p[2] - 0.085, 0.015) {
                [0.05, 0.05, 0.06]
            } else if top && p[2] > 0.2 && lines(p[0], 0.02, 0.008) && lines(p[1], 0.02, 0.008) {
                [0.15, 0.25, 0.75]
            } else if top
                && front_hood(p)
                && ((p[0] - 0.2).powi(2) + p[1] * p[1]).sqrt().rem_euclid(0.03) < 0.012
            {
                [0.80, 0.10, 0.10]
            } else {
                base
            }
        }
        Livery::Pinstripe => {
            if top && p[2] > 0.18 && p[1].abs() < 0.03 {
                if p[1].abs() > 0.024 {
                    [0.97, 0.97, 0.95]
                } else {
                    [0.82, 0.06, 0.05]
                }
            } else if side && p[2] > 0.06 && p[2] < 0.105 && lines(p[2], 0.012, 0.004) {
                [0.08, 0.06, 0.05]
            } else if (top && p[0] > 0.12) || front {
                if checker(p[0], p[1], 0.018) {
                    base
                } else {
                    mix(base, [0.55, 0.35, 0.05], 0.5)
                }
            } else {
                base
            }
        }
        Livery::Camo => {
            let (u, v) = if side { (p[0], p[2]) } else { (p[0], p[1]) };
            let m = noise(
                key ^ 0x51,
                u * 28.0,
                v * 28.0 + if n[1] > 0.0 { 7.0 } else { 0.0 },
            );
            let mut c = if m > 0.62 {
                [0.55, 0.50, 0.30]
            } else if m < 0.35 {
                [0.07, 0.25, 0.10]
            } else {
                base
            };
            if side && p[2] < 0.14 && lines(p[0] + p[2], 0.025, 0.006) && p[0].abs() < 0.12 {
                c = [0.92, 0.92, 0.88];
            }
            c
        }
    }
}

fn front_hood(p: V3) -> bool {
    p[0] > 0.13
}
