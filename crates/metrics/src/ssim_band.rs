//! The fused SSIM kernels: per band of image rows, the horizontal and vertical 11-tap passes
//! run through an 11-row ring buffer, so the filtered planes of a band (≈ 0.4 MB at 480 px)
//! stay in L2 instead of round-tripping full-image planes through memory; the backward seeds
//! are filtered horizontally as soon as each row is done. Only those filtered seeds (3
//! planes) cross bands, since the gradient's vertical pass needs rows of neighbouring bands.
//!
//! Filters are written as FIRs over fixed chunks of `LANES` outputs with every tap added into
//! `LANES` independent accumulators, which LLVM turns into packed SIMD; each kernel entry
//! point is compiled twice, for the baseline target and with AVX2 enabled (no FMA: results must not depend on the CPU), and picked
//! at run time (`simd::level`, capped by `SEMDYNREG_SIMD`), so no `-C target-cpu` is needed.

use super::{map_terms, BWD, CH, FWD, RADIUS, TAPS};

/// Outputs per FIR chunk: 4 AVX2 registers of accumulators (independent add chains).
const LANES: usize = 32;
/// Zero padding on each side of a padded row: 5 px of 3 interleaved channels.
pub(super) const PAD: usize = RADIUS * CH;

/// Image-level inputs and constants shared by all bands.
pub(super) struct Frame<'a> {
    pub a: &'a [f32],
    pub b: &'a [f32],
    pub height: usize,
    /// Floats per image row (`width · 3`).
    pub row: usize,
    pub win: [f32; TAPS],
    /// Rows and columns (floats in a row) whose map values are averaged.
    pub rows: std::ops::Range<usize>,
    pub cols: std::ops::Range<usize>,
    /// 1 / number of averaged values (scales the seeds).
    pub scale: f32,
}

/// Floats of per-band scratch: ring of filtered rows, padded source rows, vertical sums, map.
pub(super) fn scratch_len(row: usize) -> usize {
    TAPS * FWD * row + FWD * (row + 2 * PAD) + FWD * row + row
}

/// `dst[n] = Σ_k taps[k].0 · taps[k].1[n]` over whole chunks of `LANES`, then the tail.
#[inline(always)]
fn fir(dst: &mut [f32], taps: &[(f32, &[f32])]) {
    let n = dst.len();
    let whole = n - n % LANES;
    for c in (0..whole).step_by(LANES) {
        let mut acc = [0.0f32; LANES];
        for &(w, s) in taps {
            let s: &[f32; LANES] = s[c..c + LANES].try_into().expect("chunk");
            for l in 0..LANES {
                acc[l] += w * s[l];
            }
        }
        dst[c..c + LANES].copy_from_slice(&acc);
    }
    for (j, d) in dst.iter_mut().enumerate().skip(whole) {
        *d = taps.iter().map(|&(w, s)| w * s[j]).sum();
    }
}

/// Horizontal pass of one padded row (`row + 2·PAD` floats) into `dst` (`row` floats).
#[inline(always)]
fn hfilter(dst: &mut [f32], padded: &[f32], win: &[f32; TAPS]) {
    let row = dst.len();
    let taps: [(f32, &[f32]); TAPS] = std::array::from_fn(|k| (win[k], &padded[CH * k..][..row]));
    fir(dst, &taps);
}

/// Forward SSIM over output rows `r0..r0 + nrows`: returns the sum of the map over the
/// averaged region; with `hseeds` (`nrows × BWD × row`), also writes the horizontally
/// filtered seeds ∂S/∂(μa, Eaa, Eab) of those rows.
#[inline(always)]
fn band_forward_body(
    f: &Frame,
    r0: usize,
    nrows: usize,
    scratch: &mut [f32],
    mut hseeds: Option<&mut [f32]>,
) -> f64 {
    let (row, rp) = (f.row, f.row + 2 * PAD);
    let (ring, rest) = scratch.split_at_mut(TAPS * FWD * row);
    let (pad, rest) = rest.split_at_mut(FWD * rp);
    let (vsum, maps) = rest.split_at_mut(FWD * row);
    // Pads stay zero for the whole band: only the interiors are written below.
    pad.fill(0.0);
    let r1 = r0 + nrows;
    for j in r0.saturating_sub(RADIUS)..(r0 + RADIUS).min(f.height) {
        hrow(f, j, pad, ring);
    }
    let mut total = 0.0f64;
    for i in r0..r1 {
        if i + RADIUS < f.height {
            hrow(f, i + RADIUS, pad, ring);
        }
        vrow(f, i, ring, vsum);
        let seeds = hseeds.as_deref_mut().map(|h| {
            let at = (i - r0) * BWD * row;
            &mut h[at..at + BWD * row]
        });
        map_row(f, vsum, maps, pad, seeds);
        if f.rows.contains(&i) {
            total += super::lane_sum(&maps[f.cols.clone()]);
        }
    }
    total
}

/// Horizontal pass of image row `j` for the five quantities into ring slot `j mod 11`.
#[inline(always)]
fn hrow(f: &Frame, j: usize, pad: &mut [f32], ring: &mut [f32]) {
    let (row, rp) = (f.row, f.row + 2 * PAD);
    let (sa, sb) = (&f.a[j * row..][..row], &f.b[j * row..][..row]);
    {
        let mut planes = pad.chunks_exact_mut(rp).map(|p| &mut p[PAD..PAD + row]);
        let (pa, pb) = (planes.next().unwrap(), planes.next().unwrap());
        let (paa, pbb, pab) = (
            planes.next().unwrap(),
            planes.next().unwrap(),
            planes.next().unwrap(),
        );
        for n in 0..row {
            let (x, y) = (sa[n], sb[n]);
            pa[n] = x;
            pb[n] = y;
            paa[n] = x * x;
            pbb[n] = y * y;
            pab[n] = x * y;
        }
    }
    let slot = &mut ring[(j % TAPS) * FWD * row..][..FWD * row];
    for (dst, src) in slot.chunks_exact_mut(row).zip(pad.chunks_exact(rp)) {
        hfilter(dst, src, &f.win);
    }
}

/// Vertical pass at image row `i` from the ring: the five window sums into `vsum`.
#[inline(always)]
fn vrow(f: &Frame, i: usize, ring: &[f32], vsum: &mut [f32]) {
    let row = f.row;
    let (lo, hi) = (i.saturating_sub(RADIUS), (i + RADIUS + 1).min(f.height));
    for (p, dst) in vsum.chunks_exact_mut(row).enumerate() {
        let mut taps = [(0.0f32, &ring[..0]); TAPS];
        for (t, j) in (lo..hi).enumerate() {
            let at = ((j % TAPS) * FWD + p) * row;
            taps[t] = (f.win[j + RADIUS - i], &ring[at..at + row]);
        }
        fir(dst, &taps[..hi - lo]);
    }
}

/// SSIM map of one row from its window sums; with `seeds`, also its seeds, filtered
/// horizontally into `seeds` (the padded rows in `pad` are free by now and hold them).
#[inline(always)]
fn map_row(f: &Frame, vsum: &[f32], maps: &mut [f32], pad: &mut [f32], seeds: Option<&mut [f32]>) {
    let row = f.row;
    let (ma, rest) = vsum.split_at(row);
    let (mb, rest) = rest.split_at(row);
    let (eaa, rest) = rest.split_at(row);
    let (ebb, eab) = rest.split_at(row);
    let Some(out) = seeds else {
        for n in 0..row {
            maps[n] = map_terms(ma[n], mb[n], eaa[n], ebb[n], eab[n]).0;
        }
        return;
    };
    let rp = row + 2 * PAD;
    let (gm, rest) = pad.split_at_mut(rp);
    let (gaa, rest) = rest.split_at_mut(rp);
    let gab = &mut rest[..rp];
    let (gm, gaa, gab) = (
        &mut gm[PAD..PAD + row],
        &mut gaa[PAD..PAD + row],
        &mut gab[PAD..PAD + row],
    );
    let scale = f.scale;
    for n in 0..row {
        let (mua, mub) = (ma[n], mb[n]);
        let (map, a1, a2, ib1, ib2) = map_terms(mua, mub, eaa[n], ebb[n], eab[n]);
        maps[n] = map;
        // ∂map/∂μa, ∂map/∂Eaa, ∂map/∂Eab (see the module comment of `ssim`).
        let inv = ib1 * ib2;
        gm[n] = scale * (2.0 * mub * (a2 - a1) * inv + 2.0 * mua * map * (ib2 - ib1));
        gaa[n] = scale * (-map * ib2);
        gab[n] = scale * (2.0 * a1 * inv);
    }
    for (dst, src) in out.chunks_exact_mut(row).zip(pad.chunks_exact(rp)) {
        hfilter(dst, src, &f.win);
    }
}

/// Gradient row `i`: vertical pass of the filtered seeds, ∂S/∂a = F(∂S/∂μa) + 2a·F(∂S/∂Eaa)
/// + b·F(∂S/∂Eab) (the module comment of `ssim`); `scratch` holds `BWD × row` floats.
#[inline(always)]
fn grad_row_body(f: &Frame, hseeds: &[f32], i: usize, g: &mut [f32], scratch: &mut [f32]) {
    let row = f.row;
    let (lo, hi) = (i.saturating_sub(RADIUS), (i + RADIUS + 1).min(f.height));
    for (p, dst) in scratch.chunks_exact_mut(row).enumerate() {
        let mut taps = [(0.0f32, &hseeds[..0]); TAPS];
        for (t, j) in (lo..hi).enumerate() {
            let at = (j * BWD + p) * row;
            taps[t] = (f.win[j + RADIUS - i], &hseeds[at..at + row]);
        }
        fir(dst, &taps[..hi - lo]);
    }
    let (fm, rest) = scratch.split_at(row);
    let (faa, fab) = rest.split_at(row);
    let (ar, br) = (&f.a[i * row..][..row], &f.b[i * row..][..row]);
    for n in 0..row {
        g[n] = fm[n] + 2.0 * ar[n] * faa[n] + br[n] * fab[n];
    }
}

/// Forward over one band (see [`band_forward_body`]), on the best instruction set available.
pub(super) fn band_forward(
    f: &Frame,
    r0: usize,
    nrows: usize,
    scratch: &mut [f32],
    hseeds: Option<&mut [f32]>,
) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if simd::level() >= simd::Simd::Avx2 {
        // SAFETY: `simd::level` only returns levels this CPU supports.
        return unsafe { band_forward_avx2(f, r0, nrows, scratch, hseeds) };
    }
    band_forward_body(f, r0, nrows, scratch, hseeds)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn band_forward_avx2(
    f: &Frame,
    r0: usize,
    nrows: usize,
    scratch: &mut [f32],
    hseeds: Option<&mut [f32]>,
) -> f64 {
    band_forward_body(f, r0, nrows, scratch, hseeds)
}

/// Gradient rows `r0..` (`g` holds whole rows), on the best instruction set available.
pub(super) fn band_grad(f: &Frame, hseeds: &[f32], r0: usize, g: &mut [f32], scratch: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if simd::level() >= simd::Simd::Avx2 {
        // SAFETY: `simd::level` only returns levels this CPU supports.
        return unsafe { band_grad_avx2(f, hseeds, r0, g, scratch) };
    }
    band_grad_body(f, hseeds, r0, g, scratch)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn band_grad_avx2(f: &Frame, hseeds: &[f32], r0: usize, g: &mut [f32], scratch: &mut [f32]) {
    band_grad_body(f, hseeds, r0, g, scratch)
}

#[inline(always)]
fn band_grad_body(f: &Frame, hseeds: &[f32], r0: usize, g: &mut [f32], scratch: &mut [f32]) {
    let scratch = &mut scratch[..BWD * f.row];
    for (t, gr) in g.chunks_exact_mut(f.row).enumerate() {
        grad_row_body(f, hseeds, r0 + t, gr, scratch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn portable_and_dispatched_kernels_agree_bitwise() {
        // No FMA contraction and the same summation order: the SIMD build must reproduce the
        // baseline build exactly (training results must not depend on the CPU).
        let (h, row) = (23, 37 * CH);
        let a: Vec<f32> = (0..h * row)
            .map(|i| (i as f32 * 0.37).sin().abs())
            .collect();
        let b: Vec<f32> = (0..h * row)
            .map(|i| (i as f32 * 0.53).cos().abs())
            .collect();
        let f = Frame {
            a: &a,
            b: &b,
            height: h,
            row,
            win: super::super::window(),
            rows: 0..h,
            cols: 0..row,
            scale: 1.0 / (h * row) as f32,
        };
        let run = |portable: bool| {
            let mut scratch = vec![0.0f32; scratch_len(row)];
            let mut hs = vec![0.0f32; h * BWD * row];
            let mut g = vec![0.0f32; h * row];
            let s = if portable {
                band_forward_body(&f, 0, h, &mut scratch, Some(&mut hs))
            } else {
                band_forward(&f, 0, h, &mut scratch, Some(&mut hs))
            };
            if portable {
                band_grad_body(&f, &hs, 0, &mut g, &mut scratch);
            } else {
                band_grad(&f, &hs, 0, &mut g, &mut scratch);
            }
            (s, g)
        };
        assert_eq!(run(true), run(false));
    }
}
