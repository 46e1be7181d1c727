//! SAM's `LayerNorm2d` (`segment_anything/modeling/common.py`): a layer norm over the channel
//! axis of an NCHW tensor, at every pixel, with a per-channel affine. Used by MobileSAM's neck;
//! our own so that the MobileSAM path does not need candle-transformers (see
//! `crates/semantics/Cargo.toml`, feature `sam-vit`).

use candle_core::{Result, Tensor};
use candle_nn::{Module, VarBuilder};

#[derive(Debug)]
pub struct LayerNorm2d {
    weight: Tensor,
    bias: Tensor,
    channels: usize,
    eps: f64,
}

impl LayerNorm2d {
    /// Loads `weight` and `bias` (both `channels` long) from `vb`.
    pub fn new(channels: usize, eps: f64, vb: VarBuilder) -> Result<Self> {
        Ok(Self {
            weight: vb.get(channels, "weight")?,
            bias: vb.get(channels, "bias")?,
            channels,
            eps,
        })
    }
}

impl Module for LayerNorm2d {
    /// `u = mean_c(x)`, `s = mean_c((x − u)²)`, `(x − u) / √(s + ε) · w + b`, as the official
    /// module (biased variance, ε inside the root).
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let centred = x.broadcast_sub(&x.mean_keepdim(1)?)?;
        let var = centred.sqr()?.mean_keepdim(1)?;
        let normed = centred.broadcast_div(&(var + self.eps)?.sqrt()?)?;
        let shape = (1, self.channels, 1, 1);
        normed
            .broadcast_mul(&self.weight.reshape(shape)?)?
            .broadcast_add(&self.bias.reshape(shape)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};
    use std::collections::HashMap;

    /// Each pixel's channels come out with zero mean and unit (biased) variance before the
    /// affine; the affine then scales and shifts per channel.
    #[test]
    fn normalizes_each_pixel_over_channels() {
        let dev = Device::Cpu;
        let mut ws = HashMap::new();
        ws.insert(
            "weight".to_string(),
            Tensor::new(&[2.0f32, 1.0, 0.5], &dev).unwrap(),
        );
        ws.insert(
            "bias".to_string(),
            Tensor::new(&[1.0f32, 0.0, -1.0], &dev).unwrap(),
        );
        let vb = VarBuilder::from_tensors(ws, DType::F32, &dev);
        let ln = LayerNorm2d::new(3, 0.0, vb).unwrap();
        // One image, 3 channels, 1×2 pixels: pixel 0 has channels (1, 2, 3), pixel 1 (4, 4, 10).
        let x = Tensor::new(&[1.0f32, 4.0, 2.0, 4.0, 3.0, 10.0], &dev)
            .unwrap()
            .reshape((1, 3, 1, 2))
            .unwrap();
        let y: Vec<f32> = ln
            .forward(&x)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let z0 = [-1.0f32, 0.0, 1.0].map(|v| v * (1.5f32).sqrt());
        let z1 = [-1.0f32, -1.0, 2.0].map(|v| v * 2.0 / 8.0f32.sqrt());
        let (w, b) = ([2.0f32, 1.0, 0.5], [1.0f32, 0.0, -1.0]);
        for c in 0..3 {
            assert!((y[2 * c] - (z0[c] * w[c] + b[c])).abs() < 1e-5, "{y:?}");
            assert!((y[2 * c + 1] - (z1[c] * w[c] + b[c])).abs() < 1e-5, "{y:?}");
        }
    }
}
