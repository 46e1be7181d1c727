//! `--backend slurm`: the unfinished runs of the plan as `sbatch` job arrays, one array
//! task per run. Stage 0 holds the runs that train from scratch, stage 1 the runs that
//! fork from them; stage 1 is submitted with `--dependency=afterok:<stage 0>`, so no fork
//! starts before every baseline has finished (and, with `--kill-on-invalid-dep=yes`, none
//! waits forever when one failed). Each task runs `semdynreg sweep DIR --task NAME`.
//! `OUT/slurm/submit.sh` submits them by hand; `--submit` does the same from here.

use super::plan::Plan;
use crate::report::io::write_atomic;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::Command;

/// What is passed through to `#SBATCH` lines (absent: the cluster's defaults).
#[derive(Clone, Debug, Default)]
pub struct SlurmOptions {
    pub partition: Option<String>,
    pub time: Option<String>,
    pub cpus_per_task: Option<u32>,
    pub mem: Option<String>,
}

/// One written array script and the runs its tasks take, by array index.
#[derive(Clone, Debug)]
pub struct StageScript {
    pub stage: usize,
    pub path: PathBuf,
    pub runs: Vec<String>,
}

/// Quotes `s` for a POSIX shell.
fn sh(s: &str) -> String {
    format!("'{}'", s.replace('\'', "'\\''"))
}

/// The array script of one stage.
fn script(plan: &Plan, opts: &SlurmOptions, exe: &Path, stage: usize, runs: &[String]) -> String {
    let what = match stage {
        0 => "runs that train from scratch",
        _ => "runs that fork from a stage-0 run (submitted with --dependency=afterok:<stage 0>)",
    };
    let dir = plan.out.display().to_string();
    let folder = plan
        .out
        .file_name()
        .map_or("sweep".into(), |n| n.to_string_lossy().into_owned());
    let mut s = format!("#!/bin/bash\n# semdynreg sweep {dir}, stage {stage}: {what}.\n");
    s += &format!("#SBATCH --job-name=sweep-{folder}-{stage}\n");
    s += &format!("#SBATCH --array=0-{}\n", runs.len() - 1);
    s += &format!("#SBATCH --output={dir}/slurm/logs/stage{stage}_%A_%a.out\n");
    if let Some(p) = &opts.partition {
        s += &format!("#SBATCH --partition={p}\n");
    }
    if let Some(t) = &opts.time {
        s += &format!("#SBATCH --time={t}\n");
    }
    if let Some(c) = opts.cpus_per_task {
        s += &format!("#SBATCH --cpus-per-task={c}\n");
    }
    if let Some(m) = &opts.mem {
        s += &format!("#SBATCH --mem={m}\n");
    }
    s += "set -euo pipefail\n";
    let list: Vec<String> = runs.iter().map(|r| sh(r)).collect();
    s += &format!("runs=({})\n", list.join(" "));
    // Training parallelizes over the CPUs Slurm gave the task, not over the node's.
    s += "export RAYON_NUM_THREADS=\"${SLURM_CPUS_PER_TASK:-1}\"\n";
    s += &format!(
        "exec {} sweep {} --task \"${{runs[$SLURM_ARRAY_TASK_ID]}}\"\n",
        sh(&exe.display().to_string()),
        sh(&dir)
    );
    s
}

/// `OUT/slurm/submit.sh`: submits the stages in order, each after the one before.
fn submit_script(scripts: &[StageScript]) -> String {
    let mut s = String::from("#!/bin/bash\n# Submits the sweep's job arrays, each stage after the one before finished.\nset -euo pipefail\ndep=()\n");
    for st in scripts {
        s += &format!(
            "job=$(sbatch --parsable \"${{dep[@]}}\" {})\njob=${{job%%;*}}\necho \"stage {}: job $job\"\ndep=(--dependency=afterok:$job --kill-on-invalid-dep=yes)\n",
            sh(&st.path.display().to_string()),
            st.stage
        );
    }
    s
}

/// Writes the array scripts of the plan's unfinished runs (none when all are finished)
/// and `submit.sh` under `OUT/slurm/`.
pub fn write_scripts(plan: &Plan, opts: &SlurmOptions, exe: &Path) -> Result<Vec<StageScript>> {
    let dir = plan.out.join("slurm");
    std::fs::create_dir_all(dir.join("logs"))
        .with_context(|| format!("creating {}", dir.join("logs").display()))?;
    let mut scripts = Vec::new();
    for stage in 0..2 {
        let runs: Vec<String> = plan
            .runs
            .iter()
            .filter(|r| r.stage() == stage && !plan.finished(&r.name))
            .map(|r| r.name.clone())
            .collect();
        if runs.is_empty() {
            continue;
        }
        let path = dir.join(format!("stage{stage}.sbatch"));
        write_atomic(&path, script(plan, opts, exe, stage, &runs).as_bytes())?;
        scripts.push(StageScript { stage, path, runs });
    }
    write_atomic(&dir.join("submit.sh"), submit_script(&scripts).as_bytes())?;
    Ok(scripts)
}

/// Submits the stages with `sbatch`, each depending on the one before; returns the job ids.
pub fn submit(scripts: &[StageScript]) -> Result<Vec<String>> {
    let mut ids: Vec<String> = Vec::new();
    for st in scripts {
        let mut cmd = Command::new("sbatch");
        cmd.arg("--parsable");
        if let Some(prev) = ids.last() {
            cmd.args([
                &format!("--dependency=afterok:{prev}"),
                "--kill-on-invalid-dep=yes",
            ]);
        }
        cmd.arg(&st.path);
        let out = cmd
            .output()
            .context("running sbatch (is Slurm installed here, and SLURM_CONF set if needed?)")?;
        if !out.status.success() {
            bail!(
                "sbatch {} failed ({}): {}",
                st.path.display(),
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            );
        }
        let text = String::from_utf8_lossy(&out.stdout);
        // `--parsable` prints `id` or `id;cluster`.
        let id = text.trim().split(';').next().unwrap_or("").to_string();
        if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
            bail!("sbatch {} printed no job id: {text:?}", st.path.display());
        }
        tracing::info!(
            "stage {}: job {id} ({} array tasks)",
            st.stage,
            st.runs.len()
        );
        ids.push(id);
    }
    Ok(ids)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> Plan {
        let g = super::super::grid::parse(
            Path::new("/g.toml"),
            "modes = [\"baseline\", \"semdynreg\"]\n[[scenes]]\nname = \"a\"\nsynth = {}\n[[sweep]]\nreg.k = [1, 3]\n",
        )
        .unwrap();
        super::super::plan::expand(&g, Path::new("/nonexistent/sw"), true).unwrap()
    }

    #[test]
    fn the_array_script_runs_one_task_per_run_with_the_options() {
        let opts = SlurmOptions {
            partition: Some("gpu".into()),
            time: Some("01:00:00".into()),
            cpus_per_task: Some(4),
            mem: Some("8G".into()),
        };
        let p = plan();
        let runs: Vec<String> = p.runs[1..].iter().map(|r| r.name.clone()).collect();
        let s = script(&p, &opts, Path::new("/bin/semdynreg"), 1, &runs);
        for line in [
            "#SBATCH --array=0-1\n",
            "#SBATCH --partition=gpu\n",
            "#SBATCH --time=01:00:00\n",
            "#SBATCH --cpus-per-task=4\n",
            "#SBATCH --mem=8G\n",
            "#SBATCH --output=/nonexistent/sw/slurm/logs/stage1_%A_%a.out\n",
            "runs=('a_semdynreg_k=1_s0' 'a_semdynreg_k=3_s0')\n",
            "exec '/bin/semdynreg' sweep '/nonexistent/sw' --task \"${runs[$SLURM_ARRAY_TASK_ID]}\"\n",
        ] {
            assert!(s.contains(line), "missing {line:?} in\n{s}");
        }
        let none = script(&p, &SlurmOptions::default(), Path::new("/b"), 0, &runs[..1]);
        assert!(!none.contains("--partition") && none.contains("--array=0-0\n"));
    }

    #[test]
    fn the_second_stage_waits_for_the_first() {
        let st = |stage: usize| StageScript {
            stage,
            path: format!("/s/stage{stage}.sbatch").into(),
            runs: vec!["r".into()],
        };
        let s = submit_script(&[st(0), st(1)]);
        assert!(
            s.contains("sbatch --parsable \"${dep[@]}\" '/s/stage1.sbatch'"),
            "{s}"
        );
        assert!(
            s.contains("dep=(--dependency=afterok:$job --kill-on-invalid-dep=yes)"),
            "{s}"
        );
        assert!(s.find("stage0").unwrap() < s.find("stage1").unwrap());
    }
}
