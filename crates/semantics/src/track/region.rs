//! Full-image binary masks and what the tracker reads off them: box, area, IoU, points deep
//! inside, background points around, image borders touched, and a colour histogram.

/// Inclusive pixel box `[x0, y0, x1, y1]`.
pub type PixelBox = [usize; 4];

/// A binary mask over a width×height image, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    pub width: usize,
    pub height: usize,
    pub on: Vec<bool>,
}

impl Region {
    pub fn new(width: usize, height: usize, on: Vec<bool>) -> Self {
        assert_eq!(on.len(), width * height, "mask size");
        Self { width, height, on }
    }

    /// `logits > 0`, SAM's mask threshold.
    pub fn from_logits(width: usize, height: usize, logits: &[f32]) -> Self {
        Self::new(width, height, logits.iter().map(|&v| v > 0.0).collect())
    }

    pub fn empty(width: usize, height: usize) -> Self {
        Self::new(width, height, vec![false; width * height])
    }

    pub fn area(&self) -> usize {
        self.on.iter().filter(|&&b| b).count()
    }

    pub fn contains(&self, x: usize, y: usize) -> bool {
        x < self.width && y < self.height && self.on[y * self.width + x]
    }

    /// Tight inclusive box; `None` when empty.
    pub fn bbox(&self) -> Option<PixelBox> {
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for (i, _) in self.on.iter().enumerate().filter(|(_, &b)| b) {
            let (x, y) = (i % self.width, i / self.width);
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        (x0 != usize::MAX).then_some([x0, y0, x1, y1])
    }

    /// The pixels of `self` that `other` lacks.
    pub fn minus(&self, other: &Region) -> Region {
        let on = self
            .on
            .iter()
            .zip(&other.on)
            .map(|(&a, &b)| a && !b)
            .collect();
        Region::new(self.width, self.height, on)
    }

    /// The pixels within `margin` of `self`'s bounding box (clamped to the image) that are
    /// not in `self`: its immediate surroundings.
    pub fn ring(&self, margin: usize) -> Region {
        let mut on = vec![false; self.width * self.height];
        if let Some([x0, y0, x1, y1]) = self.bbox() {
            let (x1, y1) = (
                (x1 + margin).min(self.width - 1),
                (y1 + margin).min(self.height - 1),
            );
            for y in y0.saturating_sub(margin)..=y1 {
                for x in x0.saturating_sub(margin)..=x1 {
                    let i = y * self.width + x;
                    on[i] = !self.on[i];
                }
            }
        }
        Region::new(self.width, self.height, on)
    }

    /// Mean pixel position (x, y); `None` when empty.
    pub fn centroid(&self) -> Option<(f32, f32)> {
        let (mut sx, mut sy, mut n) = (0.0f64, 0.0f64, 0usize);
        for (i, _) in self.on.iter().enumerate().filter(|(_, &b)| b) {
            sx += (i % self.width) as f64;
            sy += (i / self.width) as f64;
            n += 1;
        }
        (n > 0).then(|| ((sx / n as f64) as f32, (sy / n as f64) as f32))
    }

    /// Intersection over union; 0 when both are empty.
    pub fn iou(&self, other: &Region) -> f32 {
        let (mut inter, mut union) = (0usize, 0usize);
        for (&a, &b) in self.on.iter().zip(&other.on) {
            inter += usize::from(a && b);
            union += usize::from(a || b);
        }
        if union == 0 {
            0.0
        } else {
            inter as f32 / union as f32
        }
    }

    /// How many of the image's four sides the mask touches.
    pub fn borders_touched(&self) -> usize {
        let Some([x0, y0, x1, y1]) = self.bbox() else {
            return 0;
        };
        [
            x0 == 0,
            y0 == 0,
            x1 + 1 == self.width,
            y1 + 1 == self.height,
        ]
        .iter()
        .filter(|&&b| b)
        .count()
    }

    /// City-block distance of each pixel to the nearest pixel outside the mask (the image
    /// border counts as outside); 0 outside. Two raster passes (Rosenfeld & Pfaltz).
    pub fn distance_inside(&self) -> Vec<u32> {
        let (w, h) = (self.width, self.height);
        let mut d: Vec<u32> = self
            .on
            .iter()
            .map(|&b| if b { u32::MAX } else { 0 })
            .collect();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if d[i] == 0 {
                    continue;
                }
                let up = if y > 0 { d[i - w] } else { 0 };
                let left = if x > 0 { d[i - 1] } else { 0 };
                d[i] = up.min(left).saturating_add(1);
            }
        }
        for y in (0..h).rev() {
            for x in (0..w).rev() {
                let i = y * w + x;
                if d[i] == 0 {
                    continue;
                }
                let down = if y + 1 < h { d[i + w] } else { 0 };
                let right = if x + 1 < w { d[i + 1] } else { 0 };
                d[i] = d[i].min(down.min(right).saturating_add(1));
            }
        }
        d
    }

    /// Up to `k` points well inside the mask, spread out: greedily the pixel maximizing
    /// min(distance to the mask's edge, half the distance to the points already chosen),
    /// keeping only points at least `min_depth` pixels from the edge. Pixel centres.
    pub fn interior_points(&self, k: usize, min_depth: u32) -> Vec<(f32, f32)> {
        let d = self.distance_inside();
        let w = self.width;
        let mut chosen: Vec<(usize, usize)> = Vec::new();
        for _ in 0..k {
            let mut best = (0u32, usize::MAX);
            for (i, &di) in d.iter().enumerate() {
                if di < min_depth.max(1) {
                    continue;
                }
                let (x, y) = (i % w, i / w);
                let spread = chosen
                    .iter()
                    .map(|&(cx, cy)| ((x.abs_diff(cx) + y.abs_diff(cy)) / 2) as u32)
                    .min()
                    .unwrap_or(u32::MAX);
                let score = di.min(spread);
                if score > best.0 {
                    best = (score, i);
                }
            }
            if best.1 == usize::MAX {
                break;
            }
            chosen.push((best.1 % w, best.1 / w));
        }
        chosen
            .into_iter()
            .map(|(x, y)| (x as f32 + 0.5, y as f32 + 0.5))
            .collect()
    }

    /// Up to `k` background points around `bbox`: the box's corners and edge midpoints pushed
    /// out by `gap` pixels, kept where they fall inside the image and outside `self`.
    pub fn points_around(&self, bbox: PixelBox, gap: f32, k: usize) -> Vec<(f32, f32)> {
        let [x0, y0, x1, y1] = bbox.map(|v| v as f32);
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let (l, r, t, b) = (x0 - gap, x1 + gap, y0 - gap, y1 + gap);
        // Edge midpoints first (closest to the object), then corners.
        let ring = [
            (l, cy),
            (r, cy),
            (cx, t),
            (cx, b),
            (l, t),
            (r, t),
            (l, b),
            (r, b),
        ];
        ring.into_iter()
            .filter(|&(x, y)| {
                x >= 0.0
                    && y >= 0.0
                    && (x as usize) < self.width
                    && (y as usize) < self.height
                    && !self.contains(x as usize, y as usize)
            })
            .take(k)
            .map(|(x, y)| (x.floor() + 0.5, y.floor() + 0.5))
            .collect()
    }

    /// The mask without its small islands: 4-connected components under `min_frac` of the
    /// largest one are dropped. SAM's masks sometimes take in a patch of similar texture
    /// apart from the object (a stain on the ground); kept, it would widen the next frame's
    /// box and drift. Components of similar size (an object split by an occluder) all stay.
    pub fn without_islands(&self, min_frac: f32) -> Region {
        let (w, h) = (self.width, self.height);
        let mut comp = vec![u32::MAX; w * h];
        let mut sizes: Vec<usize> = Vec::new();
        let mut stack = Vec::new();
        for start in 0..w * h {
            if !self.on[start] || comp[start] != u32::MAX {
                continue;
            }
            let id = sizes.len() as u32;
            let mut size = 0;
            comp[start] = id;
            stack.push(start);
            while let Some(i) = stack.pop() {
                size += 1;
                let (x, y) = (i % w, i / w);
                let mut visit = |j: usize| {
                    if self.on[j] && comp[j] == u32::MAX {
                        comp[j] = id;
                        stack.push(j);
                    }
                };
                if x > 0 {
                    visit(i - 1);
                }
                if x + 1 < w {
                    visit(i + 1);
                }
                if y > 0 {
                    visit(i - w);
                }
                if y + 1 < h {
                    visit(i + w);
                }
            }
            sizes.push(size);
        }
        let largest = sizes.iter().copied().max().unwrap_or(0) as f32;
        let keep: Vec<bool> = sizes
            .iter()
            .map(|&s| s as f32 >= min_frac * largest)
            .collect();
        let on = comp
            .iter()
            .map(|&c| c != u32::MAX && keep[c as usize])
            .collect();
        Region::new(w, h, on)
    }

    /// The mask moved by (dx, dy) pixels (rounded); what leaves the image is dropped.
    pub fn shifted(&self, (dx, dy): (f32, f32)) -> Region {
        let (w, h) = (self.width as i64, self.height as i64);
        let (dx, dy) = (dx.round() as i64, dy.round() as i64);
        let mut out = Region::empty(self.width, self.height);
        for (i, _) in self.on.iter().enumerate().filter(|(_, &b)| b) {
            let (x, y) = (i as i64 % w + dx, i as i64 / w + dy);
            if (0..w).contains(&x) && (0..h).contains(&y) {
                out.on[(y * w + x) as usize] = true;
            }
        }
        out
    }

    /// Normalized joint RGB histogram (4 bins per channel) of the pixels under the mask.
    pub fn histogram(&self, rgb: &[u8]) -> Histogram {
        let mut bins = [0.0f32; HIST_BINS];
        let mut n = 0.0f32;
        for (px, _) in rgb.chunks_exact(3).zip(&self.on).filter(|(_, &b)| b) {
            let bin =
                (px[0] as usize >> 6) * 16 + (px[1] as usize >> 6) * 4 + (px[2] as usize >> 6);
            bins[bin] += 1.0;
            n += 1.0;
        }
        if n > 0.0 {
            bins.iter_mut().for_each(|b| *b /= n);
        }
        Histogram(bins)
    }

    /// Distribution of chromaticity (r, g)/(r + g + b) over the mask, 8 × 8 bins over
    /// [0, 2/3) each (the last bin takes the rest); pixels darker than r + g + b < 48 have
    /// no reliable chromaticity and are skipped. A cast shadow keeps the chromaticity of
    /// the surface it darkens (Cucchiara et al. 2003, the HSV shadow test of video
    /// surveillance), so a shadow's chromaticity is its ground's.
    pub fn chroma_histogram(&self, rgb: &[u8]) -> Histogram {
        let mut bins = [0.0f32; HIST_BINS];
        let mut n = 0.0f32;
        for (px, _) in rgb.chunks_exact(3).zip(&self.on).filter(|(_, &b)| b) {
            let s = px.iter().map(|&v| v as u32).sum::<u32>();
            if s < 48 {
                continue;
            }
            let bin = |v: u8| ((v as u32 * 12 / s) as usize).min(7);
            bins[bin(px[0]) * 8 + bin(px[1])] += 1.0;
            n += 1.0;
        }
        if n > 0.0 {
            bins.iter_mut().for_each(|b| *b /= n);
        }
        Histogram(bins)
    }
}

const HIST_BINS: usize = 64;

/// A colour distribution (sums to 1, or all zero for an empty mask).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Histogram(pub [f32; HIST_BINS]);

impl Histogram {
    /// Bhattacharyya coefficient Σ√(pq): 1 for equal distributions, 0 for disjoint ones.
    pub fn similarity(&self, other: &Histogram) -> f32 {
        self.0
            .iter()
            .zip(&other.0)
            .map(|(a, b)| (a * b).sqrt())
            .sum()
    }
}

/// `bbox` grown by `frac` of its size (plus `pad` pixels) on every side, clamped to the
/// image, as a float XYXY box for a SAM prompt.
pub fn grow_box(bbox: PixelBox, frac: f32, pad: f32, width: usize, height: usize) -> [f32; 4] {
    let [x0, y0, x1, y1] = bbox.map(|v| v as f32);
    let (gx, gy) = ((x1 - x0 + 1.0) * frac + pad, (y1 - y0 + 1.0) * frac + pad);
    [
        (x0 - gx).max(0.0),
        (y0 - gy).max(0.0),
        (x1 + gx).min(width as f32 - 1.0),
        (y1 + gy).min(height as f32 - 1.0),
    ]
}

/// `bbox` moved by (dx, dy) pixels, kept inside the image.
pub fn shift_box(bbox: PixelBox, (dx, dy): (f32, f32), width: usize, height: usize) -> PixelBox {
    let mv = |v: usize, d: f32, size: usize| -> usize {
        (v as f32 + d).round().clamp(0.0, size as f32 - 1.0) as usize
    };
    [
        mv(bbox[0], dx, width),
        mv(bbox[1], dy, height),
        mv(bbox[2], dx, width),
        mv(bbox[3], dy, height),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(w: usize, h: usize, [x0, y0, x1, y1]: PixelBox) -> Region {
        Region::new(
            w,
            h,
            (0..w * h)
                .map(|i| (x0..=x1).contains(&(i % w)) && (y0..=y1).contains(&(i / w)))
                .collect(),
        )
    }

    #[test]
    fn box_area_iou_and_borders() {
        let a = rect(20, 10, [2, 3, 5, 6]);
        assert_eq!(a.bbox(), Some([2, 3, 5, 6]));
        assert_eq!(a.area(), 16);
        assert_eq!(a.centroid(), Some((3.5, 4.5)));
        let b = rect(20, 10, [4, 3, 7, 6]);
        assert!((a.iou(&b) - 8.0 / 24.0).abs() < 1e-6);
        assert_eq!(Region::empty(20, 10).iou(&Region::empty(20, 10)), 0.0);
        assert_eq!(a.borders_touched(), 0);
        assert_eq!(rect(20, 10, [0, 0, 19, 4]).borders_touched(), 3);
    }

    #[test]
    fn minus_and_ring() {
        let a = rect(20, 10, [2, 3, 5, 6]);
        let b = rect(20, 10, [4, 3, 7, 6]);
        assert_eq!(a.minus(&b), rect(20, 10, [2, 3, 3, 6]));
        assert_eq!(a.minus(&a).area(), 0);
        let ring = a.ring(1);
        assert_eq!(ring.area(), 6 * 6 - 4 * 4);
        assert_eq!(ring.bbox(), Some([1, 2, 6, 7]));
        assert_eq!(
            rect(20, 10, [0, 0, 19, 9]).ring(3).area(),
            0,
            "clamped to the image"
        );
    }

    #[test]
    fn chromaticity_ignores_brightness_and_dark_pixels() {
        let r = rect(2, 1, [0, 0, 1, 0]);
        let lit = [200u8, 120, 60, 200, 120, 60];
        let shaded = [100u8, 60, 30, 100, 60, 30];
        let grey = [90u8, 90, 90, 90, 90, 90];
        let (a, b) = (r.chroma_histogram(&lit), r.chroma_histogram(&shaded));
        assert!(
            (a.similarity(&b) - 1.0).abs() < 1e-6,
            "a shadow keeps its chromaticity"
        );
        assert!(a.similarity(&r.chroma_histogram(&grey)) < 0.01);
        assert_eq!(
            r.chroma_histogram(&[10, 10, 10, 5, 5, 5])
                .0
                .iter()
                .sum::<f32>(),
            0.0
        );
    }

    #[test]
    fn interior_points_sit_deep_and_apart() {
        let r = rect(40, 20, [5, 5, 34, 14]);
        let d = r.distance_inside();
        assert_eq!(d[5 * 40 + 5], 1);
        assert_eq!(d[10 * 40 + 20], 5);
        assert_eq!(d[0], 0);
        let pts = r.interior_points(3, 2);
        assert_eq!(pts.len(), 3);
        for &(x, y) in &pts {
            assert!(r.contains(x as usize, y as usize));
            assert!(d[y as usize * 40 + x as usize] >= 2);
        }
        // Spread: no two chosen points coincide.
        assert!(pts[0] != pts[1] && pts[1] != pts[2]);
        // Too thin for the depth asked: none.
        assert!(rect(40, 20, [5, 5, 34, 6]).interior_points(2, 3).is_empty());
    }

    #[test]
    fn points_around_stay_in_the_image_and_off_the_mask() {
        let r = rect(30, 30, [0, 10, 9, 19]);
        let pts = r.points_around([0, 10, 9, 19], 3.0, 8);
        assert!(!pts.is_empty());
        for &(x, y) in &pts {
            assert!(x >= 0.0 && y >= 0.0 && x < 30.0 && y < 30.0);
            assert!(!r.contains(x as usize, y as usize));
        }
        // The left side is off the image: of the 8 ring points, 3 fall outside.
        assert_eq!(pts.len(), 5);
    }

    #[test]
    fn islands_are_dropped_halves_kept() {
        let (w, h) = (20, 10);
        // A 6×6 block, a 1-pixel island, and a 5×6 block of similar size.
        let on = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                (x < 6 && y < 6) || (x, y) == (9, 9) || ((12..17).contains(&x) && y < 6)
            })
            .collect();
        let r = Region::new(w, h, on).without_islands(0.25);
        assert_eq!(r.area(), 36 + 30);
        assert!(!r.contains(9, 9));
        assert_eq!(Region::empty(w, h).without_islands(0.25).area(), 0);
    }

    #[test]
    fn shifted_moves_and_clips() {
        let r = rect(10, 10, [0, 0, 3, 3]);
        let s = r.shifted((2.0, 8.4));
        assert_eq!(s.bbox(), Some([2, 8, 5, 9]));
        assert_eq!(s.area(), 8);
    }

    #[test]
    fn histogram_similarity() {
        let r = rect(4, 1, [0, 0, 3, 0]);
        let red = [250u8, 0, 0].repeat(4);
        let blue = [0u8, 0, 250].repeat(4);
        let (hr, hb) = (r.histogram(&red), r.histogram(&blue));
        assert!((hr.similarity(&hr) - 1.0).abs() < 1e-6);
        assert_eq!(hr.similarity(&hb), 0.0);
    }

    #[test]
    fn grow_and_shift_clamp_to_the_image() {
        assert_eq!(
            grow_box([10, 10, 19, 19], 0.1, 0.0, 100, 100),
            [9.0, 9.0, 20.0, 20.0]
        );
        assert_eq!(
            grow_box([0, 0, 9, 9], 0.5, 0.0, 12, 12),
            [0.0, 0.0, 11.0, 11.0]
        );
        assert_eq!(
            shift_box([10, 10, 19, 19], (5.0, -20.0), 100, 100),
            [15, 0, 24, 0]
        );
    }
}
