//! Low-resolution mask logits → original image size, as SAM's `postprocess_masks`: bilinear
//! (align_corners=False) 256² → 1024², crop to the resized image, bilinear to the original
//! size. Both resizes are separable linear maps, so their composition is too: each output row
//! (column) is a fixed combination of at most four low-res rows (columns), computed once per
//! image size and applied as two sparse passes.

/// Taps of a PyTorch `F.interpolate(mode="bilinear", align_corners=False)` along one axis.
fn bilinear_taps(in_size: usize, out_size: usize) -> Vec<[(usize, f32); 2]> {
    let scale = in_size as f32 / out_size as f32;
    (0..out_size)
        .map(|d| {
            let src = ((d as f32 + 0.5) * scale - 0.5).max(0.0);
            let i0 = (src.floor() as usize).min(in_size - 1);
            let i1 = (i0 + 1).min(in_size - 1);
            let l1 = src - i0 as f32;
            [(i0, 1.0 - l1), (i1, l1)]
        })
        .collect()
}

/// One axis of the composed map: low-res (256) → padded 1024 → crop `input` → `original`.
fn composed_taps(
    low: usize,
    padded: usize,
    input: usize,
    original: usize,
) -> Vec<Vec<(usize, f32)>> {
    let first = bilinear_taps(low, padded);
    bilinear_taps(input, original)
        .into_iter()
        .map(|taps| {
            let mut out: Vec<(usize, f32)> = Vec::with_capacity(4);
            for (q, wq) in taps {
                for &(p, wp) in &first[q] {
                    match out.iter_mut().find(|(i, _)| *i == p) {
                        Some(e) => e.1 += wq * wp,
                        None => out.push((p, wq * wp)),
                    }
                }
            }
            out
        })
        .collect()
}

/// Precomputed composed resize for one (original size, resized size) pair.
#[derive(Debug, Clone)]
pub struct Upsampler {
    rows: Vec<Vec<(usize, f32)>>,
    cols: Vec<Vec<(usize, f32)>>,
    /// Low-res rows / columns the map reads (from 0), i.e. the decoder's needed extent.
    pub low_rows: usize,
    pub low_cols: usize,
}

impl Upsampler {
    /// `original` and `input` are (height, width); `low` the low-res side (256) and `padded`
    /// the encoder input side (1024).
    pub fn new(original: (usize, usize), input: (usize, usize), low: usize, padded: usize) -> Self {
        let rows = composed_taps(low, padded, input.0, original.0);
        let cols = composed_taps(low, padded, input.1, original.1);
        let extent =
            |t: &[Vec<(usize, f32)>]| t.iter().flatten().map(|&(i, _)| i + 1).max().unwrap_or(0);
        Self {
            low_rows: extent(&rows),
            low_cols: extent(&cols),
            rows,
            cols,
        }
    }

    pub fn height(&self) -> usize {
        self.rows.len()
    }

    pub fn width(&self) -> usize {
        self.cols.len()
    }

    /// Resize one low-res logit map (`lr_rows`×`lr_cols`, covering at least the extent) into
    /// `out` (height×width). `tmp` is scratch.
    pub fn apply(&self, low: &[f32], lr_cols: usize, tmp: &mut Vec<f32>, out: &mut Vec<f32>) {
        let (h, w) = (self.height(), self.width());
        let lc = self.low_cols;
        tmp.clear();
        tmp.resize(h * lc, 0.0);
        for (r, taps) in self.rows.iter().enumerate() {
            let dst = &mut tmp[r * lc..(r + 1) * lc];
            for &(p, wt) in taps {
                for (d, s) in dst.iter_mut().zip(&low[p * lr_cols..p * lr_cols + lc]) {
                    *d += wt * s;
                }
            }
        }
        out.clear();
        out.resize(h * w, 0.0);
        for (r, dst) in out.chunks_exact_mut(w).enumerate() {
            let src = &tmp[r * lc..(r + 1) * lc];
            for (d, taps) in dst.iter_mut().zip(&self.cols) {
                *d = taps.iter().map(|&(p, wt)| wt * src[p]).sum();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taps_sum_to_one_and_extent_is_tight() {
        let u = Upsampler::new((360, 480), (768, 1024), 256, 1024);
        for t in u.rows.iter().chain(&u.cols) {
            let s: f32 = t.iter().map(|x| x.1).sum();
            assert!((s - 1.0).abs() < 1e-5);
        }
        // 768 of 1024 rows are image: 192 low-res rows, plus one neighbour at the edge.
        assert!(u.low_rows == 193 || u.low_rows == 192, "{}", u.low_rows);
        assert_eq!(u.low_cols, 256);
    }

    #[test]
    fn constant_and_ramp_are_preserved() {
        let u = Upsampler::new((8, 8), (1024, 1024), 256, 1024);
        let low: Vec<f32> = (0..256 * 256).map(|i| (i % 256) as f32).collect();
        let (mut tmp, mut out) = (Vec::new(), Vec::new());
        u.apply(&low, 256, &mut tmp, &mut out);
        // Each output column j averages low-res columns around 32·j + 15.5.
        for j in 0..8 {
            assert!(
                (out[j] - (32.0 * j as f32 + 15.5)).abs() < 1e-3,
                "{} {}",
                j,
                out[j]
            );
            assert_eq!(out[j], out[7 * 8 + j]);
        }
    }
}
