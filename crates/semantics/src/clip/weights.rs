//! Reading CLIP checkpoints into one naming scheme (OpenCLIP's `state_dict` keys), with
//! every tensor converted to `f32` on the CPU.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{DType, Device, Tensor};
use rand::{Rng, SeedableRng};

use super::config::{ClipConfig, TextConfig, VisionConfig};
use super::ClipError;

/// Which published layout a checkpoint uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// OpenCLIP / OpenAI `state_dict` keys (`visual.conv1.weight`, …).
    OpenClip,
    /// Hugging Face `CLIPModel` keys (`vision_model.embeddings.patch_embedding.weight`, …).
    HuggingFace,
}

/// Named `f32` tensors in OpenCLIP naming, plus the file they came from (for errors).
pub struct Weights {
    pub path: PathBuf,
    pub layout: Layout,
    tensors: HashMap<String, Tensor>,
}

impl Weights {
    /// Loads `.safetensors`, or a PyTorch pickle (`.bin`, `.pt`, `.pth`) `state_dict`.
    pub fn load(path: &Path) -> Result<Self, ClipError> {
        if !path.is_file() {
            return Err(ClipError::MissingWeights {
                path: path.to_path_buf(),
            });
        }
        let read_err = |source| ClipError::ReadWeights {
            path: path.to_path_buf(),
            source,
        };
        let is_safetensors = path.extension().is_some_and(|e| e == "safetensors");
        let raw: Vec<(String, Tensor)> = if is_safetensors {
            candle_core::safetensors::load(path, &Device::Cpu)
                .map_err(read_err)?
                .into_iter()
                .collect()
        } else {
            crate::pth::check(path).map_err(|m| read_err(candle_core::Error::Msg(m)))?;
            candle_core::pickle::read_all(path).map_err(read_err)?
        };
        let mut tensors = HashMap::with_capacity(raw.len());
        for (name, t) in raw {
            // Checkpoints are f16/bf16/f32; inference runs in f32 like the reference code.
            let name = name
                .strip_prefix("module.")
                .map(str::to_string)
                .unwrap_or(name);
            tensors.insert(name, t.to_dtype(DType::F32)?);
        }
        let layout = if tensors.contains_key("vision_model.embeddings.patch_embedding.weight") {
            Layout::HuggingFace
        } else if tensors.contains_key("visual.conv1.weight") {
            Layout::OpenClip
        } else {
            return Err(ClipError::Layout {
                path: path.to_path_buf(),
                reason: "neither OpenCLIP keys (visual.conv1.weight) nor Hugging Face CLIPModel keys \
                         (vision_model.embeddings.patch_embedding.weight) found; only ViT CLIP models are supported"
                    .into(),
            });
        };
        let mut w = Self {
            path: path.to_path_buf(),
            layout,
            tensors,
        };
        if layout == Layout::HuggingFace {
            w.rename_hf()?;
        }
        Ok(w)
    }

    /// Random weights of the given architecture (OpenCLIP naming), reproducible from `seed`:
    /// for speed measurements without a checkpoint. LayerNorms are identity, the rest is
    /// uniform in ±0.02.
    pub fn random(config: &ClipConfig, seed: u64) -> Result<Self, ClipError> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut tensors = HashMap::new();
        for (name, shape) in expected_shapes(config) {
            let n: usize = shape.iter().product();
            let data: Vec<f32> = if name.contains("ln") && name.ends_with(".weight") {
                vec![1.0; n]
            } else if name.contains("ln") {
                vec![0.0; n]
            } else {
                (0..n).map(|_| rng.gen_range(-0.02..0.02)).collect()
            };
            tensors.insert(name, Tensor::from_vec(data, shape, &Device::Cpu)?);
        }
        Ok(Self {
            path: PathBuf::from("<random>"),
            layout: Layout::OpenClip,
            tensors,
        })
    }

    fn layout_err(&self, reason: String) -> ClipError {
        ClipError::Layout {
            path: self.path.clone(),
            reason,
        }
    }

    /// The tensor `name`, checked against `shape`.
    pub fn get(&self, name: &str, shape: &[usize]) -> Result<Tensor, ClipError> {
        let t = self
            .tensors
            .get(name)
            .ok_or_else(|| self.layout_err(format!("missing tensor {name}")))?;
        if t.dims() != shape {
            return Err(self.layout_err(format!(
                "tensor {name} has shape {:?}, expected {shape:?}",
                t.dims()
            )));
        }
        Ok(t.clone())
    }

    fn dims(&self, name: &str) -> Result<Vec<usize>, ClipError> {
        let t = self
            .tensors
            .get(name)
            .ok_or_else(|| self.layout_err(format!("missing tensor {name}")))?;
        Ok(t.dims().to_vec())
    }

    /// The shape of `name`, which must have `rank` dimensions (indexing it is then safe).
    fn dims_n(&self, name: &str, rank: usize) -> Result<Vec<usize>, ClipError> {
        let d = self.dims(name)?;
        if d.len() != rank {
            return Err(self.layout_err(format!(
                "tensor {name} has shape {d:?}, expected {rank} dimensions"
            )));
        }
        Ok(d)
    }

    fn count_blocks(&self, prefix: &str) -> usize {
        (0..)
            .take_while(|i| {
                self.tensors
                    .contains_key(&format!("{prefix}.resblocks.{i}.ln_1.weight"))
            })
            .count()
    }

    /// Architecture from tensor shapes; heads assume OpenCLIP's default head width of 64
    /// (true of every OpenAI and OpenCLIP ViT-B/L/H) — a config file overrides it.
    pub fn infer_config(&self) -> Result<ClipConfig, ClipError> {
        let conv = self.dims_n("visual.conv1.weight", 4)?;
        let vpos = self.dims_n("visual.positional_embedding", 2)?;
        let proj = self.dims_n("visual.proj", 2)?;
        let grid = ((vpos[0].saturating_sub(1)) as f64).sqrt().round() as usize;
        let (vw, patch) = (conv[0], conv[2]);
        let tok = self.dims_n("token_embedding.weight", 2)?;
        let tpos = self.dims_n("positional_embedding", 2)?;
        let v_mlp = self.dims_n("visual.transformer.resblocks.0.mlp.c_fc.weight", 2)?[0];
        let t_mlp = self.dims_n("transformer.resblocks.0.mlp.c_fc.weight", 2)?[0];
        Ok(ClipConfig {
            embed_dim: proj[1],
            vision: VisionConfig {
                image_size: grid.saturating_mul(patch),
                patch_size: patch,
                width: vw,
                layers: self.count_blocks("visual.transformer"),
                heads: (vw / 64).max(1),
                mlp_width: v_mlp,
            },
            text: TextConfig {
                context_length: tpos[0],
                vocab_size: tok[0],
                width: tok[1],
                layers: self.count_blocks("transformer"),
                heads: (tok[1] / 64).max(1),
                mlp_width: t_mlp,
            },
            activation: None,
        })
    }

    fn take(&mut self, name: &str) -> Result<Tensor, ClipError> {
        self.tensors
            .remove(name)
            .ok_or_else(|| self.layout_err(format!("missing tensor {name}")))
    }

    fn rename(&mut self, from: &str, to: &str) -> Result<(), ClipError> {
        let t = self.take(from)?;
        self.tensors.insert(to.to_string(), t);
        Ok(())
    }

    /// Hugging Face `CLIPModel` → OpenCLIP names: q/k/v projections are concatenated into
    /// `in_proj` (as `nn.MultiheadAttention` stores them) and the bias-free projection
    /// `Linear`s are transposed into OpenCLIP's `x @ proj` matrices (the inverse of
    /// `transformers`' `convert_clip_original_pytorch_to_hf.py`).
    fn rename_hf(&mut self) -> Result<(), ClipError> {
        for (hf, oc) in [
            ("vision_model", "visual.transformer"),
            ("text_model", "transformer"),
        ] {
            let n = (0..)
                .take_while(|i| {
                    self.tensors
                        .contains_key(&format!("{hf}.encoder.layers.{i}.layer_norm1.weight"))
                })
                .count();
            for i in 0..n {
                let (a, b) = (
                    format!("{hf}.encoder.layers.{i}"),
                    format!("{oc}.resblocks.{i}"),
                );
                for kind in ["weight", "bias"] {
                    let qkv = ["q", "k", "v"]
                        .map(|p| self.take(&format!("{a}.self_attn.{p}_proj.{kind}")));
                    let [q, k, v] = qkv;
                    self.tensors.insert(
                        format!("{b}.attn.in_proj_{kind}"),
                        Tensor::cat(&[q?, k?, v?], 0)?,
                    );
                    for (x, y) in [
                        ("self_attn.out_proj", "attn.out_proj"),
                        ("layer_norm1", "ln_1"),
                        ("layer_norm2", "ln_2"),
                        ("mlp.fc1", "mlp.c_fc"),
                        ("mlp.fc2", "mlp.c_proj"),
                    ] {
                        self.rename(&format!("{a}.{x}.{kind}"), &format!("{b}.{y}.{kind}"))?;
                    }
                }
            }
        }
        for (from, to) in [
            (
                "vision_model.embeddings.patch_embedding.weight",
                "visual.conv1.weight",
            ),
            (
                "vision_model.embeddings.class_embedding",
                "visual.class_embedding",
            ),
            (
                "vision_model.embeddings.position_embedding.weight",
                "visual.positional_embedding",
            ),
            (
                "text_model.embeddings.token_embedding.weight",
                "token_embedding.weight",
            ),
            (
                "text_model.embeddings.position_embedding.weight",
                "positional_embedding",
            ),
        ] {
            self.rename(from, to)?;
        }
        for kind in ["weight", "bias"] {
            self.rename(
                &format!("vision_model.pre_layrnorm.{kind}"),
                &format!("visual.ln_pre.{kind}"),
            )?;
            self.rename(
                &format!("vision_model.post_layernorm.{kind}"),
                &format!("visual.ln_post.{kind}"),
            )?;
            self.rename(
                &format!("text_model.final_layer_norm.{kind}"),
                &format!("ln_final.{kind}"),
            )?;
        }
        let vp = self.take("visual_projection.weight")?.t()?.contiguous()?;
        let tp = self.take("text_projection.weight")?.t()?.contiguous()?;
        self.tensors.insert("visual.proj".into(), vp);
        self.tensors.insert("text_projection".into(), tp);
        Ok(())
    }
}

/// Every tensor of an OpenCLIP ViT checkpoint with its shape.
pub fn expected_shapes(c: &ClipConfig) -> Vec<(String, Vec<usize>)> {
    let (v, t) = (&c.vision, &c.text);
    let grid = v.image_size / v.patch_size;
    let mut out: Vec<(String, Vec<usize>)> = vec![
        (
            "visual.conv1.weight".into(),
            vec![v.width, 3, v.patch_size, v.patch_size],
        ),
        ("visual.class_embedding".into(), vec![v.width]),
        (
            "visual.positional_embedding".into(),
            vec![grid * grid + 1, v.width],
        ),
        ("visual.proj".into(), vec![v.width, c.embed_dim]),
        ("token_embedding.weight".into(), vec![t.vocab_size, t.width]),
        (
            "positional_embedding".into(),
            vec![t.context_length, t.width],
        ),
        ("text_projection".into(), vec![t.width, c.embed_dim]),
    ];
    for (ln, w) in [
        ("visual.ln_pre", v.width),
        ("visual.ln_post", v.width),
        ("ln_final", t.width),
    ] {
        out.push((format!("{ln}.weight"), vec![w]));
        out.push((format!("{ln}.bias"), vec![w]));
    }
    for (prefix, w, layers, mlp) in [
        ("visual.transformer", v.width, v.layers, v.mlp_width),
        ("transformer", t.width, t.layers, t.mlp_width),
    ] {
        for i in 0..layers {
            let p = format!("{prefix}.resblocks.{i}");
            for (name, shape) in [
                ("ln_1.weight", vec![w]),
                ("ln_1.bias", vec![w]),
                ("attn.in_proj_weight", vec![3 * w, w]),
                ("attn.in_proj_bias", vec![3 * w]),
                ("attn.out_proj.weight", vec![w, w]),
                ("attn.out_proj.bias", vec![w]),
                ("ln_2.weight", vec![w]),
                ("ln_2.bias", vec![w]),
                ("mlp.c_fc.weight", vec![mlp, w]),
                ("mlp.c_fc.bias", vec![mlp]),
                ("mlp.c_proj.weight", vec![w, mlp]),
                ("mlp.c_proj.bias", vec![w]),
            ] {
                out.push((format!("{p}.{name}"), shape));
            }
        }
    }
    out
}
