//! `semdynreg view RUN [RUN2] [--port P] [--times a:b:step] [--iteration N]`: a local web
//! viewer of a run's deformed Gaussians over time, or of two runs side by side with one
//! camera and one time (the page, server and frames live in [`crate::view`]).

use crate::cmd::render::LoadedRun;
use crate::view::frames::FrameSource;
use crate::view::meta::{self, Meta, RunMeta};
use crate::view::server::{self, Viewer};
use anyhow::{anyhow, bail, Context, Result};
use std::io::Write;
use std::net::TcpListener;
use std::path::{Path, PathBuf};

/// Serve a page on 127.0.0.1 that shows a run's Gaussians at any time t: a time slider with
/// play/pause and speed, an orbit camera, the scene's training and test cameras as
/// viewpoints, and (for runs trained with --objects) colouring by object. With RUN2, both
/// runs side by side under one camera and one time. The page's address carries the view
/// (`?t=0.5&cam=train/r_003` or `&orbit=…`), so a link or a reload shows the same view.
/// Frames are made from the checkpoint when first asked for and cached.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder made by `semdynreg train`.
    pub run: PathBuf,
    /// A second run to show beside the first (e.g. the baseline of a `compare`).
    pub run2: Option<PathBuf>,
    /// Port on 127.0.0.1; 0 picks a free one. The address is printed.
    #[arg(long, default_value_t = 7878)]
    pub port: u16,
    /// The time slider's steps `a:b:step` within [0, 1].
    #[arg(long, default_value = "0:1:0.02")]
    pub times: String,
    /// Show the checkpoints of this iteration instead of the latest.
    #[arg(long)]
    pub iteration: Option<u32>,
    /// Memory for cached frames, in MiB, shared by the runs (least recently used go first;
    /// a frame is 32 bytes a Gaussian).
    #[arg(long, default_value_t = 2048)]
    pub cache_mb: usize,
}

/// Request threads: frames of the two runs are made in parallel, and the page's small
/// files are served meanwhile.
const THREADS: usize = 4;

pub fn run(a: Args) -> Result<()> {
    let times = super::export::parse_times(&a.times)?;
    // Bind before loading, so a port in use is reported at once.
    let listener = bind(a.port)?;
    let paths: Vec<&Path> = std::iter::once(a.run.as_path())
        .chain(a.run2.as_deref())
        .collect();
    let loaded = paths
        .iter()
        .map(|p| open(p, a.iteration))
        .collect::<Result<Vec<_>>>()?;
    let meta_json = serde_json::to_string(&metadata(&paths, &loaded, times))?;
    let cache_bytes = a.cache_mb.saturating_mul(1 << 20) / loaded.len();
    let runs = loaded
        .into_iter()
        .map(|r| FrameSource::new(r, cache_bytes))
        .collect();
    let addr = listener
        .local_addr()
        .context("reading the server's address")?;
    println!("semdynreg view: http://{addr}/  (Ctrl-C stops it)");
    std::io::stdout().flush()?;
    server::serve(listener, Viewer { runs, meta_json }, THREADS)
}

fn bind(port: u16) -> Result<TcpListener> {
    TcpListener::bind(("127.0.0.1", port)).map_err(|e| match e.kind() {
        std::io::ErrorKind::AddrInUse => anyhow!(
            "port {port} on 127.0.0.1 is in use (another viewer?): pick another with --port, \
             or --port 0 for any free one"
        ),
        _ => anyhow!(e).context(format!("listening on 127.0.0.1:{port}")),
    })
}

/// Loads a run's checkpoint, saying plainly when the folder is no run or has none yet.
fn open(run: &Path, iteration: Option<u32>) -> Result<LoadedRun> {
    let shown = run.display();
    if !run.is_dir() {
        bail!("{shown}: no such run folder");
    }
    if !run.join(train::run::RUN_FILE).is_file() {
        bail!(
            "{shown} is not a run folder: it has no {} (make one with `semdynreg train SCENE \
             --out {shown}`)",
            train::run::RUN_FILE
        );
    }
    if train::checkpoint::iterations(run)?.is_empty() {
        bail!(
            "{shown} has no checkpoint yet: its training has not saved one (still running, or \
             stopped before the first save)"
        );
    }
    tracing::info!("loading {shown}");
    LoadedRun::open(run, iteration).with_context(|| format!("opening run {shown}"))
}

fn metadata(paths: &[&Path], runs: &[LoadedRun], times: Vec<f32>) -> Meta {
    let first = &runs[0];
    for (p, r) in paths.iter().zip(runs).skip(1) {
        if r.dataset.root != first.dataset.root {
            tracing::warn!(
                "{} was trained on {}, {} on {}: the viewpoints are the first run's",
                p.display(),
                r.dataset.root.display(),
                paths[0].display(),
                first.dataset.root.display()
            );
        }
    }
    let train_cams: Vec<splat::Camera> = first
        .dataset
        .train
        .iter()
        .map(|f| f.camera.clone())
        .collect();
    let cameras = meta::cameras(&first.dataset);
    let image = cameras.first().map_or([640, 480], |c| [c.width, c.height]);
    Meta {
        runs: paths
            .iter()
            .zip(runs)
            .map(|(p, r)| RunMeta::of(run_name(p), p.display().to_string(), r))
            .collect(),
        times,
        image,
        background: first.dataset.background,
        cameras,
        orbit: meta::orbit(&train_cams, meta::median_centre(&first.model.means)),
    }
}

fn run_name(p: &Path) -> String {
    let abs = std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    abs.file_name()
        .map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into())
}
