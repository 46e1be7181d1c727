//! A batch of feature maps in NHWC layout (channels innermost), the layout the im2col
//! convolution in [`super::conv`] reads contiguously, plus the max-pool between convs.

use rayon::prelude::*;

/// `n` images of `h × w` pixels with `c` channels, `data[((i·h + y)·w + x)·c + ch]`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Nhwc {
    pub n: usize,
    pub h: usize,
    pub w: usize,
    pub c: usize,
    pub data: Vec<f32>,
}

impl Nhwc {
    /// The `c` channels of pixel (`y`, `x`) of image `i`.
    pub fn pixel(&self, i: usize, y: usize, x: usize) -> &[f32] {
        let at = ((i * self.h + y) * self.w + x) * self.c;
        &self.data[at..at + self.c]
    }

    /// Max-pool with a `k × k` window and stride `s`, no padding, floor mode (PyTorch
    /// `nn.MaxPool2d(k, s)` as in torchvision's AlexNet (3, 2) and VGG16 (2, 2)).
    pub fn max_pool(&self, k: usize, s: usize) -> Nhwc {
        let ho = (self.h - k) / s + 1;
        let wo = (self.w - k) / s + 1;
        let c = self.c;
        let mut data = vec![0.0f32; self.n * ho * wo * c];
        // One output row per task: the k input rows it reads are contiguous in NHWC.
        data.par_chunks_mut(wo * c)
            .enumerate()
            .for_each(|(row, out)| {
                let (i, oy) = (row / ho, row % ho);
                for (ox, px) in out.chunks_exact_mut(c).enumerate() {
                    px.copy_from_slice(self.pixel(i, oy * s, ox * s));
                    for ky in 0..k {
                        for kx in 0..k {
                            let src = self.pixel(i, oy * s + ky, ox * s + kx);
                            for (o, &v) in px.iter_mut().zip(src) {
                                *o = o.max(v);
                            }
                        }
                    }
                }
            });
        Nhwc {
            n: self.n,
            h: ho,
            w: wo,
            c,
            data,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_pool_takes_window_maxima_in_floor_mode() {
        // One image, 5×5, 2 channels: channel 0 = y·5 + x, channel 1 = −(y·5 + x).
        let mut data = Vec::new();
        for v in 0..25 {
            data.extend([v as f32, -(v as f32)]);
        }
        let x = Nhwc {
            n: 1,
            h: 5,
            w: 5,
            c: 2,
            data,
        };
        let p = x.max_pool(3, 2);
        assert_eq!((p.h, p.w), (2, 2));
        // Window at (0, 0) covers 0..=12; its max of ch0 is 12, of ch1 is −0.
        assert_eq!(p.pixel(0, 0, 0), &[12.0, 0.0]);
        assert_eq!(p.pixel(0, 1, 1), &[24.0, -12.0]);
        let q = x.max_pool(2, 2);
        assert_eq!((q.h, q.w), (2, 2));
        assert_eq!(q.pixel(0, 1, 0), &[16.0, -10.0]);
    }
}
