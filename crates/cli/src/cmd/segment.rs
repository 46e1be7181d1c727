//! `semdynreg segment SCENE --dict "white SUV,yellow sedan,green SUV" [--sam PATH]
//! [--clip PATH] [--labels clip|gt] [--masks sam|gt]`: object-ID maps for every training frame
//! (`SCENE/semantics/<file_path>.png`, 255 = background), colour previews and
//! `SCENE/semantics/semantics.json`; reuses them when the inputs have not changed.
//!
//! `semdynreg segment SCENE --track [--prompt NAME@x,y[@FRAME]]… [--box NAME@x0,y0,x1,y1[@FRAME]]…`:
//! objects chosen once and tracked through every frame of every split with MobileSAM
//! (`semantics::track`); without prompts, the automatic mask generator picks them on the
//! first frame.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use semantics::automask::{MaskGenConfig, Sampling};
use semantics::segment::{segment_scene, GenConfigKey, LabelSource, MaskSource, SegmentOptions};
use semantics::track::scene::{TrackSpec, TrackSummary};
use semantics::track::{AutoSeeds, Seed, TrackConfig};
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
    Alpha,
}

/// Object-ID maps of a scene's frames for `train --reg` / `--objects`: SAM masks labelled per
/// frame (CLIP or ground truth), or, with --track, objects chosen once and tracked.
#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:\n  \
    semdynreg segment SCENE --track --prompt 'white SUV@120,80' --prompt 'green SUV@300,200'\n  \
    semdynreg segment SCENE --track --box 'car@40,60,140,130@train/r_010'\n  \
    semdynreg segment SCENE --track            # objects found automatically on the first frame\n  \
    semdynreg segment lego --masks alpha --dict lego   # D-NeRF: the RGBA silhouette is the object")]
pub struct Args {
    /// Scene folder (D-NeRF layout; ground-truth masks in SCENE/masks for `gt` modes).
    pub scene: PathBuf,
    /// Comma-separated dictionary; object i ↔ prompt i [default: "white SUV,yellow sedan,green
    /// SUV"; with --masks alpha: "object", the name of the one object].
    #[arg(long)]
    pub dict: Option<String>,
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
    /// Where masks come from: `sam` (automatic mask generation), `gt` (the scene's
    /// ground-truth masks, to separate segmentation errors from the regularizer's) or
    /// `alpha` (the frames' alpha channel as one object, id 0: D-NeRF/Blender RGBA scenes,
    /// whose object is everything not transparent; --labels is ignored).
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
    /// Choose objects once and track them through every frame (all splits, in time order)
    /// with MobileSAM prompts from the previous frame's mask, instead of segmenting and
    /// labelling each training frame on its own. Objects are numbered in the order given:
    /// every --prompt, then every --box; none given: the automatic mask generator's
    /// object-like masks on the first frame (named by CLIP with --clip, else object-1, …).
    #[arg(long)]
    pub track: bool,
    /// With --track: an object and a click on it, `NAME@x,y` in pixels of the first frame in
    /// time order, or `NAME@x,y@FRAME` on another (FRAME: an index in time order or a file
    /// path such as train/r_010). Repeatable.
    #[arg(long = "prompt", value_name = "NAME@x,y[@FRAME]")]
    pub prompts: Vec<String>,
    /// With --track: an object and a box around it, `NAME@x0,y0,x1,y1[@FRAME]`. Repeatable.
    #[arg(long = "box", value_name = "NAME@x0,y0,x1,y1[@FRAME]")]
    pub boxes: Vec<String>,
    /// With --track and no prompts: at most this many automatic objects.
    #[arg(long, default_value_t = 8)]
    pub max_objects: usize,
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
    if a.masks == Masks::Alpha && a.track {
        bail!("--masks alpha reads each frame's own silhouette: it does not combine with --track");
    }
    if a.masks == Masks::Sam && a.sam.is_none() {
        crate::weights::ensure(
            "segment",
            &[&crate::weights::catalog::MOBILE_SAM],
            a.offline,
        );
    }
    let gen = generator(&a);
    let track = track_spec(&a)?;
    let dictionary = match &track {
        Some(t) if !t.seeds.is_empty() => t.seeds.iter().map(|s| s.name.clone()).collect(),
        _ => a
            .dict
            .as_deref()
            .unwrap_or(match a.masks {
                Masks::Alpha => "object",
                Masks::Sam | Masks::Gt => "white SUV,yellow sedan,green SUV",
            })
            .split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect(),
    };
    let opts = SegmentOptions {
        dictionary,
        masks: match a.masks {
            Masks::Sam => MaskSource::Sam,
            Masks::Gt => MaskSource::Gt,
            Masks::Alpha => MaskSource::Alpha,
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
        track,
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
    if let Some(t) = &report.track {
        print_track(t, secs / report.frames.len().max(1) as f64);
    }
    println!(
        "{} frames{}: {} {}, {:.1} s → {}",
        report.frames.len(),
        if report.cached { " (cached)" } else { "" },
        masks,
        if opts.track.is_some() {
            "object masks"
        } else {
            "masks"
        },
        secs,
        a.scene.join("semantics").display()
    );
    Ok(())
}

/// The tracking request, or `None` without --track; prompts without --track are refused.
fn track_spec(a: &Args) -> Result<Option<TrackSpec>> {
    if !a.track {
        if !a.prompts.is_empty() || !a.boxes.is_empty() {
            bail!("--prompt and --box choose objects to track: add --track");
        }
        return Ok(None);
    }
    if a.masks == Masks::Gt {
        bail!("--track makes its own masks with MobileSAM: drop --masks gt");
    }
    let mut seeds = Vec::new();
    for p in &a.prompts {
        seeds.push(Seed::parse(p, false).context("--prompt")?);
    }
    for b in &a.boxes {
        seeds.push(Seed::parse(b, true).context("--box")?);
    }
    if a.max_objects == 0 {
        bail!("--max-objects must be at least 1");
    }
    Ok(Some(TrackSpec {
        seeds,
        auto: AutoSeeds {
            max_objects: a.max_objects,
            ..AutoSeeds::default()
        },
        config: TrackConfig::default(),
    }))
}

/// Per object: its seed, the frames where it was lost, and its IoU against ground truth.
fn print_track(t: &TrackSummary, secs_per_frame: f64) {
    println!(
        "tracked {} objects, {secs_per_frame:.2} s per frame:",
        t.objects.len()
    );
    for (k, o) in t.objects.iter().enumerate() {
        let lost: Vec<&str> = o
            .lost_frames
            .iter()
            .map(|&f| t.frame_names[f].as_str())
            .collect();
        let lost = match lost.len() {
            0 => "never lost".to_string(),
            n if n <= 6 => format!("lost in {n} frames: {}", lost.join(", ")),
            n => format!("lost in {n} frames: {}, …", lost[..6].join(", ")),
        };
        let iou = t.scores.as_ref().map_or(String::new(), |s| {
            let s = &s[k];
            format!(
                "; IoU against ground truth: mean {:.3}, min {:.3} ({})",
                s.mean_iou, s.min_iou, t.frame_names[s.worst_frame]
            )
        });
        println!("  {k}: {} — {lost}{iou}", o.seed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn spec(argv: &[&str]) -> Result<Option<TrackSpec>> {
        let cli = Cli::try_parse_from([&["segment", "SCENE"], argv].concat())?;
        track_spec(&cli.args)
    }

    #[test]
    fn track_flags_build_seeds_in_order_and_refuse_misuse() {
        assert!(spec(&[]).unwrap().is_none());
        let t = spec(&[
            "--track",
            "--box",
            "b@1,2,30,40",
            "--prompt",
            "a@5,6@train/r_3",
        ])
        .unwrap()
        .unwrap();
        let names: Vec<&str> = t.seeds.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["a", "b"], "every --prompt, then every --box");
        assert!(spec(&["--track"]).unwrap().unwrap().seeds.is_empty());
        let err = |argv: &[&str]| format!("{:#}", spec(argv).unwrap_err());
        assert!(err(&["--prompt", "a@1,2"]).contains("add --track"));
        assert!(err(&["--track", "--masks", "gt"]).contains("drop --masks gt"));
        assert!(err(&["--track", "--prompt", "a@1"]).contains("NAME@x,y"));
        assert!(err(&["--track", "--box", "a@1,2,0,0"]).contains("x1 > x0"));
        assert!(err(&["--track", "--max-objects", "0"]).contains("at least 1"));
    }
}
