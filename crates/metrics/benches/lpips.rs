//! LPIPS-Alex (and VGG) on a 480×360 RGB pair, against a reference measured in the same
//! process: a 1024³ f32 `gemm` on all threads (2.15 GFLOP), i.e. the machine's achievable
//! GEMM rate, since LPIPS is ~9.4 GFLOP of convolutions for AlexNet at this size and our
//! convolutions are im2col + the same `gemm`.
//! Needs the weights (`semdynreg weights fetch lpips`; `SEMDYNREG_WEIGHTS`); without them
//! only the reference runs, with a printed note.
//!
//! Run: `cargo bench -p metrics --bench lpips -- --warm-up-time 1 --measurement-time 5`

use criterion::{criterion_group, criterion_main, Criterion};
use metrics::{Lpips, LpipsNet};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

const W: usize = 480;
const H: usize = 360;
const N: usize = 1024;

/// `c = a · b` for dense row-major N×N matrices, multithreaded (gemm's rayon mode).
fn reference_gemm(c: &mut [f32], a: &[f32], b: &[f32]) {
    assert!(c.len() == N * N && a.len() == N * N && b.len() == N * N);
    // SAFETY: the three buffers hold N×N row-major matrices (checked above); `c` is unique.
    unsafe {
        gemm::gemm(
            N,
            N,
            N,
            c.as_mut_ptr(),
            1,
            N as isize,
            false,
            a.as_ptr(),
            1,
            N as isize,
            b.as_ptr(),
            1,
            N as isize,
            0.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::Rayon(0),
        );
    }
}

fn bench(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let a: Vec<f32> = (0..W * H * 3).map(|_| rng.gen()).collect();
    let b: Vec<f32> = a
        .iter()
        .map(|&x| (x + 0.1 * rng.gen::<f32>()).min(1.0))
        .collect();
    let mut group = c.benchmark_group("lpips_480x360");
    group.sample_size(10);
    let x: Vec<f32> = (0..N * N).map(|_| rng.gen::<f32>() - 0.5).collect();
    let mut y = vec![0.0f32; N * N];
    group.bench_function("reference_gemm_1024", |bn| {
        bn.iter(|| reference_gemm(black_box(&mut y), &x, &x))
    });
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
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
