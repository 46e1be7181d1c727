//! MobileSAM's image encoder (TinyViT-5M at 1024²) alone: the cost of every tracked frame
//! (`segment --track` runs it once per frame; docs/performance.md "Tracking"). Needs
//! `mobile_sam.pt` (`semdynreg weights fetch`), and says so when it is absent:
//!
//!     SEMDYNREG_WEIGHTS=weights cargo bench -p semantics --bench sam_encoder_speed
//!
//! Prints one JSON object: wall and process-CPU seconds of each of `REPS` embeddings of one
//! 480×360 toycars frame after a warm-up, their medians, and the encoder's floor (its
//! multiply-adds, counted in docs/performance.md, over the GEMM rate measured in the same
//! process on the encoder's commonest product shape).

#[path = "../tests/sam_common/mod.rs"]
mod sam_common;

use std::time::Instant;

use sam_common::{cpu_seconds, mobile_sam_path, toycars_scene};
use semantics::sam::Sam;

const REPS: usize = 5;
/// TinyViT-5M plus neck at 1024² (docs/performance.md "Tracking"): 38.6 G multiply-adds.
const ENCODER_FLOP: f64 = 2.0 * 38.6e9;

/// GFLOP/s of a 16384×128×512 product (the first attention stage's MLP) through candle,
/// whose matrix products the encoder uses (all threads).
fn gemm_rate() -> f64 {
    use candle_core::{Device, Tensor};
    let a = Tensor::ones((16384, 128), candle_core::DType::F32, &Device::Cpu).unwrap();
    let b = Tensor::ones((128, 512), candle_core::DType::F32, &Device::Cpu).unwrap();
    let _ = a.matmul(&b).unwrap();
    let reps: usize = 20;
    let t = Instant::now();
    for _ in 0..reps {
        let _ = a.matmul(&b).unwrap();
    }
    2.0 * (16384 * 128 * 512 * reps) as f64 / t.elapsed().as_secs_f64() / 1e9
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let Some(weights) = mobile_sam_path() else {
        return;
    };
    // SAFETY: start of main, no other threads yet.
    unsafe { semantics::sam::set_thread_count_env() };
    let sam = Sam::load(&weights).expect("load MobileSAM");
    let tmp = tempfile::tempdir().unwrap();
    let root = toycars_scene(tmp.path(), 3);
    let ds = scene::load_dataset(&root, &Default::default()).unwrap();
    let frame = &ds.train[0];
    let (w, h) = (frame.image.width, frame.image.height);
    let rgb = &frame.image.data;
    let rate_before = gemm_rate();
    let _ = sam.embed(rgb, h as usize, w as usize).unwrap();
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for _ in 0..REPS {
        let (t, c) = (Instant::now(), cpu_seconds());
        let _ = sam.embed(rgb, h as usize, w as usize).unwrap();
        wall.push(t.elapsed().as_secs_f64());
        cpu.push(cpu_seconds() - c);
    }
    let rate = rate_before.max(gemm_rate());
    let json = serde_json::json!({
        "simd": format!("{:?}", simd::level()),
        "threads": rayon::current_num_threads(),
        "wall_s": wall,
        "cpu_s": cpu,
        "median_wall_s": median(wall.clone()),
        "median_cpu_s": median(cpu.clone()),
        "gemm_gflops": rate,
        "floor_s": ENCODER_FLOP / (rate * 1e9),
    });
    println!("{json:#}");
}
