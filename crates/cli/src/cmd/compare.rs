//! `semdynreg compare SCENE --out DIR`: the paper's experiment (issue 6, item 3) with a
//! third method — the baseline, the paper's SemDynReg and rigid objects
//! (`report::methods::METHODS`) scored on the test split (full frame, and zoomed object
//! crops at t = 0…5 s), written to `DIR/results.json`, `DIR/report.md` and
//! `DIR/report.html`, with the paper-style tables printed.

use crate::report::consistency::{run_consistency, VehicleMetrics};
use crate::report::evaluate::{evaluate_run, EvalSet, RenderDir, RunEval};
use crate::report::figure::{self, FigureMethod};
use crate::report::methods::{Method, METHODS};
use crate::report::results::{MethodResults, Protocol, Results};
use crate::report::runs::{prepare_run, RunPlan, TrainSettings};
use crate::report::scorer::{load_lpips, MetricsScorer};
use crate::report::trainlog::TrainLog;
use crate::report::{crops::CropPolicy, inputs, text_tables, write_plots, write_report, Report};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Baseline, SemDynReg and rigid objects on a scene: results.json, report.md, report.html.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (D-NeRF layout; toycars adds `masks/` and `objects.json`).
    pub scene: PathBuf,
    /// Output folder: the runs (`baseline/`, `semdynreg/`, `rigid/`), results.json,
    /// report.md, report.html and their images. Finished runs found there are reused,
    /// unfinished ones resumed; SemDynReg starts from the baseline's checkpoint at the
    /// regularizer's start (`train --fork`) when the baseline has one; rigid objects
    /// (`train --no-reg --objects`) trains from scratch.
    #[arg(long)]
    pub out: PathBuf,
    /// Rescale every run's schedule to N iterations (default: the full 40k).
    #[arg(long)]
    pub iters: Option<u32>,
    /// Seed of every run.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Training config (TOML) for every run.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Score this folder of rendered test frames as the baseline instead of training one
    /// (PNG per frame, named `<file_path>.png` or `<frame name>.png`).
    #[arg(long, requires = "semdynreg_renders")]
    pub baseline_renders: Option<PathBuf>,
    /// Score this folder of rendered test frames as SemDynReg instead of training it.
    #[arg(long, requires = "baseline_renders")]
    pub semdynreg_renders: Option<PathBuf>,
    /// Score this folder of rendered test frames as rigid objects (with the two above;
    /// without it, a renders-only comparison has no rigid-objects column).
    #[arg(long, requires = "baseline_renders")]
    pub rigid_renders: Option<PathBuf>,
    /// Seconds spanned by time 0 → 1 (toycars: 6 s), to place t = 0…5 s.
    #[arg(long, default_value_t = 6.0)]
    pub duration_s: f32,
    /// Integer downscale of the scene's images (must match the renders).
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Composite RGBA ground truth over white instead of black (must match the runs).
    #[arg(long)]
    pub white_background: bool,
    /// Never fetch missing weights (default: the LPIPS weights are fetched on first use
    /// with pip, `semdynreg weights fetch`); also `SEMDYNREG_OFFLINE=1`.
    #[arg(long)]
    pub offline: bool,
}

/// One compared method: where its renders are and, when trained here, its run folder
/// (for the consistency metric).
struct MethodRun {
    method: &'static Method,
    renders: PathBuf,
    run_dir: Option<PathBuf>,
}

/// The compared methods in display order, with what their runs left (logs, config).
struct Runs {
    methods: Vec<MethodRun>,
    /// (method display name, training log).
    logs: Vec<(String, TrainLog)>,
    config: BTreeMap<String, serde_json::Value>,
    commands: Vec<String>,
    notes: Vec<String>,
}

pub fn run(args: Args) -> Result<()> {
    let runs = match &args.baseline_renders {
        Some(_) => given_renders(&args),
        None => train_all(&args)?,
    };
    evaluate_and_report(&args, runs)
}

/// The `--<key>-renders` folder given for a method, if any.
fn renders_flag<'a>(args: &'a Args, key: &str) -> Option<&'a PathBuf> {
    match key {
        "baseline" => args.baseline_renders.as_ref(),
        "semdynreg" => args.semdynreg_renders.as_ref(),
        "rigid" => args.rigid_renders.as_ref(),
        _ => None,
    }
}

/// The renders-only comparison: the methods whose renders were given.
fn given_renders(args: &Args) -> Runs {
    let mut methods = Vec::new();
    let mut notes = Vec::new();
    for m in &METHODS {
        match renders_flag(args, m.key) {
            Some(dir) => methods.push(MethodRun {
                method: m,
                renders: dir.clone(),
                run_dir: None,
            }),
            None => notes.push(format!(
                "{} not compared: no --{}-renders given",
                m.display, m.key
            )),
        }
    }
    Runs {
        methods,
        logs: Vec::new(),
        config: BTreeMap::new(),
        commands: vec![command_line()],
        notes,
    }
}

/// Trains (or reuses) and renders `OUT/<folder>` of every method, with one schedule, in
/// list order (so that a run is there before another forks from it).
fn train_all(args: &Args) -> Result<Runs> {
    let settings = TrainSettings {
        scene: args.scene.clone(),
        iters: args.iters,
        seed: args.seed,
        config: args.config.clone(),
        downscale: args.downscale,
        white_background: args.white_background,
    };
    let mut runs = Runs {
        methods: Vec::new(),
        logs: Vec::new(),
        config: BTreeMap::new(),
        commands: vec![command_line()],
        notes: Vec::new(),
    };
    for m in &METHODS {
        let plan = RunPlan::for_method(m, &args.out);
        let (cmds, renders) = prepare_run(&plan, &settings)?;
        runs.commands.extend(cmds);
        let log_path = plan.dir.join("metrics.jsonl");
        if log_path.is_file() {
            runs.logs
                .push((m.display.to_string(), TrainLog::read(&log_path)?));
        }
        runs.config
            .insert(m.key.to_string(), run_config(&plan.dir)?);
        runs.methods.push(MethodRun {
            method: m,
            renders,
            run_dir: Some(plan.dir),
        });
    }
    Ok(runs)
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
    let style = ProgressStyle::with_template("{msg:>17} [{bar:30}] {pos}/{len} frames {elapsed}")
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

/// The scene's evaluation split, loaded as the runs were trained.
fn load_dataset(args: &Args) -> Result<scene::Dataset> {
    let opts = scene::LoadOptions {
        background: if args.white_background {
            [1.0; 3]
        } else {
            [0.0; 3]
        },
        downscale: args.downscale,
    };
    scene::load_dataset(&args.scene, &opts)
        .with_context(|| format!("loading scene {}", args.scene.display()))
}

fn evaluate_and_report(args: &Args, mut runs: Runs) -> Result<()> {
    let ds = load_dataset(args)?;
    let policy = CropPolicy::default();
    let set = inputs::eval_set(&ds, args.duration_s, policy)?;
    crate::weights::ensure(
        "compare",
        &[&crate::weights::catalog::LPIPS_ALEX],
        args.offline,
    );
    let (lpips, lpips_text) = load_lpips()?;
    let mut scorer = MetricsScorer::new(lpips);
    let mut evals = Vec::with_capacity(runs.methods.len());
    for m in &runs.methods {
        evals.push(score(&set, m.method.display, &m.renders, &mut scorer)?);
    }
    let (id_maps, id_source) = inputs::figure_id_maps(&ds, &set)?;
    let figure_methods: Vec<FigureMethod> = runs
        .methods
        .iter()
        .zip(&evals)
        .map(|(m, eval)| FigureMethod {
            key: m.method.key,
            name: m.method.display,
            eval,
        })
        .collect();
    let figure = figure::write_figure(&args.out, &set, &figure_methods, &id_maps)?;
    let mut notes = std::mem::take(&mut runs.notes);
    let by_method = method_results(&runs, evals, &set, &mut notes);
    let results = Results {
        methods: runs.methods.iter().map(|m| m.method.into()).collect(),
        by_method,
        scene: args.scene.display().to_string(),
        commands: runs.commands,
        config: runs.config,
        protocol: protocol(args, &ds, &set, policy, lpips_text),
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
        figure: &figure,
        id_map_source: &id_source,
        plots: &plots,
    };
    let paths = write_report(&args.out, &report)?;
    println!("{}", text_tables(&results));
    println!("results: {}", paths.results_json.display());
    println!("report:  {}", paths.html.display());
    Ok(())
}

/// Each method's scores with its consistency metric (when its run was trained here),
/// keyed by method; what could not be measured goes to `notes`.
fn method_results(
    runs: &Runs,
    evals: Vec<RunEval>,
    set: &EvalSet,
    notes: &mut Vec<String>,
) -> BTreeMap<String, MethodResults> {
    if set.moving_object().is_none() {
        notes.push(
            "no moving object in objects.json (or no objects.json): crop tables are empty".into(),
        );
    }
    if runs.methods.iter().any(|m| m.run_dir.is_none()) {
        notes.push(
            "deformation_consistency_rms is null: it needs the trained models, not only their renders".into(),
        );
    }
    let mut by_method = BTreeMap::new();
    for (m, eval) in runs.methods.iter().zip(evals) {
        let mut res = eval.results;
        if let Some(run) = &m.run_dir {
            add_consistency(&mut res, run, set, notes);
        }
        by_method.insert(m.method.key.to_string(), res);
    }
    by_method
}

/// How the numbers were produced (results.json's `protocol`).
fn protocol(
    args: &Args,
    ds: &scene::Dataset,
    set: &EvalSet,
    policy: CropPolicy,
    lpips: String,
) -> Protocol {
    Protocol {
        split: if ds.test.is_empty() { "val" } else { "test" }.into(),
        duration_s: args.duration_s,
        t_seconds: set.t_seconds.clone(),
        crop_policy: policy.describe(),
        ssim_variant: MetricsScorer::ssim_description().into(),
        lpips,
        moving_object: set
            .moving_object()
            .map(|o| o.name.clone())
            .unwrap_or_default(),
        moving_objects: set.moving_objects().map(|o| o.name.clone()).collect(),
    }
}

/// Fills the consistency fields of `res` from the trained run, or says in `notes` why not.
fn add_consistency(res: &mut MethodResults, run: &Path, set: &EvalSet, notes: &mut Vec<String>) {
    let Some(VehicleMetrics {
        consistency: r,
        rigidity,
    }) = consistency(run, notes)
    else {
        return;
    };
    res.deformation_consistency_rms = Some(r.rms);
    res.deformation_consistency_per_object = r
        .per_object
        .iter()
        .map(|x| (object_name(set, x.object), x.rms))
        .collect();
    res.deformation_follow_per_object = r
        .per_object
        .iter()
        .filter_map(|x| Some((object_name(set, x.object), x.follow()?)))
        .collect();
    res.rigidity_rms = Some(rigidity.rms);
    res.rigidity_rms_per_object = rigidity
        .per_object
        .iter()
        .map(|x| (object_name(set, x.object), x.rms))
        .collect();
}

/// The name `objects.json` gives object `id` (its number when it has none).
fn object_name(set: &EvalSet, id: u8) -> String {
    set.objects
        .iter()
        .find(|o| o.id == id)
        .map_or_else(|| id.to_string(), |o| o.name.clone())
}

/// The run's consistency and rigidity reports, or `None` with the reason added to `notes`.
fn consistency(run: &Path, notes: &mut Vec<String>) -> Option<VehicleMetrics> {
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
