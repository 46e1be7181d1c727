//! Projection of one 3D Gaussian to the image (gsplat 1.5.3 `_fully_fused_projection`,
//! pinhole, classic mode) and its vector–Jacobian product.
//!
//! Forward: `Σ = (R S)(R S)ᵀ` from the normalized quaternion and linear scales,
//! `Σc = W Σ Wᵀ`, EWA Jacobian `J` evaluated at the mean clamped to 1.3× the field of view
//! (gsplat `_persp_proj`), `cov2d = J Σc Jᵀ + eps2d·I`, conic = cov2d⁻¹, per-axis radius
//! `ceil(min(3.33·sqrt(cov2d_ii), 3.33·sqrt(λ_max)))`, culled when behind the near plane,
//! `det ≤ 0` or the box misses the image.

use crate::sh::{self, Real};
use crate::{Camera, Colors, Gaussians, RenderOptions};

pub(crate) type M3 = [[f32; 3]; 3];

/// Gaussians farther than this are culled (gsplat's default `far_plane`).
const FAR_PLANE: f32 = 1e10;
/// Box half-extent in standard deviations (gsplat 1.5).
const EXTEND: f32 = 3.33;

/// Camera constants shared by every Gaussian of one render.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CamInfo {
    pub w: M3,
    pub t: [f32; 3],
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: f32,
    pub height: f32,
    /// `[-lim_x_neg, lim_x_pos, -lim_y_neg, lim_y_pos]` of gsplat `_persp_proj`.
    pub lim: [f32; 4],
    pub center: [f32; 3],
    pub eps2d: f32,
    pub near: f32,
}

impl CamInfo {
    pub fn new(cam: &Camera, opts: &RenderOptions) -> Self {
        let m = &cam.viewmat;
        let (w, h) = (cam.width as f32, cam.height as f32);
        let tan_x = 0.5 * w / cam.fx;
        let tan_y = 0.5 * h / cam.fy;
        CamInfo {
            w: [
                [m[0][0], m[0][1], m[0][2]],
                [m[1][0], m[1][1], m[1][2]],
                [m[2][0], m[2][1], m[2][2]],
            ],
            t: [m[0][3], m[1][3], m[2][3]],
            fx: cam.fx,
            fy: cam.fy,
            cx: cam.cx,
            cy: cam.cy,
            width: w,
            height: h,
            lim: [
                -(cam.cx / cam.fx + 0.3 * tan_x),
                (w - cam.cx) / cam.fx + 0.3 * tan_x,
                -(cam.cy / cam.fy + 0.3 * tan_y),
                (h - cam.cy) / cam.fy + 0.3 * tan_y,
            ],
            center: cam.center(),
            eps2d: opts.eps2d,
            near: opts.near_plane,
        }
    }
}

/// What the rasterizer needs of one projected Gaussian.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Projected {
    pub mean2d: [f32; 2],
    pub depth: f32,
    pub conic: [f32; 3],
    pub radii: [i32; 2],
    pub opacity: f32,
    pub rgb: [f32; 3],
}

/// Gradient of the loss w.r.t. one Gaussian's projected quantities.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ProjGrad {
    pub mean2d: [f32; 2],
    pub conic: [f32; 3],
    pub rgb: [f32; 3],
    pub opacity: f32,
}

/// Mutable gradient slots of one Gaussian.
pub(crate) struct GaussGradMut<'a> {
    pub mean: &'a mut [f32],
    pub quat: &'a mut [f32],
    pub scale: &'a mut [f32],
    pub logit: &'a mut f32,
    pub color: &'a mut [f32],
}

fn matmul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn transpose(a: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

fn mat_vec(a: &M3, v: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

/// Rotation matrix of a unit quaternion (w, x, y, z), as gsplat `_quat_to_rotmat`.
pub(crate) fn rotmat<T: Real>(q: [T; 4]) -> [[T; 3]; 3] {
    let [w, x, y, z] = q;
    let (one, two) = (T::c(1.0), T::c(2.0));
    [
        [
            one - two * (y * y + z * z),
            two * (x * y - w * z),
            two * (x * z + w * y),
        ],
        [
            two * (x * y + w * z),
            one - two * (x * x + z * z),
            two * (y * z - w * x),
        ],
        [
            two * (x * z - w * y),
            two * (y * z + w * x),
            one - two * (x * x + y * y),
        ],
    ]
}

fn quat_normalized(g: &Gaussians, i: usize) -> ([f32; 4], f32) {
    let q: [f32; 4] = g.quats[4 * i..4 * i + 4].try_into().expect("len 4");
    let n = (q.iter().map(|v| v * v).sum::<f32>()).sqrt().max(1e-12);
    (q.map(|v| v / n), n)
}

/// Σ (world) and the factors it was built from.
struct Cov3 {
    r: M3,
    s: [f32; 3],
    m: M3,
    sigma: M3,
}

fn covariance(qn: [f32; 4], s: [f32; 3]) -> Cov3 {
    let r = rotmat(qn);
    let m: M3 = std::array::from_fn(|i| std::array::from_fn(|j| r[i][j] * s[j]));
    let sigma = matmul(&m, &transpose(&m));
    Cov3 { r, s, m, sigma }
}

/// The perspective Jacobian at camera point `p` with gsplat's clamping of x/z and y/z.
/// Returns J and, per axis, the clamped ratio and whether the clamp bound.
fn jacobian(cam: &CamInfo, p: [f32; 3]) -> ([[f32; 3]; 2], [f32; 2], [bool; 2]) {
    let [x, y, z] = p;
    let (ux, uy) = (x / z, y / z);
    let ucx = ux.max(cam.lim[0]).min(cam.lim[1]);
    let ucy = uy.max(cam.lim[2]).min(cam.lim[3]);
    let (tx, ty) = (z * ucx, z * ucy);
    let z2 = z * z;
    let j = [
        [cam.fx / z, 0.0, -cam.fx * tx / z2],
        [0.0, cam.fy / z, -cam.fy * ty / z2],
    ];
    // torch.clamp passes the gradient where min ≤ u ≤ max.
    let clamped = [
        !(ux >= cam.lim[0] && ux <= cam.lim[1]),
        !(uy >= cam.lim[2] && uy <= cam.lim[3]),
    ];
    (j, [ucx, ucy], clamped)
}

/// `J A Jᵀ` for a 2×3 J and symmetric 3×3 A.
fn jaj(j: &[[f32; 3]; 2], a: &M3) -> [[f32; 2]; 2] {
    let ja: [[f32; 3]; 2] =
        std::array::from_fn(|i| std::array::from_fn(|k| (0..3).map(|l| j[i][l] * a[l][k]).sum()));
    std::array::from_fn(|i| std::array::from_fn(|k| (0..3).map(|l| ja[i][l] * j[k][l]).sum()))
}

/// Colour of Gaussian `i` and, for SH, the unit view direction and its length.
fn color(g: &Gaussians, i: usize, cam: &CamInfo, mean: [f32; 3]) -> [f32; 3] {
    match g.colors {
        Colors::Rgb(c) => [c[3 * i], c[3 * i + 1], c[3 * i + 2]],
        Colors::Sh {
            coeffs,
            num_coeffs,
            degree,
        } => {
            let d = [
                mean[0] - cam.center[0],
                mean[1] - cam.center[1],
                mean[2] - cam.center[2],
            ];
            let (n, _) = sh::normalize(d);
            let mut b = [0.0f32; 16];
            sh::basis(degree, n, &mut b);
            let base = i * num_coeffs * 3;
            std::array::from_fn(|c| {
                let v: f32 = (0..sh::num_coeffs(degree))
                    .map(|k| b[k] * coeffs[base + 3 * k + c])
                    .sum();
                (v + 0.5).max(0.0)
            })
        }
    }
}

fn mean_of(g: &Gaussians, i: usize) -> [f32; 3] {
    [g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]]
}

fn scale_of(g: &Gaussians, i: usize) -> [f32; 3] {
    [g.scales[3 * i], g.scales[3 * i + 1], g.scales[3 * i + 2]]
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Projects Gaussian `i`. A culled Gaussian has `radii == [0, 0]`.
pub(crate) fn project(g: &Gaussians, i: usize, cam: &CamInfo) -> Projected {
    let mean = mean_of(g, i);
    let p = {
        let v = mat_vec(&cam.w, mean);
        [v[0] + cam.t[0], v[1] + cam.t[1], v[2] + cam.t[2]]
    };
    let mut out = Projected {
        depth: p[2],
        ..Default::default()
    };
    if !(p[2] > cam.near && p[2] < FAR_PLANE) {
        return out;
    }
    let (qn, _) = quat_normalized(g, i);
    let cov = covariance(qn, scale_of(g, i));
    let sigma_c = matmul(&matmul(&cam.w, &cov.sigma), &transpose(&cam.w));
    let (j, _, _) = jacobian(cam, p);
    let mut c2 = jaj(&j, &sigma_c);
    c2[0][0] += cam.eps2d;
    c2[1][1] += cam.eps2d;
    let det = (c2[0][0] * c2[1][1] - c2[0][1] * c2[1][0]).max(1e-10);
    out.conic = [
        c2[1][1] / det,
        -(c2[0][1] + c2[1][0]) / 2.0 / det,
        c2[0][0] / det,
    ];
    out.mean2d = [cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy];
    let b = (c2[0][0] + c2[1][1]) / 2.0;
    let r1 = EXTEND * (b + (b * b - det).max(0.01).sqrt()).sqrt();
    let rx = (EXTEND * c2[0][0].sqrt()).min(r1).ceil();
    let ry = (EXTEND * c2[1][1].sqrt()).min(r1).ceil();
    let [mx, my] = out.mean2d;
    let inside = mx + rx > 0.0 && mx - rx < cam.width && my + ry > 0.0 && my - ry < cam.height;
    if !inside {
        return out;
    }
    out.radii = [rx as i32, ry as i32];
    out.opacity = sigmoid(g.opacity_logits[i]);
    out.rgb = color(g, i, cam, mean);
    out
}

/// Backward of [`project`] for a visible Gaussian: writes (overwrites) its gradients.
pub(crate) fn project_vjp(
    g: &Gaussians,
    i: usize,
    cam: &CamInfo,
    pg: &ProjGrad,
    out: GaussGradMut,
) {
    let mean = mean_of(g, i);
    let p = {
        let v = mat_vec(&cam.w, mean);
        [v[0] + cam.t[0], v[1] + cam.t[1], v[2] + cam.t[2]]
    };
    let (qn, qlen) = quat_normalized(g, i);
    let cov = covariance(qn, scale_of(g, i));
    let sigma_c = matmul(&matmul(&cam.w, &cov.sigma), &transpose(&cam.w));
    let (j, uc, clamped) = jacobian(cam, p);
    let mut c2 = jaj(&j, &sigma_c);
    c2[0][0] += cam.eps2d;
    c2[1][1] += cam.eps2d;
    let det = (c2[0][0] * c2[1][1] - c2[0][1] * c2[1][0]).max(1e-10);
    let q = [
        [c2[1][1] / det, -c2[0][1] / det],
        [-c2[1][0] / det, c2[0][0] / det],
    ];
    // conic Q = cov2d⁻¹: dL/dcov2d = −Q G Q with G the symmetric gradient of Q
    // (the off-diagonal entry b appears once in σ, so it splits in halves).
    let gq = [
        [pg.conic[0], 0.5 * pg.conic[1]],
        [0.5 * pg.conic[1], pg.conic[2]],
    ];
    let qg: [[f32; 2]; 2] =
        std::array::from_fn(|a| std::array::from_fn(|b| q[a][0] * gq[0][b] + q[a][1] * gq[1][b]));
    let h: [[f32; 2]; 2] = std::array::from_fn(|a| {
        std::array::from_fn(|b| -(qg[a][0] * q[0][b] + qg[a][1] * q[1][b]))
    });
    // cov2d = J Σc Jᵀ: dΣc = Jᵀ H J, dJ = 2 H J Σc.
    let g_sigma_c: M3 = std::array::from_fn(|a| {
        std::array::from_fn(|b| {
            (0..2)
                .map(|k| (0..2).map(|l| j[k][a] * h[k][l] * j[l][b]).sum::<f32>())
                .sum()
        })
    });
    let hj: [[f32; 3]; 2] =
        std::array::from_fn(|a| std::array::from_fn(|b| h[a][0] * j[0][b] + h[a][1] * j[1][b]));
    let g_j: [[f32; 3]; 2] = std::array::from_fn(|a| {
        std::array::from_fn(|b| 2.0 * (0..3).map(|k| hj[a][k] * sigma_c[k][b]).sum::<f32>())
    });
    let g_p = camera_point_vjp(cam, p, &g_j, uc, clamped, pg.mean2d);
    // Σc = W Σ Wᵀ, Σ = M Mᵀ, M = R diag(s).
    let g_sigma = matmul(&matmul(&transpose(&cam.w), &g_sigma_c), &cam.w);
    let g_m = matmul(&g_sigma, &cov.m).map(|row| row.map(|v| 2.0 * v));
    for (jj, gs) in out.scale.iter_mut().enumerate() {
        *gs = (0..3).map(|ii| g_m[ii][jj] * cov.r[ii][jj]).sum();
    }
    let g_r: M3 = std::array::from_fn(|a| std::array::from_fn(|b| g_m[a][b] * cov.s[b]));
    let g_qn = rotmat_vjp(qn, &g_r);
    let dot: f32 = (0..4).map(|k| qn[k] * g_qn[k]).sum();
    for (k, gq) in out.quat.iter_mut().enumerate() {
        *gq = (g_qn[k] - qn[k] * dot) / qlen;
    }
    let mut g_mean = mat_vec(&transpose(&cam.w), g_p);
    color_vjp(g, i, cam, mean, pg.rgb, out.color, &mut g_mean);
    out.mean.copy_from_slice(&g_mean);
    let o = sigmoid(g.opacity_logits[i]);
    *out.logit = pg.opacity * o * (1.0 - o);
}

/// Gradient w.r.t. the camera-space mean from the Jacobian's and the 2D mean's gradients.
fn camera_point_vjp(
    cam: &CamInfo,
    p: [f32; 3],
    g_j: &[[f32; 3]; 2],
    uc: [f32; 2],
    clamped: [bool; 2],
    g_m2: [f32; 2],
) -> [f32; 3] {
    let [x, y, z] = p;
    let (z2, z3) = (z * z, z * z * z);
    let (tx, ty) = (z * uc[0], z * uc[1]);
    let mut g = [
        g_m2[0] * cam.fx / z,
        g_m2[1] * cam.fy / z,
        -(g_m2[0] * cam.fx * x + g_m2[1] * cam.fy * y) / z2,
    ];
    g[2] += -cam.fx / z2 * g_j[0][0] - cam.fy / z2 * g_j[1][1]
        + 2.0 * cam.fx * tx / z3 * g_j[0][2]
        + 2.0 * cam.fy * ty / z3 * g_j[1][2];
    let g_t = [-cam.fx / z2 * g_j[0][2], -cam.fy / z2 * g_j[1][2]];
    // t = z·clamp(u): unclamped t = x (gradient to x only); clamped t = z·bound.
    for a in 0..2 {
        if clamped[a] {
            g[2] += g_t[a] * uc[a];
        } else {
            g[a] += g_t[a];
        }
    }
    g
}

/// Gradient w.r.t. the unit quaternion (w, x, y, z) given dL/dR.
fn rotmat_vjp(q: [f32; 4], gr: &M3) -> [f32; 4] {
    let [w, x, y, z] = q;
    let g = gr;
    [
        2.0 * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]),
        2.0 * (y * g[0][1] + z * g[0][2] + y * g[1][0] - 2.0 * x * g[1][1] - w * g[1][2]
            + z * g[2][0]
            + w * g[2][1]
            - 2.0 * x * g[2][2]),
        2.0 * (-2.0 * y * g[0][0] + x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2]
            - w * g[2][0]
            + z * g[2][1]
            - 2.0 * y * g[2][2]),
        2.0 * (-2.0 * z * g[0][0] - w * g[0][1] + x * g[0][2] + w * g[1][0] - 2.0 * z * g[1][1]
            + y * g[1][2]
            + x * g[2][0]
            + y * g[2][1]),
    ]
}

/// Colour backward: writes the colour gradient and adds the view-direction term to `g_mean`.
fn color_vjp(
    g: &Gaussians,
    i: usize,
    cam: &CamInfo,
    mean: [f32; 3],
    g_rgb: [f32; 3],
    out: &mut [f32],
    g_mean: &mut [f32; 3],
) {
    let (coeffs, degree) = match g.colors {
        Colors::Rgb(_) => {
            out.copy_from_slice(&g_rgb);
            return;
        }
        Colors::Sh {
            coeffs,
            num_coeffs,
            degree,
        } => (
            &coeffs[i * num_coeffs * 3..(i + 1) * num_coeffs * 3],
            degree,
        ),
    };
    let d = [
        mean[0] - cam.center[0],
        mean[1] - cam.center[1],
        mean[2] - cam.center[2],
    ];
    let (n, len) = sh::normalize(d);
    let mut b = [0.0f32; 16];
    sh::basis(degree, n, &mut b);
    let kk = sh::num_coeffs(degree);
    // rgb = max(raw + 0.5, 0): no gradient where the clamp binds (torch clamp_min).
    let mut gc = g_rgb;
    for (c, gcc) in gc.iter_mut().enumerate() {
        let raw: f32 = (0..kk).map(|k| b[k] * coeffs[3 * k + c]).sum::<f32>() + 0.5;
        if raw < 0.0 {
            *gcc = 0.0;
        }
    }
    out.fill(0.0);
    let mut w = [0.0f32; 16];
    for k in 0..kk {
        for c in 0..3 {
            out[3 * k + c] = b[k] * gc[c];
            w[k] += coeffs[3 * k + c] * gc[c];
        }
    }
    let gn = sh::basis_vjp(degree, n, &w);
    let dot = gn[0] * n[0] + gn[1] * n[1] + gn[2] * n[2];
    for a in 0..3 {
        g_mean[a] += (gn[a] - n[a] * dot) / len;
    }
}
