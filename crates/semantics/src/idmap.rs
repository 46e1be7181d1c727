//! Object-ID maps: paint per-mask object IDs into an 8-bit image (255 = background, as on
//! disk, docs/architecture.md item 3), and a colour preview of such a map.

use thiserror::Error;

/// Value of a background pixel in an ID map.
pub const BACKGROUND: u8 = 255;

/// Errors of painting an ID map.
#[derive(Debug, Error)]
pub enum IdMapError {
    #[error("{masks} masks but {ids} object IDs: they must pair one to one")]
    CountMismatch { masks: usize, ids: usize },
    #[error("mask {index} has {got} pixels, expected {width}×{height} = {}", width * height)]
    MaskSize {
        index: usize,
        got: usize,
        width: usize,
        height: usize,
    },
    #[error("object ID {0} is reserved for background")]
    ReservedId(u8),
}

/// Paints `ids[k]` into every pixel of `masks[k]` (row-major `width × height` booleans).
///
/// The masks are expected to be non-overlapping (SAM stage, docs/architecture.md item 1);
/// should two overlap anyway, the later mask wins the pixel. Masks with `None` and pixels
/// no mask covers stay [`BACKGROUND`].
pub fn paint<M: AsRef<[bool]>>(
    masks: &[M],
    ids: &[Option<u8>],
    width: usize,
    height: usize,
) -> Result<Vec<u8>, IdMapError> {
    if masks.len() != ids.len() {
        return Err(IdMapError::CountMismatch {
            masks: masks.len(),
            ids: ids.len(),
        });
    }
    let mut out = vec![BACKGROUND; width * height];
    for (index, (mask, id)) in masks.iter().zip(ids).enumerate() {
        let mask = mask.as_ref();
        if mask.len() != out.len() {
            return Err(IdMapError::MaskSize {
                index,
                got: mask.len(),
                width,
                height,
            });
        }
        let Some(id) = *id else { continue };
        if id == BACKGROUND {
            return Err(IdMapError::ReservedId(id));
        }
        for (o, _) in out.iter_mut().zip(mask).filter(|(_, &m)| m) {
            *o = id;
        }
    }
    Ok(out)
}

/// A distinct, stable colour per object ID (golden-ratio hue steps); background is black.
pub fn color_of(id: u8) -> [u8; 3] {
    if id == BACKGROUND {
        return [0, 0, 0];
    }
    let hue = (f32::from(id) * 0.618_034 + 0.1).fract() * 6.0;
    let x = 1.0 - ((hue % 2.0) - 1.0).abs();
    let (r, g, b) = match hue as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    // Value 0.9 keeps every object visibly distinct from the black background.
    [r, g, b].map(|c: f32| (c * 230.0).round() as u8)
}

/// Colour preview of an ID map (row-major, `width × height`).
pub fn preview(ids: &[u8], width: u32, height: u32) -> Option<image::RgbImage> {
    let data: Vec<u8> = ids.iter().flat_map(|&id| color_of(id)).collect();
    image::RgbImage::from_raw(width, height, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paints_ids_and_background() {
        let a = vec![true, true, false, false, false, false];
        let b = vec![false, false, false, true, false, false];
        let c = vec![false, false, false, false, false, true];
        let map = paint(&[a, b, c], &[Some(2), Some(0), None], 3, 2).unwrap();
        assert_eq!(map, vec![2, 2, 255, 0, 255, 255]);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let a = vec![true; 4];
        assert!(matches!(
            paint(&[&a], &[], 2, 2),
            Err(IdMapError::CountMismatch { .. })
        ));
        assert!(matches!(
            paint(&[&a], &[Some(1)], 3, 2),
            Err(IdMapError::MaskSize { got: 4, .. })
        ));
        assert!(matches!(
            paint(&[&a], &[Some(255)], 2, 2),
            Err(IdMapError::ReservedId(255))
        ));
    }

    #[test]
    fn colours_are_distinct_and_background_black() {
        assert_eq!(color_of(BACKGROUND), [0, 0, 0]);
        let colours: std::collections::HashSet<[u8; 3]> = (0..16).map(color_of).collect();
        assert_eq!(colours.len(), 16);
        assert!(colours.iter().all(|c| c.iter().any(|&v| v > 100)));
        let img = preview(&[0, 255], 2, 1).unwrap();
        assert_eq!(img.get_pixel(1, 0).0, [0, 0, 0]);
        assert!(preview(&[0], 2, 1).is_none());
    }
}
