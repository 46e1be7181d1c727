//! Backward rasterization of one tile (gsplat `rasterize_to_pixels_bwd`, classic): back to
//! front from each pixel's last composited Gaussian, recovering `T_i = T_{i+1}/(1−α_i)`,
//! with `buf` the colour composited behind the current Gaussian:
//!
//! `dL/dα = Σ_c (c_c·T − buf_c/(1−α))·v_c + T_final/(1−α)·(v_A − Σ_c bg_c·v_c)`,
//! `dL/dσ = −o·e^{−σ}·dL/dα` and `dL/do = e^{−σ}·dL/dα` only where `o·e^{−σ} ≤ 0.999`
//! (no gradient through the clamp), `dL/dc = T·α·v`.
//!
//! Per-Gaussian sums over the tile's pixels are accumulated lane-wise, reduced once per
//! Gaussian and handed to `emit(depth rank, sums)`, which stores them in the Gaussian's
//! slot for this tile (`grad_slots`: a fixed-order sum afterwards keeps gradients
//! deterministic).

use crate::fastexp;
use crate::forward::{Splat, TileList, ALPHA_MAX, ALPHA_MIN, TP, TS};
use crate::raster::Simd;

/// Gradient sums of one Gaussian: mean2d x, y; conic a, b, c; rgb; opacity.
pub(crate) type GradAcc = [f32; 9];

/// One tile's inputs to the backward pass (row-major 16×16 pixel arrays).
pub(crate) struct TileGradIn<'a> {
    pub x0: u32,
    pub y0: u32,
    pub tfin: &'a [f32],
    pub last: &'a [u32],
    /// dL/dimage, planar `3·256`.
    pub v_color: &'a [f32; 3 * TP],
    /// dL/dalpha minus the background term, times T_final (see the module docs).
    pub v_alpha_eff: &'a [f32; TP],
}

pub(crate) fn backward_tile(
    simd: Simd,
    tin: &TileGradIn,
    list: TileList,
    splats: &[Splat],
    emit: &mut impl FnMut(usize, &GradAcc),
) {
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `simd_level` checked that the CPU supports these features.
        Simd::Avx512 => unsafe { return backward_avx512(tin, list, splats, emit) },
        // SAFETY: as above.
        Simd::Avx2 => unsafe { return backward_avx2(tin, list, splats, emit) },
        Simd::Portable => {}
    }
    let _ = simd;
    backward_impl(tin, list, splats, emit)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn backward_avx2(
    tin: &TileGradIn,
    list: TileList,
    splats: &[Splat],
    emit: &mut impl FnMut(usize, &GradAcc),
) {
    backward_impl(tin, list, splats, emit)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn backward_avx512(
    tin: &TileGradIn,
    list: TileList,
    splats: &[Splat],
    emit: &mut impl FnMut(usize, &GradAcc),
) {
    backward_impl(tin, list, splats, emit)
}

struct BackState {
    t: [f32; TP],
    buf: [[f32; TP]; 3],
}

#[inline(always)]
fn backward_impl(
    tin: &TileGradIn,
    list: TileList,
    splats: &[Splat],
    emit: &mut impl FnMut(usize, &GradAcc),
) {
    let mut row_last = [0u32; TS];
    for (r, rl) in row_last.iter_mut().enumerate() {
        *rl = tin.last[r * TS..(r + 1) * TS]
            .iter()
            .copied()
            .max()
            .unwrap_or(0);
    }
    let max_last = row_last.iter().copied().max().unwrap_or(0) as usize;
    let ranks = list.ranks;
    let mut st = BackState {
        t: [0.0; TP],
        buf: [[0.0; TP]; 3],
    };
    st.t.copy_from_slice(&tin.tfin[..TP]);
    let px: [f32; TS] = std::array::from_fn(|l| tin.x0 as f32 + l as f32 + 0.5);
    for pos in (0..max_last.min(ranks.len())).rev() {
        let rank = ranks[pos] as usize;
        let sp = &splats[rank];
        let mut sums = [[0.0f32; TS]; 9];
        let mut touched = false;
        // The forward's rows, in increasing order.
        let mut todo = list.rows(pos, sp, tin.x0, tin.y0);
        while todo != 0 {
            let r = todo.trailing_zeros() as usize;
            todo &= todo - 1;
            if pos as u32 >= row_last[r] {
                continue;
            }
            let dy = sp.row_dy(tin.y0, r);
            touched = true;
            backward_row(sp, &px, dy, pos as u32 + 1, r, tin, &mut st, &mut sums);
        }
        if touched {
            let total: GradAcc = std::array::from_fn(|k| sums[k].iter().sum::<f32>());
            emit(rank, &total);
        }
    }
}

/// Backward of one Gaussian over one row of 16 pixels, accumulating lane-wise `sums`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn backward_row(
    sp: &Splat,
    px: &[f32; TS],
    dy: f32,
    pos1: u32,
    r: usize,
    tin: &TileGradIn,
    st: &mut BackState,
    sums: &mut [[f32; TS]; 9],
) {
    let o = r * TS;
    let last: &[u32; TS] = tin.last[o..o + TS].try_into().expect("16");
    let vaeff: &[f32; TS] = tin.v_alpha_eff[o..o + TS].try_into().expect("16");
    let vc: [&[f32; TS]; 3] = std::array::from_fn(|c| {
        tin.v_color[c * TP + o..c * TP + o + TS]
            .try_into()
            .expect("16")
    });
    let t: &mut [f32; TS] = (&mut st.t[o..o + TS]).try_into().expect("16");
    let [b0, b1, b2] = &mut st.buf;
    let buf: [&mut [f32; TS]; 3] = [
        (&mut b0[o..o + TS]).try_into().expect("16"),
        (&mut b1[o..o + TS]).try_into().expect("16"),
        (&mut b2[o..o + TS]).try_into().expect("16"),
    ];
    let [buf_r, buf_g, buf_b] = buf;
    let [s_mx, s_my, s_a, s_b, s_c, s_r, s_g, s_bl, s_o] = sums;
    for l in 0..TS {
        let dx = sp.mx - px[l];
        let sigma = 0.5 * (sp.a * dx * dx + sp.c * dy * dy) + sp.b * dx * dy;
        let vis = fastexp::exp(-sigma);
        let araw = sp.o * vis;
        let alpha = araw.min(ALPHA_MAX);
        let ok = (sigma >= 0.0) & (alpha >= ALPHA_MIN) & (pos1 <= last[l]);
        let ra = 1.0 / (1.0 - alpha);
        let tn = t[l] * ra;
        let fac = alpha * tn;
        let (vr, vg, vb) = (vc[0][l], vc[1][l], vc[2][l]);
        let v_alpha = (sp.rgb[0] * tn - buf_r[l] * ra) * vr
            + (sp.rgb[1] * tn - buf_g[l] * ra) * vg
            + (sp.rgb[2] * tn - buf_b[l] * ra) * vb
            + vaeff[l] * ra;
        let grad_ok = ok & (araw <= ALPHA_MAX);
        let v_sigma = if grad_ok { -araw * v_alpha } else { 0.0 };
        let fac = if ok { fac } else { 0.0 };
        s_r[l] += fac * vr;
        s_g[l] += fac * vg;
        s_bl[l] += fac * vb;
        s_o[l] += if grad_ok { vis * v_alpha } else { 0.0 };
        s_a[l] += 0.5 * v_sigma * dx * dx;
        s_b[l] += v_sigma * dx * dy;
        s_c[l] += 0.5 * v_sigma * dy * dy;
        s_mx[l] += v_sigma * (sp.a * dx + sp.b * dy);
        s_my[l] += v_sigma * (sp.b * dx + sp.c * dy);
        buf_r[l] += sp.rgb[0] * fac;
        buf_g[l] += sp.rgb[1] * fac;
        buf_b[l] += sp.rgb[2] * fac;
        t[l] = if ok { tn } else { t[l] };
    }
}
