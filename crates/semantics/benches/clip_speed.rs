//! CLIP image-tower speed on masked crops, against the goal of ≤ 50 ms per mask crop for
//! ViT-B/16 (the per-frame SAM + CLIP path encodes one crop per mask). Random weights of the
//! real shape (speed does not depend on the values). Minutes on 2 cores:
//!
//!     cargo bench -p semantics --bench clip_speed
//!
//! It prints one JSON line per setting: median ms per crop over a few runs, and the
//! machine's f32 GEMM rate measured in the same process through the same candle matmul,
//! so the tower's floor (its FLOPs over that rate) and the gap can be read off.

use std::time::Instant;

use candle_core::{Device, Tensor};
use semantics::clip::{ClipConfig, ClipModel};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time<F: FnMut()>(runs: usize, mut f: F) -> f64 {
    f(); // warm-up: first-touch allocations and thread-pool start-up
    median(
        (0..runs)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// GFLOP/s of a (n×768)·(768×3072) matmul: the shape of the ViT-B MLP.
fn gemm_rate(n: usize) -> f64 {
    let a = Tensor::randn(0f32, 1.0, (n, 768), &Device::Cpu).unwrap();
    let b = Tensor::randn(0f32, 1.0, (768, 3072), &Device::Cpu).unwrap();
    let s = time(5, || {
        a.matmul(&b).unwrap();
    });
    2.0 * (n * 768 * 3072) as f64 / s / 1e9
}

/// Multiply-adds ×2 of one ViT image: patch embedding, per layer QKV/out/MLP matmuls and
/// the two attention matmuls.
fn vit_flops(c: &ClipConfig) -> f64 {
    let v = &c.vision;
    let grid = v.image_size / v.patch_size;
    let t = (grid * grid + 1) as f64;
    let w = v.width as f64;
    let patch = (grid * grid) as f64 * (3 * v.patch_size * v.patch_size) as f64 * w;
    let per_layer = t * w * (3.0 * w + w + 2.0 * v.mlp_width as f64) + 2.0 * t * t * w;
    2.0 * (patch + v.layers as f64 * per_layer)
}

fn main() {
    vit_b_16_per_crop();
    preprocess_per_crop();
}

fn vit_b_16_per_crop() {
    for (name, config) in [
        ("ViT-B/16", ClipConfig::vit_b_16()),
        ("ViT-B/32", ClipConfig::vit_b_32_openai()),
    ] {
        let model = ClipModel::random(&config, 0).unwrap();
        let s = model.image_size();
        let flops = vit_flops(&config);
        for batch in [1usize, 8] {
            let pixels = Tensor::randn(0f32, 1.0, (batch, 3, s, s), &Device::Cpu).unwrap();
            let secs = time(3, || {
                model.encode_images(&pixels).unwrap();
            });
            let tokens = (s / config.vision.patch_size).pow(2) + 1;
            let rate = gemm_rate(batch * tokens);
            let per_crop_ms = secs * 1e3 / batch as f64;
            let floor_ms = flops / (rate * 1e9) * 1e3;
            println!(
                "{{\"model\":\"{name}\",\"batch\":{batch},\"ms_per_crop\":{per_crop_ms:.1},\"gflop_per_crop\":{:.2},\"gemm_gflops\":{rate:.1},\"floor_ms\":{floor_ms:.1},\"achieved_gflops\":{:.1}}}",
                flops / 1e9,
                flops / (secs / batch as f64) / 1e9
            );
        }
    }
}

fn preprocess_per_crop() {
    // A 480×360 frame with a 300×200 elliptic mask: crop, pad, resize to 224, normalize.
    let image = image::RgbImage::from_fn(480, 360, |x, y| {
        image::Rgb([(x % 256) as u8, (y % 256) as u8, ((x + y) % 256) as u8])
    });
    let mask: Vec<bool> = (0..480 * 360)
        .map(|p| {
            let (x, y) = ((p % 480) as f32 - 240.0, (p / 480) as f32 - 180.0);
            (x / 150.0).powi(2) + (y / 100.0).powi(2) <= 1.0
        })
        .collect();
    let secs = time(10, || {
        semantics::clip::masked_crop(&image, &mask, 224).unwrap();
    });
    println!("{{\"preprocess_ms_per_crop\":{:.2}}}", secs * 1e3);
}
