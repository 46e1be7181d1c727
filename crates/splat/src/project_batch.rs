//! The projection and its backward on sixteen Gaussians at a time: the functions of
//! `project.rs` instantiated with [`F16`], compiled for each vector level and picked at run
//! time like the tile kernels. Results are bit-identical to the scalar reference
//! ([`crate::project::project`], [`crate::project::project_vjp`]); the unit tests below
//! and `tests/bit_identical.rs` check it.
//!
//! Each block gathers sixteen Gaussians from the caller's interleaved arrays into lanes,
//! computes every quantity on every lane (a culled Gaussian's lane is computed and then not
//! written), and scatters back. The tail block repeats the last Gaussian in its unused lanes.

use crate::backward::GradAcc;
use crate::lanes::{arr, Lane, F16, LANES};
use crate::project::{
    project_lanes, project_vjp_lanes, sh_color, sh_color_vjp, CamInfo, GaussIn, ProjGrad,
    Projected, ShCoeffs,
};
use crate::raster::{set_len, Simd};
use crate::{sh, Colors, Gaussians, Gradients};
use rayon::prelude::*;

/// Gaussians per parallel job (a multiple of [`LANES`]).
const CHUNK: usize = 512;

/// Lane `l` of the block starting at `i0` reads Gaussian `idx[l]`.
#[inline(always)]
fn lane_indices(i0: usize, n: usize) -> [usize; LANES] {
    let mut idx = [0; LANES];
    for (l, i) in idx.iter_mut().enumerate() {
        *i = (i0 + l).min(n - 1);
    }
    idx
}

/// Lane values `src[i][at]` for each lane's Gaussian `i`.
#[inline(always)]
fn gather_field<const K: usize>(src: &[[f32; K]], idx: &[usize; LANES], at: usize) -> F16 {
    let mut v = [0.0; LANES];
    for (l, &i) in idx.iter().enumerate() {
        v[l] = src[i][at];
    }
    F16(v)
}

#[inline(always)]
fn gather<const K: usize>(src: &[f32], idx: &[usize; LANES]) -> [F16; K] {
    let mut out = [F16([0.0; LANES]); K];
    for (l, &i) in idx.iter().enumerate() {
        let s = &src[K * i..K * i + K];
        for (a, o) in out.iter_mut().enumerate() {
            o.0[l] = s[a];
        }
    }
    out
}

#[inline(always)]
fn gather_in(g: &Gaussians, idx: &[usize; LANES]) -> GaussIn<F16> {
    GaussIn {
        mean: gather::<3>(g.means, idx),
        quat: gather::<4>(g.quats, idx),
        scale: gather::<3>(g.scales, idx),
        logit: gather::<1>(g.opacity_logits, idx)[0],
    }
}

/// The first `num_coeffs(degree)` coefficients of each lane's Gaussian.
#[inline(always)]
fn gather_sh(coeffs: &[f32], stride: usize, degree: usize, idx: &[usize; LANES]) -> ShCoeffs<F16> {
    let mut out = [[F16([0.0; LANES]); 3]; 16];
    for (l, &i) in idx.iter().enumerate() {
        let kk = sh::num_coeffs(degree);
        let src = &coeffs[i * stride * 3..i * stride * 3 + 3 * kk];
        for (k, o) in out.iter_mut().enumerate().take(kk) {
            for c in 0..3 {
                o[c].0[l] = src[3 * k + c];
            }
        }
    }
    out
}

/// Projects Gaussians `i0..i0 + out.len()` (at most [`LANES`]).
#[inline(always)]
fn forward_block(g: &Gaussians, cam: &CamInfo, i0: usize, out: &mut [Projected]) {
    let idx = lane_indices(i0, g.len());
    let x = gather_in(g, &idx);
    let pr = project_lanes(&x, cam);
    let sh_rgb = match g.colors {
        Colors::Sh {
            coeffs,
            num_coeffs,
            degree,
        } => Some(sh_color(
            degree,
            &gather_sh(coeffs, num_coeffs, degree, &idx),
            cam,
            x.mean,
        )),
        Colors::Rgb(_) => None,
    };
    for (l, o) in out.iter_mut().enumerate() {
        *o = Projected {
            depth: pr.depth.0[l],
            ..Default::default()
        };
        if !pr.in_range.0[l] {
            continue;
        }
        o.conic = arr!(a in 3 => pr.conic[a].0[l]);
        o.mean2d = arr!(a in 2 => pr.mean2d[a].0[l]);
        if !pr.visible.0[l] {
            continue;
        }
        o.radii = arr!(a in 2 => pr.radii[a].0[l] as i32);
        o.opacity = pr.opacity.0[l];
        o.rgb = match (sh_rgb, g.colors) {
            (Some(rgb), _) => arr!(a in 3 => rgb[a].0[l]),
            (None, Colors::Rgb(c)) => arr!(a in 3 => c[3 * (i0 + l) + a]),
            (None, Colors::Sh { .. }) => unreachable!("SH colours were computed above"),
        };
    }
}

#[inline(always)]
fn forward_chunk_impl(g: &Gaussians, cam: &CamInfo, i0: usize, out: &mut [Projected]) {
    for (b, o) in out.chunks_mut(LANES).enumerate() {
        forward_block(g, cam, i0 + b * LANES, o);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn forward_chunk_avx512(g: &Gaussians, cam: &CamInfo, i0: usize, out: &mut [Projected]) {
    forward_chunk_impl(g, cam, i0, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn forward_chunk_avx2(g: &Gaussians, cam: &CamInfo, i0: usize, out: &mut [Projected]) {
    forward_chunk_impl(g, cam, i0, out)
}

fn forward_chunk(simd: Simd, g: &Gaussians, cam: &CamInfo, i0: usize, out: &mut [Projected]) {
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `simd_level` checked that the CPU supports these features.
        Simd::Avx512 => return unsafe { forward_chunk_avx512(g, cam, i0, out) },
        // SAFETY: as above.
        Simd::Avx2 => return unsafe { forward_chunk_avx2(g, cam, i0, out) },
        Simd::Portable => {}
    }
    let _ = simd;
    forward_chunk_impl(g, cam, i0, out)
}

/// Projects every Gaussian of `g` into `out` (resized to `g.len()`), in parallel.
pub(crate) fn project_all(simd: Simd, g: &Gaussians, cam: &CamInfo, out: &mut Vec<Projected>) {
    set_len(out, g.len(), Projected::default());
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, o)| forward_chunk(simd, g, cam, c * CHUNK, o));
}

/// One parallel job's share of the gradient buffers, Gaussians `i0..i0 + logit.len()`.
struct GradChunk<'a> {
    i0: usize,
    mean: &'a mut [f32],
    quat: &'a mut [f32],
    scale: &'a mut [f32],
    logit: &'a mut [f32],
    color: &'a mut [f32],
    means2d: &'a mut [[f32; 2]],
}

/// What the backward pass reads besides the Gaussians: the forward's projections (to know
/// which were culled) and the per-Gaussian sums of the tiles' gradients.
#[derive(Clone, Copy)]
struct VjpIn<'a> {
    g: &'a Gaussians<'a>,
    cam: &'a CamInfo,
    proj: &'a [Projected],
    pgs: &'a [GradAcc],
}

/// Backward of Gaussians `out.i0 + b·16 ..` (one block of at most [`LANES`]).
#[inline(always)]
fn backward_block(v: VjpIn, out: &mut GradChunk, b: usize) {
    let g = v.g;
    let i0 = out.i0 + b * LANES;
    let count = (out.logit.len() - b * LANES).min(LANES);
    let idx = lane_indices(i0, g.len());
    let x = gather_in(g, &idx);
    let pg = ProjGrad {
        mean2d: arr!(a in 2 => gather_field(v.pgs, &idx, a)),
        conic: arr!(a in 3 => gather_field(v.pgs, &idx, 2 + a)),
        rgb: arr!(a in 3 => gather_field(v.pgs, &idx, 5 + a)),
        opacity: gather_field(v.pgs, &idx, 8),
    };
    let mut gg = project_vjp_lanes(&x, v.cam, &pg);
    let mut g_sh = [[F16::splat(0.0); 3]; 16];
    let (stride, kk) = match g.colors {
        Colors::Sh {
            coeffs,
            num_coeffs,
            degree,
        } => {
            let c = gather_sh(coeffs, num_coeffs, degree, &idx);
            sh_color_vjp(degree, &c, v.cam, x.mean, pg.rgb, &mut g_sh, &mut gg.mean);
            (num_coeffs * 3, sh::num_coeffs(degree))
        }
        Colors::Rgb(_) => (3, 0),
    };
    for l in 0..count {
        let j = b * LANES + l;
        out.means2d[j] = [pg.mean2d[0].0[l], pg.mean2d[1].0[l]];
        let color = &mut out.color[j * stride..(j + 1) * stride];
        let (mean, quat) = (
            &mut out.mean[3 * j..3 * j + 3],
            &mut out.quat[4 * j..4 * j + 4],
        );
        let scale = &mut out.scale[3 * j..3 * j + 3];
        if v.proj[i0 + l].radii[0] <= 0 {
            for s in [&mut *mean, &mut *quat, &mut *scale, &mut *color] {
                s.fill(0.0);
            }
            out.logit[j] = 0.0;
            continue;
        }
        for (s, lanes) in [
            (mean, &gg.mean[..]),
            (scale, &gg.scale[..]),
            (quat, &gg.quat[..]),
        ] {
            for (d, f) in s.iter_mut().zip(lanes) {
                *d = f.0[l];
            }
        }
        out.logit[j] = gg.logit.0[l];
        if kk == 0 {
            color.copy_from_slice(&arr!(c in 3 => pg.rgb[c].0[l]));
        } else {
            color.fill(0.0);
            for k in 0..kk {
                for c in 0..3 {
                    color[3 * k + c] = g_sh[k][c].0[l];
                }
            }
        }
    }
}

#[inline(always)]
fn backward_chunk_impl(v: VjpIn, out: &mut GradChunk) {
    for b in 0..out.logit.len().div_ceil(LANES) {
        backward_block(v, out, b);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn backward_chunk_avx512(v: VjpIn, out: &mut GradChunk) {
    backward_chunk_impl(v, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn backward_chunk_avx2(v: VjpIn, out: &mut GradChunk) {
    backward_chunk_impl(v, out)
}

fn backward_chunk(simd: Simd, v: VjpIn, out: &mut GradChunk) {
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `simd_level` checked that the CPU supports these features.
        Simd::Avx512 => return unsafe { backward_chunk_avx512(v, out) },
        // SAFETY: as above.
        Simd::Avx2 => return unsafe { backward_chunk_avx2(v, out) },
        Simd::Portable => {}
    }
    let _ = simd;
    backward_chunk_impl(v, out)
}

/// Backward of [`project_all`]: overwrites every gradient in `grads` (already sized for
/// `g`), zero for the Gaussians the forward culled; `means2d` gets the 2D mean's gradient.
pub(crate) fn project_vjp_all(
    simd: Simd,
    g: &Gaussians,
    cam: &CamInfo,
    (proj, pgs): (&[Projected], &[GradAcc]),
    grads: &mut Gradients,
) {
    let cstride = match g.colors {
        Colors::Sh { num_coeffs, .. } => num_coeffs * 3,
        Colors::Rgb(_) => 3,
    };
    if g.is_empty() || cstride == 0 {
        return;
    }
    let v = VjpIn { g, cam, proj, pgs };
    grads
        .means
        .par_chunks_mut(3 * CHUNK)
        .zip(grads.quats.par_chunks_mut(4 * CHUNK))
        .zip(grads.scales.par_chunks_mut(3 * CHUNK))
        .zip(grads.opacity_logits.par_chunks_mut(CHUNK))
        .zip(grads.colors.par_chunks_mut(cstride * CHUNK))
        .zip(grads.means2d.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (((((mean, quat), scale), logit), color), means2d))| {
            let mut out = GradChunk {
                i0: c * CHUNK,
                mean,
                quat,
                scale,
                logit,
                color,
                means2d,
            };
            backward_chunk(simd, v, &mut out);
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::project::{project, project_vjp, GaussGradMut};
    use crate::{Camera, RenderOptions};

    /// Gaussians around and behind a camera at the origin looking down +z: some behind the
    /// near plane, some off-screen, some far to the side (the Jacobian's clamp binds).
    fn scene(n: usize, degree: Option<usize>, seed: u64) -> (Vec<Vec<f32>>, usize) {
        let mut s = seed;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        let means = (0..n)
            .flat_map(|_| {
                let z = 3.0 * rnd() + 2.0;
                [0.9 * rnd() * z.abs(), 0.7 * rnd() * z.abs(), z]
            })
            .collect();
        let quats = (0..4 * n).map(|_| rnd()).collect();
        let scales = (0..3 * n).map(|_| 0.02 + 0.3 * rnd().abs()).collect();
        let logits = (0..n).map(|_| 4.0 * rnd()).collect();
        let k = degree.map_or(1, |d| (d + 1) * (d + 1) + 2);
        let colors = (0..3 * k * n).map(|_| rnd()).collect();
        (vec![means, quats, scales, logits, colors], k)
    }

    fn gaussians(v: &[Vec<f32>], k: usize, degree: Option<usize>) -> Gaussians<'_> {
        Gaussians {
            means: &v[0],
            quats: &v[1],
            scales: &v[2],
            opacity_logits: &v[3],
            colors: match degree {
                Some(degree) => Colors::Sh {
                    coeffs: &v[4],
                    num_coeffs: k,
                    degree,
                },
                None => Colors::Rgb(&v[4]),
            },
        }
    }

    fn camera() -> CamInfo {
        let mut viewmat = [[0.0f32; 4]; 4];
        for (a, row) in viewmat.iter_mut().enumerate() {
            row[a] = 1.0;
        }
        let cam = Camera {
            viewmat,
            fx: 90.0,
            fy: 95.0,
            cx: 41.0,
            cy: 29.5,
            width: 80,
            height: 60,
        };
        CamInfo::new(&cam, &RenderOptions::default())
    }

    fn levels() -> Vec<Simd> {
        [Simd::Portable, Simd::Avx2, Simd::Avx512]
            .into_iter()
            .filter(|&s| s <= simd::cpu_level())
            .collect()
    }

    fn bits<const K: usize>(v: [f32; K]) -> [u32; K] {
        v.map(f32::to_bits)
    }

    #[test]
    fn batched_projection_is_bit_identical_to_the_scalar_reference() {
        let cam = camera();
        for degree in [None, Some(0), Some(1), Some(2), Some(3)] {
            // 1,037 = two parallel chunks and a tail block of 13.
            let (v, k) = scene(1037, degree, 11 + degree.unwrap_or(9) as u64);
            let g = gaussians(&v, k, degree);
            let want: Vec<Projected> = (0..g.len()).map(|i| project(&g, i, &cam)).collect();
            let kinds = |p: &[Projected], r: i32| p.iter().filter(|p| p.radii[0] == r).count();
            let culled = kinds(&want, 0);
            let behind = want.iter().filter(|p| p.depth <= 0.01).count();
            assert!(
                culled > behind + 50 && behind > 50 && culled < 900,
                "{culled} {behind}"
            );
            for simd in levels() {
                let mut got = Vec::new();
                project_all(simd, &g, &cam, &mut got);
                for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                    let same = bits(a.mean2d) == bits(b.mean2d)
                        && a.depth.to_bits() == b.depth.to_bits()
                        && bits(a.conic) == bits(b.conic)
                        && a.radii == b.radii
                        && a.opacity.to_bits() == b.opacity.to_bits()
                        && bits(a.rgb) == bits(b.rgb);
                    assert!(
                        same,
                        "{simd:?}, degree {degree:?}, Gaussian {i}: {a:?} vs {b:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn batched_backward_is_bit_identical_to_the_scalar_reference() {
        let cam = camera();
        for degree in [None, Some(1), Some(3)] {
            let (v, k) = scene(1037, degree, 5);
            let g = gaussians(&v, k, degree);
            let n = g.len();
            let proj: Vec<Projected> = (0..n).map(|i| project(&g, i, &cam)).collect();
            let pgs: Vec<GradAcc> = (0..n)
                .map(|i| std::array::from_fn(|a| ((i * 9 + a) as f32 * 0.731).sin()))
                .collect();
            let stride = v[4].len() / n;
            let mut want = Gradients {
                means: vec![0.0; 3 * n],
                quats: vec![0.0; 4 * n],
                scales: vec![0.0; 3 * n],
                opacity_logits: vec![0.0; n],
                colors: vec![0.0; stride * n],
                means2d: vec![[0.0; 2]; n],
            };
            for i in (0..n).filter(|&i| proj[i].radii[0] > 0) {
                let s = &pgs[i];
                let pg = ProjGrad::from_acc(s);
                let out = GaussGradMut {
                    mean: &mut want.means[3 * i..3 * i + 3],
                    quat: &mut want.quats[4 * i..4 * i + 4],
                    scale: &mut want.scales[3 * i..3 * i + 3],
                    logit: &mut want.opacity_logits[i],
                    color: &mut want.colors[stride * i..stride * (i + 1)],
                };
                project_vjp(&g, i, &cam, &pg, out);
            }
            want.means2d = pgs.iter().map(|s| [s[0], s[1]]).collect();
            for simd in levels() {
                // Start from garbage: every entry must be overwritten.
                let mut got = want.clone();
                for buf in [&mut got.means, &mut got.quats, &mut got.colors] {
                    buf.iter_mut().for_each(|x| *x = f32::NAN);
                }
                got.means2d.iter_mut().for_each(|m| *m = [7.0, 7.0]);
                project_vjp_all(simd, &g, &cam, (&proj, &pgs), &mut got);
                let eq =
                    |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
                let ok = eq(&got.means, &want.means)
                    && eq(&got.quats, &want.quats)
                    && eq(&got.scales, &want.scales)
                    && eq(&got.opacity_logits, &want.opacity_logits)
                    && eq(&got.colors, &want.colors)
                    && got.means2d == want.means2d;
                assert!(ok, "{simd:?}, degree {degree:?}");
            }
        }
    }
}
