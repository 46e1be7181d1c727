//! Grouping `G_o` (paper Sec. 3.3) against a naive set-based reference, and its speed at the
//! issue's sizes (ignored test; run with
//! `cargo test --release -p train --test regularizer_grouping -- --ignored --nocapture`).

use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use train::regularizer::{
    evaluate, DeformGradMut, DeformView, ObjectGroups, RegConfig, TopKView, BACKGROUND_ID,
    NO_GAUSSIAN,
};

/// `G_o = { K(p) | ID(p) = o }` written literally with ordered sets.
fn naive(ids: &[u32], stride: usize, use_k: usize, map: &[u8]) -> BTreeMap<u8, BTreeSet<u32>> {
    let mut out: BTreeMap<u8, BTreeSet<u32>> = BTreeMap::new();
    for (p, &o) in map.iter().enumerate() {
        if o == BACKGROUND_ID {
            continue;
        }
        let set = out.entry(o).or_default();
        for &id in &ids[p * stride..p * stride + use_k.min(stride)] {
            if id != NO_GAUSSIAN {
                set.insert(id);
            }
        }
    }
    out
}

/// A random top-k map whose per-pixel entries are distinct and padded with NO_GAUSSIAN, as the
/// rasterizer returns them, with object regions of a few IDs (including 0 and 254).
fn random_case(rng: &mut ChaCha8Rng, pixels: usize, k: usize, n: u32) -> (Vec<u32>, Vec<u8>) {
    let mut ids = Vec::with_capacity(pixels * k);
    for _ in 0..pixels {
        let filled = rng.gen_range(0..=k);
        let mut seen = BTreeSet::new();
        while seen.len() < filled.min(n as usize) {
            seen.insert(rng.gen_range(0..n));
        }
        ids.extend(seen.iter().copied());
        ids.extend(std::iter::repeat_n(NO_GAUSSIAN, k - seen.len()));
    }
    let palette = [0u8, 3, 254, BACKGROUND_ID];
    let map = (0..pixels).map(|_| palette[rng.gen_range(0..4)]).collect();
    (ids, map)
}

#[test]
fn matches_naive_reference_across_reused_builds() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut groups = ObjectGroups::new();
    // Varying N (as densification does) and k; the same struct is reused throughout.
    for (round, &(n, k, use_k)) in [(50, 4, 2), (500, 8, 8), (20, 1, 1), (300, 8, 3), (60, 3, 5)]
        .iter()
        .enumerate()
    {
        let pixels = 400;
        let (ids, map) = random_case(&mut rng, pixels, k, n);
        groups
            .build(
                TopKView {
                    ids: &ids,
                    stride: k,
                },
                use_k,
                &map,
                n as usize,
            )
            .unwrap();
        let want = naive(&ids, k, use_k, &map);
        let got: BTreeMap<u8, BTreeSet<u32>> = groups
            .iter()
            .map(|g| {
                let set: BTreeSet<u32> = g.members.iter().copied().collect();
                assert_eq!(
                    set.len(),
                    g.members.len(),
                    "round {round}: duplicate member"
                );
                (g.object, set)
            })
            .collect();
        assert_eq!(got, want, "round {round}");
        for g in groups.iter() {
            let pixels = map.iter().filter(|&&o| o == g.object).count() as u32;
            assert_eq!(g.pixels, pixels);
        }
    }
}

/// Issue sizes: N = 500k, 480×360, k = 8, three vehicles covering ~30 % of the image.
/// Prints the median of grouping and of loss+gradient over repeated runs.
#[test]
#[ignore]
fn speed_at_issue_sizes() {
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
