//! SSIM with its gradient, as 3DGS computes it (`utils/loss_utils.py::ssim`): an 11×11
//! Gaussian window (σ = 1.5), C1 = 0.01², C2 = 0.03², zero padding ("same" convolution,
//! padding 5), and the mean of the SSIM map over all pixels and channels. The scikit-image
//! variant (`structural_similarity(..., gaussian_weights=True, sigma=1.5,
//! use_sample_covariance=False, data_range=1, channel_axis=-1)`) is the same map averaged over
//! the interior only (5 px cropped on each side); there the boundary mode does not matter,
//! since no interior window reaches past the border.
//!
//! Images are RGB, row-major, channels interleaved (HWC), values in [0, 1]. The 2D window is
//! the outer product of a normalized 1D Gaussian (as in 3DGS's `create_window`), so every
//! filtering is done as a horizontal then a vertical 11-tap pass. In the interleaved layout a
//! horizontal tap is a shift by 3 floats, so the passes run on whole rows with no
//! de-interleaving, and zero padding is a clipped index range.
//!
//! Gradient (derived by hand, checked against finite differences in the tests): with
//! μa = F(a), Eaa = F(a²), Eab = F(ab) and S = mean(map), the map depends on `a` through those
//! three filtered quantities, and F is self-adjoint (symmetric kernel, zero padding), so
//! ∂S/∂a = F(∂S/∂μa) + 2a·F(∂S/∂Eaa) + b·F(∂S/∂Eab).

use rayon::prelude::*;

/// Gaussian standard deviation of the window (3DGS, Wang et al. 2004).
pub const SIGMA: f64 = 1.5;
/// Window radius: 11×11 window.
pub const RADIUS: usize = 5;
const TAPS: usize = 2 * RADIUS + 1;
const C1: f32 = 0.01 * 0.01;
const C2: f32 = 0.03 * 0.03;
/// Interleaved channels per pixel.
const CH: usize = 3;
/// Filtered planes of the forward pass per image row: a, b, a², b², ab.
const FWD: usize = 5;
/// Planes of the backward pass per image row: ∂S/∂μa, ∂S/∂Eaa, ∂S/∂Eab.
const BWD: usize = 3;

/// Which average of the SSIM map is reported.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SsimVariant {
    /// 3DGS / Deformable-3DGS: mean over all pixels and channels (zero padding). Our tables use this.
    #[default]
    Gs3d,
    /// scikit-image: mean over the interior, 5 px cropped on each side.
    Skimage,
}

/// Bad input to the SSIM functions that return `Result`.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SsimError {
    /// A buffer does not hold `width × height × 3` floats.
    #[error("SSIM: image buffer holds {got} floats, expected {width}x{height}x3 = {expected}")]
    BadLength {
        got: usize,
        expected: usize,
        width: usize,
        height: usize,
    },
    /// The scikit-image variant needs at least 11×11 pixels (it raises for smaller images).
    #[error(
        "SSIM (scikit-image variant): image {width}x{height} is smaller than the 11x11 window"
    )]
    TooSmall { width: usize, height: usize },
}

/// The normalized 1D Gaussian of 3DGS's `gaussian(window_size, sigma)`, computed in f64.
fn window() -> [f32; TAPS] {
    let raw: Vec<f64> = (0..TAPS)
        .map(|x| {
            let d = x as f64 - RADIUS as f64;
            (-(d * d) / (2.0 * SIGMA * SIGMA)).exp()
        })
        .collect();
    let sum: f64 = raw.iter().sum();
    std::array::from_fn(|k| (raw[k] / sum) as f32)
}

/// Reusable buffers for SSIM and its gradient: no allocation per call once sized.
/// Training calls [`SsimWorkspace::ssim_with_grad`] every iteration on same-size images.
#[derive(Default)]
pub struct SsimWorkspace {
    width: usize,
    height: usize,
    /// Horizontally filtered a, b, a², b², ab; FWD planes per image row.
    hfwd: Vec<f32>,
    /// Backward seeds ∂S/∂(μa, Eaa, Eab); BWD planes per image row.
    seeds: Vec<f32>,
    /// Horizontally filtered seeds; BWD planes per image row.
    hseeds: Vec<f32>,
}

impl SsimWorkspace {
    /// An empty workspace; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    fn resize(&mut self, width: usize, height: usize, grad: bool) {
        self.width = width;
        self.height = height;
        let plane = width * CH * height;
        self.hfwd.resize(FWD * plane, 0.0);
        if grad {
            self.seeds.resize(BWD * plane, 0.0);
            self.hseeds.resize(BWD * plane, 0.0);
        }
    }

    /// 3DGS SSIM of `a` against `b`.
    ///
    /// # Panics
    /// If a buffer does not hold `width × height × 3` floats (use [`Self::ssim_variant`] for a
    /// checked call).
    pub fn ssim(&mut self, a: &[f32], b: &[f32], width: usize, height: usize) -> f32 {
        check_len(a, b, width, height).unwrap_or_else(|e| panic!("{e}"));
        self.forward(a, b, width, height, SsimVariant::Gs3d, false)
    }

    /// SSIM with the chosen averaging, with input checks.
    pub fn ssim_variant(
        &mut self,
        a: &[f32],
        b: &[f32],
        width: usize,
        height: usize,
        variant: SsimVariant,
    ) -> Result<f32, SsimError> {
        check_len(a, b, width, height)?;
        if variant == SsimVariant::Skimage && (width < TAPS || height < TAPS) {
            return Err(SsimError::TooSmall { width, height });
        }
        Ok(self.forward(a, b, width, height, variant, false))
    }

    /// 3DGS SSIM of `a` against `b`, writing ∂SSIM/∂a into `grad_a` (overwritten, same
    /// layout as `a`). Training's loss term 0.2·(1 − SSIM) has gradient −0.2·`grad_a`.
    ///
    /// # Panics
    /// If a buffer does not hold `width × height × 3` floats.
    pub fn ssim_with_grad(
        &mut self,
        a: &[f32],
        b: &[f32],
        width: usize,
        height: usize,
        grad_a: &mut [f32],
    ) -> f32 {
        check_len(a, b, width, height).unwrap_or_else(|e| panic!("{e}"));
        check_len(grad_a, b, width, height).unwrap_or_else(|e| panic!("{e} (grad_a)"));
        let s = self.forward(a, b, width, height, SsimVariant::Gs3d, true);
        self.backward(a, b, grad_a);
        s
    }

    /// Fills `hfwd` and (if `grad`) `seeds`; returns the mean of the map.
    fn forward(
        &mut self,
        a: &[f32],
        b: &[f32],
        width: usize,
        height: usize,
        variant: SsimVariant,
        grad: bool,
    ) -> f32 {
        self.resize(width, height, grad);
        let row = width * CH;
        if row == 0 || height == 0 {
            return f32::NAN;
        }
        let win = window();
        self.hfwd
            .par_chunks_mut(FWD * row)
            .zip(a.par_chunks(row).zip(b.par_chunks(row)))
            .for_each(|(out, (ar, br))| hpass_forward(ar, br, out, &win));

        let (rows, cols) = match variant {
            SsimVariant::Gs3d => (0..height, 0..row),
            SsimVariant::Skimage => (RADIUS..height - RADIUS, RADIUS * CH..row - RADIUS * CH),
        };
        let count = (rows.len() * cols.len()) as f64;
        let scale = (1.0 / count) as f32;
        let hfwd = &self.hfwd;
        let map_row = |i: usize, scratch: &mut Vec<f32>, seeds: Option<&mut [f32]>| {
            vertical_map(
                hfwd,
                i,
                height,
                row,
                &win,
                scratch,
                cols.clone(),
                seeds,
                scale,
            )
        };
        let total: f64 = if grad {
            self.seeds
                .par_chunks_mut(BWD * row)
                .enumerate()
                .map_init(Vec::new, |scr, (i, seeds)| map_row(i, scr, Some(seeds)))
                .sum()
        } else {
            rows.into_par_iter()
                .map_init(Vec::new, |scr, i| map_row(i, scr, None))
                .sum()
        };
        (total / count) as f32
    }

    /// ∂S/∂a from the seeds written by `forward`.
    fn backward(&mut self, a: &[f32], b: &[f32], grad_a: &mut [f32]) {
        let row = self.width * CH;
        let height = self.height;
        let win = window();
        self.hseeds
            .par_chunks_mut(BWD * row)
            .zip(self.seeds.par_chunks(BWD * row))
            .for_each(|(out, src)| {
                for q in 0..BWD {
                    let (s, o) = (
                        &src[q * row..(q + 1) * row],
                        &mut out[q * row..(q + 1) * row],
                    );
                    hpass(s, o, &win);
                }
            });
        let hseeds = &self.hseeds;
        grad_a
            .par_chunks_mut(row)
            .zip(a.par_chunks(row).zip(b.par_chunks(row)))
            .enumerate()
            .for_each_init(Vec::new, |scratch, (i, (g, (ar, br)))| {
                scratch.resize(BWD * row, 0.0);
                vertical_sum(hseeds, BWD, i, height, row, &win, scratch);
                let (fm, rest) = scratch.split_at(row);
                let (faa, fab) = rest.split_at(row);
                for n in 0..row {
                    g[n] = fm[n] + 2.0 * ar[n] * faa[n] + br[n] * fab[n];
                }
            });
    }
}

fn check_len(a: &[f32], b: &[f32], width: usize, height: usize) -> Result<(), SsimError> {
    let expected = width * height * CH;
    for got in [a.len(), b.len()] {
        if got != expected {
            return Err(SsimError::BadLength {
                got,
                expected,
                width,
                height,
            });
        }
    }
    Ok(())
}

/// Clipped ranges for tap `k` on a row of `len` floats, with `stride` floats per tap step:
/// destination `n` reads source `n + (k − RADIUS)·stride` when that lies in the row (zero
/// padding outside). Returns (destination start, source start, count).
fn tap_range(k: usize, len: usize, stride: usize) -> (usize, usize, usize) {
    let off = (k as isize - RADIUS as isize) * stride as isize;
    let lo = (-off).max(0);
    let hi = len as isize - off.max(0);
    if hi <= lo {
        return (0, 0, 0);
    }
    (lo as usize, (lo + off) as usize, (hi - lo) as usize)
}

/// One row: horizontal filtering of a, b, a², b², ab into the FWD planes of `out`.
fn hpass_forward(a: &[f32], b: &[f32], out: &mut [f32], win: &[f32; TAPS]) {
    let row = a.len();
    out.fill(0.0);
    let (pa, rest) = out.split_at_mut(row);
    let (pb, rest) = rest.split_at_mut(row);
    let (paa, rest) = rest.split_at_mut(row);
    let (pbb, pab) = rest.split_at_mut(row);
    for (k, &wk) in win.iter().enumerate() {
        let (lo, src, n) = tap_range(k, row, CH);
        let hi = lo + n;
        let (sa, sb) = (&a[src..src + n], &b[src..src + n]);
        let (da, db) = (&mut pa[lo..hi], &mut pb[lo..hi]);
        let (daa, dbb, dab) = (&mut paa[lo..hi], &mut pbb[lo..hi], &mut pab[lo..hi]);
        for j in 0..n {
            let (x, y) = (sa[j], sb[j]);
            da[j] += wk * x;
            db[j] += wk * y;
            daa[j] += wk * x * x;
            dbb[j] += wk * y * y;
            dab[j] += wk * x * y;
        }
    }
}

/// One plane of one row: horizontal filtering of `src` into `out`.
fn hpass(src: &[f32], out: &mut [f32], win: &[f32; TAPS]) {
    let row = src.len();
    out.fill(0.0);
    for (k, &wk) in win.iter().enumerate() {
        let (lo, s0, n) = tap_range(k, row, CH);
        let s = &src[s0..s0 + n];
        for (d, &x) in out[lo..lo + n].iter_mut().zip(s) {
            *d += wk * x;
        }
    }
}

/// Vertical filtering at image row `i` of all `planes` planes of `buf` (row-major, `planes`
/// planes of `row` floats per image row) into `out` (`planes × row` floats).
fn vertical_sum(
    buf: &[f32],
    planes: usize,
    i: usize,
    height: usize,
    row: usize,
    win: &[f32; TAPS],
    out: &mut [f32],
) {
    out.fill(0.0);
    for (k, &wk) in win.iter().enumerate() {
        let src_row = i as isize + k as isize - RADIUS as isize;
        if src_row < 0 || src_row >= height as isize {
            continue;
        }
        let base = src_row as usize * planes * row;
        let src = &buf[base..base + planes * row];
        for (d, &x) in out.iter_mut().zip(src) {
            *d += wk * x;
        }
    }
}

/// SSIM map at image row `i` (vertical pass over `hfwd`), summed over `cols`; when `seeds` is
/// given, also writes ∂S/∂(μa, Eaa, Eab) (`scale` = 1 / number of averaged values).
#[allow(clippy::too_many_arguments)]
fn vertical_map(
    hfwd: &[f32],
    i: usize,
    height: usize,
    row: usize,
    win: &[f32; TAPS],
    scratch: &mut Vec<f32>,
    cols: std::ops::Range<usize>,
    seeds: Option<&mut [f32]>,
    scale: f32,
) -> f64 {
    scratch.resize((FWD + 1) * row, 0.0);
    let (sums, maps) = scratch.split_at_mut(FWD * row);
    vertical_sum(hfwd, FWD, i, height, row, win, sums);
    let (ma, rest) = sums.split_at(row);
    let (mb, rest) = rest.split_at(row);
    let (eaa, rest) = rest.split_at(row);
    let (ebb, eab) = rest.split_at(row);
    // Branch-free loops over whole rows so that they vectorize; the map is summed afterwards.
    match seeds {
        None => {
            for n in 0..row {
                maps[n] = map_terms(ma[n], mb[n], eaa[n], ebb[n], eab[n]).0;
            }
        }
        Some(s) => {
            let (gm, rest) = s.split_at_mut(row);
            let (gaa, gab) = rest.split_at_mut(row);
            for n in 0..row {
                let (mua, mub) = (ma[n], mb[n]);
                let (map, a1, a2, ib1, ib2) = map_terms(mua, mub, eaa[n], ebb[n], eab[n]);
                maps[n] = map;
                // ∂map/∂μa, ∂map/∂Eaa, ∂map/∂Eab (see the module comment).
                let inv = ib1 * ib2;
                gm[n] = scale * (2.0 * mub * (a2 - a1) * inv + 2.0 * mua * map * (ib2 - ib1));
                gaa[n] = scale * (-map * ib2);
                gab[n] = scale * (2.0 * a1 * inv);
            }
        }
    }
    lane_sum(&maps[cols])
}

/// SSIM map value and its factors: (map, A1, A2, 1/B1, 1/B2) with A1 = 2μaμb + C1,
/// A2 = 2σab + C2, B1 = μa² + μb² + C1, B2 = σa² + σb² + C2.
#[inline(always)]
fn map_terms(mua: f32, mub: f32, eaa: f32, ebb: f32, eab: f32) -> (f32, f32, f32, f32, f32) {
    let a1 = 2.0 * mua * mub + C1;
    let a2 = 2.0 * (eab - mua * mub) + C2;
    let ib1 = 1.0 / (mua * mua + mub * mub + C1);
    let ib2 = 1.0 / ((eaa - mua * mua) + (ebb - mub * mub) + C2);
    (a1 * a2 * ib1 * ib2, a1, a2, ib1, ib2)
}

/// Sum in 8 f32 lanes (vectorizes; one row is ≤ a few thousand values), finished in f64.
fn lane_sum(v: &[f32]) -> f64 {
    let mut lanes = [0.0f32; 8];
    let chunks = v.chunks_exact(8);
    let tail: f64 = chunks.remainder().iter().map(|&x| x as f64).sum();
    for c in chunks {
        for (l, &x) in lanes.iter_mut().zip(c) {
            *l += x;
        }
    }
    lanes.iter().map(|&x| x as f64).sum::<f64>() + tail
}

/// 3DGS SSIM (see [`SsimWorkspace::ssim`]); allocates a workspace per call.
pub fn ssim(a: &[f32], b: &[f32], width: usize, height: usize) -> f32 {
    SsimWorkspace::new().ssim(a, b, width, height)
}

/// 3DGS SSIM and ∂SSIM/∂a (see [`SsimWorkspace::ssim_with_grad`]); allocates per call, so
/// training should keep a [`SsimWorkspace`].
pub fn ssim_with_grad(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    grad_a: &mut [f32],
) -> f32 {
    SsimWorkspace::new().ssim_with_grad(a, b, width, height, grad_a)
}

/// scikit-image SSIM (interior mean, 5 px cropped); errors on bad lengths or images < 11 px.
pub fn ssim_skimage(a: &[f32], b: &[f32], width: usize, height: usize) -> Result<f32, SsimError> {
    SsimWorkspace::new().ssim_variant(a, b, width, height, SsimVariant::Skimage)
}

#[cfg(test)]
#[path = "ssim_tests.rs"]
mod tests;
