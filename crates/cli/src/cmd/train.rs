//! `semdynreg train SCENE --out RUN [--config F.toml] [--iters N] [--downscale D]
//! [--seed S] [--resume | --fork FROM]`: deformable 3DGS training with a progress
//! bar, a JSONL metrics log (`RUN/metrics.jsonl`), periodic test evaluation, and atomic
//! checkpoints every `log.checkpoint_interval` iterations, at the regularizer's fork point,
//! at the end, and on Ctrl-C.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;
use train::hook::DeformHook;
use train::regularizer::SemanticHook;
use train::run::RunInfo;
use train::{checkpoint, TrainConfig, Trainer};

/// Train deformable 3DGS (the baseline, or SemDynReg with --reg); resumable with Ctrl-C.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (D-NeRF/Blender layout, toycars, or Nerfies). Optional with --resume.
    pub scene: Option<PathBuf>,
    /// Run folder: checkpoints, config, metrics log.
    #[arg(long)]
    pub out: PathBuf,
    /// TOML config overriding the defaults (unknown keys are errors).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Rescale the whole schedule to N iterations.
    #[arg(long)]
    pub iters: Option<u32>,
    /// Integer image downscale factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Seed of the initial points and the camera order: the same seed gives the same run.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Composite RGBA images on white instead of black.
    #[arg(long)]
    pub white_background: bool,
    /// Continue the run in --out from its latest checkpoint.
    #[arg(long)]
    pub resume: bool,
    /// Enable the SemDynReg regularizer (needs `SCENE/semantics/`, made by `semdynreg segment`);
    /// overrides `reg.enabled` of the config.
    #[arg(long, conflicts_with = "no_reg")]
    pub reg: bool,
    /// Train the baseline without the regularizer (the default unless the config enables it).
    #[arg(long)]
    pub no_reg: bool,
    /// Objects (beyond the paper; docs/objects.md): every object of the ID maps
    /// (`SCENE/semantics/`, made by `semdynreg segment`) gets its own motion, found from its
    /// masks; the rest keeps the deformation field. `--objects` alone: as the config says
    /// (a rigid body each by default). `--objects=rigid`: one rigid body each.
    /// `--objects=parts`: up to 4 rigid parts held at joints where they explain the views
    /// better. `--objects=auto`: as parts, and an object that neither fit covers well
    /// (median mask IoU < 0.8) stays with the field. Each object's start logs its evidence.
    #[arg(
        long,
        conflicts_with = "no_objects",
        num_args = 0..=1,
        require_equals = true,
        value_name = "MODE",
        value_parser = clap::builder::ValueParser::new(|s: &str| s.parse::<train::objects::ObjectsMode>())
    )]
    pub objects: Option<Option<train::objects::ObjectsMode>>,
    /// Train without rigid objects (the default unless the config enables them).
    #[arg(long)]
    pub no_objects: bool,
    /// Articulated objects (docs/objects.md): an object may become up to N rigid parts,
    /// found from its masks and held together at joints, when parts explain its views
    /// better than one rigid body (sets `objects.parts`; 1: rigid only). Use with --objects.
    #[arg(long, value_name = "N")]
    pub parts: Option<usize>,
    /// Start from run FROM's checkpoint just before the regularizer's start instead of from
    /// scratch: exact, since both runs are the same until then. The scene, seed, downscale
    /// and background are FROM's; --config/--iters/--reg must give FROM's config except in
    /// [reg] (`compare` does this for its SemDynReg run).
    #[arg(long, value_name = "FROM", conflicts_with_all = ["scene", "resume", "seed", "downscale", "white_background"])]
    pub fork: Option<PathBuf>,
    /// Also keep a checkpoint when the run's wall time first passes each of these marks
    /// (minutes, e.g. `10,30,60`; sets `log.checkpoint_minutes`), for quality against time:
    /// `semdynreg eval RUN --iteration N` scores each.
    #[arg(long, value_delimiter = ',', value_name = "MINUTES")]
    pub checkpoint_minutes: Option<Vec<f64>>,
}

/// The config of a new run: the defaults or --config, rescaled by --iters, --reg/--no-reg.
fn new_config(a: &Args) -> Result<TrainConfig> {
    let mut cfg = TrainConfig::for_run(a.config.as_deref(), a.iters)?;
    if a.reg || a.no_reg {
        cfg.reg.enabled = a.reg;
    }
    match a.objects {
        Some(Some(mode)) => cfg.objects.apply_mode(mode),
        Some(None) => cfg.objects.enabled = true,
        None if a.no_objects => cfg.objects.enabled = false,
        None => {}
    }
    if let Some(n) = a.parts {
        cfg.objects.parts = n;
        cfg.validate()?;
    }
    if let Some(m) = &a.checkpoint_minutes {
        cfg.log.checkpoint_minutes = m.clone();
        cfg.validate()?;
    }
    Ok(cfg)
}

fn refuse_existing(out: &Path) -> Result<()> {
    if out.join(train::run::RUN_FILE).exists() {
        bail!(
            "{} already holds a run; use --resume or another --out",
            out.display()
        );
    }
    Ok(())
}

fn fresh(a: &Args) -> Result<Trainer> {
    let Some(scene_dir) = &a.scene else {
        bail!(
            "a SCENE folder is required (or --resume to continue {})",
            a.out.display()
        );
    };
    refuse_existing(&a.out)?;
    let cfg = new_config(a)?;
    let scene = std::fs::canonicalize(scene_dir)
        .with_context(|| format!("scene folder {}", scene_dir.display()))?;
    let bg = if a.white_background { 1.0 } else { 0.0 };
    let info = RunInfo {
        scene,
        downscale: a.downscale,
        background: [bg; 3],
        seed: a.seed,
    };
    let dataset = info
        .dataset()
        .with_context(|| format!("loading {}", info.scene.display()))?;
    let trainer = Trainer::new(cfg, dataset, a.seed)?;
    // A checkpoint of the initial state first, then `run.json`: from the moment the folder
    // counts as a run (`refuse_existing`), it can be resumed, however early it is killed.
    checkpoint::save(&trainer, &a.out)?;
    info.save(&a.out)?;
    tracing::info!(
        gaussians = trainer.state.len(),
        extent = trainer.extent,
        "initialized"
    );
    Ok(trainer)
}

fn resumed(a: &Args) -> Result<Trainer> {
    if a.config.is_some()
        || a.iters.is_some()
        || a.reg
        || a.no_reg
        || a.objects.is_some()
        || a.no_objects
        || a.parts.is_some()
        || a.checkpoint_minutes.is_some()
    {
        bail!(
            "--resume continues with the run's saved config; drop --config/--iters/--reg/--no-reg/--objects/--parts/--checkpoint-minutes"
        );
    }
    let info = RunInfo::load(&a.out)?;
    let dataset = info
        .dataset()
        .with_context(|| format!("loading {}", info.scene.display()))?;
    let dir = checkpoint::latest(&a.out)?;
    let trainer = checkpoint::load_trainer(&dir, dataset)
        .with_context(|| format!("resuming from {}", dir.display()))?;
    // Lines logged after that checkpoint by the stopped segment are logged again.
    let log = a.out.join("metrics.jsonl");
    copy_log_until(&log, &log, trainer.iteration)?;
    tracing::info!(
        iteration = trainer.iteration,
        "resumed from {}",
        dir.display()
    );
    Ok(trainer)
}

/// `--fork FROM`: FROM's run settings, its checkpoint at or before the new config's fork
/// point, and its metrics log up to there (so the training curves are whole).
fn forked(a: &Args, from: &Path) -> Result<Trainer> {
    refuse_existing(&a.out)?;
    let cfg = new_config(a)?;
    if !cfg.reg.enabled {
        bail!(
            "a fork without the regularizer would repeat {}; pass --reg",
            from.display()
        );
    }
    let Some(at) = train::fork::fork_point(&cfg.reg) else {
        bail!(
            "the regularizer starts at iteration 1: there is nothing to fork; train from scratch"
        );
    };
    let (it, dir) = train::fork::checkpoint_at_or_before(from, at)
        .with_context(|| format!("looking for checkpoints of {}", from.display()))?
        .with_context(|| {
            format!(
                "{} has no checkpoint at or before iteration {at} (the regularizer's start − 1); \
                 runs trained by this version keep one there",
                from.display()
            )
        })?;
    let info = RunInfo::load(from)?;
    let dataset = info
        .dataset()
        .with_context(|| format!("loading {}", info.scene.display()))?;
    let tr = train::fork::load_fork(&dir, dataset, cfg)?;
    info.save(&a.out)?;
    copy_log_until(
        &from.join("metrics.jsonl"),
        &a.out.join("metrics.jsonl"),
        it,
    )?;
    let saved = checkpoint::save(&tr, &a.out)?;
    tracing::info!(
        iteration = it,
        "forked from {} into {}",
        dir.display(),
        saved.display()
    );
    Ok(tr)
}

/// Copies the lines of a JSONL metrics log whose `iteration` is at most `last`.
fn copy_log_until(src: &Path, dst: &Path, last: u32) -> Result<()> {
    let Ok(text) = std::fs::read_to_string(src) else {
        return Ok(()); // a run without a log forks without one
    };
    let mut out = String::new();
    let lines: Vec<&str> = text.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        let parsed = serde_json::from_str::<serde_json::Value>(line);
        // A kill can cut the line being appended: an unterminated last line that is not
        // JSON is that line, and it is logged again after the checkpoint anyway.
        if parsed.is_err() && i + 1 == lines.len() && !text.ends_with('\n') {
            tracing::warn!("{}: dropped a cut last line: {line}", src.display());
            break;
        }
        let v = parsed
            .with_context(|| format!("{} has a line that is not JSON: {line}", src.display()))?;
        if v["iteration"].as_u64().is_some_and(|i| i <= last as u64) {
            out.push_str(line);
            out.push('\n');
        }
    }
    scene::io::write_atomic(dst, |w| w.write_all(out.as_bytes()))
        .with_context(|| format!("writing {}", dst.display()))
}

fn append_jsonl(path: &Path, value: &serde_json::Value) -> Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))?;
    // One write of the whole line: `writeln!` on a `File` issues a write per formatted
    // piece, and a kill between two of them would leave a cut line in the log.
    let line = format!("{value}\n");
    f.write_all(line.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

fn progress_bar(tr: &Trainer) -> ProgressBar {
    let pb = ProgressBar::new(tr.cfg.iterations as u64);
    pb.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} {per_sec} ETA {eta}")
            .expect("static template")
            .progress_chars("=> "),
    );
    pb.set_position(tr.iteration as u64);
    pb.reset_eta();
    pb
}

pub fn run(a: Args) -> Result<()> {
    let mut tr = match (&a.fork, a.resume) {
        (Some(from), _) => forked(&a, from)?,
        (None, true) => resumed(&a)?,
        (None, false) => fresh(&a)?,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    ctrlc::set_handler(move || s.store(true, Ordering::SeqCst))
        .context("installing the Ctrl-C handler")?;
    let log = a.out.join("metrics.jsonl");
    let pb = progress_bar(&tr);
    let start = Instant::now();
    let first = tr.iteration;
    // Training time over all segments of a resumed run (checkpoints carry it).
    let before = tr.train_seconds;
    // Resaving the iteration `latest` already names would replace that folder.
    let mut last_saved = checkpoint::latest(&a.out).ok().map(|_| tr.iteration);
    let mut hook = if tr.cfg.reg.enabled {
        Some(SemanticHook::load(tr.cfg.reg.clone(), &tr.dataset)?)
    } else {
        None
    };
    while tr.iteration < tr.cfg.iterations {
        let st = tr
            .step_with(hook.as_mut().map(|h| h as &mut dyn DeformHook))
            .with_context(|| stopped_note(&a.out))?;
        let it = st.iteration;
        pb.set_position(it as u64);
        pb.set_message(format!(
            "loss {:.4} PSNR {:.2} #G {}",
            st.loss.total, st.psnr, st.num_gaussians
        ));
        let l = tr.cfg.log.clone();
        if l.log_interval > 0 && it % l.log_interval == 0 {
            let secs = start.elapsed().as_secs_f64();
            let mut line = serde_json::json!({"iteration": it, "loss": st.loss.total, "l1": st.loss.l1, "ssim": st.loss.ssim,
                "psnr": st.psnr, "num_gaussians": st.num_gaussians, "elapsed_s": before + secs,
                "it_per_s": (it - first) as f64 / secs.max(1e-9)});
            if let Some(h) = hook.as_ref().filter(|h| h.active_at(it)) {
                // Per-object group sizes, deviations and skips, so a run shows what the
                // regularizer acted on.
                line["reg_loss"] = h.last_loss().weighted.into();
                line["reg_objects"] = serde_json::to_value(h.stats())?;
            }
            append_jsonl(&log, &line)?;
        }
        let split = l.eval_split;
        if l.eval_interval > 0 && it % l.eval_interval == 0 && !split.frames(&tr.dataset).is_empty()
        {
            let rep = tr.evaluate_test(l.eval_frames)?;
            pb.println(format!(
                "[{it}] {} PSNR {:.3} SSIM {:.4}",
                split.name(),
                rep.mean.psnr,
                rep.mean.ssim
            ));
            // `test_*` names the held-out score whatever the split (`split` says which),
            // so logs of every run plot the same way.
            append_jsonl(
                &log,
                &serde_json::json!({"iteration": it, "test_psnr": rep.mean.psnr, "test_ssim": rep.mean.ssim, "split": split.name()}),
            )?;
        }
        let interrupted = stop.load(Ordering::SeqCst);
        let seconds_before_step = tr.train_seconds;
        tr.train_seconds = before + start.elapsed().as_secs_f64();
        if let Some(m) = passed_mark(&l.checkpoint_minutes, seconds_before_step, tr.train_seconds) {
            let why = format!(
                "wall-time mark {m} min (at {:.1} min)",
                tr.train_seconds / 60.0
            );
            let dir = checkpoint::save_kept(&tr, &a.out, &why)?;
            last_saved = Some(it);
            append_jsonl(
                &log,
                &serde_json::json!({"iteration": it, "wall_mark_minutes": m, "elapsed_s": tr.train_seconds}),
            )?;
            pb.println(format!("[{it}] {why}: kept {}", dir.display()));
        }
        let fork_point = train::fork::fork_point(&tr.cfg.reg) == Some(it);
        let due = (l.checkpoint_interval > 0 && it % l.checkpoint_interval == 0)
            || fork_point
            || interrupted;
        // A second save of this iteration would replace the kept one (and its KEEP file).
        if due && last_saved != Some(it) {
            let dir = checkpoint::save(&tr, &a.out)?;
            last_saved = Some(it);
            tracing::info!("checkpoint {}", dir.display());
        }
        if interrupted {
            // A stopped segment's breakdown is as useful as a finished one's.
            write_timings(&tr, &a.out, start.elapsed().as_secs_f64(), first)?;
            pb.abandon_with_message(format!("interrupted at {it}; continue with --resume"));
            return Ok(());
        }
    }
    pb.finish();
    tr.train_seconds = before + start.elapsed().as_secs_f64();
    if last_saved != Some(tr.iteration) {
        checkpoint::save(&tr, &a.out)?;
    }
    write_timings(&tr, &a.out, start.elapsed().as_secs_f64(), first)?;
    Ok(())
}

/// The largest of `marks` (minutes) in `(before, now]` (seconds), if any.
fn passed_mark(marks: &[f64], before: f64, now: f64) -> Option<f64> {
    marks
        .iter()
        .copied()
        .filter(|m| before < m * 60.0 && m * 60.0 <= now)
        .reduce(f64::max)
}

/// What a failed step leaves: the last checkpoint (never a diverged one).
fn stopped_note(run: &Path) -> String {
    match checkpoint::latest(run) {
        Ok(dir) => format!(
            "training stopped; the last good checkpoint is {} (continue from it with --resume)",
            dir.display()
        ),
        Err(_) => "training stopped before its first checkpoint".into(),
    }
}

/// `RUN/timings.json`: wall time and the per-phase breakdown (ms per iteration) of this
/// segment, and `total_train_s` over every segment of a resumed run.
fn write_timings(tr: &Trainer, run: &Path, wall: f64, first: u32) -> Result<()> {
    let phases: serde_json::Map<String, serde_json::Value> = tr
        .timings
        .per_iteration_ms()
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.into()))
        .collect();
    let v = serde_json::json!({"wall_s": wall, "iterations": tr.iteration - first,
        "total_train_s": tr.train_seconds, "total_iterations": tr.iteration,
        "num_gaussians": tr.state.len(), "ms_per_iteration": phases});
    scene::io::write_json(&run.join("timings.json"), &v).context("writing timings.json")
}

#[cfg(test)]
mod tests {
    use super::{copy_log_until, passed_mark};
    use clap::Parser;
    use train::objects::ObjectsMode;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        a: super::Args,
    }

    #[test]
    fn objects_takes_a_mode_only_after_an_equals_sign() {
        let parse = |argv: &[&str]| Cli::try_parse_from(argv).map(|c| c.a);
        let a = parse(&["t", "--objects", "scene", "--out", "o"]).unwrap();
        assert_eq!(a.objects, Some(None));
        assert_eq!(a.scene.as_deref(), Some(std::path::Path::new("scene")));
        let a = parse(&["t", "scene", "--out", "o", "--objects=auto"]).unwrap();
        assert_eq!(a.objects, Some(Some(ObjectsMode::Auto)));
        let cfg = super::new_config(&a).unwrap();
        assert!(cfg.objects.enabled && cfg.objects.parts > 1 && cfg.objects.min_rigid_iou > 0.0);
        assert!(parse(&["t", "scene", "--out", "o", "--objects=field"]).is_err());
        let a = parse(&["t", "scene", "--out", "o"]).unwrap();
        assert!(!super::new_config(&a).unwrap().objects.enabled);
    }

    #[test]
    fn a_log_cut_by_a_kill_resumes_and_a_damaged_log_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let log = tmp.path().join("metrics.jsonl");
        std::fs::write(&log, "{\"iteration\":1}\n{\"iteration\":2}\n{\"itera").unwrap();
        copy_log_until(&log, &log, 1).unwrap();
        assert_eq!(
            std::fs::read_to_string(&log).unwrap(),
            "{\"iteration\":1}\n"
        );
        // A bad line that is not the unterminated last one is damage, not a kill.
        std::fs::write(&log, "{\"iteration\":1}\n{\"itera\n{\"iteration\":2}\n").unwrap();
        let err = copy_log_until(&log, &log, 2).unwrap_err().to_string();
        assert!(err.contains("not JSON"), "{err}");
    }

    #[test]
    fn a_mark_is_passed_once_in_the_step_that_crosses_it() {
        let marks = [10.0, 30.0, 60.0];
        assert_eq!(passed_mark(&marks, 0.0, 599.0), None);
        assert_eq!(passed_mark(&marks, 599.0, 600.0), Some(10.0));
        assert_eq!(passed_mark(&marks, 600.0, 601.0), None);
        // A step (or a resume gap) that crosses two marks keeps one checkpoint, for the later.
        assert_eq!(passed_mark(&marks, 1700.0, 3700.0), Some(60.0));
        assert_eq!(passed_mark(&[], 0.0, 1e9), None);
    }
}
