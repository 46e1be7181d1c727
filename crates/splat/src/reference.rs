//! A deliberately simple float64 reference of the forward pass (gsplat classic semantics,
//! pixel by pixel, Gaussian by Gaussian, no tiles kernels, no SIMD), used by the tests as
//! an oracle: finite differences of the backward and brute-force top-k.
//! It is O(pixels × Gaussians): for tiny scenes only.

use crate::project::rotmat;
use crate::sh;
use crate::{Camera, Colors, Gaussians, RenderOptions, TILE_SIZE};

/// Gaussians in float64 with owned buffers (same layouts as [`Gaussians`]).
#[derive(Clone, Debug)]
pub struct RefGaussians {
    pub means: Vec<f64>,
    pub quats: Vec<f64>,
    pub scales: Vec<f64>,
    pub opacity_logits: Vec<f64>,
    /// SH `(N·K·3)` when `sh` is `Some((K, degree))`, else RGB `(N·3)`.
    pub colors: Vec<f64>,
    pub sh: Option<(usize, usize)>,
}

impl RefGaussians {
    pub fn from_gaussians(g: &Gaussians) -> Self {
        let up = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
        let (colors, sh) = match g.colors {
            Colors::Rgb(c) => (up(c), None),
            Colors::Sh {
                coeffs,
                num_coeffs,
                degree,
            } => (up(coeffs), Some((num_coeffs, degree))),
        };
        RefGaussians {
            means: up(g.means),
            quats: up(g.quats),
            scales: up(g.scales),
            opacity_logits: up(g.opacity_logits),
            colors,
            sh,
        }
    }

    pub fn len(&self) -> usize {
        self.opacity_logits.len()
    }

    pub fn is_empty(&self) -> bool {
        self.opacity_logits.is_empty()
    }
}

/// Reference render results (row-major, as [`crate::ForwardOutput`]).
#[derive(Clone, Debug)]
pub struct RefOutput {
    pub image: Vec<f64>,
    pub alpha: Vec<f64>,
    pub topk_ids: Vec<u32>,
    pub topk_weights: Vec<f64>,
    pub radii: Vec<[i32; 2]>,
    pub n_isects: usize,
}

struct Proj2 {
    m: [f64; 2],
    conic: [f64; 3],
    depth: f64,
    radii: [i32; 2],
    opacity: f64,
    rgb: [f64; 3],
}

fn project(g: &RefGaussians, i: usize, cam: &Camera, opts: &RenderOptions) -> Proj2 {
    let v = cam.viewmat.map(|r| r.map(|x| x as f64));
    let mean = [g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]];
    let p: [f64; 3] =
        std::array::from_fn(|r| (0..3).map(|k| v[r][k] * mean[k]).sum::<f64>() + v[r][3]);
    let q = &g.quats[4 * i..4 * i + 4];
    let qn = q.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
    let rm = rotmat([q[0] / qn, q[1] / qn, q[2] / qn, q[3] / qn]);
    let s = &g.scales[3 * i..3 * i + 3];
    let m: [[f64; 3]; 3] = std::array::from_fn(|a| std::array::from_fn(|b| rm[a][b] * s[b]));
    // Σc = W M Mᵀ Wᵀ = (W M)(W M)ᵀ.
    let wm: [[f64; 3]; 3] =
        std::array::from_fn(|a| std::array::from_fn(|b| (0..3).map(|k| v[a][k] * m[k][b]).sum()));
    let sc: [[f64; 3]; 3] =
        std::array::from_fn(|a| std::array::from_fn(|b| (0..3).map(|k| wm[a][k] * wm[b][k]).sum()));
    let (fx, fy, cx, cy) = (cam.fx as f64, cam.fy as f64, cam.cx as f64, cam.cy as f64);
    let (w, h) = (cam.width as f64, cam.height as f64);
    let (tanx, tany) = (0.5 * w / fx, 0.5 * h / fy);
    let tx = p[2] * (p[0] / p[2]).clamp(-(cx / fx + 0.3 * tanx), (w - cx) / fx + 0.3 * tanx);
    let ty = p[2] * (p[1] / p[2]).clamp(-(cy / fy + 0.3 * tany), (h - cy) / fy + 0.3 * tany);
    let z2 = p[2] * p[2];
    let j = [
        [fx / p[2], 0.0, -fx * tx / z2],
        [0.0, fy / p[2], -fy * ty / z2],
    ];
    let c2: [[f64; 2]; 2] = std::array::from_fn(|a| {
        std::array::from_fn(|b| {
            (0..3)
                .map(|k| (0..3).map(|l| j[a][k] * sc[k][l] * j[b][l]).sum::<f64>())
                .sum::<f64>()
                + if a == b { opts.eps2d as f64 } else { 0.0 }
        })
    });
    let det = (c2[0][0] * c2[1][1] - c2[0][1] * c2[1][0]).max(1e-10);
    let mxy = [fx * p[0] / p[2] + cx, fy * p[1] / p[2] + cy];
    let b = 0.5 * (c2[0][0] + c2[1][1]);
    let r1 = 3.33 * (b + (b * b - det).max(0.01).sqrt()).sqrt();
    let rx = (3.33 * c2[0][0].sqrt()).min(r1).ceil();
    let ry = (3.33 * c2[1][1].sqrt()).min(r1).ceil();
    let valid = p[2] > opts.near_plane as f64 && p[2] < 1e10;
    let inside = mxy[0] + rx > 0.0 && mxy[0] - rx < w && mxy[1] + ry > 0.0 && mxy[1] - ry < h;
    Proj2 {
        m: mxy,
        conic: [c2[1][1] / det, -c2[0][1] / det, c2[0][0] / det],
        depth: p[2],
        radii: if valid && inside {
            [rx as i32, ry as i32]
        } else {
            [0, 0]
        },
        opacity: 1.0 / (1.0 + (-g.opacity_logits[i]).exp()),
        rgb: color(g, i, cam, mean),
    }
}

fn color(g: &RefGaussians, i: usize, cam: &Camera, mean: [f64; 3]) -> [f64; 3] {
    let Some((k, degree)) = g.sh else {
        return [g.colors[3 * i], g.colors[3 * i + 1], g.colors[3 * i + 2]];
    };
    let c = cam.center().map(|x| x as f64);
    let d = [mean[0] - c[0], mean[1] - c[1], mean[2] - c[2]];
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-12);
    let mut b = [0.0f64; 16];
    sh::basis(degree, d.map(|x| x / len), &mut b);
    let co = &g.colors[i * k * 3..];
    std::array::from_fn(|ch| {
        let v: f64 = (0..sh::num_coeffs(degree))
            .map(|j| b[j] * co[3 * j + ch])
            .sum();
        (v + 0.5).max(0.0)
    })
}

/// Tile rectangle `[x0, x1, y0, y1)` as gsplat `_isect_tiles`.
fn tile_rect(p: &Proj2, tiles_x: i64, tiles_y: i64) -> [i64; 4] {
    if p.radii[0] <= 0 || p.radii[1] <= 0 {
        return [0; 4];
    }
    let ts = TILE_SIZE as f64;
    let (mx, my) = (p.m[0] / ts, p.m[1] / ts);
    let (rx, ry) = (p.radii[0] as f64 / ts, p.radii[1] as f64 / ts);
    [
        ((mx - rx).floor() as i64).clamp(0, tiles_x),
        ((mx + rx).ceil() as i64).clamp(0, tiles_x),
        ((my - ry).floor() as i64).clamp(0, tiles_y),
        ((my + ry).ceil() as i64).clamp(0, tiles_y),
    ]
}

/// Renders `g` pixel by pixel in float64; `opts.topk` as in the fast path.
pub fn render(g: &RefGaussians, cam: &Camera, opts: &RenderOptions) -> RefOutput {
    let n = g.len();
    let proj: Vec<Proj2> = (0..n).map(|i| project(g, i, cam, opts)).collect();
    let ts = TILE_SIZE as i64;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let (tiles_x, tiles_y) = ((w as i64 + ts - 1) / ts, (h as i64 + ts - 1) / ts);
    let rects: Vec<[i64; 4]> = proj
        .iter()
        .map(|p| tile_rect(p, tiles_x, tiles_y))
        .collect();
    let n_isects = rects
        .iter()
        .map(|r| ((r[1] - r[0]) * (r[3] - r[2])) as usize)
        .sum();
    let mut order: Vec<usize> = (0..n).filter(|&i| proj[i].radii[0] > 0).collect();
    order.sort_by(|&a, &b| proj[a].depth.total_cmp(&proj[b].depth).then(a.cmp(&b)));
    let k = opts.topk;
    let mut out = RefOutput {
        image: vec![0.0; w * h * 3],
        alpha: vec![0.0; w * h],
        topk_ids: vec![u32::MAX; w * h * k],
        topk_weights: vec![0.0; w * h * k],
        radii: proj.iter().map(|p| p.radii).collect(),
        n_isects,
    };
    for y in 0..h {
        for x in 0..w {
            let (tx, ty) = (x as i64 / ts, y as i64 / ts);
            let list = order.iter().copied().filter(|&i| {
                let r = rects[i];
                tx >= r[0] && tx < r[1] && ty >= r[2] && ty < r[3]
            });
            let pix = y * w + x;
            let (c, t, contribs) = composite_pixel(&proj, list, x as f64 + 0.5, y as f64 + 0.5);
            for (ch, o) in out.image[3 * pix..3 * pix + 3].iter_mut().enumerate() {
                *o = c[ch] + t * opts.background[ch] as f64;
            }
            out.alpha[pix] = 1.0 - t;
            let mut sorted = contribs;
            // Stable: equal weights keep compositing order.
            sorted.sort_by(|a, b| b.1.total_cmp(&a.1));
            for (j, (id, wt)) in sorted.into_iter().take(k).enumerate() {
                out.topk_ids[pix * k + j] = id as u32;
                out.topk_weights[pix * k + j] = wt;
            }
        }
    }
    out
}

/// Front-to-back compositing of one pixel; returns colour (no background), final T and
/// the (Gaussian, weight T·α) pairs composited.
fn composite_pixel(
    proj: &[Proj2],
    list: impl Iterator<Item = usize>,
    px: f64,
    py: f64,
) -> ([f64; 3], f64, Vec<(usize, f64)>) {
    let (mut c, mut t) = ([0.0f64; 3], 1.0f64);
    let mut contribs = Vec::new();
    for i in list {
        let p = &proj[i];
        let (dx, dy) = (p.m[0] - px, p.m[1] - py);
        let sigma = 0.5 * (p.conic[0] * dx * dx + p.conic[2] * dy * dy) + p.conic[1] * dx * dy;
        let alpha = (p.opacity * (-sigma).exp()).min(0.999);
        if sigma < 0.0 || alpha < 1.0 / 255.0 {
            continue;
        }
        let next = t * (1.0 - alpha);
        if next <= 1e-4 {
            break;
        }
        for (cc, rgb) in c.iter_mut().zip(p.rgb) {
            *cc += rgb * alpha * t;
        }
        contribs.push((i, alpha * t));
        t = next;
    }
    (c, t, contribs)
}
