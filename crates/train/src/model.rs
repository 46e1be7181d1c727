//! Canonical Gaussians stored raw (docs/architecture.md "Gaussian parameters"),
//! structure-of-arrays, with SH always allocated for degree 3 so raising the active degree
//! never reallocates (3DGS keeps `f_rest` for the full degree too and masks by
//! `active_sh_degree`).

use crate::error::{Result, TrainError};

/// SH coefficients per Gaussian at degree 3, `(3+1)²`.
pub const SH_COEFFS: usize = 16;
/// Floats of SH per Gaussian (coefficient-major, then RGB).
pub const SH_FLOATS: usize = SH_COEFFS * 3;

#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianModel {
    /// `N·3` canonical means.
    pub means: Vec<f32>,
    /// `N·4` quaternions w,x,y,z, unnormalized.
    pub quats: Vec<f32>,
    /// `N·3` log of the per-axis scales.
    pub log_scales: Vec<f32>,
    /// `N` opacity logits (opacity = sigmoid).
    pub opacity_logits: Vec<f32>,
    /// `N·16·3` SH coefficients, coefficient 0 is the DC term.
    pub sh: Vec<f32>,
    /// Active SH degree (0..=3).
    pub sh_degree: usize,
}

/// Row widths of the per-Gaussian arrays, in field order
/// (means, quats, log_scales, opacity_logits, sh).
pub const ROWS: [usize; 5] = [3, 4, 3, 1, SH_FLOATS];

impl GaussianModel {
    pub fn len(&self) -> usize {
        self.opacity_logits.len()
    }

    pub fn is_empty(&self) -> bool {
        self.opacity_logits.is_empty()
    }

    /// The five arrays in [`ROWS`] order, for code that treats them uniformly.
    pub fn arrays_mut(&mut self) -> [&mut Vec<f32>; 5] {
        [
            &mut self.means,
            &mut self.quats,
            &mut self.log_scales,
            &mut self.opacity_logits,
            &mut self.sh,
        ]
    }

    pub fn arrays(&self) -> [&Vec<f32>; 5] {
        [
            &self.means,
            &self.quats,
            &self.log_scales,
            &self.opacity_logits,
            &self.sh,
        ]
    }

    /// Checks that every array has N rows and every value is finite.
    pub fn validate(&self) -> Result<()> {
        let n = self.len();
        const NAMES: [&str; 5] = ["means", "quats", "log_scales", "opacity_logits", "sh"];
        for ((arr, row), name) in self.arrays().into_iter().zip(ROWS).zip(NAMES) {
            if arr.len() != n * row {
                return Err(TrainError::Length {
                    name,
                    got: arr.len(),
                    expected: n * row,
                });
            }
            if let Some(i) = arr.iter().position(|v| !v.is_finite()) {
                return Err(TrainError::Data(format!(
                    "Gaussian {} has a non-finite value in `{name}`",
                    i / row
                )));
            }
        }
        if self.sh_degree > 3 {
            return Err(TrainError::Data(format!(
                "SH degree {} > 3",
                self.sh_degree
            )));
        }
        Ok(())
    }

    /// Appends every row of `other` (its SH degree is ignored).
    pub fn append(&mut self, other: &GaussianModel) {
        for (dst, src) in self.arrays_mut().into_iter().zip(other.arrays()) {
            dst.extend_from_slice(src);
        }
    }

    /// Copies of the rows at `idx`, in that order.
    pub fn gather(&self, idx: &[usize]) -> GaussianModel {
        let mut out = GaussianModel {
            sh_degree: self.sh_degree,
            ..Default::default()
        };
        for ((dst, src), row) in out.arrays_mut().into_iter().zip(self.arrays()).zip(ROWS) {
            *dst = gather_rows(src, row, idx);
        }
        out
    }

    /// Keeps the rows where `keep` is true, preserving order.
    pub fn retain(&mut self, keep: &[bool]) {
        for (arr, row) in self.arrays_mut().into_iter().zip(ROWS) {
            retain_rows(arr, row, keep);
        }
    }

    /// Linear scales `exp(log_scale)`, `N·3`.
    pub fn scales_into(&self, out: &mut Vec<f32>) {
        out.clear();
        out.extend(self.log_scales.iter().map(|v| v.exp()));
    }
}

pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

pub fn inverse_sigmoid(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// Rows `idx` of a row-major array with `row` floats per row.
pub fn gather_rows(v: &[f32], row: usize, idx: &[usize]) -> Vec<f32> {
    let mut out = Vec::with_capacity(idx.len() * row);
    for &i in idx {
        out.extend_from_slice(&v[i * row..(i + 1) * row]);
    }
    out
}

/// In-place stable compaction of a row-major array by a per-row mask.
pub fn retain_rows<T: Copy>(v: &mut Vec<T>, row: usize, keep: &[bool]) {
    debug_assert_eq!(v.len(), keep.len() * row);
    let mut w = 0;
    for (i, &k) in keep.iter().enumerate() {
        if k {
            if w != i {
                v.copy_within(i * row..(i + 1) * row, w * row);
            }
            w += 1;
        }
    }
    v.truncate(w * row);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retain_and_gather_rows() {
        let mut v = vec![0., 1., 2., 3., 4., 5.];
        retain_rows(&mut v, 2, &[true, false, true]);
        assert_eq!(v, vec![0., 1., 4., 5.]);
        assert_eq!(gather_rows(&v, 2, &[1, 1, 0]), vec![4., 5., 4., 5., 0., 1.]);
    }

    #[test]
    fn sigmoid_inverts() {
        for p in [0.005f32, 0.1, 0.5, 0.99] {
            assert!((sigmoid(inverse_sigmoid(p)) - p).abs() < 1e-6);
        }
    }
}
