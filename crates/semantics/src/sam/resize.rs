//! The resize SAM's `ResizeLongestSide.apply_image` performs: Pillow's `Image.resize` with
//! BILINEAR on an 8-bit RGB image. Re-implemented bit for bit (Pillow `libImaging/Resample.c`:
//! triangle filter with support scaled on downsampling, coefficients normalized per output
//! pixel then fixed-point with 22 fractional bits, horizontal pass first with 8-bit rounding,
//! then vertical), so our encoder input equals the official one exactly.

const PRECISION_BITS: u32 = 32 - 8 - 2;

/// Target size of the longest-side resize (`ResizeLongestSide.get_preprocess_shape`).
pub fn preprocess_shape(h: usize, w: usize, long_side: usize) -> (usize, usize) {
    let scale = long_side as f64 / h.max(w) as f64;
    let nh = (h as f64 * scale + 0.5) as usize;
    let nw = (w as f64 * scale + 0.5) as usize;
    (nh, nw)
}

/// Fixed-point coefficients of one pass: for each output index, (first input index, weights).
fn coefficients(in_size: usize, out_size: usize) -> Vec<(usize, Vec<i32>)> {
    let scale = in_size as f64 / out_size as f64;
    let filterscale = scale.max(1.0);
    let support = filterscale; // bilinear support 1.0 × filterscale
    (0..out_size)
        .map(|xx| {
            let center = (xx as f64 + 0.5) * scale;
            let xmin = ((center - support + 0.5) as i64).max(0) as usize;
            let xmax = ((center + support + 0.5) as i64).min(in_size as i64) as usize;
            let w: Vec<f64> = (xmin..xmax)
                .map(|x| {
                    let t = ((x as f64 - center + 0.5) / filterscale).abs();
                    if t < 1.0 {
                        1.0 - t
                    } else {
                        0.0
                    }
                })
                .collect();
            let total: f64 = w.iter().sum();
            let k = w
                .iter()
                .map(|&v| {
                    let v = if total != 0.0 { v / total } else { v };
                    let f = v * f64::from(1u32 << PRECISION_BITS);
                    if f < 0.0 {
                        (f - 0.5) as i32
                    } else {
                        (f + 0.5) as i32
                    }
                })
                .collect();
            (xmin, k)
        })
        .collect()
}

fn clip8(v: i64) -> u8 {
    (v >> PRECISION_BITS).clamp(0, 255) as u8
}

/// Resize interleaved RGB8 `src` (h×w) to (nh×nw) as Pillow BILINEAR does.
pub fn resize_rgb_pil_bilinear(src: &[u8], h: usize, w: usize, nh: usize, nw: usize) -> Vec<u8> {
    let half = 1i64 << (PRECISION_BITS - 1);
    let horizontal = if nw != w {
        let cx = coefficients(w, nw);
        let mut out = vec![0u8; h * nw * 3];
        for y in 0..h {
            for (x, (x0, k)) in cx.iter().enumerate() {
                for c in 0..3 {
                    let mut acc = half;
                    for (i, &kw) in k.iter().enumerate() {
                        acc += i64::from(src[(y * w + x0 + i) * 3 + c]) * i64::from(kw);
                    }
                    out[(y * nw + x) * 3 + c] = clip8(acc);
                }
            }
        }
        out
    } else {
        src.to_vec()
    };
    if nh == h {
        return horizontal;
    }
    let cy = coefficients(h, nh);
    let mut out = vec![0u8; nh * nw * 3];
    for (y, (y0, k)) in cy.iter().enumerate() {
        for x in 0..nw * 3 {
            let mut acc = half;
            for (i, &kw) in k.iter().enumerate() {
                acc += i64::from(horizontal[(y0 + i) * nw * 3 + x]) * i64::from(kw);
            }
            out[y * nw * 3 + x] = clip8(acc);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preprocess_shape_matches_sam() {
        assert_eq!(preprocess_shape(360, 480, 1024), (768, 1024));
        assert_eq!(preprocess_shape(1080, 1920, 1024), (576, 1024));
        assert_eq!(preprocess_shape(100, 100, 1024), (1024, 1024));
    }

    #[test]
    fn constant_image_stays_constant() {
        let src = vec![77u8; 5 * 7 * 3];
        let out = resize_rgb_pil_bilinear(&src, 5, 7, 11, 16);
        assert!(out.iter().all(|&v| v == 77));
    }

    #[test]
    fn upsampling_interpolates_between_neighbours() {
        // A 1×2 ramp upsampled ×2 horizontally: Pillow gives 0, 64, 191, 255 (weights 1/4, 3/4).
        let src = [0u8, 0, 0, 255, 255, 255];
        let out = resize_rgb_pil_bilinear(&src, 1, 2, 1, 4);
        let r: Vec<u8> = out.chunks(3).map(|p| p[0]).collect();
        assert_eq!(r, vec![0, 64, 191, 255]);
    }
}
