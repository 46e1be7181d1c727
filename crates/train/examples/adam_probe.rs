//! Adam's step against scalar references in the same process: the four
//! one-rate groups (20M floats) and SH-like rows of 48 with two rates; asserts the results
//! are bit-identical and prints medians. `cargo run --release -p train --example adam_probe`
use rayon::prelude::*;
use std::time::Instant;
use train::adam::{Adam, AdamHyper};

fn old_step(
    m: &mut [f32],
    v: &mut [f32],
    p: &mut [f32],
    g: &[f32],
    lr: f32,
    hp: AdamHyper,
    step: u64,
) {
    let bc1 = 1.0 - (hp.beta1 as f64).powi(step as i32);
    let bc2 = 1.0 - (hp.beta2 as f64).powi(step as i32);
    let (ib1, isb2) = ((1.0 / bc1) as f32, (1.0 / bc2.sqrt()) as f32);
    let (b1, b2) = (hp.beta1, hp.beta2);
    let fl = |x: f32| if x.abs() < f32::MIN_POSITIVE { 0.0 } else { x };
    p.par_chunks_mut(4096)
        .zip(g.par_chunks(4096))
        .zip(m.par_chunks_mut(4096))
        .zip(v.par_chunks_mut(4096))
        .for_each(|(((p, g), m), v)| {
            for j in 0..p.len() {
                let gj = g[j];
                let mj = fl(b1 * m[j] + (1.0 - b1) * gj);
                let vj = fl(b2 * v[j] + (1.0 - b2) * gj * gj);
                m[j] = mj;
                v[j] = vj;
                let denom = vj.sqrt() * isb2 + hp.eps;
                p[j] -= lr * ib1 * mj / denom;
            }
        });
}

fn main() {
    let n = 20_000_000;
    let hp = AdamHyper {
        beta1: 0.9,
        beta2: 0.999,
        eps: 1e-15,
    };
    let g: Vec<f32> = (0..n).map(|i| ((i % 97) as f32 - 48.0) * 1e-4).collect();
    let mut p = vec![0.5f32; n];
    let mut a = Adam::zeros(n);
    let (mut m2, mut v2, mut p2) = (vec![0f32; n], vec![0f32; n], vec![0.5f32; n]);
    let (mut tn, mut to) = (Vec::new(), Vec::new());
    for s in 1..=15u64 {
        let t = Instant::now();
        let ok = a.step(&mut p, &g, hp, 1e-3);
        tn.push(t.elapsed().as_secs_f64());
        assert!(ok);
        let t = Instant::now();
        old_step(&mut m2, &mut v2, &mut p2, &g, 1e-3, hp, s);
        to.push(t.elapsed().as_secs_f64());
    }
    assert_eq!(p, p2);
    tn.sort_by(f64::total_cmp);
    to.sort_by(f64::total_cmp);
    // SH-like rows of 48 with two rates, against a scalar-indexed reference.
    let row = 48;
    let n2 = n / row * row;
    let mut a2 = Adam::zeros(n2);
    let mut q = vec![0.5f32; n2];
    let mut q2 = q.clone();
    let (mut mm, mut vv) = (vec![0f32; n2], vec![0f32; n2]);
    let mut ts = Vec::new();
    let fl = |x: f32| if x.abs() < f32::MIN_POSITIVE { 0.0 } else { x };
    for s in 1..=9u64 {
        let t = Instant::now();
        a2.step_rows(&mut q, &g[..n2], hp, row, |k| {
            if k < 3 {
                2.5e-3
            } else {
                1.25e-4
            }
        });
        ts.push(t.elapsed().as_secs_f64());
        let bc1 = 1.0 - (hp.beta1 as f64).powi(s as i32);
        let bc2 = 1.0 - (hp.beta2 as f64).powi(s as i32);
        let (ib1, isb2) = ((1.0 / bc1) as f32, (1.0 / bc2.sqrt()) as f32);
        for i in 0..n2 {
            let lr = if i % row < 3 { 2.5e-3 } else { 1.25e-4 };
            let gj = g[i];
            let mj = fl(hp.beta1 * mm[i] + (1.0 - hp.beta1) * gj);
            let vj = fl(hp.beta2 * vv[i] + (1.0 - hp.beta2) * gj * gj);
            mm[i] = mj;
            vv[i] = vj;
            q2[i] -= lr * ib1 * mj / (vj.sqrt() * isb2 + hp.eps);
        }
    }
    assert_eq!(q, q2, "SH rows differ from the scalar reference");
    ts.sort_by(f64::total_cmp);
    println!("SH rows of 48 (20M floats): median {:.2} ms", ts[4] * 1e3);
    println!(
        "20M floats: one rate: step median {:.2} ms, parallel reference {:.2} ms, ratio {:.3}",
        tn[7] * 1e3,
        to[7] * 1e3,
        tn[7] / to[7]
    );
}
