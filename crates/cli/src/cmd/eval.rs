//! `semdynreg eval RUN [--split test] [--iteration N] [--lpips-vgg]`: PSNR, SSIM and (when
//! the LPIPS weights are found) LPIPS-AlexNet, and LPIPS-VGG on request, of the latest
//! checkpoint (or iteration N's) on a split, written atomically to `RUN/eval/metrics.json`
//! for the test split and `RUN/eval/metrics_<split>.json` for the others
//! (`RUN/eval/iter_NNNNNNN/` with `--iteration`; `{"mean": {...}, "covered": {...},
//! "frames": [...]}`, where `covered` is the mean over the frames whose time lies inside the
//! training times' range). Renders are clamped to [0, 1] before scoring, as the reference
//! protocol does. On a toycars scene (one with `objects.json`), also the deformation
//! consistency against the vehicles' true motion: the share of it each moving vehicle's
//! Gaussians follow, and the rigidity residual of each vehicle's Gaussians (how rigidly they
//! move together; `RUN/eval/consistency.json`).

use anyhow::{Context, Result};
use metrics::{Lpips, LpipsNet};
use std::path::{Path, PathBuf};
use train::render::PerceptualScores;

/// PSNR, SSIM, LPIPS (and, on toycars, deformation consistency) of a run's checkpoint.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder made by `semdynreg train`.
    pub run: PathBuf,
    /// Which cameras to score: train, val or test. D-NeRF lego: use val (its released test
    /// set is inconsistent with its training set; Deformable-3DGS reports val).
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Score the checkpoint of this iteration instead of the latest; the results then go
    /// to `RUN/eval/iter_NNNNNNN/`.
    #[arg(long)]
    pub iteration: Option<u32>,
    /// Skip LPIPS even when its weights are in `$SEMDYNREG_WEIGHTS` (default `./weights`).
    #[arg(long)]
    pub no_lpips: bool,
    /// Also LPIPS with the VGG backbone (`lpips_vgg`), the network of Deformable-3DGS's
    /// published table (AlexNet, `lpips`, is always computed when its weights are found).
    #[arg(long, conflicts_with = "no_lpips")]
    pub lpips_vgg: bool,
    /// Skip the deformation-consistency metric of toycars scenes.
    #[arg(long)]
    pub no_consistency: bool,
    /// Never fetch missing weights (default: the LPIPS weights are fetched on first use
    /// with pip, `semdynreg weights fetch`); also `SEMDYNREG_OFFLINE=1`.
    #[arg(long)]
    pub offline: bool,
}

/// The metrics file of a split in an eval folder: `metrics.json` for test (the default,
/// where every earlier run's results are), `metrics_<split>.json` otherwise.
pub fn metrics_file(out_dir: &Path, split: &str) -> PathBuf {
    match split {
        "test" => out_dir.join("metrics.json"),
        s => out_dir.join(format!("metrics_{s}.json")),
    }
}

pub fn run(a: Args) -> Result<()> {
    let mut loaded = super::render::LoadedRun::open(&a.run, a.iteration)?;
    let frames = loaded.split(&a.split)?.to_vec();
    let (alex, lpips_text) = if a.no_lpips {
        (None, "not computed (--no-lpips)".to_string())
    } else {
        crate::weights::ensure("eval", &[&crate::weights::catalog::LPIPS_ALEX], a.offline);
        crate::report::scorer::load_lpips()?
    };
    let vgg = if a.lpips_vgg {
        crate::weights::ensure("eval", &[&crate::weights::catalog::LPIPS_VGG], a.offline);
        Some(
            Lpips::from_env(LpipsNet::Vgg)
                .context("loading the LPIPS-VGG weights (--lpips-vgg)")?,
        )
    } else {
        None
    };
    let report = if alex.is_none() && vgg.is_none() {
        loaded.evaluate(&frames, None)?
    } else {
        let mut score = |x: &[f32], y: &[f32], w: usize, h: usize| -> train::Result<_> {
            let d = |n: &Option<Lpips>| -> train::Result<Option<f64>> {
                n.as_ref()
                    .map(|n| n.distance(x, y, w, h).map(f64::from))
                    .transpose()
                    .map_err(|e| train::TrainError::Data(format!("LPIPS: {e}")))
            };
            Ok(PerceptualScores {
                alex: d(&alex)?,
                vgg: d(&vgg)?,
            })
        };
        loaded.evaluate(&frames, Some(&mut score))?
    };
    let report = report.with_covered_times(loaded.dataset.train.iter().map(|f| f.time));
    let out_dir = super::render::output_dir(&a.run, "eval", a.iteration);
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let out = metrics_file(&out_dir, &a.split);
    // The scores plus which checkpoint they are of (`--iteration` picks older ones).
    let mut json = serde_json::to_value(&report).context("serializing the metrics")?;
    json["iteration"] = loaded.iteration.into();
    json["split"] = a.split.clone().into();
    scene::io::write_json(&out, &json).with_context(|| format!("writing {}", out.display()))?;
    let m = &report.mean;
    let mut lpips = match m.lpips {
        Some(v) => format!("LPIPS-Alex {v:.4}"),
        None => format!("LPIPS {lpips_text}"),
    };
    if let Some(v) = m.lpips_vgg {
        lpips += &format!(" LPIPS-VGG {v:.4}");
    }
    println!(
        "{} (iteration {}): PSNR {:.3} SSIM {:.4} {lpips} over {} frames → {}",
        a.split,
        loaded.iteration,
        m.psnr,
        m.ssim,
        report.frames.len(),
        out.display()
    );
    if let Some(c) = report.covered.as_ref().filter(|c| c.mean.frames < m.frames) {
        println!(
            "  at the {} frames inside the training times [{:.3}, {:.3}]: PSNR {:.3} SSIM {:.4}",
            c.mean.frames, c.train_time_min, c.train_time_max, c.mean.psnr, c.mean.ssim
        );
    }
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
        let articulated = o["parts"].is_object();
        if o["follow"].is_f64() || articulated {
            let mut part = match o["follow"].as_f64() {
                Some(f) => format!("{name} follows {:.0} % of its motion", 100.0 * f),
                None => format!("{name} (its body stands still)"),
            };
            part += &format!(" (rigidity RMS {:.4})", num(&o["rigidity_rms"]));
            if let Some(share) = o["node_share"].as_f64() {
                let pct = |k: &str| {
                    o[k].as_f64()
                        .map_or("n/a".into(), |v| format!("{:.0} %", 100.0 * v))
                };
                // The group mixes the object's node with background drawn inside its mask.
                part += &format!(
                    " — its own Gaussians ({:.0} % of the group) follow {}, the other {:.0} % {}",
                    100.0 * share,
                    pct("follow_in_node"),
                    100.0 * (1.0 - share),
                    pct("follow_outside")
                );
            }
            for (pname, p) in o["parts"].as_object().into_iter().flatten() {
                let f = p["follow"]
                    .as_f64()
                    .map_or("n/a (still)".into(), |v| format!("{:.0} %", 100.0 * v));
                part += &format!("; its {pname} follows {f}");
                if let (Some(n), Some(f)) = (p["in_node"].as_u64(), p["follow_in_node"].as_f64()) {
                    let all = p["members"].as_u64().unwrap_or(0).max(1);
                    let share = 100.0 * n as f64 / all as f64;
                    part += &format!(" (its node's {share:.0} % of them {:.0} %)", 100.0 * f);
                }
            }
            parts.push(part);
        }
    }
    println!(
        "deformation consistency: {} → {}",
        parts.join(", "),
        out.display()
    );
    Ok(())
}
