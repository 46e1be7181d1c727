//! `cargo bench -p splat`: forward, backward and forward + top-8 on seeded scenes
//! (a) 100k Gaussians at 800×800 and (b) 500k at 1440×1080. Criterion with 10 samples;
//! results are recorded in docs/performance.md ("## Rasterizer").

use criterion::{criterion_group, criterion_main, Criterion};
use splat::{Gradients, Rasterizer, RenderOptions};
use std::time::Duration;

#[path = "scene_gen.rs"]
mod scene_gen;
use scene_gen::BenchScene;

fn scenario(c: &mut Criterion, name: &str, n: usize, w: u32, h: u32) {
    let scene = BenchScene::new(7, n, w, h);
    let g = scene.gaussians();
    let mut r = Rasterizer::new();
    let opts = RenderOptions::default();
    let topk = RenderOptions {
        topk: 8,
        ..Default::default()
    };
    let out = r.forward(&g, &scene.cam, &opts).expect("forward");
    eprintln!(
        "{name}: {} intersections, {} evaluated pairs",
        out.n_isects,
        r.evaluated_pairs()
    );
    let dl: Vec<f32> = (0..(w * h * 3) as usize)
        .map(|i| (i % 7) as f32 / 7.0 - 0.5)
        .collect();
    let mut grads = Gradients::default();
    let mut group = c.benchmark_group(name);
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(3));
    group.bench_function("forward", |b| {
        b.iter(|| {
            r.forward(&g, &scene.cam, &opts).expect("forward");
        })
    });
    group.bench_function("forward_topk8", |b| {
        b.iter(|| {
            r.forward(&g, &scene.cam, &topk).expect("forward");
        })
    });
    r.forward(&g, &scene.cam, &opts).expect("forward");
    group.bench_function("backward", |b| {
        b.iter(|| {
            r.backward(&g, &scene.cam, &opts, &dl, None, &mut grads)
                .expect("backward");
        })
    });
    group.finish();
}

fn benches(c: &mut Criterion) {
    scenario(c, "a_100k_800x800", 100_000, 800, 800);
    scenario(c, "b_500k_1440x1080", 500_000, 1440, 1080);
}

criterion_group!(raster, benches);
criterion_main!(raster);
