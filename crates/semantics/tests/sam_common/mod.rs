//! Shared helpers of the SAM integration tests: finding the real weights (skipping with a
//! printed reason when absent) and the synthetic image of `scripts/make_sam_fixture.py`.

use std::path::PathBuf;

/// `$SEMDYNREG_WEIGHTS/mobile_sam.pt`, else `<workspace>/weights/mobile_sam.pt`; `None` (and a
/// printed reason) when the file is absent.
pub fn mobile_sam_path() -> Option<PathBuf> {
    let dir = std::env::var_os("SEMDYNREG_WEIGHTS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../weights"));
    let p = dir.join("mobile_sam.pt");
    if p.is_file() {
        Some(p)
    } else {
        eprintln!(
            "SKIPPED: {} absent (run `semdynreg weights fetch`, or set SEMDYNREG_WEIGHTS)",
            p.display()
        );
        None
    }
}

#[allow(dead_code)]
pub const H: usize = 180;
#[allow(dead_code)]
pub const W: usize = 240;

/// Same integer formula as `synthetic_image` in scripts/make_sam_fixture.py.
#[allow(dead_code)]
pub fn synthetic_image() -> Vec<u8> {
    let mut img = vec![0u8; H * W * 3];
    for y in 0..H as i64 {
        for x in 0..W as i64 {
            let mut px = [
                (x * 255 / (W as i64 - 1)) / 3 + 40,
                (y * 255 / (H as i64 - 1)) / 3 + 60,
                90 + (x + y) % 32,
            ];
            if (30..90).contains(&x) && (40..100).contains(&y) {
                px = [230, 230, 235];
            } else if (x - 160).pow(2) * 22 * 22 + (y - 60).pow(2) * 35 * 35 <= 35 * 35 * 22 * 22 {
                px = [220, 200, 30];
            } else if (120..200).contains(&x) && (110..160).contains(&y) {
                px = [40, 160, 60];
            }
            let o = (y as usize * W + x as usize) * 3;
            for c in 0..3 {
                img[o + c] = px[c] as u8;
            }
        }
    }
    img
}

/// Render a small toycars scene (480×360, `frames` frames: frame 0 test, 1 val, 2… train).
#[allow(dead_code)]
pub fn toycars_scene(dir: &std::path::Path, frames: usize) -> PathBuf {
    let cfg = scene::toycars::ToycarsConfig {
        frames,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, dir, &|_, _| {}).unwrap();
    dir.to_path_buf()
}

/// Per-object IoU (object IDs 0..n) between an ID map and the ground truth.
#[allow(dead_code)]
pub fn per_object_iou(ids: &[u8], gt: &[u8], n: u8) -> Vec<f64> {
    (0..n)
        .map(|o| {
            let inter = ids
                .iter()
                .zip(gt)
                .filter(|(a, b)| **a == o && **b == o)
                .count();
            let union = ids
                .iter()
                .zip(gt)
                .filter(|(a, b)| **a == o || **b == o)
                .count();
            inter as f64 / union.max(1) as f64
        })
        .collect()
}

/// User + system CPU seconds of this process so far (all threads), from /proc/self/stat
/// (fields 14 and 15, in USER_HZ = 100 ticks per second on Linux); 0 where unavailable.
/// Used by the benches, which time CPU beside wall clock.
#[allow(dead_code)]
pub fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // The command name (field 2) may hold spaces; fields after its closing parenthesis.
    let rest = stat.rsplit_once(')').map(|r| r.1).unwrap_or("");
    let f: Vec<f64> = rest
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|v| v.parse().ok())
        .collect();
    f.iter().sum::<f64>() / 100.0
}
