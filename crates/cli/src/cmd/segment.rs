//! `semdynreg segment SCENE --dict "white SUV,yellow sedan,green SUV" [--sam PATH]
//! [--clip PATH] [--labels clip|gt] [--masks sam|gt]`: object-ID maps for every training frame
//! (`SCENE/semantics/<file_path>.png`, 255 = background), colour previews and
//! `SCENE/semantics/semantics.json`; reuses them when the inputs have not changed.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use semantics::automask::{MaskGenConfig, Sampling};
use semantics::segment::{segment_scene, GenConfigKey, LabelSource, MaskSource, SegmentOptions};
use std::path::PathBuf;

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum Labels {
    Clip,
    Gt,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Masks {
    Sam,
    Gt,
}

/// Object-ID maps of a scene's training frames (SAM masks + CLIP labels), for `train --reg`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene folder (D-NeRF layout; ground-truth masks in SCENE/masks for `gt` modes).
    pub scene: PathBuf,
    /// Comma-separated dictionary; object i ↔ prompt i.
    #[arg(long, default_value = "white SUV,yellow sedan,green SUV")]
    pub dict: String,
    /// SAM checkpoint (mobile_sam.pt, sam_vit_*.pth or .safetensors); default
    /// $SEMDYNREG_WEIGHTS/mobile_sam.pt, else ./weights/mobile_sam.pt.
    #[arg(long)]
    pub sam: Option<PathBuf>,
    /// CLIP checkpoint (safetensors) for `--labels clip`.
    #[arg(long)]
    pub clip: Option<PathBuf>,
    /// How masks get an object: `clip` scores each against the dictionary (needs
    /// --clip), `gt` takes the ground-truth object it overlaps most (toycars `masks/`).
    #[arg(long, value_enum, default_value = "clip")]
    pub labels: Labels,
    /// Where masks come from: `sam` (automatic mask generation) or `gt` (the scene's
    /// ground-truth masks, to separate segmentation errors from the regularizer's).
    #[arg(long, value_enum, default_value = "sam")]
    pub masks: Masks,
    /// SAM point grid side (32 = SAM's default).
    #[arg(long, default_value_t = 32)]
    pub points: usize,
    /// Faster mode: prompt a COARSE grid first, then only uncovered points of the full grid.
    #[arg(long)]
    pub adaptive: Option<usize>,
    /// Relevance threshold τ (docs/architecture.md).
    #[arg(long, default_value_t = 0.5)]
    pub tau: f32,
    /// Keep masks whose predicted IoU is at least this (SAM's automatic generator).
    #[arg(long, default_value_t = 0.88)]
    pub pred_iou_thresh: f32,
    /// Keep masks whose stability score is at least this (SAM's automatic generator).
    #[arg(long, default_value_t = 0.95)]
    pub stability_thresh: f32,
    /// Box IoU above which the lower-scored of two masks is dropped.
    #[arg(long, default_value_t = 0.7)]
    pub nms_thresh: f32,
    /// Holes / islands smaller than this many pixels are removed from each mask.
    #[arg(long, default_value_t = 0)]
    pub min_region_area: usize,
    /// Masks with fewer pixels after the non-overlapping assignment are dropped.
    #[arg(long, default_value_t = 16)]
    pub min_mask_area: usize,
    /// Recompute even when the cache matches.
    #[arg(long)]
    pub force: bool,
    /// Never fetch missing weights (default: MobileSAM's checkpoint is fetched on first use
    /// with pip when --sam is not given, `semdynreg weights fetch`); also `SEMDYNREG_OFFLINE=1`.
    #[arg(long)]
    pub offline: bool,
}

fn generator(a: &Args) -> MaskGenConfig {
    MaskGenConfig {
        sampling: match a.adaptive {
            Some(coarse) => Sampling::Adaptive {
                coarse,
                fine: a.points,
            },
            None => Sampling::Grid(a.points),
        },
        pred_iou_thresh: a.pred_iou_thresh,
        stability_score_thresh: a.stability_thresh,
        box_nms_thresh: a.nms_thresh,
        min_region_area: a.min_region_area,
        min_mask_area: a.min_mask_area,
        ..MaskGenConfig::default()
    }
}

pub fn run(a: Args) -> Result<()> {
    // SAFETY: the dispatcher calls this first, before the command starts any thread (the
    // progress bar's and rayon's come later), so nothing else touches the environment.
    unsafe { semantics::sam::set_thread_count_env() };
    if a.masks == Masks::Sam && a.sam.is_none() {
        crate::weights::ensure(
            "segment",
            &[&crate::weights::catalog::MOBILE_SAM],
            a.offline,
        );
    }
    let gen = generator(&a);
    let opts = SegmentOptions {
        dictionary: a
            .dict
            .split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect(),
        masks: match a.masks {
            Masks::Sam => MaskSource::Sam,
            Masks::Gt => MaskSource::Gt,
        },
        labels: match a.labels {
            Labels::Clip => LabelSource::Clip,
            Labels::Gt => LabelSource::Gt,
        },
        sam: a
            .sam
            .clone()
            .unwrap_or_else(semantics::sam::default_checkpoint),
        clip: a.clip.clone(),
        tau: a.tau,
        generator: GenConfigKey::of(&gen),
    };
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("segment {bar:30} {pos}/{len} frames {elapsed}/{eta}")
            .context("progress style")?,
    );
    let report = segment_scene(&a.scene, &opts, &gen, a.force, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })
    .with_context(|| format!("segmenting {}", a.scene.display()))?;
    bar.finish_and_clear();
    let masks: usize = report.frames.iter().map(|f| f.masks).sum();
    let secs: f64 = report.frames.iter().map(|f| f.seconds).sum();
    println!(
        "{} frames{}: {} masks, {:.1} s → {}",
        report.frames.len(),
        if report.cached { " (cached)" } else { "" },
        masks,
        secs,
        a.scene.join("semantics").display()
    );
    Ok(())
}
