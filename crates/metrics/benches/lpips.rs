//! LPIPS-Alex (and VGG) on a 480×360 RGB pair, against a reference measured in the same
//! process: a 1024³ f32 matmul through candle (2.15 GFLOP), i.e. the machine's achievable
//! GEMM rate, since LPIPS is ~9.4 GFLOP of convolutions for AlexNet at this size.
//! Needs the weights (`scripts/fetch_lpips.sh weights`; `SEMDYNREG_WEIGHTS`); without them
//! only the reference runs, with a printed note.
//!
//! Run: `cargo bench -p metrics --bench lpips -- --warm-up-time 1 --measurement-time 5`

use candle_core::{Device, Tensor};
use criterion::{criterion_group, criterion_main, Criterion};
use metrics::{Lpips, LpipsNet};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

const W: usize = 480;
const H: usize = 360;

fn bench(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let a: Vec<f32> = (0..W * H * 3).map(|_| rng.gen()).collect();
    let b: Vec<f32> = a
        .iter()
        .map(|&x| (x + 0.1 * rng.gen::<f32>()).min(1.0))
        .collect();
    let mut group = c.benchmark_group("lpips_480x360");
    group.sample_size(10);
    for net in [LpipsNet::Alex, LpipsNet::Vgg] {
        match Lpips::from_env(net) {
            Ok(m) => {
                group.bench_function(format!("{net:?}"), |bn| {
                    bn.iter(|| black_box(m.distance(black_box(&a), &b, W, H).unwrap()))
                });
            }
            Err(e) => eprintln!("skipping LPIPS-{net:?}: {e}"),
        }
    }
    let x = Tensor::randn(0f32, 1.0, (1024, 1024), &Device::Cpu).unwrap();
    group.bench_function("reference_matmul_1024", |bn| {
        bn.iter(|| black_box(x.matmul(&x).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
