//! Exact tile culling (`Cull::Exact`) against gsplat's 3.33σ-box binning
//! (`Cull::Box3Sigma`) in one process: images, alphas, top-k lists and weights, radii and
//! every gradient must be **bit-identical** (the dropped (tile, Gaussian) pairs are ones the
//! kernels evaluate no row of, so nothing downstream can change; the backward's per-Gaussian
//! slot sums keep their row-major tile order). Each check also requires that the exact
//! culling dropped intersections (else the comparison would test nothing) and that the
//! forward kernels evaluated exactly the same pairs.

mod common;
use common::{Case, Scene, CASES};
use rand::{Rng, SeedableRng};
use splat::{Cull, Gaussians, Gradients, RasterStats, Rasterizer, RenderOptions};

struct Run {
    image: Vec<f32>,
    alpha: Vec<f32>,
    topk_ids: Vec<u32>,
    topk_w: Vec<f32>,
    radii: Vec<[i32; 2]>,
    grads: Gradients,
    stats: RasterStats,
}

fn run(
    g: &Gaussians,
    cam: &splat::Camera,
    opts: &RenderOptions,
    cull: Cull,
    dl: &[f32],
    da: Option<&[f32]>,
) -> Run {
    let opts = RenderOptions {
        cull,
        ..opts.clone()
    };
    let mut r = Rasterizer::new();
    let out = r.forward(g, cam, &opts).expect("forward");
    assert_eq!(out.stats.tile_intersections as usize, out.n_isects);
    let (image, alpha, topk_ids, topk_w, radii, stats) = (
        out.image.to_vec(),
        out.alpha.to_vec(),
        out.topk_ids.to_vec(),
        out.topk_weights.to_vec(),
        out.radii.to_vec(),
        out.stats,
    );
    let mut grads = Gradients::default();
    r.backward(g, cam, &opts, dl, da, &mut grads)
        .expect("backward");
    Run {
        image,
        alpha,
        topk_ids,
        topk_w,
        radii,
        grads,
        stats,
    }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Runs both cullings and requires bit-identical results; returns (exact, box) stats.
fn compare(
    what: &str,
    g: &Gaussians,
    cam: &splat::Camera,
    opts: &RenderOptions,
    dl: &[f32],
    da: Option<&[f32]>,
) -> (RasterStats, RasterStats) {
    let e = run(g, cam, opts, Cull::Exact, dl, da);
    let b = run(g, cam, opts, Cull::Box3Sigma, dl, da);
    assert_eq!(bits(&e.image), bits(&b.image), "{what}: image");
    assert_eq!(bits(&e.alpha), bits(&b.alpha), "{what}: alpha");
    assert_eq!(e.topk_ids, b.topk_ids, "{what}: top-k ids");
    assert_eq!(bits(&e.topk_w), bits(&b.topk_w), "{what}: top-k weights");
    assert_eq!(e.radii, b.radii, "{what}: radii");
    let (x, y) = (&e.grads, &b.grads);
    let m2 = |v: &[[f32; 2]]| v.iter().flat_map(|p| *p).collect::<Vec<f32>>();
    for (name, p, q) in [
        ("means", &x.means, &y.means),
        ("quats", &x.quats, &y.quats),
        ("scales", &x.scales, &y.scales),
        ("opacity", &x.opacity_logits, &y.opacity_logits),
        ("colors", &x.colors, &y.colors),
        ("means2d", &m2(&x.means2d), &m2(&y.means2d)),
    ] {
        assert_eq!(bits(p), bits(q), "{what}: gradient of {name}");
    }
    // The dropped pairs are ones no kernel row was evaluated for.
    assert_eq!(
        e.stats.evaluated_pairs, b.stats.evaluated_pairs,
        "{what}: evaluated pairs"
    );
    assert!(
        e.stats.tile_intersections < b.stats.tile_intersections,
        "{what}: nothing culled ({:?})",
        e.stats
    );
    assert!(e.stats.gradient_slots <= b.stats.gradient_slots);
    assert!(
        x.means.iter().any(|&v| v != 0.0),
        "{what}: all-zero gradients"
    );
    eprintln!(
        "{what}: intersections {} -> {}, slots {} -> {}, evaluated pairs {}",
        b.stats.tile_intersections,
        e.stats.tile_intersections,
        b.stats.gradient_slots,
        e.stats.gradient_slots,
        e.stats.evaluated_pairs
    );
    (e.stats, b.stats)
}

#[test]
fn reference_cases_bit_identical() {
    for stem in CASES {
        let (case, _) = Case::load(stem);
        let g = case.gaussians();
        let aw = case.alpha_weights.as_deref();
        compare(stem, &g, &case.cam, &case.opts, &case.weights, aw);
        let top4 = RenderOptions {
            topk: 4,
            ..case.opts.clone()
        };
        compare(
            &format!("{stem} top-4"),
            &g,
            &case.cam,
            &top4,
            &case.weights,
            aw,
        );
    }
}

/// `Scene::random` plus Gaussians that stress the culling: opacity within a few percent of
/// 1/255 (either side), huge and needle-thin elongated ones, and means on tile borders.
fn stress_scene(seed: u64, n: usize, w: u32, h: u32) -> Scene {
    let mut s = Scene::random(seed, n, w, h, Some(1));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let logit = |o: f32| (o / (1.0 - o)).ln();
    for i in 0..n {
        match i % 5 {
            // Faint: o ∈ 1/255 · [0.97, 1.3].
            0 => s.logits[i] = logit(rng.gen_range(0.97f32..1.3) / 255.0),
            // Needle: one long axis, two thin ones.
            1 => {
                let long = rng.gen_range(0.3f32..1.5);
                let thin = rng.gen_range(0.002f32..0.01);
                s.scales[3 * i..3 * i + 3].copy_from_slice(&[long, thin, thin]);
            }
            // Huge and faint-ish: covers many tiles.
            2 => {
                let big = rng.gen_range(0.5f32..1.2);
                s.scales[3 * i..3 * i + 3].fill(big);
                s.logits[i] = rng.gen_range(-5.0f32..-1.0);
            }
            // Mean on a tile corner (projected): back-project pixel (16k, 16l) at depth z.
            3 => {
                let z = s.means[3 * i + 2];
                let (px, py) = (
                    16.0 * rng.gen_range(0..w.div_ceil(16)) as f32,
                    16.0 * rng.gen_range(0..h.div_ceil(16)) as f32,
                );
                let cam = [
                    (px - s.cam.cx) / s.cam.fx * z,
                    (py - s.cam.cy) / s.cam.fy * z,
                    z,
                ];
                s.means[3 * i..3 * i + 3].copy_from_slice(&world_of(&s.cam, cam));
            }
            _ => {}
        }
    }
    s
}

/// Inverse of `Camera::to_camera` for a rigid `viewmat`.
fn world_of(cam: &splat::Camera, p: [f32; 3]) -> [f32; 3] {
    let m = &cam.viewmat;
    let d = [p[0] - m[0][3], p[1] - m[1][3], p[2] - m[2][3]];
    std::array::from_fn(|k| m[0][k] * d[0] + m[1][k] * d[1] + m[2][k] * d[2])
}

#[test]
fn random_scenes_bit_identical() {
    for (seed, n, w, h) in [(1u64, 300, 97, 71), (2, 800, 160, 120), (3, 2000, 250, 190)] {
        let s = stress_scene(seed, n, w, h);
        let g = s.gaussians();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let dl: Vec<f32> = (0..(w * h * 3) as usize)
            .map(|_| rng.gen_range(-1.0..1.0))
            .collect();
        let da: Vec<f32> = (0..(w * h) as usize)
            .map(|_| rng.gen_range(-1.0..1.0))
            .collect();
        for topk in [0, 3] {
            let opts = RenderOptions {
                topk,
                background: [0.1, 0.4, 0.8],
                ..Default::default()
            };
            let what = format!("seed {seed} top-{topk}");
            let (e, b) = compare(&what, &g, &s.cam, &opts, &dl, Some(&da));
            // The stress Gaussians must make the culling bite, not only graze it.
            assert!(
                e.tile_intersections * 10 < b.tile_intersections * 9,
                "{what}: less than 10 % culled"
            );
        }
    }
}

/// The diagnostic counter: pairs with α ≥ 1/255 are a subset of the evaluated ones, are the
/// same for both cullings, and counting them changes no result.
#[test]
fn alpha_pair_counter() {
    let s = stress_scene(4, 600, 130, 90);
    let g = s.gaussians();
    let opts = RenderOptions::default();
    let mut plain = Rasterizer::new();
    let want = plain.forward(&g, &s.cam, &opts).expect("forward");
    assert_eq!(want.stats.alpha_pairs, None);
    assert_eq!((want.stats.pairs_4x4, want.stats.pairs_8x2), (None, None));
    let want_image = bits(want.image);
    let mut counts = Vec::new();
    for cull in [Cull::Exact, Cull::Box3Sigma] {
        let mut r = Rasterizer::new();
        r.set_count_alpha_pairs(true);
        let o = RenderOptions {
            cull,
            ..opts.clone()
        };
        let out = r.forward(&g, &s.cam, &o).expect("forward");
        assert_eq!(
            bits(out.image),
            want_image,
            "{cull:?}: counting changed the image"
        );
        let st = out.stats;
        let a = st.alpha_pairs.expect("counted");
        assert!(a > 0 && a < st.evaluated_pairs, "{cull:?}: {st:?}");
        // A block layout evaluates every pixel that passes (its row's chord meets its
        // block), so it is bounded below by the alpha pairs.
        let (b4, b8) = (
            st.pairs_4x4.expect("counted"),
            st.pairs_8x2.expect("counted"),
        );
        assert!(b4 >= a && b8 >= a, "{cull:?}: {st:?}");
        assert!(b4 % 16 == 0 && b8 % 16 == 0, "whole blocks: {st:?}");
        counts.push((a, b4, b8));
    }
    assert_eq!(counts[0], counts[1]);
}

/// Nothing to bin (no Gaussians; all behind the camera): both cullings give the background
/// and zero gradients, with no intersections.
#[test]
fn empty_scenes() {
    let mut behind = Scene::random(5, 50, 40, 30, None);
    for m in behind.means.chunks_mut(3) {
        m[2] = -m[2];
    }
    let mut none = Scene::random(5, 1, 40, 30, None);
    for v in [
        &mut none.means,
        &mut none.quats,
        &mut none.scales,
        &mut none.logits,
        &mut none.colors,
    ] {
        v.clear();
    }
    let dl = vec![0.5f32; 40 * 30 * 3];
    for (what, sc) in [("behind", &behind), ("none", &none)] {
        let g = sc.gaussians();
        let opts = RenderOptions {
            background: [0.25, 0.5, 0.75],
            ..Default::default()
        };
        for cull in [Cull::Exact, Cull::Box3Sigma] {
            let r = run(&g, &sc.cam, &opts, cull, &dl, None);
            assert_eq!(r.stats.tile_intersections, 0, "{what} {cull:?}");
            assert!(r.image.chunks(3).all(|p| p == [0.25, 0.5, 0.75]), "{what}");
            assert!(r.grads.means.iter().all(|&v| v == 0.0), "{what}");
        }
    }
}
