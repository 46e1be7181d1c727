//! Top-k contributors equal a brute-force per-pixel reference (float64, sorted weights).

mod common;
use common::Scene;
use splat::reference::{render, RefGaussians};
use splat::{Rasterizer, RenderOptions};

fn check(k: usize, seed: u64) {
    let s = Scene::random(seed, 80, 48, 40, Some(1));
    let opts = RenderOptions {
        topk: k,
        ..Default::default()
    };
    let g = s.gaussians();
    let mut r = Rasterizer::new();
    let out = r.forward(&g, &s.cam, &opts).expect("forward");
    let want = render(&RefGaussians::from_gaussians(&g), &s.cam, &opts);
    let px = (s.cam.width * s.cam.height) as usize;
    assert_eq!(out.topk_ids.len(), px * k);
    assert_eq!(out.topk_weights.len(), px * k);
    let mut filled = 0;
    for p in 0..px {
        for j in 0..k {
            let i = p * k + j;
            let (id, wt) = (out.topk_ids[i], out.topk_weights[i] as f64);
            let (rid, rwt) = (want.topk_ids[i], want.topk_weights[i]);
            assert!(
                (wt - rwt).abs() < 1e-5,
                "pixel {p} slot {j}: weight {wt} vs {rwt}"
            );
            // Different ids are only acceptable for (near-)equal weights.
            if id != rid {
                let near_tie = j + 1 < k && (want.topk_weights[i + 1] - rwt).abs() < 1e-5
                    || j > 0 && (want.topk_weights[i - 1] - rwt).abs() < 1e-5;
                assert!(near_tie, "pixel {p} slot {j}: id {id} vs {rid}");
            }
            if j > 0 {
                assert!(out.topk_weights[i] <= out.topk_weights[i - 1], "not sorted");
            }
            filled += (id != u32::MAX) as usize;
        }
    }
    // The scene must exercise both full and partly empty lists.
    assert!(filled > px / 2, "filled {filled} of {}", px * k);
    if k > 1 {
        assert!(
            filled < px * k,
            "every list full: the fewer-than-k case is untested"
        );
    }
}

#[test]
fn topk_1() {
    check(1, 11);
}

#[test]
fn topk_3() {
    check(3, 12);
}

#[test]
fn topk_8() {
    check(8, 13);
}

#[test]
fn topk_zero_gives_empty_maps() {
    let s = Scene::random(5, 10, 20, 20, None);
    let mut r = Rasterizer::new();
    let out = r
        .forward(&s.gaussians(), &s.cam, &RenderOptions::default())
        .expect("forward");
    assert!(out.topk_ids.is_empty() && out.topk_weights.is_empty());
}
