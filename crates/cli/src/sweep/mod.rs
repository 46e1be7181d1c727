//! `semdynreg sweep`: experiment grids (scenes × modes × config overrides × seeds) as runs
//! with stable names, run here or as Slurm job arrays, and collected into one table.
//!
//! - `grid.rs`: the grid file, read strictly and checked before anything runs;
//! - `plan.rs`: the grid expanded into runs (`OUT/sweep.json`), sharing baselines;
//! - `scenes.rs`: the scenes made (synth recipes, object-ID maps) before any run;
//! - `task.rs`: one run (train, render, score → `RUN/results.json`), for every backend;
//! - `local.rs` / `slurm.rs`: the backends;
//! - `collect.rs` / `plot.rs`: the table (Markdown, CSV, JSON) and its plots.

pub mod collect;
pub mod grid;
pub mod local;
pub mod plan;
pub mod plot;
pub mod scenes;
pub mod slurm;
pub mod task;
