//! SSIM against a direct f64 transcription of 3DGS's `ssim` (2D zero-padded convolution), and
//! its gradient against central finite differences of that transcription.

use super::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_image(rng: &mut ChaCha8Rng, w: usize, h: usize) -> Vec<f32> {
    (0..w * h * 3).map(|_| rng.gen::<f32>()).collect()
}

/// 3DGS's `_ssim` written out literally in f64: 2D 11×11 window, zero padding, per channel.
fn reference_map(a: &[f64], b: &[f64], w: usize, h: usize) -> Vec<f64> {
    let g: Vec<f64> = window().iter().map(|&x| x as f64).collect();
    let filt = |f: &dyn Fn(usize) -> f64, i: usize, j: usize, c: usize| {
        let mut s = 0.0;
        for (ki, gi) in g.iter().enumerate() {
            for (kj, gj) in g.iter().enumerate() {
                let (y, x) = (i as isize + ki as isize - 5, j as isize + kj as isize - 5);
                if y >= 0 && x >= 0 && (y as usize) < h && (x as usize) < w {
                    s += gi * gj * f((y as usize * w + x as usize) * 3 + c);
                }
            }
        }
        s
    };
    let (c1, c2) = (1e-4, 9e-4);
    let mut map = vec![0.0; w * h * 3];
    for i in 0..h {
        for j in 0..w {
            for c in 0..3 {
                let mu1 = filt(&|n| a[n], i, j, c);
                let mu2 = filt(&|n| b[n], i, j, c);
                let s11 = filt(&|n| a[n] * a[n], i, j, c) - mu1 * mu1;
                let s22 = filt(&|n| b[n] * b[n], i, j, c) - mu2 * mu2;
                let s12 = filt(&|n| a[n] * b[n], i, j, c) - mu1 * mu2;
                map[(i * w + j) * 3 + c] = ((2.0 * mu1 * mu2 + c1) * (2.0 * s12 + c2))
                    / ((mu1 * mu1 + mu2 * mu2 + c1) * (s11 + s22 + c2));
            }
        }
    }
    map
}

fn reference_ssim(a: &[f64], b: &[f64], w: usize, h: usize) -> f64 {
    let m = reference_map(a, b, w, h);
    m.iter().sum::<f64>() / m.len() as f64
}

fn to_f64(x: &[f32]) -> Vec<f64> {
    x.iter().map(|&v| v as f64).collect()
}

#[test]
fn matches_direct_2d_convolution() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for (w, h) in [(23, 17), (4, 30), (1, 1), (12, 11)] {
        let a = random_image(&mut rng, w, h);
        let b: Vec<f32> = a
            .iter()
            .map(|&x| (x + 0.2 * rng.gen::<f32>()).min(1.0))
            .collect();
        let got = ssim(&a, &b, w, h) as f64;
        let want = reference_ssim(&to_f64(&a), &to_f64(&b), w, h);
        assert!((got - want).abs() < 1e-5, "{w}x{h}: {got} vs {want}");
    }
}

#[test]
fn skimage_variant_is_interior_mean() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let (w, h) = (20, 16);
    let a = random_image(&mut rng, w, h);
    let b = random_image(&mut rng, w, h);
    let map = reference_map(&to_f64(&a), &to_f64(&b), w, h);
    let (mut sum, mut n) = (0.0, 0);
    for i in 5..h - 5 {
        for j in 5..w - 5 {
            for c in 0..3 {
                sum += map[(i * w + j) * 3 + c];
                n += 1;
            }
        }
    }
    let got = ssim_skimage(&a, &b, w, h).unwrap() as f64;
    assert!(
        (got - sum / n as f64).abs() < 1e-5,
        "{got} vs {}",
        sum / n as f64
    );
    assert_eq!(
        ssim_skimage(&a[..30], &b[..30], 10, 1),
        Err(SsimError::TooSmall {
            width: 10,
            height: 1
        })
    );
}

#[test]
fn identical_images_give_one() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let a = random_image(&mut rng, 31, 9);
    assert!((ssim(&a, &a, 31, 9) - 1.0).abs() < 1e-6);
}

#[test]
fn bad_length_is_an_error() {
    let a = vec![0.0f32; 10];
    let err = SsimWorkspace::new().ssim_variant(&a, &a, 2, 2, SsimVariant::Gs3d);
    assert!(matches!(
        err,
        Err(SsimError::BadLength {
            got: 10,
            expected: 12,
            ..
        })
    ));
}

#[test]
fn gradient_matches_finite_differences() {
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    let (w, h) = (19, 14);
    let a = random_image(&mut rng, w, h);
    let b = random_image(&mut rng, w, h);
    let mut grad = vec![0.0f32; a.len()];
    let mut ws = SsimWorkspace::new();
    let s = ws.ssim_with_grad(&a, &b, w, h, &mut grad);
    assert!((s - ws.ssim(&a, &b, w, h)).abs() < 1e-7);
    let (a64, b64) = (to_f64(&a), to_f64(&b));
    let eps = 1e-4;
    let mut max_err = 0.0f64;
    let mut max_grad = 0.0f64;
    // Corners, edges and interior, all three channels.
    for n in [
        0,
        1,
        2,
        3 * w - 1,
        3 * (w * 5 + 7) + 1,
        3 * (w * h) - 1,
        3 * (w * (h - 1)),
    ] {
        let (mut p, mut m) = (a64.clone(), a64.clone());
        p[n] += eps;
        m[n] -= eps;
        let fd = (reference_ssim(&p, &b64, w, h) - reference_ssim(&m, &b64, w, h)) / (2.0 * eps);
        max_err = max_err.max((fd - grad[n] as f64).abs());
        max_grad = max_grad.max(fd.abs());
    }
    assert!(max_grad > 1e-5, "test points have no gradient");
    assert!(
        max_err < 1e-3 * max_grad,
        "max error {max_err} vs max |grad| {max_grad}"
    );
}

#[test]
fn workspace_reuse_across_sizes() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut ws = SsimWorkspace::new();
    for (w, h) in [(30, 20), (8, 5), (30, 20)] {
        let a = random_image(&mut rng, w, h);
        let b = random_image(&mut rng, w, h);
        let mut g1 = vec![0.0; a.len()];
        let mut g2 = vec![0.0; a.len()];
        let s1 = ws.ssim_with_grad(&a, &b, w, h, &mut g1);
        let s2 = ssim_with_grad(&a, &b, w, h, &mut g2);
        assert_eq!(s1, s2);
        assert_eq!(g1, g2);
    }
}

#[test]
fn bands_give_identical_results_and_match_reference() {
    // 7-row bands: interior bands, a short last band (40 = 5·7 + 5), and halos crossing
    // band edges; every row is computed the same way whatever the banding, so the results
    // must be bit-identical to a single band.
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let (w, h) = (13, 40);
    let a = random_image(&mut rng, w, h);
    let b = random_image(&mut rng, w, h);
    let mut ws = SsimWorkspace::new();
    let mut grads = Vec::new();
    for band in [7, 16, 40] {
        let mut g = vec![0.0f32; a.len()];
        let s = ws.ssim_with_grad_banded(&a, &b, w, h, &mut g, band);
        let fwd = ws.forward(&a, &b, w, h, SsimVariant::Gs3d, false, band);
        assert_eq!(s, fwd, "band {band}");
        grads.push((s, g));
    }
    assert!(grads.windows(2).all(|p| p[0] == p[1]));
    let want = reference_ssim(&to_f64(&a), &to_f64(&b), w, h);
    assert!((grads[0].0 as f64 - want).abs() < 1e-5);
    // Finite differences on rows at and next to band edges (6, 7, 13, 35).
    let (a64, b64) = (to_f64(&a), to_f64(&b));
    let eps = 1e-4;
    for (y, x, c) in [(6, 3, 0), (7, 0, 1), (13, 12, 2), (35, 6, 1)] {
        let n = (y * w + x) * 3 + c;
        let (mut p, mut m) = (a64.clone(), a64.clone());
        p[n] += eps;
        m[n] -= eps;
        let fd = (reference_ssim(&p, &b64, w, h) - reference_ssim(&m, &b64, w, h)) / (2.0 * eps);
        let g = grads[0].1[n] as f64;
        assert!(
            (fd - g).abs() < 1e-3 * fd.abs().max(1e-4),
            "({y},{x},{c}): {g} vs {fd}"
        );
    }
}
