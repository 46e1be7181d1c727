//! Which frames and which pixels the crop tables score.
//!
//! Time steps: the paper reports t = 0, 1, …, 5 s. Our scenes store time in [0, 1]; toycars
//! maps it to `duration_s` = 6 s. For each second we take the evaluation frame whose time
//! is nearest to `t_seconds / duration_s` (ties → the earlier frame). With toycars' 120
//! frames and every 8th frame in the test split, the chosen frame is at most ~0.2 s away;
//! the frame actually used is written into `results.json`.
//!
//! Crop boxes: the ground-truth box is the tight bounding box of the object's pixels in
//! its mask; we pad each side by `max(min_pad_px, pad_fraction × longer box side)` and clamp
//! to the image, like the paper's "zoomed-in views", so the box includes the object's
//! outline and a band of background where blur and ghosting show. A box still shorter than
//! `min_side` (31 px, the smallest input LPIPS-AlexNet accepts) is grown around its centre
//! (shifted to stay inside the image), so all three metrics score the same pixels.

/// An axis-aligned pixel rectangle, `x, y` its top-left corner.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CropBox {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl CropBox {
    pub fn to_array(self) -> [u32; 4] {
        [self.x, self.y, self.width, self.height]
    }
}

/// How far a ground-truth box is grown before scoring.
#[derive(Clone, Copy, Debug)]
pub struct CropPolicy {
    /// Padding as a fraction of the box's longer side, per side.
    pub pad_fraction: f32,
    /// Lower bound on the padding, pixels per side.
    pub min_pad_px: u32,
    /// Objects with fewer mask pixels than this count as not visible.
    pub min_pixels: usize,
    /// Smallest crop side after padding (LPIPS-AlexNet needs 31 px).
    pub min_side: u32,
}

impl Default for CropPolicy {
    fn default() -> Self {
        Self {
            pad_fraction: 0.15,
            min_pad_px: 16,
            min_pixels: 16,
            min_side: 31,
        }
    }
}

impl CropPolicy {
    /// The rule in words, `masks` naming where the masks come from.
    pub fn describe(&self, masks: &str) -> String {
        format!(
            "{masks} box padded by max({} px, {}% of its longer side) per side, \
             clamped to the image, grown to ≥ {} px per side; objects with < {} mask pixels \
             are not scored",
            self.min_pad_px,
            // Rounded: 0.15 × 100 in f32 prints as 15.000001.
            (self.pad_fraction as f64 * 1e5).round() / 1e3,
            self.min_side,
            self.min_pixels
        )
    }

    /// The padded box of object `id` in an `H·W` ID mask, or `None` if it is not visible.
    pub fn object_crop(&self, mask: &[u8], width: u32, height: u32, id: u8) -> Option<CropBox> {
        let tight = tight_box(mask, width, height, id, self.min_pixels)?;
        let side = tight.width.max(tight.height) as f32;
        let pad = ((side * self.pad_fraction).round() as u32).max(self.min_pad_px);
        let (x, w) = pad_span(tight.x, tight.width, pad, self.min_side, width);
        let (y, h) = pad_span(tight.y, tight.height, pad, self.min_side, height);
        Some(CropBox {
            x,
            y,
            width: w,
            height: h,
        })
    }
}

/// One axis of the padded box: `[start − pad, end + pad)` clamped to `[0, limit)`, then
/// grown around its centre to `min_len` (≤ `limit`) and shifted back inside.
fn pad_span(start: u32, len: u32, pad: u32, min_len: u32, limit: u32) -> (u32, u32) {
    let lo = start.saturating_sub(pad);
    let hi = (start + len + pad).min(limit);
    let want = min_len.min(limit);
    if hi - lo >= want {
        return (lo, hi - lo);
    }
    let centre = (lo + hi) / 2;
    let lo = centre.saturating_sub(want / 2).min(limit - want);
    (lo, want)
}

/// Tight bounding box of the pixels equal to `id`; `None` if fewer than `min_pixels`.
pub fn tight_box(
    mask: &[u8],
    width: u32,
    height: u32,
    id: u8,
    min_pixels: usize,
) -> Option<CropBox> {
    let (w, h) = (width as usize, height as usize);
    debug_assert_eq!(mask.len(), w * h);
    let (mut x0, mut y0, mut x1, mut y1, mut count) = (usize::MAX, usize::MAX, 0, 0, 0usize);
    for (row, line) in mask.chunks_exact(w).take(h).enumerate() {
        for (col, _) in line.iter().enumerate().filter(|(_, &v)| v == id) {
            x0 = x0.min(col);
            x1 = x1.max(col);
            y0 = y0.min(row);
            y1 = y1.max(row);
            count += 1;
        }
    }
    (count >= min_pixels.max(1)).then(|| CropBox {
        x: x0 as u32,
        y: y0 as u32,
        width: (x1 - x0 + 1) as u32,
        height: (y1 - y0 + 1) as u32,
    })
}

/// For each time step in seconds, the index of the frame whose time (in [0, 1]) is nearest
/// to `t / duration_s`; ties go to the earlier frame. `None` if `times` is empty.
pub fn nearest_frames(times: &[f32], t_seconds: &[u32], duration_s: f32) -> Option<Vec<usize>> {
    if times.is_empty() {
        return None;
    }
    let pick = |t: u32| {
        let target = t as f32 / duration_s;
        let mut best = 0;
        for (i, &time) in times.iter().enumerate() {
            if (time - target).abs() < (times[best] - target).abs() {
                best = i;
            }
        }
        best
    };
    Some(t_seconds.iter().map(|&t| pick(t)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask_with_rect(w: u32, h: u32, id: u8, r: CropBox) -> Vec<u8> {
        let mut m = vec![255u8; (w * h) as usize];
        for y in r.y..r.y + r.height {
            for x in r.x..r.x + r.width {
                m[(y * w + x) as usize] = id;
            }
        }
        m
    }

    #[test]
    fn tight_box_finds_the_rectangle() {
        let r = CropBox {
            x: 10,
            y: 5,
            width: 7,
            height: 3,
        };
        let m = mask_with_rect(40, 30, 2, r);
        assert_eq!(tight_box(&m, 40, 30, 2, 1), Some(r));
        assert_eq!(tight_box(&m, 40, 30, 1, 1), None);
        assert_eq!(tight_box(&m, 40, 30, 2, 22), None, "21 pixels < 22");
    }

    #[test]
    fn padding_uses_fraction_or_minimum_and_clamps() {
        let policy = CropPolicy {
            pad_fraction: 0.25,
            min_pad_px: 2,
            min_pixels: 1,
            min_side: 1,
        };
        // 40 px wide box → 10 px padding per side.
        let r = CropBox {
            x: 50,
            y: 50,
            width: 40,
            height: 20,
        };
        let m = mask_with_rect(200, 150, 0, r);
        let c = policy.object_crop(&m, 200, 150, 0).unwrap();
        assert_eq!(
            c,
            CropBox {
                x: 40,
                y: 40,
                width: 60,
                height: 40
            }
        );
        // A tiny box at the corner: minimum padding, clamped at 0 and at the image edge.
        let r = CropBox {
            x: 0,
            y: 148,
            width: 4,
            height: 2,
        };
        let m = mask_with_rect(200, 150, 0, r);
        let c = policy.object_crop(&m, 200, 150, 0).unwrap();
        assert_eq!(
            c,
            CropBox {
                x: 0,
                y: 146,
                width: 6,
                height: 4
            }
        );
        // The same box grown to the minimum side, kept inside the image.
        let policy = CropPolicy {
            min_side: 31,
            ..policy
        };
        let c = policy.object_crop(&m, 200, 150, 0).unwrap();
        assert_eq!(
            c,
            CropBox {
                x: 0,
                y: 119,
                width: 31,
                height: 31
            }
        );
        // A minimum larger than the image is limited to the image.
        let policy = CropPolicy {
            min_side: 500,
            ..policy
        };
        let c = policy.object_crop(&m, 200, 150, 0).unwrap();
        assert_eq!(
            c,
            CropBox {
                x: 0,
                y: 0,
                width: 200,
                height: 150
            }
        );
    }

    #[test]
    fn nearest_frames_picks_closest_time() {
        // 15 test frames at every 8th of 120 frames, time = i / 119.
        let times: Vec<f32> = (0..120).step_by(8).map(|i| i as f32 / 119.0).collect();
        let idx = nearest_frames(&times, &[0, 1, 2, 3, 4, 5], 6.0).unwrap();
        assert_eq!(idx[0], 0);
        for (t, &i) in idx.iter().enumerate() {
            let target = t as f32 / 6.0;
            for &other in &times {
                assert!((times[i] - target).abs() <= (other - target).abs() + 1e-7);
            }
            assert!(
                (times[i] - target).abs() * 6.0 < 0.21,
                "t={t}s picked {}",
                times[i]
            );
        }
        assert!(nearest_frames(&[], &[0], 6.0).is_none());
        // Ties go to the earlier frame.
        assert_eq!(nearest_frames(&[0.25, 0.75], &[1], 2.0).unwrap(), vec![0]);
    }
}
