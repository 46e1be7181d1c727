//! `semdynreg eval RUN [--split test] [--iteration N]`: PSNR, SSIM and (when the LPIPS
//! weights are found) LPIPS-AlexNet of the latest checkpoint (or iteration N's) on a split,
//! written atomically to `RUN/eval/metrics.json` (`RUN/eval/iter_NNNNNNN/` with
//! `--iteration`; `{"mean": {...}, "frames": [...]}`). On a toycars scene (one
//! with `objects.json`), also the deformation consistency against the vehicles' true motion
//! the share of it each moving vehicle's Gaussians follow, and the rigidity residual of each
//! vehicle's Gaussians (how rigidly they move together; `RUN/eval/consistency.json`).

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// PSNR, SSIM, LPIPS (and, on toycars, deformation consistency) of a run's checkpoint.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder made by `semdynreg train`.
    pub run: PathBuf,
    /// Which cameras to score: train, val or test.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Score the checkpoint of this iteration instead of the latest; the results then go
    /// to `RUN/eval/iter_NNNNNNN/`.
    #[arg(long)]
    pub iteration: Option<u32>,
    /// Skip LPIPS even when its weights are in `$SEMDYNREG_WEIGHTS` (default `./weights`).
    #[arg(long)]
    pub no_lpips: bool,
    /// Skip the deformation-consistency metric of toycars scenes.
    #[arg(long)]
    pub no_consistency: bool,
    /// Never fetch missing weights (default: the LPIPS weights are fetched on first use
    /// with pip, `semdynreg weights fetch`); also `SEMDYNREG_OFFLINE=1`.
    #[arg(long)]
    pub offline: bool,
}

pub fn run(a: Args) -> Result<()> {
    let mut loaded = super::render::LoadedRun::open(&a.run, a.iteration)?;
    let frames = loaded.split(&a.split)?.to_vec();
    let (net, lpips_text) = if a.no_lpips {
        (None, "not computed (--no-lpips)".to_string())
    } else {
        crate::weights::ensure("eval", &[&crate::weights::catalog::LPIPS_ALEX], a.offline);
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
    let out_dir = super::render::output_dir(&a.run, "eval", a.iteration);
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let out = out_dir.join("metrics.json");
    // The scores plus which checkpoint they are of (`--iteration` picks older ones).
    let mut json = serde_json::to_value(&report).context("serializing the metrics")?;
    json["iteration"] = loaded.iteration.into();
    json["split"] = a.split.clone().into();
    scene::io::write_json(&out, &json).with_context(|| format!("writing {}", out.display()))?;
    let lpips = match report.mean.lpips {
        Some(v) => format!("LPIPS {v:.4}"),
        None => format!("LPIPS {lpips_text}"),
    };
    println!(
        "{} (iteration {}): PSNR {:.3} SSIM {:.4} {lpips} over {} frames → {}",
        a.split,
        loaded.iteration,
        report.mean.psnr,
        report.mean.ssim,
        report.frames.len(),
        out.display()
    );
    if a.split == "test" && !a.no_consistency {
        consistency(&a.run, a.iteration, &out_dir)?;
    }
    Ok(())
}

/// Writes and prints the deformation consistency of a toycars run (no-op elsewhere).
fn consistency(run: &Path, iteration: Option<u32>, out_dir: &Path) -> Result<()> {
    let Some(v) = crate::report::consistency::named_consistency(run, iteration)? else {
        return Ok(());
    };
    let out = out_dir.join("consistency.json");
    scene::io::write_json(&out, &v).with_context(|| format!("writing {}", out.display()))?;
    let num = |x: &serde_json::Value| x.as_f64().unwrap_or(f64::NAN);
    let mut parts = vec![format!(
        "RMS {:.4}, rigidity RMS {:.4}",
        num(&v["rms"]),
        num(&v["rigidity_rms"])
    )];
    for (name, o) in v["per_object"].as_object().into_iter().flatten() {
        if let Some(f) = o["follow"].as_f64() {
            parts.push(format!(
                "{name} follows {:.0} % of its motion (rigidity RMS {:.4})",
                100.0 * f,
                num(&o["rigidity_rms"])
            ));
        }
    }
    println!(
        "deformation consistency: {} → {}",
        parts.join(", "),
        out.display()
    );
    Ok(())
}
