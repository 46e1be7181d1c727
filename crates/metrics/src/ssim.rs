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
    /// Per-band scratch (ring buffer of filtered rows etc., see `ssim_band.rs`).
    bands: Vec<f32>,
    /// Horizontally filtered backward seeds ∂S/∂(μa, Eaa, Eab); BWD planes per image row.
    hseeds: Vec<f32>,
}

/// Rows per band: enough bands for every thread to get two (load balance), each at least 16
/// rows (the ring's 10-row halo is recomputed per band) and at most 64.
fn band_rows(height: usize) -> usize {
    height
        .div_ceil(2 * rayon::current_num_threads())
        .clamp(16, 64)
}

impl SsimWorkspace {
    /// An empty workspace; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    fn resize(&mut self, width: usize, height: usize, band: usize, grad: bool) {
        self.width = width;
        self.height = height;
        let row = width * CH;
        self.bands
            .resize(height.div_ceil(band) * band::scratch_len(row), 0.0);
        if grad {
            self.hseeds.resize(BWD * row * height, 0.0);
        }
    }

    /// 3DGS SSIM of `a` against `b`.
    ///
    /// # Panics
    /// If a buffer does not hold `width × height × 3` floats (use [`Self::ssim_variant`] for a
    /// checked call).
    pub fn ssim(&mut self, a: &[f32], b: &[f32], width: usize, height: usize) -> f32 {
        check_len(a, b, width, height).unwrap_or_else(|e| panic!("{e}"));
        self.forward(
            a,
            b,
            width,
            height,
            SsimVariant::Gs3d,
            false,
            band_rows(height),
        )
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
        Ok(self.forward(a, b, width, height, variant, false, band_rows(height)))
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
        self.ssim_with_grad_banded(a, b, width, height, grad_a, band_rows(height))
    }

    fn ssim_with_grad_banded(
        &mut self,
        a: &[f32],
        b: &[f32],
        width: usize,
        height: usize,
        grad_a: &mut [f32],
        band: usize,
    ) -> f32 {
        check_len(a, b, width, height).unwrap_or_else(|e| panic!("{e}"));
        check_len(grad_a, b, width, height).unwrap_or_else(|e| panic!("{e} (grad_a)"));
        let s = self.forward(a, b, width, height, SsimVariant::Gs3d, true, band);
        self.backward(a, b, grad_a, band);
        s
    }

    fn frame<'a>(&self, a: &'a [f32], b: &'a [f32], variant: SsimVariant) -> band::Frame<'a> {
        let (row, height) = (self.width * CH, self.height);
        let (rows, cols) = match variant {
            SsimVariant::Gs3d => (0..height, 0..row),
            SsimVariant::Skimage => (RADIUS..height - RADIUS, RADIUS * CH..row - RADIUS * CH),
        };
        let count = rows.len() * cols.len();
        band::Frame {
            a,
            b,
            height,
            row,
            win: window(),
            rows,
            cols,
            scale: (1.0 / count as f64) as f32,
        }
    }

    /// Runs the fused forward per band (writing `hseeds` if `grad`); returns the mean map.
    #[allow(clippy::too_many_arguments)]
    fn forward(
        &mut self,
        a: &[f32],
        b: &[f32],
        width: usize,
        height: usize,
        variant: SsimVariant,
        grad: bool,
        band: usize,
    ) -> f32 {
        self.resize(width, height, band, grad);
        let row = width * CH;
        if row == 0 || height == 0 {
            return f32::NAN;
        }
        let f = self.frame(a, b, variant);
        let scratch = self.bands.par_chunks_mut(band::scratch_len(row));
        let total: f64 = if grad {
            scratch
                .zip(self.hseeds[..BWD * row * height].par_chunks_mut(band * BWD * row))
                .enumerate()
                .map(|(k, (scr, hs))| {
                    band::band_forward(&f, k * band, hs.len() / (BWD * row), scr, Some(hs))
                })
                .sum()
        } else {
            scratch
                .take(height.div_ceil(band))
                .enumerate()
                .map(|(k, scr)| {
                    let nrows = band.min(height - k * band);
                    band::band_forward(&f, k * band, nrows, scr, None)
                })
                .sum()
        };
        (total / (f.rows.len() * f.cols.len()) as f64) as f32
    }

    /// ∂S/∂a from the filtered seeds written by `forward`.
    fn backward(&mut self, a: &[f32], b: &[f32], grad_a: &mut [f32], band: usize) {
        let row = self.width * CH;
        if row == 0 || self.height == 0 {
            return;
        }
        let f = self.frame(a, b, SsimVariant::Gs3d);
        let hseeds = &self.hseeds[..BWD * row * self.height];
        self.bands
            .par_chunks_mut(band::scratch_len(row))
            .zip(grad_a.par_chunks_mut(band * row))
            .enumerate()
            .for_each(|(k, (scr, g))| band::band_grad(&f, hseeds, k * band, g, scr));
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

#[path = "ssim_band.rs"]
mod band;

#[cfg(test)]
#[path = "ssim_tests.rs"]
mod tests;
