//! CLIP architecture: read from the checkpoint's JSON config when one is present, else
//! inferred from the tensor shapes.
//!
//! How the variant is chosen (first that applies):
//! 1. [`super::LoadOptions::activation`] (the CLI's `--clip-act gelu|quick-gelu`);
//! 2. the config JSON: OpenCLIP's `quick_gelu` flag (model config or
//!    `open_clip_config.json`'s `model_cfg`), or Hugging Face's `hidden_act`;
//! 3. the weight layout: Hugging Face `CLIPModel` checkpoints are OpenAI's → QuickGELU;
//!    OpenCLIP checkpoints → GELU, as OpenCLIP's `ViT-B-16` config trained on LAION
//!    (the paper's model). OpenAI weights in the OpenCLIP layout need `quick_gelu: true` in
//!    the config, as OpenCLIP's own `*-quickgelu` configs say.

use std::path::Path;

use serde::Deserialize;

use super::ClipError;

/// The MLP non-linearity of the residual blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activation {
    /// `nn.GELU` (erf form): OpenCLIP models trained by LAION.
    Gelu,
    /// `x·σ(1.702x)`: OpenAI's CLIP models.
    QuickGelu,
}

impl std::str::FromStr for Activation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().replace('-', "_").as_str() {
            "gelu" => Ok(Self::Gelu),
            "quick_gelu" | "quickgelu" => Ok(Self::QuickGelu),
            other => Err(format!(
                "unknown CLIP activation {other:?}: use gelu or quick-gelu"
            )),
        }
    }
}

/// Vision transformer shape.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VisionConfig {
    pub image_size: usize,
    pub patch_size: usize,
    pub width: usize,
    pub layers: usize,
    pub heads: usize,
    pub mlp_width: usize,
}

/// Text transformer shape.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TextConfig {
    pub context_length: usize,
    pub vocab_size: usize,
    pub width: usize,
    pub layers: usize,
    pub heads: usize,
    pub mlp_width: usize,
}

/// A whole CLIP model: both towers, the joint embedding size and the activation.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClipConfig {
    pub embed_dim: usize,
    pub vision: VisionConfig,
    pub text: TextConfig,
    /// `None` until resolved by the rules in the module note.
    pub activation: Option<Activation>,
}

fn d_64() -> usize {
    64
}
fn d_4() -> f64 {
    4.0
}
fn d_77() -> usize {
    77
}
fn d_vocab() -> usize {
    49408
}

#[derive(Deserialize)]
struct OcVision {
    image_size: usize,
    layers: usize,
    width: usize,
    patch_size: usize,
    #[serde(default = "d_64")]
    head_width: usize,
    #[serde(default = "d_4")]
    mlp_ratio: f64,
}

#[derive(Deserialize)]
struct OcText {
    #[serde(default = "d_77")]
    context_length: usize,
    #[serde(default = "d_vocab")]
    vocab_size: usize,
    width: usize,
    heads: usize,
    layers: usize,
    #[serde(default = "d_4")]
    mlp_ratio: f64,
}

/// OpenCLIP's model config (`model_configs/ViT-B-16.json`, or `model_cfg` of
/// `open_clip_config.json`).
#[derive(Deserialize)]
struct OcModel {
    embed_dim: usize,
    quick_gelu: Option<bool>,
    vision_cfg: OcVision,
    text_cfg: OcText,
}

/// One tower of a Hugging Face `CLIPConfig`; defaults are `transformers`' for ViT-B/32.
#[derive(Deserialize)]
struct HfTower {
    hidden_size: usize,
    num_hidden_layers: usize,
    num_attention_heads: usize,
    intermediate_size: Option<usize>,
    hidden_act: Option<String>,
    image_size: Option<usize>,
    patch_size: Option<usize>,
    max_position_embeddings: Option<usize>,
    vocab_size: Option<usize>,
}

#[derive(Deserialize)]
struct HfModel {
    projection_dim: Option<usize>,
    vision_config: HfTower,
    text_config: HfTower,
}

impl ClipConfig {
    /// Reads an OpenCLIP model config (bare or wrapped in `model_cfg`) or a Hugging Face
    /// `config.json`.
    pub fn from_json_file(path: &Path) -> Result<Self, ClipError> {
        let err = |reason: String| ClipError::Config {
            path: path.to_path_buf(),
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| err(e.to_string()))?;
        let value = value.get("model_cfg").cloned().unwrap_or(value);
        if value.get("vision_cfg").is_some() {
            let m: OcModel =
                serde_json::from_value(value).map_err(|e| err(format!("OpenCLIP config: {e}")))?;
            let c = Self::from_open_clip(m).map_err(&err)?;
            c.validate().map_err(err)?;
            Ok(c)
        } else if value.get("vision_config").is_some() {
            let m: HfModel = serde_json::from_value(value)
                .map_err(|e| err(format!("Hugging Face config: {e}")))?;
            let c = Self::from_hf(m).map_err(&err)?;
            c.validate().map_err(err)?;
            Ok(c)
        } else {
            Err(err("neither an OpenCLIP config (vision_cfg) nor a Hugging Face CLIPConfig (vision_config)".into()))
        }
    }

    fn from_open_clip(m: OcModel) -> Result<Self, String> {
        let v = m.vision_cfg;
        let t = m.text_cfg;
        let mlp = |w: usize, r: f64| (w as f64 * r) as usize; // int(d_model * mlp_ratio)
        if v.head_width == 0 {
            return Err("vision_cfg.head_width must be ≥ 1".into());
        }
        Ok(Self {
            embed_dim: m.embed_dim,
            vision: VisionConfig {
                image_size: v.image_size,
                patch_size: v.patch_size,
                width: v.width,
                layers: v.layers,
                heads: v.width / v.head_width,
                mlp_width: mlp(v.width, v.mlp_ratio),
            },
            text: TextConfig {
                context_length: t.context_length,
                vocab_size: t.vocab_size,
                width: t.width,
                layers: t.layers,
                heads: t.heads,
                mlp_width: mlp(t.width, t.mlp_ratio),
            },
            activation: m.quick_gelu.map(|q| {
                if q {
                    Activation::QuickGelu
                } else {
                    Activation::Gelu
                }
            }),
        })
    }

    fn from_hf(m: HfModel) -> Result<Self, String> {
        let (v, t) = (m.vision_config, m.text_config);
        let act = |tower: &HfTower| {
            tower
                .hidden_act
                .as_deref()
                .map(str::parse::<Activation>)
                .transpose()
        };
        let activation = act(&v)?.or(act(&t)?);
        Ok(Self {
            embed_dim: m.projection_dim.unwrap_or(512),
            vision: VisionConfig {
                image_size: v.image_size.unwrap_or(224),
                patch_size: v.patch_size.unwrap_or(32),
                width: v.hidden_size,
                layers: v.num_hidden_layers,
                heads: v.num_attention_heads,
                mlp_width: v
                    .intermediate_size
                    .unwrap_or(v.hidden_size.saturating_mul(4)),
            },
            text: TextConfig {
                context_length: t.max_position_embeddings.unwrap_or(77),
                vocab_size: t.vocab_size.unwrap_or(49408),
                width: t.hidden_size,
                layers: t.num_hidden_layers,
                heads: t.num_attention_heads,
                mlp_width: t
                    .intermediate_size
                    .unwrap_or(t.hidden_size.saturating_mul(4)),
            },
            activation,
        })
    }

    /// OpenCLIP `ViT-B-16` (the paper's model: laion2b_s34b_b88k weights, GELU).
    pub fn vit_b_16() -> Self {
        Self::vit_b(16, Activation::Gelu)
    }

    /// OpenAI `ViT-B/32` (QuickGELU).
    pub fn vit_b_32_openai() -> Self {
        Self::vit_b(32, Activation::QuickGelu)
    }

    fn vit_b(patch_size: usize, activation: Activation) -> Self {
        Self {
            embed_dim: 512,
            vision: VisionConfig {
                image_size: 224,
                patch_size,
                width: 768,
                layers: 12,
                heads: 12,
                mlp_width: 3072,
            },
            text: TextConfig {
                context_length: 77,
                vocab_size: 49408,
                width: 512,
                layers: 12,
                heads: 8,
                mlp_width: 2048,
            },
            activation: Some(activation),
        }
    }

    /// Refuses shapes no CLIP has, before any of them sizes an allocation or a product
    /// (`grid² + 1`, the `context²` causal mask): every size ≥ 1 and within bounds 8–64×
    /// beyond ViT-bigG's, the image a whole number of patches, the widths divisible by the
    /// head counts.
    pub fn validate(&self) -> Result<(), String> {
        let (v, t) = (&self.vision, &self.text);
        for (name, value, max) in [
            ("embed_dim", self.embed_dim, 1 << 16),
            ("vision image_size", v.image_size, 1 << 13),
            ("vision patch_size", v.patch_size, 1 << 13),
            ("vision width", v.width, 1 << 16),
            ("vision layers", v.layers, 1 << 10),
            ("vision heads", v.heads, 1 << 10),
            ("vision mlp_width", v.mlp_width, 1 << 18),
            ("text context_length", t.context_length, 1 << 13),
            ("text vocab_size", t.vocab_size, 1 << 22),
            ("text width", t.width, 1 << 16),
            ("text layers", t.layers, 1 << 10),
            ("text heads", t.heads, 1 << 10),
            ("text mlp_width", t.mlp_width, 1 << 18),
        ] {
            if value == 0 || value > max {
                return Err(format!("{name} = {value} is outside 1..={max}"));
            }
        }
        if !v.image_size.is_multiple_of(v.patch_size) {
            return Err(format!(
                "vision image_size {} is not a multiple of patch_size {}",
                v.image_size, v.patch_size
            ));
        }
        for (name, width, heads) in [("vision", v.width, v.heads), ("text", t.width, t.heads)] {
            if !width.is_multiple_of(heads) {
                return Err(format!(
                    "{name} width {width} is not divisible by {heads} heads"
                ));
            }
        }
        Ok(())
    }

    /// The resolved activation (GELU if nothing decided it; see the module note).
    pub fn activation(&self) -> Activation {
        self.activation.unwrap_or(Activation::Gelu)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(json: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        std::io::Write::write_all(&mut f, json.as_bytes()).unwrap();
        f
    }

    #[test]
    fn reads_open_clip_vit_b_16() {
        let f = write(
            r#"{"model_cfg": {"embed_dim": 512, "vision_cfg": {"image_size": 224, "layers": 12,
            "width": 768, "patch_size": 16}, "text_cfg": {"context_length": 77, "vocab_size": 49408,
            "width": 512, "heads": 8, "layers": 12}}, "preprocess_cfg": {}}"#,
        );
        let c = ClipConfig::from_json_file(f.path()).unwrap();
        assert_eq!(c.vision.heads, 12);
        assert_eq!(c.vision.mlp_width, 3072);
        assert_eq!(c.text.mlp_width, 2048);
        assert_eq!(c.activation, None);
        assert_eq!(c.activation(), Activation::Gelu);
    }

    #[test]
    fn reads_hf_quick_gelu() {
        let f = write(
            r#"{"projection_dim": 512, "vision_config": {"hidden_size": 768, "num_hidden_layers": 12,
            "num_attention_heads": 12, "patch_size": 32, "hidden_act": "quick_gelu"},
            "text_config": {"hidden_size": 512, "num_hidden_layers": 12, "num_attention_heads": 8}}"#,
        );
        let c = ClipConfig::from_json_file(f.path()).unwrap();
        assert_eq!(c.activation, Some(Activation::QuickGelu));
        assert_eq!((c.vision.image_size, c.vision.mlp_width), (224, 3072));
    }

    #[test]
    fn bad_configs_name_the_file() {
        let f = write(r#"{"something": 1}"#);
        let e = ClipConfig::from_json_file(f.path())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&f.path().display().to_string()) && e.contains("vision_cfg"),
            "{e}"
        );
        assert!(ClipConfig::from_json_file(Path::new("/nonexistent/clip.json")).is_err());
        assert!("relu".parse::<Activation>().is_err());
        assert_eq!(
            "quick-gelu".parse::<Activation>(),
            Ok(Activation::QuickGelu)
        );
    }
}
