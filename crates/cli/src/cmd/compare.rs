//! `semdynreg compare SCENE --out DIR`: the paper's experiment with a
//! third method — the baseline, the paper's SemDynReg and rigid objects
//! (`report::methods::METHODS`) scored on the test split (full frame, and zoomed object
//! crops at t = 0…5 s), written to `DIR/results.json`, `DIR/report.md` and
//! `DIR/report.html`, with the paper-style tables printed.

use crate::report::figure::{self, FigureMethod};
use crate::report::methods::METHODS;
use crate::report::results::Results;
use crate::report::runs::{prepare_run, RunPlan, TrainSettings};
use crate::report::scoring::{method_results, MethodRun, SceneEval, Scoring};
use crate::report::trainlog::TrainLog;
use crate::report::{inputs, text_tables, write_plots, write_report, Report};
use anyhow::{Context, Result};
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
pub(crate) fn run_config(run: &Path) -> Result<serde_json::Value> {
    let ckpt = train::checkpoint::latest(run)?;
    let cfg = train::checkpoint::read_config(&ckpt)
        .with_context(|| format!("reading {}", ckpt.display()))?;
    serde_json::to_value(&cfg).context("serializing the training config")
}

/// This process's command line, shell-quoted where needed.
pub(crate) fn command_line() -> String {
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

fn evaluate_and_report(args: &Args, mut runs: Runs) -> Result<()> {
    crate::weights::ensure(
        "compare",
        &[&crate::weights::catalog::LPIPS_ALEX],
        args.offline,
    );
    let mut scoring = Scoring::load(&SceneEval {
        scene: args.scene.clone(),
        downscale: args.downscale,
        white_background: args.white_background,
        duration_s: args.duration_s,
    })?;
    let mut evals = Vec::with_capacity(runs.methods.len());
    for m in &runs.methods {
        evals.push(scoring.score(m.method.display, &m.renders)?);
    }
    let set = &scoring.set;
    let (id_maps, id_source) = inputs::figure_id_maps(&scoring.ds, set)?;
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
    let figure = figure::write_figure(&args.out, set, &figure_methods, &id_maps)?;
    let mut notes = std::mem::take(&mut runs.notes);
    let by_method = method_results(&runs.methods, evals, set, &mut notes);
    let results = Results {
        methods: runs.methods.iter().map(|m| m.method.into()).collect(),
        by_method,
        scene: args.scene.display().to_string(),
        commands: runs.commands,
        config: runs.config,
        protocol: scoring.protocol(args.duration_s),
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
