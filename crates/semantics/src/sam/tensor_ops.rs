//! Candle custom ops over whole tensors, built on the vectorized kernels of `elementwise.rs`
//! and split over rayon's threads: the exact (erf) GELU, and the window attention's biased
//! softmax. Used by the encoder's layers (`conv_bn.rs`, `dense.rs`, `tiny_vit.rs`).

use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

use super::elementwise::{gelu_inplace, softmax_rows_biased};

/// The f32 elements of a contiguous tensor's storage, or an error naming `op`.
pub(crate) fn f32_slice<'a>(s: &'a CpuStorage, l: &Layout, op: &str) -> Result<&'a [f32]> {
    let CpuStorage::F32(v) = s else {
        candle_core::bail!("{op}: f32 tensors only");
    };
    let Some((a, b)) = l.contiguous_offsets() else {
        candle_core::bail!("{op}: contiguous tensors only");
    };
    Ok(&v[a..b])
}

/// Exact GELU over a contiguous f32 tensor (see the module comment).
struct GeluErf;

impl CustomOp1 for GeluErf {
    fn name(&self) -> &'static str {
        "gelu-erf-simd"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let mut out = f32_slice(storage, layout, "gelu-erf-simd")?.to_vec();
        out.par_chunks_mut(1 << 15).for_each(gelu_inplace);
        Ok((CpuStorage::F32(out), layout.shape().clone()))
    }
}

pub(crate) trait GeluExt {
    fn gelu_erf_simd(&self) -> Result<Tensor>;
}

impl GeluExt for Tensor {
    fn gelu_erf_simd(&self) -> Result<Tensor> {
        gelu(self)
    }
}

/// Exact GELU of a tensor (any layout), vectorized and multi-threaded.
pub fn gelu(xs: &Tensor) -> Result<Tensor> {
    xs.contiguous()?.apply_op1_no_bwd(&GeluErf)
}

/// `softmax(scores·scale + ab)` over the last axis, the relative-position bias `ab`
/// (heads × N × N) broadcast over the windows: one pass per row instead of candle's scale,
/// broadcast add and scalar-`exp` softmax (three passes over the scores).
pub struct BiasedSoftmax {
    pub scale: f32,
}

impl CustomOp2 for BiasedSoftmax {
    fn name(&self) -> &'static str {
        "biased-softmax"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (x, bias) = (
            f32_slice(s1, l1, "biased-softmax")?,
            f32_slice(s2, l2, "biased-softmax")?,
        );
        let n = l1.shape().dims().last().copied().unwrap_or(0);
        let per_bias = bias.len();
        if n == 0 || per_bias == 0 || x.len() % per_bias != 0 || per_bias % (n * n) != 0 {
            candle_core::bail!(
                "biased-softmax: scores {:?} do not repeat bias {:?}",
                l1.shape(),
                l2.shape()
            );
        }
        let mut out = x.to_vec();
        out.par_chunks_mut(n * n)
            .enumerate()
            .for_each(|(i, chunk)| {
                let b = &bias[(i * n * n) % per_bias..][..n * n];
                softmax_rows_biased(chunk, b, n, self.scale);
            });
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }
}

/// Deterministic test tensors and their comparison, shared by the encoder's layer tests.
#[cfg(test)]
pub(crate) mod testing {
    use candle_core::{Device, Tensor};

    /// A tensor of `shape` with values spread over [−1, 1), different per `seed`.
    pub fn tensor(shape: &[usize], seed: usize) -> Tensor {
        let n: usize = shape.iter().product();
        let v: Vec<f32> = (0..n)
            .map(|i| ((i * 2654435761 + seed * 97) % 1000) as f32 / 500.0 - 1.0)
            .collect();
        Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
    }

    /// max |a − b| over two tensors of one shape.
    pub fn max_abs_diff(a: &Tensor, b: &Tensor) -> f32 {
        assert_eq!(a.dims(), b.dims());
        let d = (a - b).unwrap().abs().unwrap().flatten_all().unwrap();
        d.max(0).unwrap().to_scalar().unwrap()
    }
}

#[cfg(test)]
mod tests {
    use super::testing::{max_abs_diff, tensor};
    use super::*;

    /// Scores over [−5, 5), the range a softmax meets.
    fn t(shape: &[usize], seed: usize) -> Tensor {
        (tensor(shape, seed) * 5.0).unwrap()
    }

    #[test]
    fn biased_softmax_matches_candle_scale_add_softmax() {
        // 3 windows × 2 heads of 5×5 scores; the bias repeats per window, not per head.
        let (scores, ab) = (t(&[3, 2, 5, 5], 1), t(&[2, 5, 5], 2));
        let got = scores
            .apply_op2_no_bwd(&ab, &BiasedSoftmax { scale: 0.3 })
            .unwrap();
        let z = (&scores * 0.3).unwrap().broadcast_add(&ab).unwrap();
        let want = candle_nn::ops::softmax_last_dim(&z).unwrap();
        let d = max_abs_diff(&got, &want);
        assert!(d < 1e-6, "max |Δ| = {d}");
        // A bias that does not tile the scores is an error, not a panic.
        let bad = t(&[3, 5, 5], 3);
        assert!(t(&[2, 2, 5, 5], 1)
            .apply_op2_no_bwd(&bad, &BiasedSoftmax { scale: 1.0 })
            .is_err());
    }

    #[test]
    fn gelu_of_a_transposed_tensor_is_elementwise() {
        let x = t(&[4, 6], 5);
        let got = gelu(&x.t().unwrap()).unwrap();
        let want: Vec<f32> = x
            .t()
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap()
            .into_iter()
            .map(crate::sam::elementwise::gelu)
            .collect();
        assert_eq!(got.flatten_all().unwrap().to_vec1::<f32>().unwrap(), want);
    }
}
