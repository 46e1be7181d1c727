//! LPIPS v0.1 (Zhang et al. 2018, github.com/richzhang/PerceptualSimilarity) with the AlexNet
//! (default, as gsplat's examples) or VGG16 (as Deformable-3DGS's `metrics.py`) backbone,
//! inference only, on our own NHWC im2col + `gemm` convolution (`lpips/conv.rs`).
//!
//! Semantics follow the reference `lpips.LPIPS(net=..., version='0.1')` forward exactly:
//! inputs in [0, 1] are mapped to [−1, 1] (`2x − 1`), then the ScalingLayer
//! `(x − shift) / scale`; each tapped ReLU output is unit-normalized over channels
//! (`x / (‖x‖₂ + 1e-10)`), the squared difference goes through the learned 1×1 linear layer
//! (no bias), is averaged over space, and the five layers are summed.
//!
//! Weights: `lpips_alex.safetensors` / `lpips_vgg.safetensors` written by
//! `semdynreg weights fetch lpips` (PyTorch layout: `net.conv{i}.weight` OIHW, `net.conv{i}.bias`,
//! `lin{j}.weight` (1, C, 1, 1)), found in `$SEMDYNREG_WEIGHTS`, default `./weights`.

mod conv;
mod tensor;
mod weights;

use conv::Conv2d;
use rayon::prelude::*;
use safetensors::SafeTensors;
use std::path::{Path, PathBuf};
use tensor::Nhwc;

/// ScalingLayer constants of the reference implementation (ImageNet statistics in [−1, 1]).
const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
const SCALE: [f32; 3] = [0.458, 0.448, 0.450];
/// Environment variable naming the weights directory.
pub const WEIGHTS_ENV: &str = "SEMDYNREG_WEIGHTS";

/// The LPIPS backbone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LpipsNet {
    /// AlexNet `features` relu1..relu5 (the reference default).
    #[default]
    Alex,
    /// VGG16 relu1_2, relu2_2, relu3_3, relu4_3, relu5_3.
    Vgg,
}

impl LpipsNet {
    /// File name of the converted weights inside the weights directory.
    pub fn file_name(self) -> &'static str {
        match self {
            LpipsNet::Alex => "lpips_alex.safetensors",
            LpipsNet::Vgg => "lpips_vgg.safetensors",
        }
    }

    /// Smallest image side the backbone accepts: AlexNet's stride-4 11×11 conv and two 3×3/2
    /// max-pools need 31 px; VGG16's four 2×2/2 pools need 16 px.
    pub fn min_side(self) -> usize {
        match self {
            LpipsNet::Alex => 31,
            LpipsNet::Vgg => 16,
        }
    }

    /// Convolutions (in order) as (out, in, kernel, padding, stride, max-pool before it,
    /// tapped after its ReLU). Max-pool sizes: AlexNet 3×3/2, VGG 2×2/2.
    fn layers(self) -> Vec<ConvSpec> {
        match self {
            LpipsNet::Alex => vec![
                ConvSpec::new(64, 3, 11, 2, 4, false, true),
                ConvSpec::new(192, 64, 5, 2, 1, true, true),
                ConvSpec::new(384, 192, 3, 1, 1, true, true),
                ConvSpec::new(256, 384, 3, 1, 1, false, true),
                ConvSpec::new(256, 256, 3, 1, 1, false, true),
            ],
            LpipsNet::Vgg => {
                // torchvision vgg16 cfg D; taps after conv 1, 3, 6, 9, 12.
                let chans = [
                    64, 64, 128, 128, 256, 256, 256, 512, 512, 512, 512, 512, 512,
                ];
                let pool_before = [2, 4, 7, 10];
                let taps = [1, 3, 6, 9, 12];
                (0..13)
                    .map(|i| {
                        let c_in = if i == 0 { 3 } else { chans[i - 1] };
                        let pool = pool_before.contains(&i);
                        ConvSpec::new(chans[i], c_in, 3, 1, 1, pool, taps.contains(&i))
                    })
                    .collect()
            }
        }
    }

    fn pool(self) -> (usize, usize) {
        match self {
            LpipsNet::Alex => (3, 2),
            LpipsNet::Vgg => (2, 2),
        }
    }
}

impl std::str::FromStr for LpipsNet {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "alex" | "alexnet" => Ok(LpipsNet::Alex),
            "vgg" | "vgg16" => Ok(LpipsNet::Vgg),
            _ => Err(format!("unknown LPIPS net '{s}' (expected alex or vgg)")),
        }
    }
}

#[derive(Clone, Copy)]
struct ConvSpec {
    c_out: usize,
    c_in: usize,
    kernel: usize,
    padding: usize,
    stride: usize,
    pool_before: bool,
    tap: bool,
}

impl ConvSpec {
    const fn new(
        c_out: usize,
        c_in: usize,
        kernel: usize,
        padding: usize,
        stride: usize,
        pool_before: bool,
        tap: bool,
    ) -> Self {
        Self {
            c_out,
            c_in,
            kernel,
            padding,
            stride,
            pool_before,
            tap,
        }
    }
}

/// Errors from loading or running LPIPS.
#[derive(Debug, thiserror::Error)]
pub enum LpipsError {
    /// The weights file is absent.
    #[error("LPIPS weights not found at {path} (run `semdynreg weights fetch lpips --dir DIR` and set {WEIGHTS_ENV}=DIR)")]
    NotFound { path: PathBuf },
    /// The weights file is unreadable or lacks a tensor of the expected shape.
    #[error("LPIPS weights {path}: {reason}")]
    BadWeights { path: PathBuf, reason: String },
    /// Image buffers do not match the given size.
    #[error("LPIPS: image buffers hold {a} and {b} floats, expected {width}x{height}x3")]
    BadLength {
        a: usize,
        b: usize,
        width: usize,
        height: usize,
    },
    /// The image is smaller than the backbone accepts.
    #[error("LPIPS-{net:?}: image {width}x{height} is smaller than the {min} px minimum side")]
    TooSmall {
        net: LpipsNet,
        width: usize,
        height: usize,
        min: usize,
    },
}

/// A loaded LPIPS model.
pub struct Lpips {
    net: LpipsNet,
    /// Each convolution with whether it is preceded by a max-pool and tapped.
    convs: Vec<(ConvSpec, Conv2d)>,
    /// Linear-layer weights, one per tap, `C` each.
    lins: Vec<Vec<f32>>,
}

/// The weights directory: `$SEMDYNREG_WEIGHTS`, or `./weights` when unset.
pub fn weights_dir() -> PathBuf {
    std::env::var_os(WEIGHTS_ENV)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("weights"))
}

impl Lpips {
    /// Loads `net`'s weights from [`weights_dir`].
    pub fn from_env(net: LpipsNet) -> Result<Self, LpipsError> {
        Self::load(net, &weights_dir().join(net.file_name()))
    }

    /// Loads `net`'s weights from a safetensors file written by `semdynreg weights fetch`.
    pub fn load(net: LpipsNet, path: &Path) -> Result<Self, LpipsError> {
        if !path.is_file() {
            return Err(LpipsError::NotFound {
                path: path.to_owned(),
            });
        }
        let bad = |reason: String| LpipsError::BadWeights {
            path: path.to_owned(),
            reason,
        };
        let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
        let st = SafeTensors::deserialize(&bytes).map_err(|e| bad(e.to_string()))?;
        let get = |name: &str, shape: &[usize]| weights::tensor_f32(&st, name, shape).map_err(bad);
        let mut convs = Vec::new();
        let mut lins = Vec::new();
        for (i, spec) in net.layers().into_iter().enumerate() {
            let k = spec.kernel;
            let w = get(
                &format!("net.conv{i}.weight"),
                &[spec.c_out, spec.c_in, k, k],
            )?;
            let b = get(&format!("net.conv{i}.bias"), &[spec.c_out])?;
            if spec.tap {
                lins.push(get(
                    &format!("lin{}.weight", lins.len()),
                    &[1, spec.c_out, 1, 1],
                )?);
            }
            let conv = Conv2d::from_oihw(&w, b, spec.c_in, k, spec.padding, spec.stride);
            convs.push((spec, conv));
        }
        Ok(Self { net, convs, lins })
    }

    /// The backbone this model uses.
    pub fn net(&self) -> LpipsNet {
        self.net
    }

    /// LPIPS distance between two RGB HWC images in [0, 1] of `width × height`.
    pub fn distance(
        &self,
        a: &[f32],
        b: &[f32],
        width: usize,
        height: usize,
    ) -> Result<f32, LpipsError> {
        let n = width * height * 3;
        if a.len() != n || b.len() != n {
            return Err(LpipsError::BadLength {
                a: a.len(),
                b: b.len(),
                width,
                height,
            });
        }
        let min = self.net.min_side();
        if width < min || height < min {
            return Err(LpipsError::TooSmall {
                net: self.net,
                width,
                height,
                min,
            });
        }
        // Both images go through the backbone as one batch of two.
        let mut data = to_scaled(a);
        data.extend(to_scaled(b));
        let x = Nhwc {
            n: 2,
            h: height,
            w: width,
            c: 3,
            data,
        };
        Ok(self.pair_distance(x))
    }

    /// Runs the backbone on the scaled pair `x` and sums each tapped layer's term as soon as
    /// it is produced (no copies of the taps are kept).
    fn pair_distance(&self, mut x: Nhwc) -> f32 {
        let (pk, ps) = self.net.pool();
        let mut lins = self.lins.iter();
        let mut total = 0.0f32;
        for (spec, conv) in &self.convs {
            if spec.pool_before {
                x = x.max_pool(pk, ps);
            }
            x = conv.forward_relu(&x);
            if spec.tap {
                let lin = lins
                    .next()
                    .expect("one linear layer per tap (checked at load)");
                total += layer_distance(&x, lin);
            }
        }
        total
    }
}

/// Pixels per rayon task in [`layer_distance`].
const DIST_TASK_PIXELS: usize = 256;

/// One layer's term for a batch of two (Zhang et al. 2018, Eq. 1): unit-normalize each
/// pixel's channels (`x / (‖x‖₂ + 1e-10)`, the reference `normalize_tensor`), squared
/// difference, weighted by the linear layer `lin`, averaged over space.
fn layer_distance(feat: &Nhwc, lin: &[f32]) -> f32 {
    let c = feat.c;
    let plane = feat.h * feat.w * c;
    let (fa, fb) = feat.data.split_at(plane);
    let pixel = |pa: &[f32], pb: &[f32]| {
        let inv = |p: &[f32]| 1.0 / (p.iter().map(|v| v * v).sum::<f32>().sqrt() + 1e-10);
        let (ia, ib) = (inv(pa), inv(pb));
        let d: f32 = pa
            .iter()
            .zip(pb)
            .zip(lin)
            .map(|((&u, &v), &w)| w * (u * ia - v * ib).powi(2))
            .sum();
        f64::from(d)
    };
    let sum: f64 = fa
        .par_chunks(c * DIST_TASK_PIXELS)
        .zip(fb.par_chunks(c * DIST_TASK_PIXELS))
        .map(|(ta, tb)| {
            ta.chunks_exact(c)
                .zip(tb.chunks_exact(c))
                .map(|(pa, pb)| pixel(pa, pb))
                .sum::<f64>()
        })
        .sum();
    (sum / (feat.h * feat.w) as f64) as f32
}

/// HWC [0, 1] → `(2x − 1 − shift) / scale` per channel (reference normalization), still
/// HWC (= NHWC for one image).
fn to_scaled(img: &[f32]) -> Vec<f32> {
    img.chunks_exact(3)
        .flat_map(|px| {
            std::array::from_fn::<f32, 3, _>(|c| (2.0 * px[c] - 1.0 - SHIFT[c]) / SCALE[c])
        })
        .collect()
}
