//! Bicubic resize of 8-bit RGB, bit-exact with Pillow's `Image.resize(…, BICUBIC)`
//! (libImaging/Resample.c): the kernel is widened by the scale when shrinking, clipped to
//! the image and renormalized, coefficients are 22-bit fixed point, and the horizontal pass
//! is rounded to 8 bits before the vertical pass. CLIP's eval transform resizes with Pillow,
//! so matching it exactly keeps our crops identical to what CLIP was trained on; the `image`
//! crate's Catmull-Rom filter differs (float intermediate, other window), by up to ~13
//! grey levels on noisy crops.

use image::RgbImage;

/// Pillow's `PRECISION_BITS` for 8-bit images: `32 − 8 − 2`.
const PRECISION_BITS: u32 = 22;

/// Keys' cubic with a = −0.5 (Pillow's `bicubic_filter`), support 2.
fn bicubic(x: f64) -> f64 {
    const A: f64 = -0.5;
    let x = x.abs();
    if x < 1.0 {
        ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
    } else if x < 2.0 {
        (((x - 5.0) * x + 8.0) * x - 4.0) * A
    } else {
        0.0
    }
}

/// Per output pixel: first input index and fixed-point weights (`precompute_coeffs` +
/// `normalize_coeffs_8bpc`).
fn coefficients(in_size: usize, out_size: usize) -> Vec<(usize, Vec<i32>)> {
    let scale = in_size as f64 / out_size as f64;
    let filter_scale = scale.max(1.0);
    let support = 2.0 * filter_scale;
    (0..out_size)
        .map(|xx| {
            let center = (xx as f64 + 0.5) * scale;
            // Truncation toward zero as C's (int) cast; both bounds are ≥ 0 after clamping.
            let xmin = ((center - support + 0.5) as i64).max(0) as usize;
            let xmax = ((center + support + 0.5) as i64).min(in_size as i64) as usize;
            let ss = 1.0 / filter_scale;
            let w: Vec<f64> = (xmin..xmax)
                .map(|x| bicubic((x as f64 - center + 0.5) * ss))
                .collect();
            let total: f64 = w.iter().sum();
            let fixed = w
                .iter()
                .map(|&k| {
                    let k = if total != 0.0 { k / total } else { k };
                    let v = k * f64::from(1u32 << PRECISION_BITS);
                    (if v < 0.0 { v - 0.5 } else { v + 0.5 }) as i32
                })
                .collect();
            (xmin, fixed)
        })
        .collect()
}

fn clip8(acc: i64) -> u8 {
    (acc >> PRECISION_BITS).clamp(0, 255) as u8
}

/// One separable pass over interleaved RGB rows: `along_x` resamples within rows.
fn pass(
    src: &[u8],
    (w, h): (usize, usize),
    coeffs: &[(usize, Vec<i32>)],
    along_x: bool,
) -> Vec<u8> {
    let (ow, oh) = if along_x {
        (coeffs.len(), h)
    } else {
        (w, coeffs.len())
    };
    let mut out = vec![0u8; ow * oh * 3];
    for y in 0..oh {
        for x in 0..ow {
            let (start, k) = &coeffs[if along_x { x } else { y }];
            for c in 0..3 {
                let mut acc: i64 = 1 << (PRECISION_BITS - 1);
                for (i, &kk) in k.iter().enumerate() {
                    let (sx, sy) = if along_x {
                        (start + i, y)
                    } else {
                        (x, start + i)
                    };
                    acc += i64::from(src[(sy * w + sx) * 3 + c]) * i64::from(kk);
                }
                out[(y * ow + x) * 3 + c] = clip8(acc);
            }
        }
    }
    out
}

/// Resizes `img` to `width × height` as Pillow's BICUBIC does.
pub fn resize_bicubic(img: &RgbImage, width: u32, height: u32) -> RgbImage {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (ow, oh) = (width as usize, height as usize);
    let mut data = img.as_raw().clone();
    let mut cur_w = w;
    // Pillow skips a pass whose size is unchanged; horizontal first, then vertical.
    if ow != w {
        data = pass(&data, (w, h), &coefficients(w, ow), true);
        cur_w = ow;
    }
    if oh != h {
        data = pass(&data, (cur_w, h), &coefficients(h, oh), false);
    }
    RgbImage::from_raw(width, height, data).expect("buffer sized width × height × 3")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_one_and_identity_is_exact() {
        for (i, o) in [(22, 64), (300, 224), (7, 7)] {
            for (_, k) in coefficients(i, o) {
                let s: i64 = k.iter().map(|&v| i64::from(v)).sum();
                assert!(
                    (s - (1 << PRECISION_BITS)).abs() <= k.len() as i64,
                    "{i}->{o}: {s}"
                );
            }
        }
        let img = RgbImage::from_fn(5, 3, |x, y| image::Rgb([x as u8 * 40, y as u8 * 70, 9]));
        assert_eq!(resize_bicubic(&img, 5, 3), img);
    }

    #[test]
    fn constant_image_stays_constant() {
        let img = RgbImage::from_pixel(13, 9, image::Rgb([200, 17, 255]));
        let out = resize_bicubic(&img, 31, 4);
        assert!(out.pixels().all(|p| p.0 == [200, 17, 255]));
    }
}
