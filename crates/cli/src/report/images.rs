//! Small image operations for the report figures: cropping, zooming, colourized object-ID
//! maps, box outlines, and PNG I/O. Images are `image::RgbImage` (8-bit RGB).

use super::crops::CropBox;
use super::io::write_atomic;
use anyhow::{ensure, Context, Result};
use image::{imageops, Rgb, RgbImage};
use std::path::Path;

/// Object-ID value meaning "background / irrelevant" in masks and ID maps
/// (docs/architecture.md, "Object IDs").
pub const BACKGROUND_ID: u8 = 255;

/// Reads a PNG (or JPEG) as RGB; an alpha channel is dropped (renders are opaque).
pub fn load_rgb(path: &Path) -> Result<RgbImage> {
    let img = image::open(path).with_context(|| format!("reading image {}", path.display()))?;
    Ok(img.to_rgb8())
}

/// Writes a PNG atomically.
pub fn save_png(img: &RgbImage, path: &Path) -> Result<()> {
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .with_context(|| format!("encoding {}", path.display()))?;
    write_atomic(path, &bytes)
}

/// Wraps an interleaved RGB buffer.
pub fn from_rgb_bytes(width: u32, height: u32, data: Vec<u8>) -> Result<RgbImage> {
    let len = data.len();
    RgbImage::from_raw(width, height, data)
        .with_context(|| format!("{len} bytes is not a {width}×{height} RGB image"))
}

/// Interleaved RGB in [0, 1], the layout the metrics take.
pub fn to_f32(img: &RgbImage) -> Vec<f32> {
    img.as_raw().iter().map(|&v| v as f32 / 255.0).collect()
}

/// The pixels inside `b` (which must lie inside the image).
pub fn crop(img: &RgbImage, b: CropBox) -> RgbImage {
    imageops::crop_imm(img, b.x, b.y, b.width, b.height).to_image()
}

/// Enlarges by the largest integer factor whose height stays ≤ `max_height` (at least 1),
/// with nearest-neighbour sampling so that the zoomed views show the pixels as rendered.
pub fn zoom(img: &RgbImage, max_height: u32) -> RgbImage {
    let factor = (max_height / img.height().max(1)).max(1);
    imageops::resize(
        img,
        img.width() * factor,
        img.height() * factor,
        imageops::FilterType::Nearest,
    )
}

/// A fixed, distinguishable colour per object ID; background is dark grey.
pub fn id_color(id: u8) -> Rgb<u8> {
    const PALETTE: [[u8; 3]; 8] = [
        [230, 25, 75],
        [60, 180, 75],
        [0, 130, 200],
        [255, 225, 25],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
    ];
    if id == BACKGROUND_ID {
        Rgb([40, 40, 40])
    } else {
        Rgb(PALETTE[id as usize % PALETTE.len()])
    }
}

/// Colourizes an `H·W` object-ID map.
pub fn colorize_ids(ids: &[u8], width: u32, height: u32) -> Result<RgbImage> {
    ensure!(
        ids.len() == (width * height) as usize,
        "ID map has {} pixels, expected {width}×{height}",
        ids.len()
    );
    Ok(RgbImage::from_fn(width, height, |x, y| {
        id_color(ids[(y * width + x) as usize])
    }))
}

/// Draws a `thickness`-pixel outline of `b` (clipped to the image) in `color`.
pub fn draw_box(img: &mut RgbImage, b: CropBox, color: Rgb<u8>, thickness: u32) {
    let (w, h) = img.dimensions();
    let x1 = (b.x + b.width).min(w);
    let y1 = (b.y + b.height).min(h);
    for y in b.y.min(h)..y1 {
        for x in b.x.min(w)..x1 {
            let inner = x >= b.x + thickness
                && x + thickness < x1
                && y >= b.y + thickness
                && y + thickness < y1;
            if !inner {
                img.put_pixel(x, y, color);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zoom_uses_integer_factor_within_limit() {
        let img = RgbImage::new(10, 7);
        let z = zoom(&img, 30);
        assert_eq!(z.dimensions(), (40, 28));
        assert_eq!(zoom(&RgbImage::new(10, 50), 30).dimensions(), (10, 50));
    }

    #[test]
    fn crop_and_box_touch_the_right_pixels() {
        let mut img = RgbImage::from_fn(8, 6, |x, y| Rgb([x as u8, y as u8, 0]));
        let b = CropBox {
            x: 2,
            y: 1,
            width: 4,
            height: 3,
        };
        let c = crop(&img, b);
        assert_eq!(c.dimensions(), (4, 3));
        assert_eq!(c.get_pixel(0, 0), &Rgb([2, 1, 0]));
        draw_box(&mut img, b, Rgb([255, 255, 255]), 1);
        assert_eq!(img.get_pixel(2, 1), &Rgb([255, 255, 255]));
        assert_eq!(img.get_pixel(5, 3), &Rgb([255, 255, 255]));
        assert_eq!(img.get_pixel(3, 2), &Rgb([3, 2, 0]), "interior untouched");
        assert_eq!(img.get_pixel(6, 2), &Rgb([6, 2, 0]), "outside untouched");
    }

    #[test]
    fn colorize_checks_size_and_marks_background() {
        assert!(colorize_ids(&[0, 1], 3, 1).is_err());
        let c = colorize_ids(&[0, 255], 2, 1).unwrap();
        assert_eq!(c.get_pixel(1, 0), &id_color(BACKGROUND_ID));
        assert_ne!(c.get_pixel(0, 0), c.get_pixel(1, 0));
    }

    #[test]
    fn png_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let img = RgbImage::from_fn(5, 4, |x, y| Rgb([x as u8 * 40, y as u8 * 60, 7]));
        let p = dir.path().join("a.png");
        save_png(&img, &p).unwrap();
        assert_eq!(load_rgb(&p).unwrap(), img);
        let err = load_rgb(&dir.path().join("missing.png")).unwrap_err();
        assert!(format!("{err:#}").contains("missing.png"));
    }
}
