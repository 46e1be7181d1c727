//! A binary mask stored inside its bounding box, with SAM's box convention.

/// Inclusive pixel box `[x0, y0, x1, y1]` (SAM's `batched_mask_to_box`: max indices, not +1).
pub type BoxXyxy = [usize; 4];

#[derive(Debug, Clone, PartialEq)]
pub struct BoxMask {
    pub bbox: BoxXyxy,
    /// Row-major over the box, (x1−x0+1)×(y1−y0+1).
    pub bits: Vec<bool>,
    pub area: usize,
}

impl BoxMask {
    /// From a full-image predicate; `None` when empty.
    pub fn from_fn(h: usize, w: usize, on: impl Fn(usize) -> bool) -> Option<Self> {
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for y in 0..h {
            for x in 0..w {
                if on(y * w + x) {
                    x0 = x0.min(x);
                    x1 = x1.max(x);
                    y0 = y0.min(y);
                    y1 = y1.max(y);
                }
            }
        }
        if x0 == usize::MAX {
            return None;
        }
        let bw = x1 - x0 + 1;
        let mut bits = Vec::with_capacity(bw * (y1 - y0 + 1));
        for y in y0..=y1 {
            bits.extend((x0..=x1).map(|x| on(y * w + x)));
        }
        let area = bits.iter().filter(|&&b| b).count();
        Some(Self {
            bbox: [x0, y0, x1, y1],
            bits,
            area,
        })
    }

    pub fn box_width(&self) -> usize {
        self.bbox[2] - self.bbox[0] + 1
    }

    /// Whether full-image pixel (x, y) is on.
    pub fn contains(&self, x: usize, y: usize) -> bool {
        let [x0, y0, x1, y1] = self.bbox;
        x >= x0
            && x <= x1
            && y >= y0
            && y <= y1
            && self.bits[(y - y0) * self.box_width() + (x - x0)]
    }

    /// Full-image pixel indices that are on.
    pub fn pixels(&self, w: usize) -> impl Iterator<Item = usize> + '_ {
        let bw = self.box_width();
        let [x0, y0, ..] = self.bbox;
        self.bits
            .iter()
            .enumerate()
            .filter(|(_, &b)| b)
            .map(move |(i, _)| (y0 + i / bw) * w + x0 + i % bw)
    }
}

/// Box IoU as torchvision's `box_iou` computes it on SAM's inclusive boxes (areas are
/// (x1−x0)·(y1−y0), so the convention matches the official NMS exactly).
pub fn box_iou(a: &BoxXyxy, b: &BoxXyxy) -> f32 {
    let area = |r: &BoxXyxy| ((r[2] - r[0]) * (r[3] - r[1])) as f32;
    let iw = (a[2].min(b[2]) as f32 - a[0].max(b[0]) as f32).max(0.0);
    let ih = (a[3].min(b[3]) as f32 - a[1].max(b[1]) as f32).max(0.0);
    let inter = iw * ih;
    let union = area(a) + area(b) - inter;
    if union <= 0.0 {
        0.0
    } else {
        inter / union
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_fn_crops_to_box() {
        let m = BoxMask::from_fn(4, 5, |i| i == 6 || i == 13).unwrap();
        assert_eq!(m.bbox, [1, 1, 3, 2]);
        assert_eq!(m.area, 2);
        assert!(m.contains(1, 1) && m.contains(3, 2) && !m.contains(2, 1));
        assert_eq!(m.pixels(5).collect::<Vec<_>>(), vec![6, 13]);
        assert!(BoxMask::from_fn(2, 2, |_| false).is_none());
    }

    #[test]
    fn box_iou_matches_torchvision_convention() {
        assert_eq!(box_iou(&[0, 0, 10, 10], &[0, 0, 10, 10]), 1.0);
        assert!((box_iou(&[0, 0, 10, 10], &[5, 0, 15, 10]) - 50.0 / 150.0).abs() < 1e-6);
        assert_eq!(box_iou(&[0, 0, 1, 1], &[5, 5, 6, 6]), 0.0);
    }
}
