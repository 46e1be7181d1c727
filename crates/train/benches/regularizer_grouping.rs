//! The regularizer's grouping `G_o` and its loss + gradient at full size: N = 500k
//! Gaussians, 480×360, k = 8, three vehicles covering ~30 % of the image. Prints the median
//! (and minimum) of 31 runs of each, beside a reference measured in the same process: one
//! dense read of δ and one dense read-modify-write of dL/dδ.
//!
//! ```text
//! cargo bench -p train --bench regularizer_grouping
//! ```

use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use train::regularizer::{
    evaluate, DeformGradMut, DeformView, ObjectGroups, RegConfig, TopKView, BACKGROUND_ID,
};

fn main() {
    let (n, w, h, k) = (500_000u32, 480usize, 360usize, 8usize);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let pixels = w * h;
    // Spatially coherent ids: neighbouring pixels share most contributors, as in a render.
    let ids: Vec<u32> = (0..pixels * k)
        .map(|e| {
            let (p, r) = (e / k, e % k);
            let (i, j) = (p / w, p % w);
            let cell = (i / 4 * (w / 4) + j / 4) as u32;
            (cell * 37 + r as u32 * 7919 + rng.gen_range(0..3)) % n
        })
        .collect();
    let map: Vec<u8> = (0..pixels)
        .map(|p| match (p % w) / 48 {
            1 | 2 => 0,
            4 => 1,
            7 => 2,
            _ => BACKGROUND_ID,
        })
        .collect();
    let mut d = vec![0.1f32; n as usize * 3];
    d.iter_mut()
        .enumerate()
        .for_each(|(i, v)| *v += (i % 13) as f32 * 0.01);
    let (dr, ds) = (vec![0.01f32; n as usize * 4], vec![0.02f32; n as usize * 3]);
    let (mut gx, mut gr, mut gs) = (vec![0.0; d.len()], vec![0.0; dr.len()], vec![0.0; ds.len()]);
    let mut groups = ObjectGroups::new();
    let mut stats = Vec::new();
    let cfg = RegConfig::default();
    let (mut t_group, mut t_loss, mut t_ref) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..31 {
        // Reference measured in the same process: one dense read of δ and one dense
        // read-modify-write of dL/dδ, the memory traffic of a pass touching every cache line.
        let t0 = Instant::now();
        let sum: f32 = d.iter().chain(&dr).chain(&ds).sum();
        for v in gx.iter_mut().chain(&mut gr).chain(&mut gs) {
            *v += 1e-30 * sum;
        }
        t_ref.push(t0.elapsed());
        let t0 = Instant::now();
        groups
            .build(
                TopKView {
                    ids: &ids,
                    stride: k,
                },
                k,
                &map,
                n as usize,
            )
            .unwrap();
        let t1 = Instant::now();
        let mut g = DeformGradMut {
            dx: &mut gx,
            dr: &mut gr,
            ds: &mut gs,
        };
        let view = DeformView {
            dx: &d,
            dr: &dr,
            ds: &ds,
        };
        evaluate(&groups, view, &cfg, Some(&mut g), &mut stats).unwrap();
        t_group.push(t1 - t0);
        t_loss.push(t1.elapsed());
    }
    t_group.sort();
    t_loss.sort();
    t_ref.sort();
    let members: usize = groups.iter().map(|g| g.members.len()).sum();
    let ms = |v: &[std::time::Duration]| {
        let f = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        format!("median {:.2} ms (min {:.2})", f(v[v.len() / 2]), f(v[0]))
    };
    println!(
        "N={n} {w}x{h} k={k}: groups={} members={members}\n  grouping {}\n  loss+grad {}\n  \
         reference dense read δ + RMW grad {}",
        groups.len(),
        ms(&t_group),
        ms(&t_loss),
        ms(&t_ref)
    );
}
