//! Per-object crops (the paper's Tables 1–2 score zoomed crops of the moving object): a box
//! from a mask or object-ID map, padded by a margin and clamped to the image, then grown to
//! at least [`MIN_CROP_SIDE`] px so that LPIPS-Alex accepts it.
//!
//! Small-crop policy: boxes are grown around their centre with real image context (no
//! resampling, no constant padding, which would change what LPIPS sees), and the same grown
//! box is used for all three metrics so that they describe the same pixels. When the image
//! itself is smaller than the minimum, the box is the whole image along that axis and LPIPS
//! reports `TooSmall`.

/// Smallest crop side: LPIPS-Alex needs 31 px (see `LpipsNet::min_side`); 32 keeps it even.
pub const MIN_CROP_SIDE: usize = 32;

/// An axis-aligned pixel box: columns `x..x + w`, rows `y..y + h`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct BBox {
    pub x: usize,
    pub y: usize,
    pub w: usize,
    pub h: usize,
}

impl BBox {
    /// Clamps the box to a `width × height` image; `None` if nothing is left.
    pub fn clamp(self, width: usize, height: usize) -> Option<BBox> {
        let x1 = (self.x.saturating_add(self.w)).min(width);
        let y1 = (self.y.saturating_add(self.h)).min(height);
        (self.x < x1 && self.y < y1).then(|| BBox {
            x: self.x,
            y: self.y,
            w: x1 - self.x,
            h: y1 - self.y,
        })
    }

    /// Grows each side to at least `min` px around the centre, shifted to stay inside a
    /// `width × height` image (a side stays the image's size if that is smaller).
    pub fn grow_to(self, min: usize, width: usize, height: usize) -> BBox {
        let (x, w) = grow_axis(self.x, self.w, min, width);
        let (y, h) = grow_axis(self.y, self.h, min, height);
        BBox { x, y, w, h }
    }
}

fn grow_axis(start: usize, len: usize, min: usize, limit: usize) -> (usize, usize) {
    let target = min.min(limit);
    if len >= target {
        return (start, len);
    }
    let extra = target - len;
    let new_start = start.saturating_sub(extra / 2).min(limit - target);
    (new_start, target)
}

/// Bounding box of the pixels equal to `id` in a row-major `width × height` label map,
/// padded by `margin` px on every side and clamped; `None` if no pixel has `id`.
pub fn bbox_from_mask<T: PartialEq>(
    mask: &[T],
    width: usize,
    height: usize,
    id: &T,
    margin: usize,
) -> Option<BBox> {
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (i, row) in mask.chunks_exact(width.max(1)).take(height).enumerate() {
        for (j, v) in row.iter().enumerate() {
            if v == id {
                (x0, y0, x1, y1) = (x0.min(j), y0.min(i), x1.max(j + 1), y1.max(i + 1));
            }
        }
    }
    if x0 == usize::MAX {
        return None;
    }
    let (x, y) = (x0.saturating_sub(margin), y0.saturating_sub(margin));
    let w = x1 + margin - x;
    let h = y1 + margin - y;
    BBox { x, y, w, h }.clamp(width, height)
}

/// Copies the box out of an RGB HWC image (box assumed inside the image).
pub fn crop_rgb(img: &[f32], width: usize, b: BBox) -> Vec<f32> {
    let mut out = Vec::with_capacity(b.w * b.h * 3);
    for row in b.y..b.y + b.h {
        let start = (row * width + b.x) * 3;
        out.extend_from_slice(&img[start..start + b.w * 3]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_box_with_margin_is_clamped() {
        // 10×6 map, object 2 covers columns 1..=3, rows 2..=4.
        let mut m = vec![0u8; 60];
        for i in 2..=4 {
            for j in 1..=3 {
                m[i * 10 + j] = 2;
            }
        }
        let b = bbox_from_mask(&m, 10, 6, &2, 2).unwrap();
        assert_eq!(
            b,
            BBox {
                x: 0,
                y: 0,
                w: 6,
                h: 6
            }
        );
        assert_eq!(
            bbox_from_mask(&m, 10, 6, &2, 0).unwrap(),
            BBox {
                x: 1,
                y: 2,
                w: 3,
                h: 3
            }
        );
        assert_eq!(bbox_from_mask(&m, 10, 6, &7, 2), None);
    }

    #[test]
    fn grow_stays_inside() {
        let b = BBox {
            x: 95,
            y: 10,
            w: 4,
            h: 20,
        }
        .grow_to(32, 100, 40);
        assert_eq!(
            b,
            BBox {
                x: 68,
                y: 4,
                w: 32,
                h: 32
            }
        );
        let small = BBox {
            x: 2,
            y: 10,
            w: 4,
            h: 5,
        }
        .grow_to(32, 100, 20);
        assert_eq!(
            small,
            BBox {
                x: 0,
                y: 0,
                w: 32,
                h: 20
            }
        );
        let c = BBox {
            x: 40,
            y: 0,
            w: 10,
            h: 10,
        }
        .grow_to(32, 100, 100);
        assert_eq!(
            c,
            BBox {
                x: 29,
                y: 0,
                w: 32,
                h: 32
            }
        );
    }

    #[test]
    fn clamp_and_crop() {
        assert_eq!(
            BBox {
                x: 5,
                y: 5,
                w: 10,
                h: 10
            }
            .clamp(4, 4),
            None
        );
        let img: Vec<f32> = (0..4 * 3 * 3).map(|v| v as f32).collect();
        let b = BBox {
            x: 1,
            y: 1,
            w: 2,
            h: 5,
        }
        .clamp(4, 3)
        .unwrap();
        assert_eq!(
            b,
            BBox {
                x: 1,
                y: 1,
                w: 2,
                h: 2
            }
        );
        let c = crop_rgb(&img, 4, b);
        assert_eq!(
            c,
            vec![15., 16., 17., 18., 19., 20., 27., 28., 29., 30., 31., 32.]
        );
    }
}
