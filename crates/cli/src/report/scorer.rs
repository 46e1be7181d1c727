//! The [`Scorer`] backed by `crates/metrics`: PSNR as 3DGS (`10·log10(1/MSE)` over all
//! values), SSIM in the 3DGS variant (11×11 Gaussian window, σ 1.5, zero padding, mean over
//! all pixels and channels — what Deformable-3DGS reports), LPIPS v0.1 with AlexNet when
//! its weights are present.

use super::evaluate::Scorer;
use super::images::to_f32;
use super::results::Scores;
use anyhow::{Context, Result};
use image::RgbImage;
use metrics::{Lpips, LpipsError, LpipsNet, SsimVariant, SsimWorkspace};

/// Reusable metric state (SSIM buffers, the LPIPS network).
pub struct MetricsScorer {
    ssim: SsimWorkspace,
    lpips: Option<Lpips>,
}

/// Loads LPIPS-AlexNet from `$SEMDYNREG_WEIGHTS` (default `./weights`). Absent weights
/// are not an error: LPIPS is then reported as `null`, and the returned text says why.
/// Present but broken weights are an error.
pub fn load_lpips() -> Result<(Option<Lpips>, String)> {
    match Lpips::from_env(LpipsNet::Alex) {
        Ok(l) => Ok((Some(l), "LPIPS v0.1, AlexNet backbone".into())),
        Err(e @ LpipsError::NotFound { .. }) => Ok((None, format!("not computed (null): {e}"))),
        Err(e) => Err(e).context("loading LPIPS weights"),
    }
}

impl MetricsScorer {
    pub fn new(lpips: Option<Lpips>) -> Self {
        Self {
            ssim: SsimWorkspace::new(),
            lpips,
        }
    }

    /// Text for `results.json`'s protocol.
    pub fn ssim_description() -> &'static str {
        "3DGS variant (11×11 Gaussian window, σ 1.5, zero padding, mean over all pixels and channels)"
    }
}

impl Scorer for MetricsScorer {
    fn score(&mut self, gt: &RgbImage, render: &RgbImage) -> Result<Scores> {
        let (w, h) = (gt.width() as usize, gt.height() as usize);
        let (a, b) = (to_f32(render), to_f32(gt));
        // Identical images give +inf dB, which JSON cannot hold: recorded as null.
        let psnr = Some(metrics::psnr(&a, &b)).filter(|v| v.is_finite());
        let ssim = self.ssim.ssim_variant(&a, &b, w, h, SsimVariant::Gs3d)?;
        let lpips = match &self.lpips {
            Some(net) => match net.distance(&a, &b, w, h) {
                Ok(d) => Some(d as f64),
                // Only possible for a crop clamped by a tiny image (crops are ≥ 31 px).
                Err(LpipsError::TooSmall { .. }) => None,
                Err(e) => return Err(e.into()),
            },
            None => None,
        };
        Ok(Scores {
            psnr,
            ssim: Some(ssim as f64),
            lpips,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    #[test]
    fn scores_a_noisy_pair_and_nulls_identical_psnr() {
        let gt = RgbImage::from_fn(40, 32, |x, y| Rgb([(x * 6) as u8, (y * 7) as u8, 128]));
        let noisy = RgbImage::from_fn(40, 32, |x, y| {
            let p = gt.get_pixel(x, y).0;
            let d = if (x + y) % 2 == 0 { 10 } else { 0 };
            Rgb([p[0].saturating_add(d), p[1], p[2]])
        });
        let mut s = MetricsScorer::new(None);
        let same = s.score(&gt, &gt).unwrap();
        assert_eq!(same.psnr, None);
        assert!((same.ssim.unwrap() - 1.0).abs() < 1e-6);
        let diff = s.score(&gt, &noisy).unwrap();
        // MSE = half the R values off by 10/255: PSNR = 10·log10(1/(0.5·(10/255)²/3)).
        let expected = 10.0 * (1.0 / (0.5 * (10.0f64 / 255.0).powi(2) / 3.0)).log10();
        assert!(
            (diff.psnr.unwrap() - expected).abs() < 1e-3,
            "{:?}",
            diff.psnr
        );
        assert!(diff.ssim.unwrap() < 1.0);
        assert_eq!(diff.lpips, None);
    }
}
