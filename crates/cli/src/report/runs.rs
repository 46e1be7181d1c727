//! The training runs of `compare`, one per method of `methods::METHODS`: each is trained (or resumed, or reused when
//! finished) and rendered by running this same executable's `train` and `render`
//! subcommands, so that a run made by `compare` is exactly a run made by hand, and the
//! recorded command lines reproduce it.

use super::methods::{self, Method};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::Command;
use train::{checkpoint, run::RUN_FILE, TrainConfig};

/// Settings shared by every run (the same seed and schedule, so the
/// methods differ only in the method).
#[derive(Clone, Debug)]
pub struct TrainSettings {
    pub scene: PathBuf,
    pub iters: Option<u32>,
    pub seed: u64,
    pub config: Option<PathBuf>,
    pub downscale: u32,
    pub white_background: bool,
}

/// One run of the comparison.
#[derive(Clone, Debug)]
pub struct RunPlan {
    pub label: &'static str,
    pub dir: PathBuf,
    /// The SemDynReg loss on (`--reg`) or off (`--no-reg`).
    pub reg: bool,
    /// Each object as a rigid body with its own trajectory (`--objects`).
    pub objects: bool,
    /// A run to fork from (`train --fork`) when it holds a checkpoint at the regularizer's
    /// fork point: SemDynReg starts from the baseline's instead of repeating its first quarter.
    pub fork_from: Option<PathBuf>,
}

impl RunPlan {
    /// The run of `method` under `compare --out OUT`.
    pub fn for_method(method: &Method, out: &Path) -> Self {
        let t = method.training;
        let fork_from = t.fork_from.map(|key| {
            let from = methods::method(key).expect("METHODS forks from a listed method");
            out.join(from.folder)
        });
        Self {
            label: method.key,
            dir: out.join(method.folder),
            reg: t.reg,
            objects: t.objects,
            fork_from,
        }
    }
}

/// How far a run folder got.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunState {
    Missing,
    Unfinished { iteration: u32, total: u32 },
    Finished,
}

/// Reads the run's latest checkpoint to see whether it reached its schedule's end.
pub fn run_state(dir: &Path) -> Result<RunState> {
    if !dir.join(RUN_FILE).is_file() {
        return Ok(RunState::Missing);
    }
    let ckpt = checkpoint::latest(dir).with_context(|| {
        format!(
            "{} holds a run without a checkpoint; delete it to start over",
            dir.display()
        )
    })?;
    let m = checkpoint::load_model(&ckpt).with_context(|| format!("reading {}", ckpt.display()))?;
    let (cfg, iteration) = (m.cfg, m.iteration);
    Ok(if iteration >= cfg.iterations {
        RunState::Finished
    } else {
        RunState::Unfinished {
            iteration,
            total: cfg.iterations,
        }
    })
}

/// `train` arguments for a fresh run (forked from `fork` when given), or `--resume` for an
/// unfinished one.
pub fn train_args(
    plan: &RunPlan,
    s: &TrainSettings,
    state: RunState,
    fork: Option<&Path>,
) -> Vec<String> {
    let out = plan.dir.display().to_string();
    if let RunState::Unfinished { .. } = state {
        return vec!["train".into(), "--out".into(), out, "--resume".into()];
    }
    let mut a: Vec<String> = vec!["train".into()];
    match fork {
        // The fork takes scene, seed, downscale and background from the run it starts from.
        Some(from) => a.extend(["--fork".into(), from.display().to_string()]),
        None => {
            a.push(s.scene.display().to_string());
            a.extend(["--seed".into(), s.seed.to_string()]);
            a.extend(["--downscale".into(), s.downscale.to_string()]);
            if s.white_background {
                a.push("--white-background".into());
            }
        }
    }
    a.extend(["--out".into(), out]);
    if let Some(n) = s.iters {
        a.extend(["--iters".into(), n.to_string()]);
    }
    if let Some(c) = &s.config {
        a.extend(["--config".into(), c.display().to_string()]);
    }
    a.push(if plan.reg { "--reg" } else { "--no-reg" }.into());
    if plan.objects {
        a.push("--objects".into());
    }
    a
}

/// Runs `semdynreg ARGS` (this executable) with inherited output; returns its command line.
pub fn run_self(args: &[String]) -> Result<String> {
    let exe = std::env::current_exe().context("locating the semdynreg executable")?;
    let line = format!("semdynreg {}", args.join(" "));
    tracing::info!("running: {line}");
    let status = Command::new(&exe)
        .args(args)
        .status()
        .with_context(|| format!("starting {}", exe.display()))?;
    if !status.success() {
        bail!("`{line}` failed ({status})");
    }
    Ok(line)
}

/// `from` when it holds a checkpoint `plan` can fork from (same settings, before the
/// regularizer's start), else `None` (train from scratch). A checkpoint whose config differs
/// outside `[reg]` is an error: the two runs would not share a schedule.
fn fork_source(from: &Path, plan: &RunPlan, s: &TrainSettings) -> Result<Option<PathBuf>> {
    let mut cfg = TrainConfig::for_run(s.config.as_deref(), s.iters)?;
    cfg.reg.enabled = plan.reg;
    let Some(at) = train::fork::fork_point(&cfg.reg) else {
        return Ok(None);
    };
    let Some((it, dir)) = train::fork::checkpoint_at_or_before(from, at)? else {
        tracing::info!(
            "{}: no checkpoint of {} to fork from; training from scratch",
            plan.label,
            from.display()
        );
        return Ok(None);
    };
    let src = checkpoint::read_config(&dir)?;
    if let Some(problem) = train::fork::fork_problem(&src, it, &cfg) {
        bail!(
            "{} cannot share its first {it} iterations with {}: {problem}. Delete {} to train both again",
            from.display(),
            plan.label,
            from.display()
        );
    }
    Ok(Some(from.to_path_buf()))
}

/// Trains (unless finished) and renders the test split of a run; returns the commands run
/// and the folder of renders (`RUN/renders/test`).
pub fn prepare_run(plan: &RunPlan, s: &TrainSettings) -> Result<(Vec<String>, PathBuf)> {
    let mut commands = Vec::new();
    match run_state(&plan.dir)? {
        RunState::Finished => {
            tracing::info!(
                "{}: reusing the finished run in {}",
                plan.label,
                plan.dir.display()
            )
        }
        state => {
            let fork = match (state, &plan.fork_from) {
                (RunState::Missing, Some(from)) => fork_source(from, plan, s)?,
                _ => None,
            };
            commands.push(run_self(&train_args(plan, s, state, fork.as_deref()))?)
        }
    }
    let dir = plan.dir.display().to_string();
    commands.push(run_self(&[
        "render".into(),
        dir,
        "--split".into(),
        "test".into(),
    ])?);
    Ok((commands, plan.dir.join("renders").join("test")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn train_arguments_carry_the_shared_schedule() {
        let s = TrainSettings {
            scene: "sc".into(),
            iters: Some(300),
            seed: 7,
            config: None,
            downscale: 2,
            white_background: false,
        };
        let plan = RunPlan {
            label: "ours",
            dir: "out/semdynreg".into(),
            reg: true,
            objects: false,
            fork_from: None,
        };
        let a = train_args(&plan, &s, RunState::Missing, None).join(" ");
        assert_eq!(
            a,
            "train sc --seed 7 --downscale 2 --out out/semdynreg --iters 300 --reg"
        );
        let fork = train_args(
            &plan,
            &s,
            RunState::Missing,
            Some(Path::new("out/baseline")),
        );
        assert_eq!(
            fork.join(" "),
            "train --fork out/baseline --out out/semdynreg --iters 300 --reg"
        );
        let plan = RunPlan { reg: false, ..plan };
        assert!(train_args(&plan, &s, RunState::Missing, None)
            .join(" ")
            .ends_with("--no-reg"));
        let resume = train_args(
            &plan,
            &s,
            RunState::Unfinished {
                iteration: 5,
                total: 300,
            },
            None,
        );
        assert_eq!(resume.join(" "), "train --out out/semdynreg --resume");
    }

    #[test]
    fn each_method_has_its_plan() {
        let out = Path::new("out");
        let plans: Vec<RunPlan> = methods::METHODS
            .iter()
            .map(|m| RunPlan::for_method(m, out))
            .collect();
        let ours = &plans[1];
        assert_eq!(ours.dir, out.join("semdynreg"));
        assert!(ours.reg && !ours.objects);
        assert_eq!(
            ours.fork_from.as_deref(),
            Some(out.join("baseline").as_path())
        );
        let rigid = &plans[2];
        assert_eq!(
            (rigid.label, rigid.dir.as_path()),
            ("rigid", out.join("rigid").as_path())
        );
        assert!(!rigid.reg && rigid.objects && rigid.fork_from.is_none());
        let s = TrainSettings {
            scene: "sc".into(),
            iters: None,
            seed: 0,
            config: None,
            downscale: 1,
            white_background: false,
        };
        assert_eq!(
            train_args(rigid, &s, RunState::Missing, None).join(" "),
            "train sc --seed 0 --downscale 1 --out out/rigid --no-reg --objects"
        );
        // A resumed run keeps the flags it was started with (its saved config).
        let resumed = RunState::Unfinished {
            iteration: 1,
            total: 2,
        };
        assert_eq!(
            train_args(rigid, &s, resumed, None).join(" "),
            "train --out out/rigid --resume"
        );
    }

    #[test]
    fn missing_run_folder_is_missing() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(
            run_state(&dir.path().join("nope")).unwrap(),
            RunState::Missing
        );
    }
}
