//! CLIP towers against the official OpenCLIP PyTorch code: small random-weight models in the
//! OpenCLIP layout (GELU) and the Hugging Face layout (QuickGELU), reference embeddings
//! computed once by `scripts/make_clip_fixture.py`. Tolerance 1e-4 (absolute).

use std::path::PathBuf;

use candle_core::{DType, Device, Tensor};
use semantics::clip::{batch_pixels, masked_crop, Activation, ClipModel, Layout, LoadOptions};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/clip")
        .join(name)
}

fn load(name: &str) -> std::collections::HashMap<String, Tensor> {
    candle_core::safetensors::load(fixture(name), &Device::Cpu).expect("fixture")
}

fn max_abs_diff(a: &Tensor, b: &Tensor) -> f32 {
    let d = (a.to_dtype(DType::F32).unwrap() - b.to_dtype(DType::F32).unwrap()).unwrap();
    d.abs()
        .unwrap()
        .flatten_all()
        .unwrap()
        .max(0)
        .unwrap()
        .to_scalar::<f32>()
        .unwrap()
}

fn token_rows(t: &Tensor) -> Vec<Vec<u32>> {
    let rows: Vec<Vec<i64>> = t.to_vec2().unwrap();
    rows.into_iter()
        .map(|r| r.into_iter().map(|v| v as u32).collect())
        .collect()
}

fn check_model(name: &str, layout: Layout, activation: Activation) {
    let opts = LoadOptions {
        config: Some(fixture(&format!("{name}.json"))),
        activation: None,
    };
    let model = ClipModel::load(&fixture(&format!("{name}.safetensors")), &opts).unwrap();
    assert_eq!(model.layout, layout);
    assert_eq!(model.config.activation, Some(activation));
    let r = load("reference.safetensors");
    let images = &r["images"];
    let tokens = token_rows(&r["tokens"]);

    let raw = model.image_features(images).unwrap();
    let d = max_abs_diff(&raw, &r[&format!("{name}.image_raw")]);
    assert!(d < 1e-4, "{name} raw image features differ by {d}");
    let img = Tensor::new(model.encode_images(images).unwrap(), &Device::Cpu).unwrap();
    let d = max_abs_diff(&img, &r[&format!("{name}.image")]);
    assert!(d < 1e-4, "{name} image embeddings differ by {d}");

    let raw = model.text_features(&tokens).unwrap();
    let d = max_abs_diff(&raw, &r[&format!("{name}.text_raw")]);
    assert!(d < 1e-4, "{name} raw text features differ by {d}");
    // The fixture's token rows are the official tokenizer's ids of prompts 0, 1, 2, 7, 13.
    let prompts = [
        "white SUV",
        "yellow sedan",
        "green SUV",
        "a photo of a dog's toy car",
        "unbelievably photorealistic hyperparameterization",
    ];
    let txt = Tensor::new(model.encode_texts(&prompts).unwrap(), &Device::Cpu).unwrap();
    let d = max_abs_diff(&txt, &r[&format!("{name}.text")]);
    assert!(d < 1e-4, "{name} text embeddings differ by {d}");
}

#[test]
fn open_clip_layout_gelu_matches_reference() {
    check_model("tiny_gelu", Layout::OpenClip, Activation::Gelu);
}

#[test]
fn hf_layout_quick_gelu_matches_reference() {
    check_model(
        "tiny_quickgelu_hf",
        Layout::HuggingFace,
        Activation::QuickGelu,
    );
}

#[test]
fn wrong_activation_changes_the_output() {
    // Guards the test above against an activation that does not matter.
    let opts = LoadOptions {
        config: Some(fixture("tiny_gelu.json")),
        activation: Some(Activation::QuickGelu),
    };
    let model = ClipModel::load(&fixture("tiny_gelu.safetensors"), &opts).unwrap();
    let r = load("reference.safetensors");
    let img = Tensor::new(model.encode_images(&r["images"]).unwrap(), &Device::Cpu).unwrap();
    assert!(max_abs_diff(&img, &r["tiny_gelu.image"]) > 1e-3);
}

#[test]
fn config_inferred_from_weights_equals_config_file() {
    let dir = tempfile::tempdir().unwrap();
    let weights = dir.path().join("w.safetensors");
    std::fs::copy(fixture("tiny_gelu.safetensors"), &weights).unwrap();
    // No config beside the weights: shapes are inferred (heads default to width/64, which
    // only a config file can override: the tiny model's 2 heads are not inferable).
    let inferred = ClipModel::load(&weights, &LoadOptions::default()).unwrap();
    let opts = LoadOptions {
        config: Some(fixture("tiny_gelu.json")),
        activation: None,
    };
    let explicit = ClipModel::load(&fixture("tiny_gelu.safetensors"), &opts).unwrap();
    let (a, b) = (&inferred.config, &explicit.config);
    assert_eq!(
        (
            a.embed_dim,
            a.vision.image_size,
            a.vision.patch_size,
            a.vision.layers
        ),
        (
            b.embed_dim,
            b.vision.image_size,
            b.vision.patch_size,
            b.vision.layers
        )
    );
    assert_eq!(
        (
            a.text.context_length,
            a.text.vocab_size,
            a.text.layers,
            a.text.mlp_width
        ),
        (
            b.text.context_length,
            b.text.vocab_size,
            b.text.layers,
            b.text.mlp_width
        )
    );
}

#[test]
fn missing_weights_say_what_to_get() {
    let err = ClipModel::load(
        &PathBuf::from("/nonexistent/open_clip_model.safetensors"),
        &LoadOptions::default(),
    )
    .err()
    .unwrap();
    let msg = err.to_string();
    assert!(
        msg.contains("/nonexistent/open_clip_model.safetensors")
            && msg.contains("laion/CLIP-ViT-B-16"),
        "{msg}"
    );
}

#[test]
fn masked_crop_matches_clip_preprocess() {
    let r = load("preprocess.safetensors");
    let img: Vec<Vec<Vec<u8>>> = r["image"].to_vec3().unwrap();
    let (h, w) = (img.len(), img[0].len());
    let raw: Vec<u8> = img.into_iter().flatten().flatten().collect();
    let image = image::RgbImage::from_raw(w as u32, h as u32, raw).unwrap();
    let mask: Vec<u8> = r["mask"].flatten_all().unwrap().to_vec1().unwrap();
    let mask: Vec<bool> = mask.into_iter().map(|m| m != 0).collect();
    let expected = &r["pixels"];
    let size = expected.dim(1).unwrap();
    let ours = batch_pixels(&[masked_crop(&image, &mask, size as u32).unwrap()], size)
        .unwrap()
        .squeeze(0)
        .unwrap();
    // Both sides resample 8-bit values with rounding; allow one grey level (1/255/std).
    let d = max_abs_diff(&ours, expected);
    assert!(d <= 1.0 / 255.0 / 0.26 + 1e-4, "preprocess differs by {d}");
}

#[test]
fn masks_and_dictionary_feed_relevance() {
    let opts = LoadOptions {
        config: Some(fixture("tiny_gelu.json")),
        activation: None,
    };
    let model = ClipModel::load(&fixture("tiny_gelu.safetensors"), &opts).unwrap();
    let image = image::RgbImage::from_fn(20, 10, |x, y| {
        image::Rgb([(x * 12) as u8, (y * 25) as u8, 90])
    });
    // 9 masks: more than one batch of MASK_BATCH, each a vertical stripe.
    let masks: Vec<Vec<bool>> = (0..9)
        .map(|k| (0..200).map(|p| p % 20 / 2 == k).collect())
        .collect();
    let feats = model.encode_masks(&image, &masks).unwrap();
    assert_eq!(feats.len(), 9);
    let single = model.encode_masks(&image, &masks[8..]).unwrap();
    let d: f32 = feats[8]
        .iter()
        .zip(&single[0])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(d < 1e-5, "batched and single encodings differ by {d}");
    for f in &feats {
        let norm: f32 = f.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-5);
    }
    let dict = model
        .encode_dictionary(&["white SUV", "green SUV"])
        .unwrap();
    assert_eq!((dict.prompts.len(), dict.canonical.len()), (2, 4));
    let ids = semantics::relevance::object_ids(&feats, &dict, 0.0).unwrap();
    assert!(
        ids.iter().all(|id| id.is_some()),
        "τ = 0 accepts every mask"
    );
    let empty = vec![vec![false; 200]];
    assert!(model
        .encode_masks(&image, &empty)
        .unwrap_err()
        .to_string()
        .contains("empty mask"));
}
