//! `semdynreg compare SCENE --out DIR`: the paper's experiment (issue 6, item 3) — the
//! baseline and SemDynReg scored on the test split (full frame, and zoomed object crops at
//! t = 0…5 s), written to `DIR/results.json`, `DIR/report.md` and `DIR/report.html`, with
//! the paper-style tables printed.

use crate::report::consistency::run_consistency;
use crate::report::evaluate::{evaluate_run, EvalSet, RenderDir, RunEval};
use crate::report::results::{Protocol, Results};
use crate::report::runs::{prepare_run, RunPlan, TrainSettings};
use crate::report::scorer::{load_lpips, MetricsScorer};
use crate::report::trainlog::TrainLog;
use crate::report::{
    crops::CropPolicy, figure, inputs, text_tables, write_plots, write_report, Report,
};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use train::regularizer::ConsistencyReport;

/// Baseline vs SemDynReg on a scene: results.json, report.md, report.html.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (D-NeRF layout; toycars adds `masks/` and `objects.json`).
    pub scene: PathBuf,
    /// Output folder: the runs (`baseline/`, `semdynreg/`), results.json, report.md,
    /// report.html and their images. Finished runs found there are reused, unfinished ones
    /// resumed; SemDynReg starts from the baseline's checkpoint at the regularizer's start
    /// (`train --fork`) when the baseline has one.
    #[arg(long)]
    pub out: PathBuf,
    /// Rescale both runs' schedule to N iterations (default: the full 40k).
    #[arg(long)]
    pub iters: Option<u32>,
    /// Seed of both runs.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Training config (TOML) for both runs.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Score this folder of rendered test frames as the baseline instead of training one
    /// (PNG per frame, named `<file_path>.png` or `<frame name>.png`).
    #[arg(long, requires = "semdynreg_renders")]
    pub baseline_renders: Option<PathBuf>,
    /// Score this folder of rendered test frames as SemDynReg instead of training it.
    #[arg(long, requires = "baseline_renders")]
    pub semdynreg_renders: Option<PathBuf>,
    /// Seconds spanned by time 0 → 1 (toycars: 6 s), to place t = 0…5 s.
    #[arg(long, default_value_t = 6.0)]
    pub duration_s: f32,
    /// Integer downscale of the scene's images (must match the renders).
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Composite RGBA ground truth over white instead of black (must match the runs).
    #[arg(long)]
    pub white_background: bool,
}

/// Where each method's renders (and, when trained here, logs and config) are.
struct Runs {
    baseline: PathBuf,
    semdynreg: PathBuf,
    /// The run folders, when trained here (for the consistency metric).
    run_dirs: Option<[PathBuf; 2]>,
    logs: Vec<(&'static str, TrainLog)>,
    config: BTreeMap<String, serde_json::Value>,
    commands: Vec<String>,
}

pub fn run(args: Args) -> Result<()> {
    let runs = match (&args.baseline_renders, &args.semdynreg_renders) {
        (Some(b), Some(s)) => Runs {
            baseline: b.clone(),
            semdynreg: s.clone(),
            run_dirs: None,
            logs: Vec::new(),
            config: BTreeMap::new(),
            commands: vec![command_line()],
        },
        _ => train_both(&args)?,
    };
    evaluate_and_report(&args, runs)
}

/// Trains (or reuses) and renders `OUT/baseline` and `OUT/semdynreg` with one schedule.
fn train_both(args: &Args) -> Result<Runs> {
    let settings = TrainSettings {
        scene: args.scene.clone(),
        iters: args.iters,
        seed: args.seed,
        config: args.config.clone(),
        downscale: args.downscale,
        white_background: args.white_background,
    };
    let plans = [
        RunPlan {
            label: "baseline",
            dir: args.out.join("baseline"),
            reg: false,
            fork_from: None,
        },
        RunPlan {
            label: "semdynreg",
            dir: args.out.join("semdynreg"),
            reg: true,
            fork_from: Some(args.out.join("baseline")),
        },
    ];
    let mut commands = vec![command_line()];
    let mut renders = Vec::new();
    let mut logs = Vec::new();
    let mut config = BTreeMap::new();
    for plan in &plans {
        let (cmds, dir) = prepare_run(plan, &settings)?;
        commands.extend(cmds);
        renders.push(dir);
        let log_path = plan.dir.join("metrics.jsonl");
        if log_path.is_file() {
            logs.push((plan.label, TrainLog::read(&log_path)?));
        }
        config.insert(plan.label.to_string(), run_config(&plan.dir)?);
    }
    Ok(Runs {
        baseline: renders[0].clone(),
        semdynreg: renders[1].clone(),
        run_dirs: Some(plans.map(|p| p.dir)),
        logs,
        config,
        commands,
    })
}

/// The resolved config of a run's latest checkpoint, as JSON.
fn run_config(run: &Path) -> Result<serde_json::Value> {
    let ckpt = train::checkpoint::latest(run)?;
    let cfg = train::checkpoint::read_config(&ckpt)
        .with_context(|| format!("reading {}", ckpt.display()))?;
    serde_json::to_value(&cfg).context("serializing the training config")
}

/// This process's command line, shell-quoted where needed.
fn command_line() -> String {
    std::env::args()
        .map(|a| {
            if a.is_empty() || a.contains(|c: char| c.is_whitespace() || "'\"$`\\".contains(c)) {
                format!("'{}'", a.replace('\'', "'\\''"))
            } else {
                a
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

fn progress_bar(label: &str, total: usize) -> ProgressBar {
    let bar = ProgressBar::new(total as u64);
    let style = ProgressStyle::with_template("{msg:>12} [{bar:30}] {pos}/{len} frames {elapsed}")
        .expect("static template")
        .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(label.to_string());
    bar
}

fn score(set: &EvalSet, label: &str, dir: &Path, scorer: &mut MetricsScorer) -> Result<RunEval> {
    let bar = progress_bar(label, set.frames.len());
    let eval = evaluate_run(set, &RenderDir(dir.to_path_buf()), scorer, &|done, _| {
        bar.set_position(done as u64)
    })
    .with_context(|| format!("evaluating the {label} renders in {}", dir.display()))?;
    bar.finish();
    Ok(eval)
}

fn evaluate_and_report(args: &Args, runs: Runs) -> Result<()> {
    let opts = scene::LoadOptions {
        background: if args.white_background {
            [1.0; 3]
        } else {
            [0.0; 3]
        },
        downscale: args.downscale,
    };
    let ds = scene::load_dataset(&args.scene, &opts)
        .with_context(|| format!("loading scene {}", args.scene.display()))?;
    let policy = CropPolicy::default();
    let set = inputs::eval_set(&ds, args.duration_s, policy)?;
    let (lpips, lpips_text) = load_lpips()?;
    let mut scorer = MetricsScorer::new(lpips);
    let base = score(&set, "baseline", &runs.baseline, &mut scorer)?;
    let ours = score(&set, "SemDynReg", &runs.semdynreg, &mut scorer)?;
    let (id_maps, id_source) = inputs::figure_id_maps(&ds, &set)?;
    let rows = figure::write_figure(&args.out, &set, &base, &ours, &id_maps)?;
    let mut notes = Vec::new();
    if set.moving_object().is_none() {
        notes.push(
            "no moving object in objects.json (or no objects.json): crop tables are empty".into(),
        );
    }
    let mut base_results = base.results;
    let mut ours_results = ours.results;
    match &runs.run_dirs {
        Some([b, o]) => {
            for (run, res) in [(b, &mut base_results), (o, &mut ours_results)] {
                if let Some(r) = consistency(run, &mut notes) {
                    res.deformation_consistency_rms = Some(r.rms);
                    res.deformation_consistency_per_object = r
                        .per_object
                        .iter()
                        .map(|x| (object_name(&set, x.object), x.rms))
                        .collect();
                    res.deformation_follow_per_object = r
                        .per_object
                        .iter()
                        .filter_map(|x| Some((object_name(&set, x.object), x.follow()?)))
                        .collect();
                }
            }
        }
        None => notes.push(
            "deformation_consistency_rms is null: it needs the trained models, not only their renders".into(),
        ),
    }
    let results = Results {
        baseline: base_results,
        semdynreg: ours_results,
        scene: args.scene.display().to_string(),
        commands: runs.commands,
        config: runs.config,
        protocol: Protocol {
            split: if ds.test.is_empty() { "val" } else { "test" }.into(),
            duration_s: args.duration_s,
            t_seconds: set.t_seconds.clone(),
            crop_policy: policy.describe(),
            ssim_variant: MetricsScorer::ssim_description().into(),
            lpips: lpips_text,
            moving_object: set
                .moving_object()
                .map(|o| o.name.clone())
                .unwrap_or_default(),
        },
        notes,
    };
    let plots = write_plots(
        &args.out,
        &results,
        &runs.logs,
        &[("loss", "loss"), ("psnr", "train PSNR (dB)")],
    )?;
    let report = Report {
        results: &results,
        rows: &rows,
        id_map_source: &id_source,
        plots: &plots,
    };
    let paths = write_report(&args.out, &report)?;
    println!("{}", text_tables(&results));
    println!("results: {}", paths.results_json.display());
    println!("report:  {}", paths.html.display());
    Ok(())
}

/// The name `objects.json` gives object `id` (its number when it has none).
fn object_name(set: &EvalSet, id: u8) -> String {
    set.objects
        .iter()
        .find(|o| o.id == id)
        .map_or_else(|| id.to_string(), |o| o.name.clone())
}

/// The run's consistency report, or `None` with the reason added to `notes`.
fn consistency(run: &Path, notes: &mut Vec<String>) -> Option<ConsistencyReport> {
    match run_consistency(run, None) {
        Ok(r) => Some(r),
        Err(e) => {
            notes.push(format!(
                "deformation consistency of {} not computed: {e:#}",
                run.display()
            ));
            None
        }
    }
}
