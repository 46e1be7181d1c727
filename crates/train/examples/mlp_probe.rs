//! The default field's MLP (4×64, skip after layer 2, 63 encoded-position inputs + 13 time
//! features, 10 outputs) alone on random rows: forward and backward with the time
//! features given in every row (the reference) and folded into the biases, alternated in
//! one process; medians and the multiply-add rates they reach (the floor of
//! docs/performance.md is the `gemm` rate).
//!
//! `cargo run --release -p train --example mlp_probe -- [ROWS=51088] [REPS=15]`

use rand::{Rng, SeedableRng};
use std::time::Instant;
use train::mlp::{Mlp, MlpCache};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let arg = |i: usize, d: usize| {
        std::env::args()
            .nth(i)
            .map(|s| s.parse().expect("ROWS and REPS are counts"))
            .unwrap_or(d)
    };
    let (rows, reps) = (arg(1, 51_088), arg(2, 15));
    let (pos, time) = (63, 13);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let mlp = Mlp::new(pos + time, 64, 4, 2, 10, &mut rng);
    let t: Vec<f32> = (0..time).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let own: Vec<f32> = (0..rows * pos).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let full: Vec<f32> = own
        .chunks_exact(pos)
        .flat_map(|r| r.iter().chain(&t).copied())
        .collect();
    let d: Vec<f32> = (0..rows * 10).map(|_| rng.gen_range(-1.0..1.0)).collect();
    // Multiply-adds per row actually computed by each variant (backward: dW of every
    // per-row weight, dh of layers 1..=4).
    let dh = (64 * 64 * 3 + 64 * 10) as f64;
    let macs = |per_row: usize| {
        let f = (per_row * 64 + 64 * 64 * 2 + (per_row + 64) * 64 + 640) as f64;
        (f, f + dh)
    };
    let variants = [
        ("time per row", &full, &[][..], pos + time),
        ("time in the bias", &own, &t[..], pos),
    ];
    let mut times = vec![(Vec::new(), Vec::new()); 2];
    let (mut c, mut g) = (MlpCache::default(), Vec::new());
    for _ in 0..reps {
        for (v, &(_, x, shared, _)) in variants.iter().enumerate() {
            let t0 = Instant::now();
            mlp.forward(x, rows, shared, &mut c);
            times[v].0.push(t0.elapsed().as_secs_f64());
            let t0 = Instant::now();
            mlp.backward(x, &d, &mut c, &mut g);
            times[v].1.push(t0.elapsed().as_secs_f64());
        }
    }
    println!(
        "{rows} rows, {} threads, medians of {reps}:",
        rayon::current_num_threads()
    );
    for ((name, _, _, per_row), (f, b)) in variants.iter().zip(times) {
        let (f, b) = (median(f), median(b));
        let (mf, mb) = macs(*per_row);
        let rate = |m: f64, s: f64| 2.0 * m * rows as f64 / s / 1e9;
        println!(
            "  {name:<18} forward {:6.2} ms ({:4.0} Gflop/s)  backward {:6.2} ms ({:4.0} Gflop/s)",
            f * 1e3,
            rate(mf, f),
            b * 1e3,
            rate(mb, b)
        );
    }
}
