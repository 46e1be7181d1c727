//! `--backend local`: every unfinished run of the plan, one after another on this machine,
//! runs that start from scratch before the ones that fork from them (the plan's order). A
//! rerun skips finished runs and resumes unfinished ones (`train --resume`); a run whose
//! baseline failed is not started.

use super::plan::Plan;
use super::task::{run_task, Outcome};
use anyhow::{bail, Result};

/// Runs the plan; fails at the end, naming them, when runs failed.
pub fn run_local(plan: &Plan) -> Result<()> {
    let total = plan.runs.len();
    let (mut ran, mut skipped) = (0usize, 0usize);
    let mut failed: Vec<String> = Vec::new();
    for (i, r) in plan.runs.iter().enumerate() {
        if let Some(from) = r.fork_from.as_ref().filter(|f| failed.contains(f)) {
            tracing::error!("[{}/{total}] {}: not started, {from} failed", i + 1, r.name);
            failed.push(r.name.clone());
            continue;
        }
        tracing::info!("[{}/{total}] {}", i + 1, r.name);
        match run_task(plan, &r.name) {
            Ok(Outcome::Finished) => skipped += 1,
            Ok(Outcome::Ran) => ran += 1,
            Err(e) => {
                tracing::error!("{e:#}");
                failed.push(r.name.clone());
            }
        }
    }
    tracing::info!(
        "{ran} runs done now, {skipped} finished before, {} failed",
        failed.len()
    );
    if !failed.is_empty() {
        bail!(
            "{} of {total} runs failed: {}; the same command resumes them",
            failed.len(),
            failed.join(", ")
        );
    }
    Ok(())
}
