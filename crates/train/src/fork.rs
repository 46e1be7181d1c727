//! Forking a run at the regularizer's start. SemDynReg and its baseline are the same
//! computation until `reg.start_iter` (the paper's L_reg joins the loss from 10k of 40k,
//! Sec. 3.4): before it the hook asks for no top-k, adds no loss and creates no hook rows
//! (they start as zeros when first used). So a SemDynReg run, or any `[reg]` variant of an
//! ablation, can start from the baseline's checkpoint at iteration `start_iter − 1` and end
//! bit-identical to one trained from scratch, skipping a quarter of the schedule.

use crate::checkpoint;
use crate::config::TrainConfig;
use crate::error::{Result, TrainError};
use crate::regularizer::RegConfig;
use crate::trainer::Trainer;
use std::path::{Path, PathBuf};

/// The last iteration at which the regularizer of `reg` is still off (`start_iter − 1`);
/// `None` when it is on from the first iteration. Runs keep their checkpoint here.
pub fn fork_point(reg: &RegConfig) -> Option<u32> {
    reg.fork_point()
}

/// Why a checkpoint at `iteration` trained with `src` cannot start a run with `dst`.
pub fn fork_problem(src: &TrainConfig, iteration: u32, dst: &TrainConfig) -> Option<String> {
    if src.reg.active_at(iteration as u64) || (src.reg.enabled && src.reg.start_iter <= 1) {
        return Some(format!(
            "it was trained with the regularizer on (from iteration {}); fork from a baseline \
             run or from a checkpoint before that",
            src.reg.start_iter
        ));
    }
    if dst.reg.enabled && iteration as u64 >= dst.reg.start_iter {
        return Some(format!(
            "it is at iteration {iteration}, but the new run's regularizer starts at {}: \
             the fork would skip it",
            dst.reg.start_iter
        ));
    }
    let mut same = dst.clone();
    same.reg = src.reg.clone();
    let (a, b) = (src.to_toml(), same.to_toml());
    let first = a.lines().zip(b.lines()).find(|(x, y)| x != y);
    match first {
        None if a == b => None,
        None => Some("its config and the new one differ outside [reg]".into()),
        Some((x, y)) => Some(format!(
            "only [reg] may change in a fork, but its config has `{}` and the new one `{}`",
            x.trim(),
            y.trim()
        )),
    }
}

/// The newest checkpoint of `run` at or before iteration `at`, with its iteration.
pub fn checkpoint_at_or_before(run: &Path, at: u32) -> Result<Option<(u32, PathBuf)>> {
    let held = checkpoint::iterations(run)?;
    Ok(held.into_iter().rev().find(|(it, _)| *it <= at))
}

/// Loads the checkpoint `dir` as the start of a run configured by `cfg`: the state is the
/// checkpoint's, the config `cfg`, which may differ from the checkpoint's only in `[reg]`.
pub fn load_fork(dir: &Path, dataset: scene::Dataset, cfg: TrainConfig) -> Result<Trainer> {
    let mut tr = checkpoint::load_trainer(dir, dataset)?;
    if let Some(problem) = fork_problem(&tr.cfg, tr.iteration, &cfg) {
        return Err(TrainError::Checkpoint {
            path: dir.to_path_buf(),
            problem: format!("cannot fork from it: {problem}"),
        });
    }
    tr.cfg = cfg;
    Ok(tr)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfgs() -> (TrainConfig, TrainConfig) {
        let base = TrainConfig::default().rescaled(400).unwrap();
        let mut reg = base.clone();
        reg.reg.enabled = true;
        reg.reg.lambda = 1.0;
        (base, reg)
    }

    #[test]
    fn fork_point_is_the_iteration_before_the_start() {
        let (base, _) = cfgs();
        assert_eq!(base.reg.start_iter, 100);
        assert_eq!(fork_point(&base.reg), Some(99));
        let mut r = base.reg.clone();
        r.start_iter = 1;
        assert_eq!(fork_point(&r), None);
    }

    #[test]
    fn only_reg_may_change_and_only_before_the_start() {
        let (base, reg) = cfgs();
        assert_eq!(fork_problem(&base, 99, &reg), None);
        assert_eq!(fork_problem(&base, 50, &reg), None);
        let late = fork_problem(&base, 100, &reg).unwrap();
        assert!(late.contains("starts at 100"), "{late}");
        let mut other = reg.clone();
        other.field.width = 32;
        let msg = fork_problem(&base, 99, &other).unwrap();
        assert!(
            msg.contains("width = 64") && msg.contains("width = 32"),
            "{msg}"
        );
        let from_reg_run = fork_problem(&reg, 150, &reg).unwrap();
        assert!(from_reg_run.contains("regularizer on"), "{from_reg_run}");
        assert_eq!(fork_problem(&reg, 99, &base), None);
    }
}
