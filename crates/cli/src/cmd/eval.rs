//! `semdynreg eval RUN [--split test]`: PSNR, SSIM and (when the LPIPS weights are found)
//! LPIPS-AlexNet of the latest checkpoint on a split, written atomically to
//! `RUN/eval/metrics.json` (`{"mean": {...}, "frames": [...]}`). On a toycars scene (one
//! with `objects.json`), also the deformation consistency against the vehicles' true motion
//! and the share of it each moving vehicle's Gaussians follow (`RUN/eval/consistency.json`).

use anyhow::{Context, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    pub run: PathBuf,
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Skip LPIPS even when its weights are in `$SEMDYNREG_WEIGHTS` (default `./weights`).
    #[arg(long)]
    pub no_lpips: bool,
    /// Skip the deformation-consistency metric of toycars scenes.
    #[arg(long)]
    pub no_consistency: bool,
}

pub fn run(a: Args) -> Result<()> {
    let mut loaded = super::render::LoadedRun::open(&a.run)?;
    let frames = loaded.split(&a.split)?.to_vec();
    let (net, lpips_text) = if a.no_lpips {
        (None, "not computed (--no-lpips)".to_string())
    } else {
        crate::report::scorer::load_lpips()?
    };
    let mut score = net.as_ref().map(|n| {
        move |x: &[f32], y: &[f32], w: usize, h: usize| -> train::Result<f64> {
            n.distance(x, y, w, h)
                .map(f64::from)
                .map_err(|e| train::TrainError::Data(format!("LPIPS: {e}")))
        }
    });
    let scorer = score.as_mut().map(|f| f as train::render::FrameScorer);
    let report = loaded.evaluate(&frames, scorer)?;
    let out = a.run.join("eval").join("metrics.json");
    std::fs::create_dir_all(a.run.join("eval")).context("creating eval folder")?;
    scene::io::write_json(&out, &report).with_context(|| format!("writing {}", out.display()))?;
    let lpips = match report.mean.lpips {
        Some(v) => format!("LPIPS {v:.4}"),
        None => format!("LPIPS {lpips_text}"),
    };
    println!(
        "{}: PSNR {:.3} SSIM {:.4} {lpips} over {} frames → {}",
        a.split,
        report.mean.psnr,
        report.mean.ssim,
        report.frames.len(),
        out.display()
    );
    if a.split == "test" && !a.no_consistency {
        consistency(&a.run)?;
    }
    Ok(())
}

/// Writes and prints the deformation consistency of a toycars run (no-op elsewhere).
fn consistency(run: &std::path::Path) -> Result<()> {
    let Some(v) = crate::report::consistency::named_consistency(run)? else {
        return Ok(());
    };
    let out = run.join("eval").join("consistency.json");
    scene::io::write_json(&out, &v).with_context(|| format!("writing {}", out.display()))?;
    let mut parts = vec![format!("RMS {:.4}", v["rms"].as_f64().unwrap_or(f64::NAN))];
    for (name, o) in v["per_object"].as_object().into_iter().flatten() {
        if let Some(f) = o["follow"].as_f64() {
            parts.push(format!("{name} follows {:.0} % of its motion", 100.0 * f));
        }
    }
    println!(
        "deformation consistency: {} → {}",
        parts.join(", "),
        out.display()
    );
    Ok(())
}
