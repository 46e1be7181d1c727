//! 8-bit images kept in memory (a 300-frame 1440×1080 scene is ~1.4 GB as u8, four times
//! that as f32) and converted to f32 on use; object-ID masks.

use crate::io::write_atomic;
use crate::SceneError;
use image::{ImageBuffer, Luma, Rgb, Rgba};
use std::path::Path;

/// An RGB image, 8 bits per channel, `H·W·3` interleaved row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImageU8 {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl ImageU8 {
    /// Pixels as f32 in [0, 1] (`H·W·3`).
    pub fn to_f32(&self) -> Vec<f32> {
        let mut out = Vec::new();
        self.to_f32_into(&mut out);
        out
    }

    /// Like [`Self::to_f32`] into a reused buffer (no allocation once it is large enough).
    pub fn to_f32_into(&self, out: &mut Vec<f32>) {
        out.clear();
        out.extend(self.data.iter().map(|&v| f32::from(v) * (1.0 / 255.0)));
    }

    /// Quantizes `H·W·3` values in [0, 1] (clamped; NaN → 0) to 8 bits with rounding.
    pub fn from_f32(width: u32, height: u32, pixels: &[f32]) -> Self {
        debug_assert_eq!(pixels.len(), width as usize * height as usize * 3);
        Self {
            width,
            height,
            data: pixels.iter().map(|&v| quantize(v)).collect(),
        }
    }

    /// Writes an RGB PNG atomically.
    pub fn save_png(&self, path: &Path) -> Result<(), SceneError> {
        let buf: ImageBuffer<Rgb<u8>, &[u8]> =
            ImageBuffer::from_raw(self.width, self.height, self.data.as_slice()).ok_or_else(
                || SceneError::invalid(path, "image buffer smaller than width × height × 3"),
            )?;
        save_png_buffer(path, &buf)
    }

    /// Reads any 8/16-bit PNG or JPEG; RGBA is composited over `background` (values in
    /// [0, 1]) as `c·a + bg·(1 − a)`, the way D-NeRF/Deformable-3DGS do.
    pub fn load(path: &Path, background: [f32; 3]) -> Result<Self, SceneError> {
        let img = decode(path)?;
        if !img.color().has_alpha() {
            let rgb = img.into_rgb8();
            let (width, height) = rgb.dimensions();
            return Ok(Self {
                width,
                height,
                data: rgb.into_raw(),
            });
        }
        let rgba = img.into_rgba8();
        let (width, height) = rgba.dimensions();
        Ok(Self {
            width,
            height,
            data: composite(rgba.as_raw(), background),
        })
    }

    /// Box-filters by an integer `factor` (each output pixel is the mean of a factor×factor
    /// block; a remainder of rows/columns at the border is dropped).
    pub fn downscale(&self, factor: u32) -> Self {
        if factor <= 1 {
            return self.clone();
        }
        let (w, h) = (self.width / factor, self.height / factor);
        let f = factor as usize;
        let inv = 1.0 / (f * f) as f32;
        let mut data = Vec::with_capacity(w as usize * h as usize * 3);
        for y in 0..h as usize {
            for x in 0..w as usize {
                let mut acc = [0u32; 3];
                for dy in 0..f {
                    let row = (y * f + dy) * self.width as usize;
                    for dx in 0..f {
                        let p = (row + x * f + dx) * 3;
                        for (a, &v) in acc.iter_mut().zip(&self.data[p..p + 3]) {
                            *a += u32::from(v);
                        }
                    }
                }
                data.extend(acc.iter().map(|&a| (a as f32 * inv).round() as u8));
            }
        }
        Self {
            width: w,
            height: h,
            data,
        }
    }
}

fn quantize(v: f32) -> u8 {
    // `as` saturates and maps NaN to 0, which is the clamp we want.
    (v * 255.0 + 0.5) as u8
}

fn composite(rgba: &[u8], bg: [f32; 3]) -> Vec<u8> {
    let mut out = Vec::with_capacity(rgba.len() / 4 * 3);
    for px in rgba.chunks_exact(4) {
        let a = f32::from(px[3]) / 255.0;
        for c in 0..3 {
            out.push(quantize(f32::from(px[c]) / 255.0 * a + bg[c] * (1.0 - a)));
        }
    }
    out
}

/// Writes any `image` buffer as PNG, atomically.
pub(crate) fn save_png_buffer<P, C>(path: &Path, buf: &ImageBuffer<P, C>) -> Result<(), SceneError>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    let mut bytes = Vec::new();
    buf.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| SceneError::image(path, e))?;
    write_atomic(path, |w| w.write_all(&bytes))
}

/// Writes straight (not premultiplied) RGBA, `H·W·4`, as PNG, atomically.
pub fn save_rgba_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<(), SceneError> {
    let buf: ImageBuffer<Rgba<u8>, &[u8]> = ImageBuffer::from_raw(width, height, rgba)
        .ok_or_else(|| SceneError::invalid(path, "RGBA buffer smaller than width × height × 4"))?;
    save_png_buffer(path, &buf)
}

/// Value of a [`MaskU8`] pixel that belongs to no object.
pub const MASK_BACKGROUND: u8 = 255;

/// An 8-bit object-ID map, `H·W` row-major: 0, 1, 2… are object IDs, 255 is background.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MaskU8 {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl MaskU8 {
    /// ID at (row, col).
    pub fn get(&self, row: u32, col: u32) -> u8 {
        self.data[row as usize * self.width as usize + col as usize]
    }

    /// Writes a grayscale 8-bit PNG atomically.
    pub fn save(&self, path: &Path) -> Result<(), SceneError> {
        save_mask(path, self)
    }
}

/// Any PNG or JPEG (format guessed from the bytes), with errors naming the file.
fn decode(path: &Path) -> Result<image::DynamicImage, SceneError> {
    image::ImageReader::open(path)
        .map_err(|e| SceneError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| SceneError::io(path, e))?
        .decode()
        .map_err(|e| SceneError::image(path, e))
}

/// Reads an 8-bit grayscale PNG of object IDs. Any other pixel format is refused rather
/// than converted, since a colour conversion would silently change the IDs.
pub fn load_mask(path: &Path) -> Result<MaskU8, SceneError> {
    let img = decode(path)?;
    match img {
        image::DynamicImage::ImageLuma8(buf) => {
            let (width, height) = buf.dimensions();
            Ok(MaskU8 {
                width,
                height,
                data: buf.into_raw(),
            })
        }
        other => Err(SceneError::invalid(
            path,
            format!(
                "object-ID mask must be 8-bit grayscale, found {:?}",
                other.color()
            ),
        )),
    }
}

/// A one-object ID map from an RGBA image's alpha channel: 0 where the pixel is at least
/// half opaque, [`MASK_BACKGROUND`] elsewhere. Synthetic scenes rendered over a transparent
/// background (D-NeRF, Blender) carry the object's silhouette this way; `segment --masks
/// alpha` uses it. An image without alpha is refused: it has no silhouette to read.
pub fn load_alpha_ids(path: &Path) -> Result<MaskU8, SceneError> {
    let img = decode(path)?;
    if !img.color().has_alpha() {
        return Err(SceneError::invalid(
            path,
            format!(
                "has no alpha channel ({:?}): alpha masks need RGBA frames",
                img.color()
            ),
        ));
    }
    let rgba = img.into_rgba8();
    let (width, height) = rgba.dimensions();
    let data = rgba
        .pixels()
        .map(|p| if p[3] >= 128 { 0 } else { MASK_BACKGROUND })
        .collect();
    Ok(MaskU8 {
        width,
        height,
        data,
    })
}

/// Writes `mask` as an 8-bit grayscale PNG, atomically.
pub fn save_mask(path: &Path, mask: &MaskU8) -> Result<(), SceneError> {
    let buf: ImageBuffer<Luma<u8>, &[u8]> =
        ImageBuffer::from_raw(mask.width, mask.height, mask.data.as_slice())
            .ok_or_else(|| SceneError::invalid(path, "mask buffer smaller than width × height"))?;
    save_png_buffer(path, &buf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alpha_ids_mark_the_opaque_half_and_refuse_rgb() {
        let dir = std::env::temp_dir().join(format!("alpha_ids_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rgba = dir.join("a.png");
        let px = [9, 9, 9, 0, 9, 9, 9, 127, 9, 9, 9, 128, 9, 9, 9, 255];
        save_rgba_png(&rgba, 4, 1, &px).unwrap();
        let ids = load_alpha_ids(&rgba).unwrap();
        assert_eq!((ids.width, ids.height), (4, 1));
        assert_eq!(ids.data, [MASK_BACKGROUND, MASK_BACKGROUND, 0, 0]);
        let rgb = dir.join("b.png");
        ImageU8 {
            width: 1,
            height: 1,
            data: vec![1, 2, 3],
        }
        .save_png(&rgb)
        .unwrap();
        let err = load_alpha_ids(&rgb).unwrap_err().to_string();
        assert!(err.contains("b.png") && err.contains("no alpha"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn composite_blends_over_background() {
        let out = composite(&[255, 0, 0, 128, 10, 20, 30, 0], [1.0, 1.0, 1.0]);
        assert_eq!(&out[..3], &[255, 127, 127]);
        assert_eq!(&out[3..], &[255, 255, 255]);
    }

    #[test]
    fn downscale_averages_blocks() {
        let img = ImageU8 {
            width: 2,
            height: 2,
            data: vec![0, 0, 0, 100, 100, 100, 200, 200, 200, 255, 255, 255],
        };
        let d = img.downscale(2);
        assert_eq!((d.width, d.height), (1, 1));
        assert_eq!(d.data, vec![139, 139, 139]);
    }

    #[test]
    fn f32_roundtrip_is_exact() {
        let img = ImageU8 {
            width: 2,
            height: 1,
            data: vec![0, 1, 2, 127, 254, 255],
        };
        assert_eq!(ImageU8::from_f32(2, 1, &img.to_f32()), img);
    }
}
