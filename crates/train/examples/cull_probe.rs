//! The rasterizer's exact tile culling at a trained state: loads a checkpoint,
//! deforms its Gaussians to each chosen training frame's time exactly as rendering does
//! (`render.rs`: visible-rows rule, objects placed), and runs forward + backward with
//! `Cull::Box3Sigma` (gsplat's 3.33σ boxes) and `Cull::Exact` alternately in one process.
//! Prints intersections, gradient slots, evaluated pairs and pairs with α ≥ 1/255, checks
//! that both give bit-identical images and gradients, and reports medians and ratios:
//!
//! `cargo run --profile test -p train --example cull_probe -- CHECKPOINT SCENE [frames]
//! [reps]` (frames: how many training frames, spread over the sequence; default 4, 7 reps).

use splat::{Cull, Gradients, Rasterizer, RenderOptions};
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(ckpt), Some(scene)) = (args.get(1), args.get(2)) else {
        panic!("usage: cull_probe CHECKPOINT SCENE [frames] [reps]");
    };
    let frames: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(4);
    let reps: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(7);
    let mut lm = train::checkpoint::load_model(ckpt.as_ref()).expect("checkpoint");
    let ds = scene::load_dataset(scene.as_ref(), &scene::LoadOptions::default()).expect("scene");
    println!(
        "checkpoint {ckpt}: iteration {}, {} Gaussians",
        lm.iteration,
        lm.model.opacity_logits.len()
    );
    let culls = [Cull::Box3Sigma, Cull::Exact];
    let mut rs = [Rasterizer::new(), Rasterizer::new()];
    // [cull][forward, backward, forward binning, forward tiles, backward tiles, forward
    // projection, backward projection, backward slots (zeroing + reduction)] over all
    // frames and rounds
    let mut t: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); 8]; 2];
    let mut totals = [[0u64; 6]; 2];
    let mut renderer = train::render::Renderer::default();
    let step = ds.train.len().div_ceil(frames).max(1);
    for fr in ds.train.iter().step_by(step) {
        let cam = &fr.camera;
        let deformed = renderer.deformed(lm.scene(), cam, fr.time);
        let g = train::deform::gaussians(&lm.model, deformed);
        let opts: Vec<RenderOptions> = culls
            .iter()
            .map(|&cull| RenderOptions {
                background: ds.background,
                cull,
                ..RenderOptions::default()
            })
            .collect();
        let dl: Vec<f32> = (0..(cam.width * cam.height * 3) as usize)
            .map(|i| (i % 7) as f32 / 7.0 - 0.5)
            .collect();
        let mut out_bits = Vec::new();
        for k in 0..2 {
            rs[k].set_count_alpha_pairs(true);
            let out = rs[k].forward(&g, cam, &opts[k]).expect("forward");
            let st = out.stats;
            let img: Vec<u32> = out.image.iter().map(|v| v.to_bits()).collect();
            rs[k].set_count_alpha_pairs(false);
            let mut grads = Gradients::default();
            rs[k].forward(&g, cam, &opts[k]).expect("forward");
            rs[k]
                .backward(&g, cam, &opts[k], &dl, None, &mut grads)
                .expect("backward");
            let gb: Vec<u32> = [
                &grads.means,
                &grads.scales,
                &grads.quats,
                &grads.opacity_logits,
                &grads.colors,
            ]
            .iter()
            .flat_map(|v| v.iter().map(|x| x.to_bits()))
            .collect();
            out_bits.push((img, gb));
            let s = [
                st.tile_intersections,
                st.gradient_slots,
                st.evaluated_pairs,
                st.alpha_pairs.unwrap_or(0),
                st.pairs_4x4.unwrap_or(0),
                st.pairs_8x2.unwrap_or(0),
            ];
            for (a, b) in totals[k].iter_mut().zip(s) {
                *a += b;
            }
        }
        assert!(
            out_bits[0] == out_bits[1],
            "{}: results differ",
            fr.file_path
        );
        let mut grads = Gradients::default();
        for rep in 0..reps {
            for k in [rep % 2, 1 - rep % 2] {
                let t0 = Instant::now();
                rs[k].forward(&g, cam, &opts[k]).expect("forward");
                let t1 = Instant::now();
                let ft = rs[k].timings();
                t[k][2].push(ft.bin);
                t[k][3].push(ft.raster);
                t[k][5].push(ft.project);
                rs[k]
                    .backward(&g, cam, &opts[k], &dl, None, &mut grads)
                    .expect("backward");
                t[k][0].push((t1 - t0).as_secs_f64());
                t[k][1].push(t1.elapsed().as_secs_f64());
                let bt = rs[k].timings();
                t[k][4].push(bt.raster);
                t[k][6].push(bt.project);
                t[k][7].push(bt.bin + bt.finish);
            }
        }
        println!("{} (t = {:.3}): bit-identical", fr.file_path, fr.time);
    }
    for (k, c) in culls.iter().enumerate() {
        let [i, s, p, a, b4, b8] = totals[k];
        let pct = |x: u64| 100.0 * x as f64 / p.max(1) as f64;
        println!(
            "{c:?}, summed over frames: intersections {i}, gradient slots {s}, evaluated pairs {p}, \
             alpha >= 1/255 pairs {a} ({:.1} %); a 4x4-block layout would evaluate {b4} \
             ({:.1} %), 8x2 blocks {b8} ({:.1} %)",
            pct(a),
            pct(b4),
            pct(b8)
        );
    }
    let m: Vec<Vec<f64>> = t
        .into_iter()
        .map(|v| v.into_iter().map(|x| median(x) * 1e3).collect())
        .collect();
    for (k, c) in culls.iter().enumerate() {
        println!(
            "{c:?}: forward {:.2} ms (projection {:.2}, binning {:.2}, tiles {:.2}), backward \
             {:.2} ms (tiles {:.2}, slots {:.2}, projection {:.2}), medians over frames × \
             {reps} rounds",
            m[k][0], m[k][5], m[k][2], m[k][3], m[k][1], m[k][4], m[k][7], m[k][6]
        );
    }
    println!(
        "Box3Sigma/Exact: forward {:.3}x, backward {:.3}x, forward+backward {:.3}x",
        m[0][0] / m[1][0],
        m[0][1] / m[1][1],
        (m[0][0] + m[0][1]) / (m[1][0] + m[1][1])
    );
}
