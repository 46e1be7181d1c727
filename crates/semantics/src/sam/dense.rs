//! `nn.Linear` layers (TinyViT's, and CLIP's towers') as one pass each: `y = x·Wᵀ + b`, then GELU or a residual
//! added when asked, over blocks of rows split across rayon's threads. Candle's `Linear` runs
//! the product and then a separate broadcast add for the bias (single-threaded in candle-core
//! 0.9), and the GELU and residual were further passes over the same rows.
//!
//! The weight is kept transposed (in×out, row-major), which keeps `gemm` on its no-packing path
//! (as the decoder's `layers::Linear`). `linear_reference` is candle's `Linear`, which the tests
//! hold this to.

use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor};
use candle_nn::VarBuilder;
use rayon::prelude::*;

use super::elementwise::{add_assign, gelu_inplace};
use super::kernels::{matmul, transpose};
use super::tensor_ops::f32_slice;

/// `nn.Linear(in, out)` with a bias.
#[derive(Debug)]
pub struct Dense {
    /// in×out, row-major.
    wt: Vec<f32>,
    bias: Vec<f32>,
    n_in: usize,
    n_out: usize,
}

/// What follows the product, fused into the same pass over each block of rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Then {
    Nothing,
    Gelu,
}

impl Dense {
    /// Loads `weight` (out×in) and `bias` under `vb`.
    pub fn new(n_in: usize, n_out: usize, vb: VarBuilder) -> Result<Self> {
        let w = vb.get((n_out, n_in), "weight")?.flatten_all()?.to_vec1()?;
        let bias = vb.get(n_out, "bias")?.to_vec1()?;
        Ok(Self {
            wt: transpose(&w, n_out, n_in),
            bias,
            n_in,
            n_out,
        })
    }

    /// From a PyTorch-layout weight (out×in) and bias (out) already loaded (CLIP's towers).
    pub fn from_tensors(weight: &Tensor, bias: &Tensor) -> Result<Self> {
        let (n_out, n_in) = weight.dims2()?;
        let bias = bias.to_vec1::<f32>()?;
        if bias.len() != n_out {
            candle_core::bail!("linear: bias of {} for {n_out} outputs", bias.len());
        }
        let w = weight.flatten_all()?.to_vec1::<f32>()?;
        Ok(Self {
            wt: transpose(&w, n_out, n_in),
            bias,
            n_in,
            n_out,
        })
    }

    /// `x·Wᵀ + b` over the last axis of `x`, then `then`.
    pub fn forward(&self, x: &Tensor, then: Then) -> Result<Tensor> {
        x.contiguous()?.apply_op1_no_bwd(&Op { dense: self, then })
    }

    /// `residual + x·Wᵀ + b` (`residual` shaped as the output).
    pub fn forward_add(&self, x: &Tensor, residual: &Tensor) -> Result<Tensor> {
        x.contiguous()?
            .apply_op2_no_bwd(&residual.contiguous()?, &AddOp { dense: self })
    }

    /// The output rows for input rows `x` (rows × in), with `extra` applied per block.
    fn rows(&self, x: &[f32], extra: impl Fn(usize, &mut [f32]) + Sync) -> Vec<f32> {
        let (n_in, n_out) = (self.n_in, self.n_out);
        let rows = x.len() / n_in;
        let mut y = vec![0.0f32; rows * n_out];
        let block = (rows / (4 * rayon::current_num_threads())).clamp(16, 256);
        y.par_chunks_mut(block * n_out)
            .enumerate()
            .for_each(|(i, out)| {
                let r = out.len() / n_out;
                for row in out.chunks_exact_mut(n_out) {
                    row.copy_from_slice(&self.bias);
                }
                let xs = &x[i * block * n_in..(i * block + r) * n_in];
                matmul(
                    r,
                    n_out,
                    n_in,
                    xs,
                    (n_in, 1),
                    &self.wt,
                    (n_out, 1),
                    out,
                    n_out,
                    true,
                );
                extra(i * block * n_out, out);
            });
        y
    }

    fn out_shape(&self, layout: &Layout) -> Result<Shape> {
        let dims = layout.shape().dims();
        match dims.last() {
            Some(&d) if d == self.n_in => {
                let mut out = dims.to_vec();
                *out.last_mut().expect("non-empty") = self.n_out;
                Ok(Shape::from(out))
            }
            _ => candle_core::bail!("linear: input {dims:?}, the weights take {}", self.n_in),
        }
    }
}

struct Op<'a> {
    dense: &'a Dense,
    then: Then,
}

impl CustomOp1 for Op<'_> {
    fn name(&self) -> &'static str {
        "dense"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let shape = self.dense.out_shape(l)?;
        let x = f32_slice(s, l, "linear")?;
        let gelu = self.then == Then::Gelu;
        let y = self.dense.rows(x, |_, out| {
            if gelu {
                gelu_inplace(out);
            }
        });
        Ok((CpuStorage::F32(y), shape))
    }
}

struct AddOp<'a> {
    dense: &'a Dense,
}

impl CustomOp2 for AddOp<'_> {
    fn name(&self) -> &'static str {
        "dense-add"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let shape = self.dense.out_shape(l1)?;
        if l2.shape() != &shape {
            candle_core::bail!("linear: residual {:?}, output {shape:?}", l2.shape());
        }
        let (x, res) = (f32_slice(s1, l1, "linear")?, f32_slice(s2, l2, "linear")?);
        let y = self.dense.rows(x, |start, out| {
            add_assign(out, &res[start..start + out.len()])
        });
        Ok((CpuStorage::F32(y), shape))
    }
}

/// Candle's `Linear` over the same weights (tests only).
#[cfg(test)]
pub fn linear_reference(x: &Tensor, n_in: usize, n_out: usize, vb: VarBuilder) -> Result<Tensor> {
    use candle_core::Module;
    candle_nn::linear(n_in, n_out, vb)?.forward(x)
}

#[cfg(test)]
mod tests {
    use super::super::tensor_ops::testing::{max_abs_diff, tensor as t};
    use super::*;
    use candle_core::{DType, Device};
    use std::collections::HashMap;

    fn vb(n_in: usize, n_out: usize) -> VarBuilder<'static> {
        let mut m = HashMap::new();
        m.insert("weight".to_string(), (t(&[n_out, n_in], 1) * 0.3).unwrap());
        m.insert("bias".to_string(), t(&[n_out], 2));
        VarBuilder::from_tensors(m, DType::F32, &Device::Cpu)
    }

    #[test]
    fn matches_candle_linear_with_and_without_fusions() {
        // 3×37 rows: several blocks and a partial last one.
        let (n_in, n_out) = (24, 40);
        let x = t(&[3, 37, n_in], 5);
        let dense = Dense::new(n_in, n_out, vb(n_in, n_out)).unwrap();
        let want = linear_reference(&x, n_in, n_out, vb(n_in, n_out)).unwrap();
        let d = max_abs_diff(&dense.forward(&x, Then::Nothing).unwrap(), &want);
        assert!(d < 1e-5, "plain: {d}");
        let want_gelu = super::super::tensor_ops::gelu(&want).unwrap();
        let d = max_abs_diff(&dense.forward(&x, Then::Gelu).unwrap(), &want_gelu);
        assert!(d < 1e-5, "GELU: {d}");
        let res = t(&[3, 37, n_out], 9);
        let d = max_abs_diff(
            &dense.forward_add(&x, &res).unwrap(),
            &(&want + &res).unwrap(),
        );
        assert!(d < 1e-5, "residual: {d}");
        // A transposed (non-contiguous) input is made contiguous first.
        let xt = t(&[n_in, 5], 3).t().unwrap();
        let want = linear_reference(&xt, n_in, n_out, vb(n_in, n_out)).unwrap();
        let d = max_abs_diff(&dense.forward(&xt, Then::Nothing).unwrap(), &want);
        assert!(d < 1e-5, "transposed input: {d}");
    }

    #[test]
    fn shape_mismatches_are_errors() {
        let dense = Dense::new(4, 6, vb(4, 6)).unwrap();
        assert!(dense.forward(&t(&[2, 5], 0), Then::Nothing).is_err());
        assert!(dense.forward_add(&t(&[2, 4], 0), &t(&[2, 5], 0)).is_err());
    }
}
