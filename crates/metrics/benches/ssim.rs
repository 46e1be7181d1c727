//! SSIM forward and forward+backward on a 480×360 RGB pair (the trainer's image size), with
//! a memory-bandwidth reference measured in the same process: streaming the ~40 MB that
//! SSIM with gradient reads and writes (see docs/performance.md, "Metrics").
//!
//! Run: `cargo bench -p metrics --bench ssim -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, Criterion};
use metrics::SsimWorkspace;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

const W: usize = 480;
const H: usize = 360;

fn bench(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let a: Vec<f32> = (0..W * H * 3).map(|_| rng.gen()).collect();
    let b: Vec<f32> = a
        .iter()
        .map(|&x| (x + 0.1 * rng.gen::<f32>()).min(1.0))
        .collect();
    let mut grad = vec![0.0f32; a.len()];
    let mut ws = SsimWorkspace::new();
    let mut group = c.benchmark_group("ssim_480x360");
    group.sample_size(20);
    group.bench_function("forward", |bn| {
        bn.iter(|| black_box(ws.ssim(black_box(&a), &b, W, H)))
    });
    group.bench_function("forward_backward", |bn| {
        bn.iter(|| black_box(ws.ssim_with_grad(black_box(&a), &b, W, H, &mut grad)))
    });
    // Reference: copy 20 MB (= 40 MB of traffic), the bytes the gradient path must move.
    let src = vec![1.0f32; 5 * 1024 * 1024];
    let mut dst = vec![0.0f32; src.len()];
    group.bench_function("reference_copy_20MB", |bn| {
        bn.iter(|| dst.copy_from_slice(black_box(&src)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
