//! `semdynreg render RUN [--split test] [--time T] [--iteration N] [--only|--without
//! NAME,…]`: PNGs of a split's cameras from the latest checkpoint (or iteration N's), each
//! at its own time or all at time T, into `RUN/renders/<split>/`
//! (`RUN/renders/iter_NNNNNNN/<split>/` with `--iteration`; `<split>_only-NAME…/` or
//! `<split>_without-NAME…/` with a selection of objects), named after the frame
//! (`r_007.png`, or `r_007_t0.500.png` with `--time`). Also holds [`LoadedRun`], shared by
//! `eval` and `export`.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use train::render::{EvalReport, Renderer};
use train::{checkpoint, GaussianModel};

/// PNGs of a split's cameras from a run's latest (or chosen) checkpoint.
///
/// They go to `RUN/renders/<split>/`. With --only or --without (runs trained with
/// --objects) they go to `RUN/renders/<split>_only-NAME[+NAME…]/` (or `_without-…`), so the
/// full renders are never overwritten; e.g. `--only white-suv` renders the white SUV alone
/// over the background colour, `--without background` every object and nothing else.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder made by `semdynreg train`.
    pub run: PathBuf,
    /// Which cameras: train, val or test.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Render every camera at this time in [0, 1] instead of its own.
    #[arg(long)]
    pub time: Option<f32>,
    /// Use the checkpoint of this iteration instead of the latest; the PNGs then go to
    /// `RUN/renders/iter_NNNNNNN/<split>/`.
    #[arg(long)]
    pub iteration: Option<u32>,
    #[command(flatten)]
    pub select: super::select::SelectArgs,
}

/// Where a command that reads a checkpoint writes its outputs: `RUN/<what>` for the
/// latest checkpoint, `RUN/<what>/iter_NNNNNNN` for one chosen with `--iteration`, so
/// that evaluating an older checkpoint never overwrites the latest one's results.
pub fn output_dir(run: &Path, what: &str, iteration: Option<u32>) -> PathBuf {
    match iteration {
        None => run.join(what),
        Some(it) => run.join(what).join(format!("iter_{it:07}")),
    }
}

/// One checkpoint of a run (the latest unless chosen) with its data set.
pub struct LoadedRun {
    pub model: GaussianModel,
    pub iteration: u32,
    /// Rigid objects (empty for runs without them), for selecting and naming, and the
    /// per-Gaussian object column.
    pub objects: Vec<train::objects::RigidObject>,
    pub column: Vec<u8>,
    /// The per-Gaussian rows the nodes keep beside the parameters (skinning weights).
    pub aux: Vec<train::state::AuxRows>,
    /// The scene model's nodes, which place the Gaussians at any time.
    pub nodes: train::nodes::Nodes,
    pub dataset: scene::Dataset,
    pub renderer: Renderer,
}

impl LoadedRun {
    pub fn open(run: &Path, iteration: Option<u32>) -> Result<Self> {
        let info = train::run::RunInfo::load(run)?;
        let dir = checkpoint::select(run, iteration)?;
        let m =
            checkpoint::load_model(&dir).with_context(|| format!("loading {}", dir.display()))?;
        let dataset = info
            .dataset()
            .with_context(|| format!("loading {}", info.scene.display()))?;
        Ok(Self {
            objects: m.objects().to_vec(),
            model: m.model,
            iteration: m.iteration,
            column: m.column,
            aux: m.aux,
            nodes: m.nodes,
            dataset,
            renderer: Renderer::default(),
        })
    }

    /// The scene for `train::render`.
    pub fn scene(&mut self) -> train::render::Scene<'_> {
        train::render::Scene {
            model: &self.model,
            column: &self.column,
            aux: &self.aux,
            nodes: &mut self.nodes,
            iteration: self.iteration,
        }
    }

    /// Keeps only the Gaussians `sel` keeps (the model shrinks to them, with their column).
    pub fn keep(&mut self, sel: &train::objects::Selection) {
        let keep = sel.keep_mask(&self.column);
        for a in &mut self.aux {
            train::model::retain_rows(&mut a.data, a.cols, &keep);
        }
        let (model, column) = sel.apply(&self.model, &self.column);
        self.model = model;
        self.column = column;
    }

    /// The selection of `--only/--without` applied to the run; None without them.
    pub fn select(
        &mut self,
        args: &super::select::SelectArgs,
    ) -> Result<Option<train::objects::Selection>> {
        let sel = args.resolve(&self.objects)?;
        if let Some(s) = &sel {
            let total = self.model.len();
            self.keep(s);
            let kept = self.model.len();
            let what = super::select::describe(s);
            if kept == 0 {
                bail!("{what}: the selection keeps none of the {total} Gaussians");
            }
            println!("{what}: {kept} of {total} Gaussians");
        }
        Ok(sel)
    }

    pub fn split(&self, name: &str) -> Result<&[scene::Frame]> {
        match name {
            "train" => Ok(&self.dataset.train),
            "val" => Ok(&self.dataset.val),
            "test" => Ok(&self.dataset.test),
            s => bail!("unknown split `{s}` (train, val or test)"),
        }
    }

    pub fn evaluate(
        &mut self,
        frames: &[scene::Frame],
        lpips: Option<train::render::FrameScorer>,
    ) -> Result<EvalReport> {
        let bg = self.dataset.background;
        let scene = train::render::Scene {
            model: &self.model,
            column: &self.column,
            aux: &self.aux,
            nodes: &mut self.nodes,
            iteration: self.iteration,
        };
        Ok(self.renderer.evaluate(scene, frames, bg, lpips)?)
    }
}

/// A render's file name: the frame's own name (`test/r_007.png` → `r_007`), so renders sit
/// beside their ground truth by name; the split index when the path has no usable name.
fn frame_stem(file_path: &str, index: usize) -> String {
    Path::new(file_path.trim_end_matches(".png"))
        .file_name()
        .and_then(|n| n.to_str())
        .filter(|n| !n.is_empty())
        .map_or_else(|| format!("{index:04}"), str::to_string)
}

pub fn run(a: Args) -> Result<()> {
    let mut r = LoadedRun::open(&a.run, a.iteration)?;
    if let Some(t) = a.time {
        if !(0.0..=1.0).contains(&t) {
            bail!("--time {t} is outside [0, 1]");
        }
    }
    let frames = r.split(&a.split)?.to_vec();
    let folder = match r.select(&a.select)? {
        Some(s) => format!("{}_{}", a.split, s.label()),
        None => a.split.clone(),
    };
    let dir = output_dir(&a.run, "renders", a.iteration).join(folder);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let bg = r.dataset.background;
    for (i, fr) in frames.iter().enumerate() {
        let t = a.time.unwrap_or(fr.time);
        let scene = train::render::Scene {
            model: &r.model,
            column: &r.column,
            aux: &r.aux,
            nodes: &mut r.nodes,
            iteration: r.iteration,
        };
        let img = r.renderer.render(scene, &fr.camera, t, bg)?;
        let png = scene::ImageU8::from_f32(fr.camera.width, fr.camera.height, &img);
        let name = match a.time {
            Some(t) => format!("{}_t{t:.3}.png", frame_stem(&fr.file_path, i)),
            None => format!("{}.png", frame_stem(&fr.file_path, i)),
        };
        png.save_png(&dir.join(&name))
            .with_context(|| format!("writing {name}"))?;
    }
    println!("{} images → {}", frames.len(), dir.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::frame_stem;

    #[test]
    fn renders_are_named_after_their_frame() {
        assert_eq!(frame_stem("./test/r_007.png", 3), "r_007");
        assert_eq!(frame_stem("test/r_007", 3), "r_007");
        assert_eq!(frame_stem("", 3), "0003");
    }
}
