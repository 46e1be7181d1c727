//! SAM automatic-mask speed on one 480×360 toycars frame, and the quality of the faster
//! adaptive mode against the full 32×32 grid (≈30 s+; needs `mobile_sam.pt`, which
//! `semdynreg weights fetch` gets, and says so when it is absent):
//!
//!     SEMDYNREG_WEIGHTS=weights cargo bench -p semantics --bench sam_speed
//!
//! Prints one JSON object: the measured GEMM rate for the decoder's dominant product shape and
//! the decoder's floor at that rate (its FLOPs per prompt, `docs/performance.md`), encoder and
//! decoder times — wall clock and process CPU time, the latter less sensitive to other jobs on
//! a shared machine — prompt counts, and for the faster modes the per-vehicle IoU (with GT
//! labels) and the area-weighted best-match IoU of the full grid's masks.

#[path = "../tests/sam_common/mod.rs"]
mod sam_common;

use std::time::Instant;

use rayon::prelude::*;
use sam_common::{cpu_seconds, mobile_sam_path, per_object_iou, toycars_scene};
use semantics::automask::{generate_from_embedding, AutoMasks, MaskGenConfig, Sampling};
use semantics::sam::kernels::matmul;
use semantics::sam::Sam;
use semantics::segment::{labels_from_gt, paint_labels};

/// Decoder FLOPs per prompt (docs/performance.md "Floor"): the two-way transformer, and the
/// output upscaling over the 48×64 embedding cells a 480×360 frame covers, for upscaled prompts.
const TRANSFORMER_FLOP: f64 = 0.86e9;
const UPSCALE_FLOP: f64 = 0.61e9;

/// GFLOP/s of the 4096×256×56 product (the folded attention shape), one thread per core.
fn gemm_rate(threads: usize) -> f64 {
    let (m, k, n) = (4096, 256, 56);
    let a: Vec<f32> = (0..m * k).map(|i| (i % 17) as f32 * 0.01).collect();
    let b: Vec<f32> = (0..k * n).map(|i| (i % 13) as f32 * 0.01).collect();
    let reps = 200;
    let t = Instant::now();
    (0..threads).into_par_iter().for_each(|_| {
        let mut c = vec![0.0f32; m * n];
        for _ in 0..reps {
            matmul(m, n, k, &a, (k, 1), &b, (n, 1), &mut c, n, false);
        }
    });
    (2 * m * k * n * reps * threads) as f64 / t.elapsed().as_secs_f64() / 1e9
}

/// Area-weighted mean over `reference` masks of the best IoU with any mask of `other`.
fn best_match_iou(reference: &AutoMasks, other: &AutoMasks) -> f64 {
    let (nr, no) = (reference.masks.len(), other.masks.len());
    let mut inter = vec![0usize; nr * (no + 1)];
    for (&a, &b) in reference.labels.iter().zip(&other.labels) {
        if a != u16::MAX {
            let bi = if b == u16::MAX { no } else { b as usize };
            inter[a as usize * (no + 1) + bi] += 1;
        }
    }
    let (mut num, mut den) = (0.0, 0.0);
    for (i, r) in reference.masks.iter().enumerate() {
        let best = (0..no)
            .map(|j| {
                let x = inter[i * (no + 1) + j] as f64;
                x / ((r.area + other.masks[j].area) as f64 - x)
            })
            .fold(0.0f64, f64::max);
        num += best * r.area as f64;
        den += r.area as f64;
    }
    num / den.max(1.0)
}

fn main() {
    // SAFETY: the first thing the program does, before any thread exists (as `semdynreg
    // segment` does).
    unsafe { semantics::sam::set_thread_count_env() };
    let Some(ckpt) = mobile_sam_path() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let root = toycars_scene(dir.path(), 3);
    let ds = scene::load_dataset(&root, &Default::default()).unwrap();
    let frame = &ds.train[0];
    let gt = scene::load_mask(&scene::mask_path(&root, &frame.file_path))
        .unwrap()
        .data;
    let (w, h) = (frame.image.width as usize, frame.image.height as usize);
    let sam = Sam::load(&ckpt).unwrap();

    let (t, c) = (Instant::now(), cpu_seconds());
    let emb = sam.embed(&frame.image.data, h, w).unwrap();
    let (encode_s, encode_cpu_s) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    let threads = rayon::current_num_threads();
    let gemm_all = gemm_rate(threads);
    let mut runs = Vec::new();
    let mut full: Option<AutoMasks> = None;
    for sampling in [
        Sampling::Grid(32),
        Sampling::Adaptive {
            coarse: 16,
            fine: 32,
        },
        Sampling::Grid(16),
    ] {
        let cfg = MaskGenConfig {
            sampling,
            ..Default::default()
        };
        let (t, c) = (Instant::now(), cpu_seconds());
        let am = generate_from_embedding(&sam, &emb, &cfg).unwrap();
        let (total_s, cpu_s) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
        let flop = am.stats.prompts as f64 * TRANSFORMER_FLOP
            + am.stats.upscaled_prompts as f64 * UPSCALE_FLOP;
        let floor_s = flop / (gemm_all * 1e9);
        let iou = per_object_iou(&paint_labels(&am, &labels_from_gt(&am, &gt)), &gt, 3);
        let vs_full = full.as_ref().map(|f| best_match_iou(f, &am));
        runs.push(serde_json::json!({
            "sampling": format!("{sampling:?}"), "masks_s": total_s, "masks_cpu_s": cpu_s,
            "decoder_floor_s": floor_s, "vs_floor": total_s / floor_s, "stats": am.stats,
            "final_masks": am.masks.len(), "vehicle_iou": iou, "full_grid_best_match_iou": vs_full,
        }));
        if full.is_none() {
            full = Some(am);
        }
    }
    let report = serde_json::json!({
        "image": [w, h], "threads": threads, "gemm_gflops_1thread": gemm_rate(1),
        "gemm_gflops_all_before": gemm_all, "gemm_gflops_all_after": gemm_rate(threads),
        "encode_s": encode_s, "encode_cpu_s": encode_cpu_s, "runs": runs,
    });
    println!("{}", serde_json::to_string_pretty(&report).unwrap());
}
