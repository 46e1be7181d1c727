//! `semdynreg sweep GRID.toml --out DIR [--backend local|slurm [--submit]]`,
//! `semdynreg sweep DIR --collect` and `semdynreg sweep DIR --task NAME` (one run; what a
//! Slurm array task runs). The machinery lives in `crate::sweep`.

use crate::sweep::{collect, grid, local, plan, scenes, slurm, task};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// Every run here, one after another; rerun to resume.
    Local,
    /// sbatch job arrays (one task per run), written to DIR/slurm/; --submit submits them.
    Slurm,
}

/// Run a grid of trainings (scenes × modes × config overrides × seeds) here or as Slurm
/// job arrays, and collect their scores into one table (docs/sweeps.md).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The grid file (TOML, e.g. configs/sweeps/ablation.toml); with --collect or --task,
    /// the sweep folder.
    pub input: PathBuf,
    /// Sweep folder: sweep.json (the runs), scenes/, configs/, runs/<name>/, slurm/, and
    /// the collected table. Finished runs found there are skipped, unfinished ones resumed.
    #[arg(long, required_unless_present_any = ["collect", "task"])]
    pub out: Option<PathBuf>,
    #[arg(long, value_enum, default_value = "local")]
    pub backend: Backend,
    /// Submit the job arrays with sbatch (--backend slurm); without it, DIR/slurm/submit.sh does.
    #[arg(long)]
    pub submit: bool,
    /// sbatch --partition of every task (--backend slurm).
    #[arg(long)]
    pub partition: Option<String>,
    /// sbatch --time of every task, e.g. 02:00:00 (--backend slurm).
    #[arg(long)]
    pub time: Option<String>,
    /// sbatch --cpus-per-task; training uses that many threads (--backend slurm).
    #[arg(long)]
    pub cpus_per_task: Option<u32>,
    /// sbatch --mem of every task, e.g. 4G (--backend slurm).
    #[arg(long)]
    pub mem: Option<String>,
    /// The semdynreg executable the tasks run (--backend slurm; default: this one), for
    /// clusters where the nodes see it under another path.
    #[arg(long)]
    pub bin: Option<PathBuf>,
    /// Gather the finished runs of sweep folder INPUT into DIR/table.{md,csv,json} and
    /// DIR/plots/<key>.svg.
    #[arg(long, conflicts_with_all = ["out", "task", "submit"])]
    pub collect: bool,
    /// Run one run of sweep folder INPUT (what each Slurm array task does).
    #[arg(long, value_name = "NAME", conflicts_with_all = ["out", "submit"])]
    pub task: Option<String>,
    /// Never fetch the LPIPS weights (runs are scored without them when absent); also
    /// `SEMDYNREG_OFFLINE=1`.
    #[arg(long)]
    pub offline: bool,
}

pub fn run(a: Args) -> Result<()> {
    if a.collect {
        return print_collected(&a.input);
    }
    if let Some(name) = &a.task {
        let plan = plan::Plan::read(&a.input)?;
        task::run_task(&plan, name)?;
        return Ok(());
    }
    let out = a.out.as_deref().context("--out is required")?;
    let slurm_opts = slurm_options(&a)?;
    let plan = make_plan(&a.input, out, a.offline)?;
    scenes::prepare(&plan)?;
    match a.backend {
        Backend::Local => {
            crate::weights::ensure("sweep", &[&crate::weights::catalog::LPIPS_ALEX], a.offline);
            local::run_local(&plan)?;
            print_collected(&plan.out)
        }
        Backend::Slurm => write_and_submit(&plan, &slurm_opts, &a),
    }
}

/// The `#SBATCH` options, refused with the local backend (where they would do nothing).
fn slurm_options(a: &Args) -> Result<slurm::SlurmOptions> {
    let o = slurm::SlurmOptions {
        partition: a.partition.clone(),
        time: a.time.clone(),
        cpus_per_task: a.cpus_per_task,
        mem: a.mem.clone(),
    };
    let any = o.partition.is_some() || o.time.is_some() || o.cpus_per_task.is_some();
    if a.backend == Backend::Local && (any || o.mem.is_some() || a.submit || a.bin.is_some()) {
        bail!("--submit, --bin, --partition, --time, --cpus-per-task and --mem are for --backend slurm");
    }
    Ok(o)
}

/// Reads the grid, expands it for `out`, checks it against a plan already there and
/// writes it (with a copy of the grid file as `out/grid.toml`).
fn make_plan(grid_file: &Path, out: &Path, offline: bool) -> Result<plan::Plan> {
    let grid_file = std::fs::canonicalize(grid_file)
        .with_context(|| format!("grid file {}", grid_file.display()))?;
    let checked = grid::load(&grid_file)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let out = std::fs::canonicalize(out)?;
    let offline = offline || crate::weights::offline_env();
    let plan = plan::expand(&checked, &out, offline)?;
    if out.join(plan::PLAN_FILE).is_file() {
        plan.check_against(&plan::Plan::read(&out)?)?;
    }
    let text = std::fs::read(&grid_file)?;
    crate::report::io::write_atomic(&out.join("grid.toml"), &text)?;
    plan.write()?;
    let forks = plan.runs.iter().filter(|r| r.fork_from.is_some()).count();
    tracing::info!(
        "{}: {} runs ({} forked from a shared run), {} finished",
        grid_file.display(),
        plan.runs.len(),
        forks,
        plan.runs.iter().filter(|r| plan.finished(&r.name)).count()
    );
    Ok(plan)
}

fn write_and_submit(plan: &plan::Plan, opts: &slurm::SlurmOptions, a: &Args) -> Result<()> {
    let exe = match &a.bin {
        Some(b) => b.clone(),
        None => std::env::current_exe().context("locating the semdynreg executable")?,
    };
    let scripts = slurm::write_scripts(plan, opts, &exe)?;
    let dir = plan.out.display();
    if scripts.is_empty() {
        println!("every run is finished; collect with: semdynreg sweep {dir} --collect");
        return Ok(());
    }
    for s in &scripts {
        println!(
            "stage {}: {} ({} tasks)",
            s.stage,
            s.path.display(),
            s.runs.len()
        );
    }
    if a.submit {
        let ids = slurm::submit(&scripts)?;
        println!("submitted: job {}", ids.join(", then job "));
    } else {
        println!("submit with: bash {dir}/slurm/submit.sh");
    }
    println!("when they are done: semdynreg sweep {dir} --collect");
    Ok(())
}

fn print_collected(dir: &Path) -> Result<()> {
    let c = collect::collect(dir)?;
    println!("{}", collect::markdown(&c.table));
    println!("table: {} (and .csv, .json)", c.markdown.display());
    for p in &c.plots {
        println!("plot:  {}", p.display());
    }
    Ok(())
}
