//! `semdynreg demo`: the paper's experiment end to end at a small size —
//! generate toycars scene1, build its object-ID maps (the ground-truth masks by default,
//! SAM or SAM + CLIP on request, saying which), run `compare` (three trainings: baseline,
//! SemDynReg, rigid objects), print the paper-style tables and the path of `report.html`.

use crate::report::runs::run_self;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// Small toycars scene1, three trainings (baseline, the paper's SemDynReg forked from it,
/// rigid objects from scratch), evaluation and report in one command.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output folder: `scene/`, the three runs (`baseline/`, `semdynreg/`, `rigid/`) and
    /// the report.
    #[arg(long, default_value = "demo")]
    pub out: PathBuf,
    #[arg(long, default_value_t = 160)]
    pub width: u32,
    #[arg(long, default_value_t = 120)]
    pub height: u32,
    /// Frames of the generated sequence (every 8th is a test frame).
    #[arg(long, default_value_t = 96)]
    pub frames: usize,
    /// Training iterations of each run (the 40k schedule rescaled). 1,500 keeps the demo
    /// within ~5 minutes on two cores; 3,000 is the schedule of the project's other
    /// toycars measurements (docs/objects.md), about three times the demo's time.
    #[arg(long, default_value_t = 1500)]
    pub iters: u32,
    /// Random initial Gaussians: fewer than the 40k schedule's 100k, which the field would
    /// evaluate at every step, to keep the demo short. Written to `OUT/demo.toml` for all runs.
    #[arg(long, default_value_t = 20_000)]
    pub points: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fraction of its ~2.6-unit route the white SUV drives in the 6 s (`synth toycars
    /// --drive`): 1 is the full drive, 0.25 a slower one the baseline can follow. Used when
    /// OUT/scene is generated; an existing OUT/scene is reused as it is.
    #[arg(long, default_value_t = 1.0)]
    pub drive: f32,
    /// Object-ID maps: `gt` (the scene's ground-truth instance masks, the default), `sam`
    /// (`segment --track`: MobileSAM tracks each vehicle from one click, taken from the
    /// ground truth of the first frame showing it; no other ground truth), or `sam-clip`
    /// (the paper's per-frame MobileSAM masks labelled by CLIP; needs --clip, and no package
    /// ships CLIP weights).
    #[arg(long, value_enum, default_value = "gt")]
    pub id_maps: IdMaps,
    /// CLIP weights (safetensors) for `--id-maps sam-clip`.
    #[arg(long)]
    pub clip: Option<PathBuf>,
    /// Never fetch missing weights (default: the LPIPS weights, and MobileSAM's for `--id-maps sam|sam-clip`, are fetched on first use
    /// with pip, `semdynreg weights fetch`); also `SEMDYNREG_OFFLINE=1`.
    #[arg(long)]
    pub offline: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum IdMaps {
    Gt,
    Sam,
    SamClip,
}

/// The toycars dictionary, object i ↔ prompt i (as in `objects.json`).
const DICTIONARY: &str = "white SUV,yellow sedan,green SUV";

fn s(v: impl ToString) -> String {
    v.to_string()
}

/// One click per object of `objects.json` for `segment --track`: the pixel deepest inside its
/// ground-truth mask on the first frame in time order that shows it (`NAME@x,y@FRAME`). The
/// demo's only use of ground truth with `--id-maps sam`, standing in for a user's click.
fn first_clicks(scene: &Path) -> Result<Vec<String>> {
    let objects = scene::objects::ObjectsFile::load(&scene.join("objects.json"))
        .with_context(|| format!("reading {}", scene.join("objects.json").display()))?;
    let ds = scene::load_dataset(scene, &scene::LoadOptions::default())?;
    let mut frames: Vec<&scene::Frame> = ds.all_frames().collect();
    frames.sort_by(|a, b| a.time.total_cmp(&b.time));
    let mut clicks = Vec::new();
    for o in &objects.objects {
        let found = frames.iter().enumerate().find_map(|(i, f)| {
            let m = scene::load_mask(&ds.gt_mask_path(f)).ok()?;
            let (w, h) = (m.width as usize, m.height as usize);
            let r =
                semantics::track::Region::new(w, h, m.data.iter().map(|&v| v == o.id).collect());
            let &(x, y) = r.interior_points(1, 1).first()?;
            Some(format!("{}@{x:.1},{y:.1}@{i}", o.name))
        });
        clicks.push(
            found.with_context(|| {
                format!("object {} ({}) is in no ground-truth mask", o.id, o.name)
            })?,
        );
    }
    Ok(clicks)
}

/// Builds `SCENE/semantics/` and returns a sentence saying which maps were used.
fn id_maps(scene: &str, a: &Args) -> Result<String> {
    let mut cmd = vec![
        s("segment"),
        s(scene),
        s("--dict"),
        s(DICTIONARY),
        s("--offline"),
    ];
    let sam = semantics::sam::default_checkpoint();
    let source = match a.id_maps {
        IdMaps::Gt => {
            cmd.extend([s("--masks"), s("gt"), s("--labels"), s("gt")]);
            "ground-truth masks as object-ID maps (SAM: --id-maps sam; SAM + CLIP: --id-maps sam-clip --clip PATH)".to_string()
        }
        IdMaps::Sam => {
            cmd.push(s("--track"));
            for p in first_clicks(Path::new(scene))? {
                cmd.extend([s("--prompt"), p]);
            }
            format!(
                "MobileSAM ({}) tracking each vehicle from one click (taken from the ground truth \
                 of the first frame showing it, the only ground truth used)",
                sam.display()
            )
        }
        IdMaps::SamClip => {
            let Some(clip) = &a.clip else {
                bail!("--id-maps sam-clip needs --clip PATH (CLIP ViT-B/16 safetensors)");
            };
            cmd.extend([s("--labels"), s("clip"), s("--clip"), s(clip.display())]);
            format!(
                "SAM ({}) + CLIP ({}) object-ID maps",
                sam.display(),
                clip.display()
            )
        }
    };
    run_self(&cmd)?;
    Ok(source)
}

pub fn run(a: Args) -> Result<()> {
    if a.frames < 48 {
        bail!("--frames {} is too few: the crop tables need a test frame near each of t = 0…5 s (≥ 48 frames)", a.frames);
    }
    let scene = a.out.join("scene");
    let scene_s = scene.display().to_string();
    if !scene.join("objects.json").is_file() {
        run_self(&[
            s("synth"),
            s("toycars"),
            s("--out"),
            s(&scene_s),
            s("--preset"),
            s("scene1"),
            s("--width"),
            s(a.width),
            s("--height"),
            s(a.height),
            s("--frames"),
            s(a.frames),
            s("--seed"),
            s(a.seed),
            s("--drive"),
            s(a.drive),
        ])?;
    }
    let mut needed = vec![&crate::weights::catalog::LPIPS_ALEX];
    if a.id_maps != IdMaps::Gt {
        needed.push(&crate::weights::catalog::MOBILE_SAM);
    }
    crate::weights::ensure("demo", &needed, a.offline);
    let source = id_maps(&scene_s, &a)?;
    println!("object-ID maps: {source}");
    let config = a.out.join("demo.toml");
    let toml = format!("[init]\nrandom_points = {}\n", a.points);
    crate::report::io::write_atomic(&config, toml.as_bytes())?;
    run_self(&[
        s("compare"),
        s(&scene_s),
        s("--out"),
        s(a.out.display()),
        s("--iters"),
        s(a.iters),
        s("--seed"),
        s(a.seed),
        s("--config"),
        s(config.display()),
        // Weights were fetched above (or declined): compare must not try again.
        s("--offline"),
    ])?;
    println!("object-ID maps used for training: {source}");
    Ok(())
}
