//! The `semdynreg` command line. Each subcommand lives in `cmd/<name>.rs` with its own
//! clap `Args` and a `run` function; this file only dispatches.

mod cmd;
mod npz;
mod report;
mod sweep;
mod view;
mod weights;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "semdynreg",
    version,
    about = "Semantics-guided deformable 3D Gaussian Splatting on the CPU"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    // SUBCOMMANDS (one line each, alphabetical)
    Compare(cmd::compare::Args),
    ComparePoses(cmd::compare_poses::Args),
    Demo(cmd::demo::Args),
    Eval(cmd::eval::Args),
    Export(cmd::export::Args),
    Metrics(cmd::metrics::Args),
    Prepare(cmd::prepare::Args),
    Render(cmd::render::Args),
    Segment(cmd::segment::Args),
    Sweep(cmd::sweep::Args),
    Synth(cmd::synth::Args),
    Train(cmd::train::Args),
    View(cmd::view::Args),
    Weights(cmd::weights::Args),
    RenderCase(cmd::render_case::Args),
}

fn main() -> anyhow::Result<()> {
    // Colour codes only on a terminal: logs redirected to a file or a pipe (CI, Slurm,
    // `compare`'s child processes) stay plain text. NO_COLOR (no-color.org) turns them off.
    use std::io::IsTerminal;
    let ansi = std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    tracing_subscriber::fmt()
        .with_ansi(ansi)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    check_simd_env()?;
    match cli.command {
        // DISPATCH (one arm each)
        Command::Compare(a) => cmd::compare::run(a),
        Command::ComparePoses(a) => cmd::compare_poses::run(a),
        Command::Demo(a) => cmd::demo::run(a),
        Command::Eval(a) => cmd::eval::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Metrics(a) => cmd::metrics::run(a),
        Command::Prepare(a) => cmd::prepare::run(a),
        Command::Render(a) => cmd::render::run(a),
        Command::Segment(a) => cmd::segment::run(a),
        Command::Sweep(a) => cmd::sweep::run(a),
        Command::Synth(a) => cmd::synth::run(a),
        Command::Train(a) => cmd::train::run(a),
        Command::View(a) => cmd::view::run(a),
        Command::Weights(a) => cmd::weights::run(a),
        Command::RenderCase(a) => cmd::render_case::run(a),
    }
}

/// Refuses a misspelt `SEMDYNREG_SIMD` (the kernels would silently ignore it) and logs the
/// vector level the kernels use.
fn check_simd_env() -> anyhow::Result<()> {
    let cap = simd::env_cap()?;
    let (cpu, used) = (simd::cpu_level(), simd::level());
    match cap {
        Some(c) if c > cpu => tracing::warn!(
            "{}={c}: this CPU has only {cpu}; the kernels use {used}",
            simd::ENV
        ),
        Some(_) => tracing::info!("vector kernels: {used} (CPU: {cpu}; set by {})", simd::ENV),
        None => tracing::debug!("vector kernels: {used}"),
    }
    Ok(())
}
