//! Projection of 3D Gaussians to the image (gsplat 1.5.3 `_fully_fused_projection`,
//! pinhole, classic mode), their colour (`_spherical_harmonics`) and the vector–Jacobian
//! products of both.
//!
//! The arithmetic is written once over [`Lane`]: [`project`] and [`project_vjp`] run it on one
//! Gaussian in `f32` and are the reference; `project_batch.rs` runs the same functions on
//! sixteen Gaussians at a time ([`crate::lanes::F16`]), where each branch becomes a select.
//!
//! Forward: `Σ = (R S)(R S)ᵀ` from the normalized quaternion and linear scales,
//! `Σc = W Σ Wᵀ`, EWA Jacobian `J` evaluated at the mean clamped to 1.3× the field of view
//! (gsplat `_persp_proj`), `cov2d = J Σc Jᵀ + eps2d·I`, conic = cov2d⁻¹, per-axis radius
//! `ceil(min(3.33·sqrt(cov2d_ii), 3.33·sqrt(λ_max)))`, culled when behind the near plane,
//! `det ≤ 0` or the box misses the image.

use crate::lanes::{arr, Lane};
use crate::sh::{self, Real};
use crate::{Camera, Colors, Gaussians, RenderOptions};

pub(crate) type M3<T = f32> = [[T; 3]; 3];

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

/// Gradient of the loss w.r.t. the projected quantities (of one Gaussian, or of 16).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ProjGrad<T = f32> {
    pub mean2d: [T; 2],
    pub conic: [T; 3],
    pub rgb: [T; 3],
    pub opacity: T,
}

impl ProjGrad {
    /// From one Gaussian's sum of its tile gradients (`backward::GradAcc`: 2D mean, conic,
    /// colour, opacity).
    pub(crate) fn from_acc(s: &[f32; 9]) -> Self {
        ProjGrad {
            mean2d: [s[0], s[1]],
            conic: [s[2], s[3], s[4]],
            rgb: [s[5], s[6], s[7]],
            opacity: s[8],
        }
    }
}

/// Mutable gradient slots of one Gaussian.
pub(crate) struct GaussGradMut<'a> {
    pub mean: &'a mut [f32],
    pub quat: &'a mut [f32],
    pub scale: &'a mut [f32],
    pub logit: &'a mut f32,
    pub color: &'a mut [f32],
}

/// The parameters of one Gaussian (or of 16) that the projection reads, colour aside.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GaussIn<T> {
    pub mean: [T; 3],
    /// As stored, not normalized.
    pub quat: [T; 4],
    /// Linear scales.
    pub scale: [T; 3],
    pub logit: T,
}

impl GaussIn<f32> {
    pub(crate) fn of(g: &Gaussians, i: usize) -> Self {
        GaussIn {
            mean: std::array::from_fn(|a| g.means[3 * i + a]),
            quat: std::array::from_fn(|a| g.quats[4 * i + a]),
            scale: std::array::from_fn(|a| g.scales[3 * i + a]),
            logit: g.opacity_logits[i],
        }
    }
}

/// Gradient w.r.t. [`GaussIn`], field by field (the quaternion's through its
/// normalization).
pub(crate) type GaussGrad<T> = GaussIn<T>;

/// SH coefficients of one Gaussian (or of 16), `[k][channel]`, the first
/// `num_coeffs(degree)` entries used.
pub(crate) type ShCoeffs<T> = [[T; 3]; 16];

/// The projection of [`GaussIn`] before culling is applied: every field is computed on every
/// lane, and the masks say which of them [`project`] keeps.
pub(crate) struct Proj<T: Lane> {
    pub depth: T,
    pub mean2d: [T; 2],
    pub conic: [T; 3],
    /// Per-axis radius in pixels, already rounded up.
    pub radii: [T; 2],
    pub opacity: T,
    /// In front of the near plane and before the far one: mean and conic are kept.
    pub in_range: T::Mask,
    /// `in_range` and the radius box meets the image: radii, opacity and colour are kept.
    pub visible: T::Mask,
}

/// The camera's world-to-camera rotation W, one value per lane.
#[inline(always)]
fn cam_rotation<T: Lane>(cam: &CamInfo) -> M3<T> {
    arr!(i in 3 => arr!(j in 3 => T::splat(cam.w[i][j])))
}

#[inline(always)]
fn matmul<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    arr!(i in 3 => arr!(j in 3 => a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j]))
}

#[inline(always)]
fn transpose<T: Copy>(a: &M3<T>) -> M3<T> {
    arr!(i in 3 => arr!(j in 3 => a[j][i]))
}

#[inline(always)]
fn mat_vec<T: Real>(a: &M3<T>, v: [T; 3]) -> [T; 3] {
    arr!(i in 3 => a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

/// Rotation matrix of a unit quaternion (w, x, y, z), as gsplat `_quat_to_rotmat`.
#[inline(always)]
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

#[inline(always)]
fn sigmoid<T: Lane>(x: T) -> T {
    let one = T::c(1.0);
    one / (one + (-x).exp())
}

/// Everything the forward pass computes before the 2D covariance is inverted; the backward
/// pass recomputes it rather than storing it (gsplat does the same).
struct Geometry<T: Lane> {
    /// Mean in camera coordinates.
    p: [T; 3],
    qn: [T; 4],
    qlen: T,
    r: M3<T>,
    /// `M = R diag(s)`, so `Σ = M Mᵀ`.
    m: M3<T>,
    sigma_c: M3<T>,
    j: [[T; 3]; 2],
    /// Clamped x/z and y/z, and whether each clamp bound.
    uc: [T; 2],
    clamped: [T::Mask; 2],
    /// `J Σc Jᵀ + eps2d·I` and its determinant (floored at 1e-10).
    c2: [[T; 2]; 2],
    det: T,
}

#[inline(always)]
fn geometry<T: Lane>(x: &GaussIn<T>, cam: &CamInfo) -> Geometry<T> {
    let w = cam_rotation(cam);
    let p = {
        let v = mat_vec(&w, x.mean);
        arr!(a in 3 => v[a] + T::splat(cam.t[a]))
    };
    let q = x.quat;
    let qlen = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        .sqrt()
        .max(T::c(1e-12));
    let qn = arr!(k in 4 => q[k] / qlen);
    let r = rotmat(qn);
    let m: M3<T> = arr!(i in 3 => arr!(j in 3 => r[i][j] * x.scale[j]));
    let sigma = matmul(&m, &transpose(&m));
    let sigma_c = matmul(&matmul(&w, &sigma), &transpose(&w));
    let (j, uc, clamped) = jacobian(cam, p);
    let mut c2 = jaj(&j, &sigma_c);
    c2[0][0] = c2[0][0] + T::splat(cam.eps2d);
    c2[1][1] = c2[1][1] + T::splat(cam.eps2d);
    let det = (c2[0][0] * c2[1][1] - c2[0][1] * c2[1][0]).max(T::c(1e-10));
    Geometry {
        p,
        qn,
        qlen,
        r,
        m,
        sigma_c,
        j,
        uc,
        clamped,
        c2,
        det,
    }
}

/// The perspective Jacobian at camera point `p` with gsplat's clamping of x/z and y/z.
/// Returns J and, per axis, the clamped ratio and whether the clamp bound.
#[inline(always)]
fn jacobian<T: Lane>(cam: &CamInfo, p: [T; 3]) -> ([[T; 3]; 2], [T; 2], [T::Mask; 2]) {
    let [x, y, z] = p;
    let lim = arr!(k in 4 => T::splat(cam.lim[k]));
    let (ux, uy) = (x / z, y / z);
    let ucx = ux.max(lim[0]).min(lim[1]);
    let ucy = uy.max(lim[2]).min(lim[3]);
    let (tx, ty) = (z * ucx, z * ucy);
    let z2 = z * z;
    let (fx, fy, zero) = (T::splat(cam.fx), T::splat(cam.fy), T::c(0.0));
    let j = [
        [fx / z, zero, T::splat(-cam.fx) * tx / z2],
        [zero, fy / z, T::splat(-cam.fy) * ty / z2],
    ];
    // torch.clamp passes the gradient where min ≤ u ≤ max.
    let clamped = [
        !(ux.ge(lim[0]) & ux.le(lim[1])),
        !(uy.ge(lim[2]) & uy.le(lim[3])),
    ];
    (j, [ucx, ucy], clamped)
}

/// `J A Jᵀ` for a 2×3 J and symmetric 3×3 A.
#[inline(always)]
fn jaj<T: Real>(j: &[[T; 3]; 2], a: &M3<T>) -> [[T; 2]; 2] {
    let ja: [[T; 3]; 2] =
        arr!(i in 2 => arr!(k in 3 => j[i][0] * a[0][k] + j[i][1] * a[1][k] + j[i][2] * a[2][k]));
    arr!(i in 2 => arr!(k in 2 => ja[i][0] * j[k][0] + ja[i][1] * j[k][1] + ja[i][2] * j[k][2]))
}

/// Projects `x` on every lane; [`Proj`]'s masks say what culling keeps.
#[inline(always)]
pub(crate) fn project_lanes<T: Lane>(x: &GaussIn<T>, cam: &CamInfo) -> Proj<T> {
    let geo = geometry(x, cam);
    let (p, c2, det) = (geo.p, geo.c2, geo.det);
    let in_range = p[2].gt(T::splat(cam.near)) & p[2].lt(T::splat(FAR_PLANE));
    let two = T::c(2.0);
    let conic = [
        c2[1][1] / det,
        -(c2[0][1] + c2[1][0]) / two / det,
        c2[0][0] / det,
    ];
    let mean2d = [
        T::splat(cam.fx) * p[0] / p[2] + T::splat(cam.cx),
        T::splat(cam.fy) * p[1] / p[2] + T::splat(cam.cy),
    ];
    let b = (c2[0][0] + c2[1][1]) / two;
    let ext = T::splat(EXTEND);
    let r1 = ext * (b + (b * b - det).max(T::c(0.01)).sqrt()).sqrt();
    let rx = (ext * c2[0][0].sqrt()).min(r1).ceil();
    let ry = (ext * c2[1][1].sqrt()).min(r1).ceil();
    let [mx, my] = mean2d;
    let zero = T::c(0.0);
    let inside = (mx + rx).gt(zero)
        & (mx - rx).lt(T::splat(cam.width))
        & (my + ry).gt(zero)
        & (my - ry).lt(T::splat(cam.height));
    Proj {
        depth: p[2],
        mean2d,
        conic,
        radii: [rx, ry],
        opacity: sigmoid(x.logit),
        in_range,
        visible: in_range & inside,
    }
}

/// Unit view direction from the camera centre to `mean`, and the distance.
#[inline(always)]
fn view_dir<T: Lane>(cam: &CamInfo, mean: [T; 3]) -> ([T; 3], T) {
    sh::normalize(arr!(a in 3 => mean[a] - T::splat(cam.center[a])))
}

/// SH colour `max(Σ_k basis_k(dir)·coeff_k + 0.5, 0)` per channel, before the clamp.
#[inline(always)]
fn sh_raw<T: Lane>(degree: usize, coeffs: &ShCoeffs<T>, b: &[T; 16]) -> [T; 3] {
    arr!(c in 3 => {
        let mut v = b[0] * coeffs[0][c];
        for k in 1..sh::num_coeffs(degree) {
            v = v + b[k] * coeffs[k][c];
        }
        v + T::c(0.5)
    })
}

/// Colour of a Gaussian with SH coefficients `coeffs` at `mean`.
#[inline(always)]
pub(crate) fn sh_color<T: Lane>(
    degree: usize,
    coeffs: &ShCoeffs<T>,
    cam: &CamInfo,
    mean: [T; 3],
) -> [T; 3] {
    let (n, _) = view_dir(cam, mean);
    let mut b = [T::c(0.0); 16];
    sh::basis(degree, n, &mut b);
    let raw = sh_raw(degree, coeffs, &b);
    arr!(c in 3 => raw[c].max(T::c(0.0)))
}

fn sh_coeffs_of(coeffs: &[f32], num_coeffs: usize, i: usize) -> ShCoeffs<f32> {
    let base = i * num_coeffs * 3;
    std::array::from_fn(|k| {
        std::array::from_fn(|c| {
            if k < num_coeffs {
                coeffs[base + 3 * k + c]
            } else {
                0.0
            }
        })
    })
}

/// Projects Gaussian `i` (the reference for `project_batch.rs`). A culled Gaussian has
/// `radii == [0, 0]`.
pub(crate) fn project(g: &Gaussians, i: usize, cam: &CamInfo) -> Projected {
    let x = GaussIn::of(g, i);
    let pr = project_lanes(&x, cam);
    let mut out = Projected {
        depth: pr.depth,
        ..Default::default()
    };
    if !pr.in_range {
        return out;
    }
    out.conic = pr.conic;
    out.mean2d = pr.mean2d;
    if !pr.visible {
        return out;
    }
    out.radii = pr.radii.map(|r| r as i32);
    out.opacity = pr.opacity;
    out.rgb = match g.colors {
        Colors::Rgb(c) => [c[3 * i], c[3 * i + 1], c[3 * i + 2]],
        Colors::Sh {
            coeffs,
            num_coeffs,
            degree,
        } => sh_color(degree, &sh_coeffs_of(coeffs, num_coeffs, i), cam, x.mean),
    };
    out
}

/// Backward of [`project_lanes`]: the gradient w.r.t. [`GaussIn`], the colour's view
/// direction term not included (see [`sh_color_vjp`]).
#[inline(always)]
pub(crate) fn project_vjp_lanes<T: Lane>(
    x: &GaussIn<T>,
    cam: &CamInfo,
    pg: &ProjGrad<T>,
) -> GaussGrad<T> {
    let geo = geometry(x, cam);
    let (j, c2, det) = (&geo.j, geo.c2, geo.det);
    let q = [
        [c2[1][1] / det, -c2[0][1] / det],
        [-c2[1][0] / det, c2[0][0] / det],
    ];
    // conic Q = cov2d⁻¹: dL/dcov2d = −Q G Q with G the symmetric gradient of Q
    // (the off-diagonal entry b appears once in σ, so it splits in halves).
    let half_b = T::c(0.5) * pg.conic[1];
    let gq = [[pg.conic[0], half_b], [half_b, pg.conic[2]]];
    let qg: [[T; 2]; 2] = arr!(a in 2 => arr!(b in 2 => q[a][0] * gq[0][b] + q[a][1] * gq[1][b]));
    let h: [[T; 2]; 2] = arr!(a in 2 => arr!(b in 2 => -(qg[a][0] * q[0][b] + qg[a][1] * q[1][b])));
    // cov2d = J Σc Jᵀ: dΣc = Jᵀ H J, dJ = 2 H J Σc.
    let g_sigma_c: M3<T> = arr!(a in 3 => arr!(b in 3 => {
        let row0 = j[0][a] * h[0][0] * j[0][b] + j[0][a] * h[0][1] * j[1][b];
        let row1 = j[1][a] * h[1][0] * j[0][b] + j[1][a] * h[1][1] * j[1][b];
        row0 + row1
    }));
    let hj: [[T; 3]; 2] = arr!(a in 2 => arr!(b in 3 => h[a][0] * j[0][b] + h[a][1] * j[1][b]));
    let sc = &geo.sigma_c;
    let g_j: [[T; 3]; 2] = arr!(a in 2 => arr!(b in 3 =>
        T::c(2.0) * (hj[a][0] * sc[0][b] + hj[a][1] * sc[1][b] + hj[a][2] * sc[2][b])
    ));
    let g_p = camera_point_vjp(cam, &geo, &g_j, pg.mean2d);
    // Σc = W Σ Wᵀ, Σ = M Mᵀ, M = R diag(s).
    let w = cam_rotation(cam);
    let g_sigma = matmul(&matmul(&transpose(&w), &g_sigma_c), &w);
    let g_m = {
        let gm = matmul(&g_sigma, &geo.m);
        arr!(a in 3 => arr!(b in 3 => T::c(2.0) * gm[a][b]))
    };
    let r = &geo.r;
    let scale =
        arr!(jj in 3 => g_m[0][jj] * r[0][jj] + g_m[1][jj] * r[1][jj] + g_m[2][jj] * r[2][jj]);
    let g_r: M3<T> = arr!(a in 3 => arr!(b in 3 => g_m[a][b] * x.scale[b]));
    let qn = geo.qn;
    let g_qn = rotmat_vjp(qn, &g_r);
    let dot = qn[0] * g_qn[0] + qn[1] * g_qn[1] + qn[2] * g_qn[2] + qn[3] * g_qn[3];
    let quat = arr!(k in 4 => (g_qn[k] - qn[k] * dot) / geo.qlen);
    let o = sigmoid(x.logit);
    GaussGrad {
        mean: mat_vec(&transpose(&w), g_p),
        quat,
        scale,
        logit: pg.opacity * o * (T::c(1.0) - o),
    }
}

/// Backward of [`project`] for a visible Gaussian: writes (overwrites) its gradients.
pub(crate) fn project_vjp(
    g: &Gaussians,
    i: usize,
    cam: &CamInfo,
    pg: &ProjGrad,
    out: GaussGradMut,
) {
    let x = GaussIn::of(g, i);
    let mut gg = project_vjp_lanes(&x, cam, pg);
    match g.colors {
        Colors::Rgb(_) => out.color.copy_from_slice(&pg.rgb),
        Colors::Sh {
            coeffs,
            num_coeffs,
            degree,
        } => {
            let c = sh_coeffs_of(coeffs, num_coeffs, i);
            let mut g_c = [[0.0f32; 3]; 16];
            sh_color_vjp(degree, &c, cam, x.mean, pg.rgb, &mut g_c, &mut gg.mean);
            out.color.fill(0.0);
            for (k, gk) in g_c.iter().enumerate().take(sh::num_coeffs(degree)) {
                out.color[3 * k..3 * k + 3].copy_from_slice(gk);
            }
        }
    }
    out.mean.copy_from_slice(&gg.mean);
    out.quat.copy_from_slice(&gg.quat);
    out.scale.copy_from_slice(&gg.scale);
    *out.logit = gg.logit;
}

/// Gradient w.r.t. the camera-space mean from the Jacobian's and the 2D mean's gradients.
#[inline(always)]
fn camera_point_vjp<T: Lane>(
    cam: &CamInfo,
    geo: &Geometry<T>,
    g_j: &[[T; 3]; 2],
    g_m2: [T; 2],
) -> [T; 3] {
    let [x, y, z] = geo.p;
    let (uc, clamped) = (geo.uc, geo.clamped);
    let (fx, fy) = (T::splat(cam.fx), T::splat(cam.fy));
    let (nfx, nfy) = (T::splat(-cam.fx), T::splat(-cam.fy));
    let (z2, z3) = (z * z, z * z * z);
    let (tx, ty) = (z * uc[0], z * uc[1]);
    let mut g = [
        g_m2[0] * fx / z,
        g_m2[1] * fy / z,
        -(g_m2[0] * fx * x + g_m2[1] * fy * y) / z2,
    ];
    g[2] = g[2]
        + (nfx / z2 * g_j[0][0] - fy / z2 * g_j[1][1]
            + T::splat(2.0 * cam.fx) * tx / z3 * g_j[0][2]
            + T::splat(2.0 * cam.fy) * ty / z3 * g_j[1][2]);
    let g_t = [nfx / z2 * g_j[0][2], nfy / z2 * g_j[1][2]];
    // t = z·clamp(u): unclamped t = x (gradient to x only); clamped t = z·bound.
    for a in 0..2 {
        g[2] = T::select(clamped[a], g[2] + g_t[a] * uc[a], g[2]);
        g[a] = T::select(clamped[a], g[a], g[a] + g_t[a]);
    }
    g
}

/// Gradient w.r.t. the unit quaternion (w, x, y, z) given dL/dR.
#[inline(always)]
fn rotmat_vjp<T: Real>(q: [T; 4], gr: &M3<T>) -> [T; 4] {
    let [w, x, y, z] = q;
    let g = gr;
    let two = T::c(2.0);
    [
        two * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]),
        two * (y * g[0][1] + z * g[0][2] + y * g[1][0] - two * x * g[1][1] - w * g[1][2]
            + z * g[2][0]
            + w * g[2][1]
            - two * x * g[2][2]),
        two * (-two * y * g[0][0] + x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2]
            - w * g[2][0]
            + z * g[2][1]
            - two * y * g[2][2]),
        two * (-two * z * g[0][0] - w * g[0][1] + x * g[0][2] + w * g[1][0] - two * z * g[1][1]
            + y * g[1][2]
            + x * g[2][0]
            + y * g[2][1]),
    ]
}

/// SH colour backward: writes dL/dcoeffs into `g_coeffs` (the first `num_coeffs(degree)`
/// entries) and adds the view-direction term to `g_mean`.
#[inline(always)]
pub(crate) fn sh_color_vjp<T: Lane>(
    degree: usize,
    coeffs: &ShCoeffs<T>,
    cam: &CamInfo,
    mean: [T; 3],
    g_rgb: [T; 3],
    g_coeffs: &mut ShCoeffs<T>,
    g_mean: &mut [T; 3],
) {
    let (n, len) = view_dir(cam, mean);
    let zero = T::c(0.0);
    let mut b = [zero; 16];
    sh::basis(degree, n, &mut b);
    let kk = sh::num_coeffs(degree);
    // rgb = max(raw + 0.5, 0): no gradient where the clamp binds (torch clamp_min).
    let raw = sh_raw(degree, coeffs, &b);
    let gc: [T; 3] = arr!(c in 3 => T::select(raw[c].lt(zero), zero, g_rgb[c]));
    let mut w = [zero; 16];
    for k in 0..kk {
        for c in 0..3 {
            g_coeffs[k][c] = b[k] * gc[c];
            w[k] = w[k] + coeffs[k][c] * gc[c];
        }
    }
    let gn = sh::basis_vjp(degree, n, &w);
    let dot = gn[0] * n[0] + gn[1] * n[1] + gn[2] * n[2];
    for a in 0..3 {
        g_mean[a] = g_mean[a] + (gn[a] - n[a] * dot) / len;
    }
}
