//! Image-tower input for one mask (docs/architecture.md "SemDynReg" item 2): the bounding
//! box of `I ⊙ M` (zero outside the mask), zero-padded to a centred square (as LangSplat's
//! `pad_img`), resized to the model's side length, scaled to [0, 1] and normalized with
//! CLIP's mean and std.
//!
//! The resize is Pillow's bicubic, bit for bit ([`super::resize`]): CLIP's own eval transform
//! is torchvision `Resize(S, BICUBIC)` on a PIL image, and the square input makes its centre
//! crop a no-op. LangSplat uses OpenCV's bilinear resize here instead; we follow the
//! preprocessing CLIP was trained with.

use candle_core::{Device, Tensor};
use image::{Rgb, RgbImage};

use super::resize::resize_bicubic;
use super::ClipError;

/// OpenAI CLIP's normalization (`OPENAI_DATASET_MEAN`/`STD`), used by OpenCLIP's ViT-B/16 too.
pub const CLIP_MEAN: [f32; 3] = [0.481_454_66, 0.457_827_5, 0.408_210_73];
pub const CLIP_STD: [f32; 3] = [0.268_629_55, 0.261_302_6, 0.275_777_1];

/// Inclusive pixel bounds `(x0, y0, x1, y1)` of the mask, or `None` when it is empty.
fn mask_bounds(mask: &[bool], width: usize) -> Option<(usize, usize, usize, usize)> {
    let mut b: Option<(usize, usize, usize, usize)> = None;
    for (k, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        let (x, y) = (k % width, k / width);
        b = Some(match b {
            None => (x, y, x, y),
            Some((x0, y0, x1, y1)) => (x0.min(x), y0.min(y), x1.max(x), y1.max(y)),
        });
    }
    b
}

/// Normalized CHW pixels (`3 × size × size`) of the masked crop of `image`.
/// `mask` is row-major with the image's dimensions.
pub fn masked_crop(image: &RgbImage, mask: &[bool], size: u32) -> Result<Vec<f32>, ClipError> {
    let (w, h) = (image.width() as usize, image.height() as usize);
    if mask.len() != w * h {
        return Err(ClipError::Input(format!(
            "mask has {} pixels, the image is {w}×{h}",
            mask.len()
        )));
    }
    let (x0, y0, x1, y1) = mask_bounds(mask, w)
        .ok_or_else(|| ClipError::Input("empty mask: nothing to encode".into()))?;
    let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
    let side = cw.max(ch);
    let (left, top) = ((side - cw) / 2, (side - ch) / 2);
    let mut square = RgbImage::new(side as u32, side as u32);
    for y in 0..ch {
        for x in 0..cw {
            let (sx, sy) = (x0 + x, y0 + y);
            if mask[sy * w + sx] {
                square.put_pixel(
                    (left + x) as u32,
                    (top + y) as u32,
                    *image.get_pixel(sx as u32, sy as u32),
                );
            }
        }
    }
    let resized = resize_bicubic(&square, size, size);
    Ok(to_normalized_chw(&resized))
}

fn to_normalized_chw(img: &RgbImage) -> Vec<f32> {
    let n = (img.width() * img.height()) as usize;
    let mut out = vec![0.0; 3 * n];
    for (k, Rgb(px)) in img.pixels().enumerate() {
        for c in 0..3 {
            out[c * n + k] = (f32::from(px[c]) / 255.0 - CLIP_MEAN[c]) / CLIP_STD[c];
        }
    }
    out
}

/// Stacks crops from [`masked_crop`] into a `(batch, 3, size, size)` tensor.
pub fn batch_pixels(crops: &[Vec<f32>], size: usize) -> Result<Tensor, ClipError> {
    let per = 3 * size * size;
    if let Some(bad) = crops.iter().find(|c| c.len() != per) {
        return Err(ClipError::Input(format!(
            "crop has {} values, expected 3×{size}×{size}",
            bad.len()
        )));
    }
    let flat: Vec<f32> = crops.concat();
    Ok(Tensor::from_vec(
        flat,
        (crops.len(), 3, size, size),
        &Device::Cpu,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_and_errors() {
        let mut mask = vec![false; 12];
        assert_eq!(mask_bounds(&mask, 4), None);
        mask[5] = true;
        mask[11] = true;
        assert_eq!(mask_bounds(&mask, 4), Some((1, 1, 3, 2)));
        let img = RgbImage::new(4, 3);
        assert!(masked_crop(&img, &[false; 12], 8)
            .unwrap_err()
            .to_string()
            .contains("empty mask"));
        assert!(masked_crop(&img, &[true; 5], 8).is_err());
        assert!(batch_pixels(&[vec![0.0; 5]], 2).is_err());
    }

    #[test]
    fn single_colour_mask_normalizes_to_that_colour() {
        let img = RgbImage::from_pixel(6, 4, Rgb([255, 128, 0]));
        let mut mask = vec![false; 24];
        (0..4).for_each(|y| (1..5).for_each(|x| mask[y * 6 + x] = true));
        let px = masked_crop(&img, &mask, 8).unwrap();
        assert_eq!(px.len(), 3 * 64);
        for (c, v) in [1.0, 128.0 / 255.0, 0.0].iter().enumerate() {
            let expected = (v - CLIP_MEAN[c]) / CLIP_STD[c];
            assert!(px[c * 64..(c + 1) * 64]
                .iter()
                .all(|p| (p - expected).abs() < 1e-5));
        }
    }

    #[test]
    fn padding_is_centred_and_black() {
        let img = RgbImage::from_pixel(6, 4, Rgb([255, 255, 255]));
        let mut mask = vec![false; 24];
        (0..4).for_each(|y| mask[y * 6 + 2] = true); // a 1×4 column → column 1 of a 4×4 square
        let px = masked_crop(&img, &mask, 8).unwrap();
        let black = -CLIP_MEAN[0] / CLIP_STD[0];
        // Output column 7 samples input x = 3.75, beyond the bicubic support of column 1.
        assert!((0..8).all(|y| (px[y * 8 + 7] - black).abs() < 1e-6));
        assert!(
            px[3 * 8 + 2] > 1.0,
            "column 1 of the square holds the masked pixels"
        );
    }
}
