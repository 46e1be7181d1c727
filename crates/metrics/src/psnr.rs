//! PSNR for images in [0, 1]: `10·log10(1 / MSE)`, the MSE taken over all values (pixels and
//! channels) in f64, as 3DGS's `utils/image_utils.py::psnr` per image.
//!
//! Convention for identical images (MSE = 0): PSNR is `+inf` (`f64::INFINITY`), the limit of
//! the formula; nothing is clamped. JSON has no infinity, so the CLI writes `null` there (see
//! docs/metrics.md).

/// PSNR of `a` against `b` (same length, values in [0, 1]); `+inf` when identical, NaN when empty.
///
/// # Panics
/// If the lengths differ (a programming error: callers compare images of one size).
pub fn psnr(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(
        a.len(),
        b.len(),
        "PSNR: images hold {} and {} values",
        a.len(),
        b.len()
    );
    if a.is_empty() {
        return f64::NAN;
    }
    let sse: f64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = x as f64 - y as f64;
            d * d
        })
        .sum();
    let mse = sse / a.len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

#[cfg(test)]
mod tests {
    use super::psnr;

    #[test]
    fn identical_is_infinite() {
        let a = [0.2f32, 0.4, 0.9];
        assert_eq!(psnr(&a, &a), f64::INFINITY);
    }

    #[test]
    fn known_value() {
        // MSE = 0.01 everywhere → 20 dB.
        let a = [0.5f32; 12];
        let b = [0.6f32; 12];
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-5, "{}", psnr(&a, &b));
        // One value off by 1 among 4 → MSE 0.25 → 6.0206 dB.
        assert!((psnr(&[0.0, 0.0, 0.0, 0.0], &[1.0, 0.0, 0.0, 0.0]) - 6.020_599_913).abs() < 1e-6);
    }

    #[test]
    fn empty_is_nan() {
        assert!(psnr(&[], &[]).is_nan());
    }
}
