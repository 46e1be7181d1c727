//! Positional encoding of 100k means (10 frequencies, one thread): the double-angle version
//! the field uses against the one-`sin_cos`-per-term reference, timed alternately in one
//! process (median of 9). `cargo run --release -p train --example encoding_speed`

use std::hint::black_box;
use std::time::Instant;
use train::encoding::{encode_one, encode_reference, encoded_dim};

fn time(f: impl Fn(&[f32], usize, &mut [f32]), means: &[f32], out: &mut [f32]) -> f64 {
    let t = Instant::now();
    for x in means.chunks_exact(3) {
        f(x, 10, out);
        black_box(&*out);
    }
    t.elapsed().as_secs_f64() * 1e3
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let means: Vec<f32> = (0..300_000)
        .map(|i| (i as f32 * 0.37).sin() * 1.3)
        .collect();
    let mut out = vec![0.0; encoded_dim(3, 10)];
    let (mut fast, mut reference) = (Vec::new(), Vec::new());
    for _ in 0..9 {
        reference.push(time(encode_reference, &means, &mut out));
        fast.push(time(encode_one, &means, &mut out));
    }
    let (f, r) = (median(fast), median(reference));
    println!(
        "100k rows: double-angle {f:.1} ms, reference {r:.1} ms, speed-up {:.2}×",
        r / f
    );
}
