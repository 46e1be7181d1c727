//! Synthetic objects for the tracking tests: boxes of Gaussians with checkered faces, a
//! camera that looks at them, the ground plane's depth, and frames rendered by our
//! rasterizer with the objects' masks from their alpha.

#![allow(dead_code)]

use rand::Rng;
use splat::{Camera, Colors, Gaussians, Rasterizer, RenderOptions};
use train::model::{GaussianModel, SH_FLOATS};
use train::objects::lift::DepthMap;
use train::objects::trajectory::Pose;
use train::quat;

pub const W: u32 = 128;
pub const H: u32 = 96;

/// A camera `dist` from `target`, `elev` degrees up, at azimuth `az` degrees, looking at it.
pub fn look_at(az: f32, elev: f32, dist: f32, target: [f32; 3]) -> Camera {
    let (a, e) = (az.to_radians(), elev.to_radians());
    let c = [
        target[0] + dist * e.cos() * a.cos(),
        target[1] + dist * e.cos() * a.sin(),
        target[2] + dist * e.sin(),
    ];
    let f = norm([target[0] - c[0], target[1] - c[1], target[2] - c[2]]);
    let r = norm([f[1], -f[0], 0.0]);
    let d = [
        f[1] * r[2] - f[2] * r[1],
        f[2] * r[0] - f[0] * r[2],
        f[0] * r[1] - f[1] * r[0],
    ];
    let rows = [r, d, f];
    let mut viewmat = [[0.0f32; 4]; 4];
    for (i, row) in rows.iter().enumerate() {
        viewmat[i][..3].copy_from_slice(row);
        viewmat[i][3] = -(row[0] * c[0] + row[1] * c[1] + row[2] * c[2]);
    }
    viewmat[3][3] = 1.0;
    Camera {
        width: W,
        height: H,
        fx: 110.0,
        fy: 110.0,
        cx: W as f32 / 2.0,
        cy: H as f32 / 2.0,
        viewmat,
    }
}

pub fn norm(v: [f32; 3]) -> [f32; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / n)
}

/// A 0.5 × 0.3 × 0.2 box of small Gaussians on its faces, each face in checks of its own
/// two colours (object frame, origin at its centre).
pub fn textured_box(rng: &mut impl Rng) -> GaussianModel {
    checkered_box([0.25, 0.15, 0.1], [0.0; 3], 2500, rng)
}

/// A box of half-sizes `half` centred at `centre`, `n` small Gaussians on its faces, each
/// face in checks of its own two colours.
pub fn checkered_box(
    half: [f32; 3],
    centre: [f32; 3],
    n: usize,
    rng: &mut impl Rng,
) -> GaussianModel {
    let mut m = GaussianModel::default();
    for _ in 0..n {
        let axis = rng.gen_range(0..3);
        let side = if rng.gen::<bool>() { 1.0 } else { -1.0 };
        let mut p: [f32; 3] = std::array::from_fn(|k| rng.gen_range(-half[k]..half[k]));
        p[axis] = side * half[axis];
        let (u, v) = (
            (p[(axis + 1) % 3] * 12.0).floor(),
            (p[(axis + 2) % 3] * 12.0).floor(),
        );
        let check = (u + v).rem_euclid(2.0) as usize;
        let face = axis * 2 + usize::from(side > 0.0);
        let base = [
            [0.9, 0.2, 0.1],
            [0.1, 0.6, 0.9],
            [0.95, 0.85, 0.1],
            [0.2, 0.8, 0.3],
            [0.8, 0.3, 0.8],
            [0.9, 0.9, 0.9],
        ][face];
        let rgb = base.map(|c: f32| if check == 0 { c } else { c * 0.35 });
        m.means.extend([0, 1, 2].map(|k| p[k] + centre[k]));
        m.quats.extend([1.0, 0.0, 0.0, 0.0]);
        m.log_scales.extend([0.012f32.ln(); 3]);
        m.opacity_logits.push(3.0);
        let mut sh = [0.0f32; SH_FLOATS];
        for c in 0..3 {
            sh[c] = (rgb[c] - 0.5) / train::init::SH_C0;
        }
        m.sh.extend(sh);
    }
    m
}

pub struct Frame {
    pub cam: Camera,
    pub time: f32,
    pub image: scene::ImageU8,
    pub id_map: Vec<u8>,
    /// Camera depth of the ground plane z = 0 the box stands on.
    pub ground: DepthMap,
}

/// Camera depth of the plane z = 0 in every pixel (NaN where a ray misses it).
pub fn plane_depth(cam: &Camera) -> DepthMap {
    let c = cam.center();
    let mut depth = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let far = train::objects::lift::unproject(cam, x as f32 + 0.5, y as f32 + 0.5, 1.0);
            let dir = [far[0] - c[0], far[1] - c[1], far[2] - c[2]];
            let s = -c[2] / dir[2];
            depth.push(if s > 0.0 { s } else { f32::NAN });
        }
    }
    DepthMap {
        width: W,
        height: H,
        depth,
    }
}

/// Frame `i` of `n`: the bodies `parts(t)` (Gaussians in their frame, pose at t) seen by
/// `camera(t)`; the ID map marks their pixels (alpha > ½) with `id`.
pub fn render_frame(
    raster: &mut Rasterizer,
    cam: Camera,
    t: f32,
    parts: &[(&GaussianModel, Pose)],
    id: u8,
) -> Frame {
    let mut obj = GaussianModel::default();
    let (mut means, mut quats) = (Vec::new(), Vec::new());
    for (m, pose) in parts {
        means.extend(
            m.means
                .chunks(3)
                .flat_map(|x| pose.apply([x[0], x[1], x[2]])),
        );
        quats.extend(
            m.quats
                .chunks(4)
                .flat_map(|q| quat::mul(pose.q, [q[0], q[1], q[2], q[3]])),
        );
        obj.append(m);
    }
    let scales: Vec<f32> = obj.log_scales.iter().map(|s| s.exp()).collect();
    let g = Gaussians {
        means: &means,
        quats: &quats,
        scales: &scales,
        opacity_logits: &obj.opacity_logits,
        colors: Colors::Sh {
            coeffs: &obj.sh,
            num_coeffs: 16,
            degree: 0,
        },
    };
    let out = raster.forward(&g, &cam, &RenderOptions::default()).unwrap();
    let image = scene::ImageU8::from_f32(cam.width, cam.height, out.image);
    let id_map = out
        .alpha
        .iter()
        .map(|&a| if a > 0.5 { id } else { 255 })
        .collect();
    let ground = plane_depth(&cam);
    Frame {
        cam,
        time: t,
        image,
        id_map,
        ground,
    }
}
