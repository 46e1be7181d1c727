//! One run of a sweep, the same whichever backend starts it (`--backend local` in a loop,
//! or a Slurm array task through `semdynreg sweep DIR --task NAME`): train it (or resume
//! it, or fork it from its baseline) and render it with `compare`'s machinery
//! (`report::runs::prepare_run`), score it as `compare` scores a method, and write
//! `RUN/results.json` last, so that a run with that file is finished.

use super::plan::{Plan, RunSpec, RESULTS_FILE};
use crate::report::io::write_atomic;
use crate::report::results::Results;
use crate::report::runs::{prepare_run, RunPlan, TrainSettings};
use crate::report::scoring::{method_results, MethodRun, SceneEval, Scoring};
use anyhow::{Context, Result};
use std::collections::BTreeMap;

/// What became of one run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// It had its results already: nothing was run.
    Finished,
    /// It was trained (or resumed) and scored now.
    Ran,
}

/// Runs `name` of `plan` unless it is finished.
pub fn run_task(plan: &Plan, name: &str) -> Result<Outcome> {
    let r = plan.run(name)?;
    if plan.finished(name) {
        tracing::info!("{name}: finished already ({RESULTS_FILE} present), skipped");
        return Ok(Outcome::Finished);
    }
    run_unfinished(plan, r).with_context(|| format!("sweep run {name}"))?;
    Ok(Outcome::Ran)
}

fn run_unfinished(plan: &Plan, r: &RunSpec) -> Result<()> {
    let method = r.method()?;
    let scene = plan.scene(&r.scene)?;
    let dir = plan.run_dir(&r.name);
    let run_plan = RunPlan {
        label: method.key,
        dir: dir.clone(),
        reg: method.training.reg,
        objects: method.training.objects,
        fork_from: r.fork_from.as_ref().map(|f| plan.run_dir(f)),
    };
    let settings = TrainSettings {
        scene: scene.dir.clone(),
        iters: plan.iters,
        seed: r.seed,
        config: Some(plan.config_path(&r.name)),
        downscale: plan.downscale,
        white_background: plan.white_background,
    };
    let (mut commands, renders) = prepare_run(&run_plan, &settings)?;
    commands.insert(0, crate::cmd::compare::command_line());
    crate::weights::ensure(
        "sweep",
        &[&crate::weights::catalog::LPIPS_ALEX],
        plan.offline,
    );
    let mut scoring = Scoring::load(&SceneEval {
        scene: scene.dir.clone(),
        downscale: plan.downscale,
        white_background: plan.white_background,
        duration_s: plan.duration_s,
    })?;
    let eval = scoring.score(&r.name, &renders)?;
    let mut notes = Vec::new();
    let methods = [MethodRun {
        method,
        renders,
        run_dir: Some(dir.clone()),
    }];
    let by_method = method_results(&methods, vec![eval], &scoring.set, &mut notes);
    let results = Results {
        methods: vec![method.into()],
        by_method,
        scene: scene.dir.display().to_string(),
        commands,
        config: BTreeMap::from([(
            method.key.to_string(),
            crate::cmd::compare::run_config(&dir)?,
        )]),
        protocol: scoring.protocol(plan.duration_s),
        notes,
    };
    let json = serde_json::to_string_pretty(&results).context("serializing results")?;
    write_atomic(&dir.join(RESULTS_FILE), json.as_bytes())
}
