//! Times the rasterizer on the benchmark scenes with a phase breakdown, plus this
//! machine's rates for the floor (docs/performance.md, "## Rasterizer"):
//!
//! `cargo run --release -p splat --example raster_probe -- [a|b|probe|case03] [reps]`
//! (`/usr/bin/time -v` around it gives the peak memory of a scenario).
//!
//! `-- cull [a|b|cases] [reps]`: the exact tile culling against gsplat's 3.33σ boxes
//! in one process: intersections, gradient slots, evaluated pairs and pairs with
//! α ≥ 1/255 of each, then forward and backward timed alternately (`reps` rounds, each one
//! forward + backward per culling, order swapped every round), medians and ratios.
//!
//! `-- npz PATH [reps]`: forward + backward of a scene in the reference cases' format
//! (FORMAT.md), median wall time (`scripts/bench_gsplat_cpu.py` runs it beside gsplat).
//!
//! `-- proj [a|b|demo|small] [reps]`: the projection and its backward one Gaussian at a time
//! (the scalar reference) against sixteen at a time, alternated in one process: median
//! phase times and their ratio (the images and gradients are bit-identical,
//! tests/bit_identical.rs).

use splat::{Camera, Cull, Gaussians, Gradients, Rasterizer, RenderOptions};
use std::time::Instant;

#[path = "../benches/scene_gen.rs"]
mod scene_gen;

#[path = "../tests/common/mod.rs"]
mod common;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median wall seconds of `reps` runs of `f`.
fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    let v: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .collect();
    median(v)
}

fn scenario(n: usize, w: u32, h: u32, reps: usize) {
    let scene = scene_gen::BenchScene::new(7, n, w, h);
    let g = scene.gaussians();
    let mut r = Rasterizer::new();
    let opts = RenderOptions::default();
    let top8 = RenderOptions {
        topk: 8,
        ..Default::default()
    };
    let dl: Vec<f32> = (0..(w * h * 3) as usize)
        .map(|i| (i % 7) as f32 / 7.0 - 0.5)
        .collect();
    let mut grads = Gradients::default();
    let f = time(reps, || {
        r.forward(&g, &scene.cam, &opts).expect("forward");
    });
    println!("forward phases: {:?}", r.timings());
    let b = time(reps, || {
        r.backward(&g, &scene.cam, &opts, &dl, None, &mut grads)
            .expect("backward");
    });
    println!("backward phases: {:?}", r.timings());
    let t8 = time(reps, || {
        r.forward(&g, &scene.cam, &top8).expect("forward");
    });
    let out = r.forward(&g, &scene.cam, &opts).expect("forward");
    let visible = out.radii.iter().filter(|r| r[0] > 0).count();
    let (isects, pairs) = (out.stats.tile_intersections, out.stats.evaluated_pairs);
    println!(
        "N {n} {w}x{h}: visible {visible}, intersections {isects}, evaluated pairs {pairs}\n\
         forward {f:.4} s ({:.3e} pairs/s), backward {b:.4} s ({:.3e} pairs/s), \
         forward+top8 {t8:.4} s (+{:.1}%)",
        pairs as f64 / f,
        pairs as f64 / b,
        100.0 * (t8 / f - 1.0)
    );
}

/// Arithmetic rate of an autovectorized f32 multiply-add loop on L1-resident data and
/// memory bandwidth of a large sum, both on all rayon threads.
fn probe() {
    use rayon::prelude::*;
    let threads = rayon::current_num_threads();
    let reps = 200_000usize;
    let t = Instant::now();
    let acc: f32 = (0..threads)
        .into_par_iter()
        .map(|s| {
            let mut x = [s as f32 * 1e-3; 64];
            for _ in 0..reps {
                for v in x.iter_mut() {
                    *v = *v * 0.999_9 + 1e-4;
                }
            }
            x.iter().sum::<f32>()
        })
        .sum();
    let flops = (threads * reps * 64 * 2) as f64 / t.elapsed().as_secs_f64();
    let big = vec![1.0f32; 64 << 20];
    let t = Instant::now();
    let mut total = 0.0f32;
    for _ in 0..3 {
        total += big
            .par_chunks(1 << 16)
            .map(|c| c.iter().sum::<f32>())
            .sum::<f32>();
    }
    let bw = (3 * big.len() * 4) as f64 / t.elapsed().as_secs_f64();
    println!(
        "threads {threads}: {flops:.3e} f32 flop/s (mul+add, autovectorized), read bandwidth {:.2} GB/s [{acc} {total}]",
        bw / 1e9
    );
}

/// Forward + backward of reference case 03 (gsplat's PyTorch CPU path: ≈ 0.22 s).
fn case03(reps: usize) {
    let (case, _) = common::Case::load(common::CASES[2]);
    let wall = forward_backward(&case, reps);
    println!(
        "case 03 forward+backward: {wall:.5} s (median of {reps}); \
         gsplat PyTorch CPU 0.22 s is {:.0}x that",
        0.22 / wall
    );
}

/// Median wall seconds of one forward + backward of `case` with its loss weights.
fn forward_backward(case: &common::Case, reps: usize) -> f64 {
    let g = case.gaussians();
    let mut r = Rasterizer::new();
    let mut grads = Gradients::default();
    let aw = case.alpha_weights.clone();
    let wall = time(reps, || {
        r.forward(&g, &case.cam, &case.opts).expect("forward");
        r.backward(
            &g,
            &case.cam,
            &case.opts,
            &case.weights,
            aw.as_deref(),
            &mut grads,
        )
        .expect("backward");
    });
    wall
}

/// Counts and alternated timings of both cullings on one scene (see the header).
fn cull_compare(name: &str, g: &Gaussians, cam: &Camera, base: &RenderOptions, reps: usize) {
    let culls = [Cull::Box3Sigma, Cull::Exact];
    let dl: Vec<f32> = (0..(cam.width * cam.height * 3) as usize)
        .map(|i| (i % 7) as f32 / 7.0 - 0.5)
        .collect();
    let mut rs: Vec<Rasterizer> = culls.iter().map(|_| Rasterizer::new()).collect();
    let opts: Vec<RenderOptions> = culls
        .iter()
        .map(|&cull| RenderOptions {
            cull,
            ..base.clone()
        })
        .collect();
    for ((r, o), c) in rs.iter_mut().zip(&opts).zip(culls) {
        r.set_count_alpha_pairs(true);
        let st = r.forward(g, cam, o).expect("forward").stats;
        r.set_count_alpha_pairs(false);
        let a = st.alpha_pairs.unwrap_or(0);
        println!(
            "{name} {c:?}: intersections {}, gradient slots {}, evaluated pairs {}, \
             pairs with alpha >= 1/255 {a} ({:.1} % of evaluated)",
            st.tile_intersections,
            st.gradient_slots,
            st.evaluated_pairs,
            100.0 * a as f64 / st.evaluated_pairs.max(1) as f64
        );
    }
    // [cull][forward, backward, forward tiles, backward tiles, forward binning, backward
    // slot reduction + zeroing]
    let mut t = vec![vec![Vec::new(); 6]; 2];
    let mut grads = Gradients::default();
    for rep in 0..reps {
        for k in [rep % 2, 1 - rep % 2] {
            let (r, o) = (&mut rs[k], &opts[k]);
            let t0 = Instant::now();
            r.forward(g, cam, o).expect("forward");
            let ft = r.timings();
            let t1 = Instant::now();
            r.backward(g, cam, o, &dl, None, &mut grads)
                .expect("backward");
            let bt = r.timings();
            t[k][0].push((t1 - t0).as_secs_f64());
            t[k][1].push(t1.elapsed().as_secs_f64());
            t[k][2].push(ft.raster);
            t[k][3].push(bt.raster);
            t[k][4].push(ft.bin);
            t[k][5].push(bt.bin + bt.finish);
        }
    }
    let m: Vec<Vec<f64>> = t
        .into_iter()
        .map(|v| v.into_iter().map(median).collect())
        .collect();
    let ms = |v: f64| v * 1e3;
    for (k, c) in culls.iter().enumerate() {
        println!(
            "{name} {c:?}: forward {:.2} ms (binning {:.2}, tiles {:.2}), backward {:.2} ms \
             (tiles {:.2}, slots {:.2}), forward+backward {:.2} ms (medians of {reps})",
            ms(m[k][0]),
            ms(m[k][4]),
            ms(m[k][2]),
            ms(m[k][1]),
            ms(m[k][3]),
            ms(m[k][5]),
            ms(m[k][0] + m[k][1])
        );
    }
    println!(
        "{name} Box3Sigma/Exact: forward {:.3}x, backward {:.3}x, forward+backward {:.3}x",
        m[0][0] / m[1][0],
        m[0][1] / m[1][1],
        (m[0][0] + m[0][1]) / (m[1][0] + m[1][1])
    );
}

fn cull(which: &str, reps: usize) {
    match which {
        "cases" => {
            for stem in common::CASES {
                let (case, _) = common::Case::load(stem);
                cull_compare(stem, &case.gaussians(), &case.cam, &case.opts, reps);
            }
        }
        "b" | "a" => {
            let (n, w, h) = if which == "b" {
                (500_000, 1440, 1080)
            } else {
                (100_000, 800, 800)
            };
            let scene = scene_gen::BenchScene::new(7, n, w, h);
            let opts = RenderOptions::default();
            cull_compare(which, &scene.gaussians(), &scene.cam, &opts, reps);
        }
        _ => panic!("cull [a|b|cases] [reps]"),
    }
}

/// Scalar against 16-lane projection (see the header).
fn proj(which: &str, reps: usize) {
    let (n, w, h) = match which {
        "b" => (500_000, 1440, 1080),
        // The demo baseline's end state has ~51k Gaussians at 160×120.
        "demo" => (51_000, 160, 120),
        "small" => (4_000, 160, 120),
        _ => (100_000, 800, 800),
    };
    let scene = scene_gen::BenchScene::new(7, n, w, h);
    let g = scene.gaussians();
    let opts = RenderOptions::default();
    let dl: Vec<f32> = (0..(w * h * 3) as usize)
        .map(|i| (i % 7) as f32 / 7.0 - 0.5)
        .collect();
    let mut rs = [Rasterizer::new(), Rasterizer::new()];
    rs[0].set_scalar_projection(true);
    // [scalar, 16 lanes][forward projection, backward projection]
    let mut t = [[(); 2].map(|_| Vec::new()), [(); 2].map(|_| Vec::new())];
    let mut grads = Gradients::default();
    for rep in 0..reps {
        for k in [rep % 2, 1 - rep % 2] {
            let r = &mut rs[k];
            r.forward(&g, &scene.cam, &opts).expect("forward");
            t[k][0].push(r.timings().project);
            r.backward(&g, &scene.cam, &opts, &dl, None, &mut grads)
                .expect("backward");
            t[k][1].push(r.timings().project);
        }
    }
    let m = t.map(|v| v.map(median));
    let visible = rs[1]
        .forward(&g, &scene.cam, &opts)
        .expect("forward")
        .radii
        .iter()
        .filter(|r| r[0] > 0)
        .count();
    let ms = |v: f64| v * 1e3;
    println!(
        "{which}: {n} Gaussians ({visible} visible), {w}x{h}, SIMD {:?}, medians of {reps}\n\
         scalar:   projection forward {:.2} ms, backward {:.2} ms\n\
         16 lanes: projection forward {:.2} ms, backward {:.2} ms\n\
         scalar/16 lanes: forward {:.2}x, backward {:.2}x, both {:.2}x",
        rs[1].simd(),
        ms(m[0][0]),
        ms(m[0][1]),
        ms(m[1][0]),
        ms(m[1][1]),
        m[0][0] / m[1][0],
        m[0][1] / m[1][1],
        (m[0][0] + m[0][1]) / (m[1][0] + m[1][1])
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3);
    match args.get(1).map(String::as_str) {
        Some("b") => scenario(500_000, 1440, 1080, reps),
        Some("probe") => probe(),
        Some("case03") => case03(reps),
        Some("npz") => {
            let path = args.get(2).expect("npz PATH [reps]");
            let reps = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(21);
            let case = common::Case::from_npz(std::path::Path::new(path));
            let wall = forward_backward(&case, reps);
            println!("forward+backward {wall:.6} s (median of {reps})");
        }
        Some("proj") => {
            let reps = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(21);
            proj(args.get(2).map_or("a", String::as_str), reps)
        }
        Some("cull") => {
            let reps = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(5);
            cull(args.get(2).map_or("a", String::as_str), reps)
        }
        _ => scenario(100_000, 800, 800, reps),
    }
}
