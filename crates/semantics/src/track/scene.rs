//! `segment --track` on a scene: every frame of every split in time order (so identities
//! agree across train, val and test), written to the same `semantics/` layout, previews and
//! `semantics.json` cache as per-frame segmentation, with a `track` section recording each
//! object's seed, the frames where it was lost, and its IoU against the scene's
//! ground-truth masks when it has them.

use std::path::Path;

use serde::Serialize;

use super::evaluate::{against_gt, ObjectScore};
use super::seed::{Seed, SeedShape};
use super::sequence::{track_sequence, FrameRgb, ObjectReport};
use super::{AutoSeeds, TrackConfig};
use crate::automask::{generate_from_embedding, MaskGenConfig};
use crate::idmap::BACKGROUND;
use crate::sam::Sam;
use crate::segment::{
    cached_report, preview, preview_path, record_json, record_path, ClipLabeler, FrameReport,
    LabelSource, SegmentError, SegmentOptions, SegmentReport,
};

/// What `--track` was asked: the seeds given (none: automatic), how automatic seeds are
/// chosen, and the tracker's constants. Part of the cache key.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TrackSpec {
    pub seeds: Vec<Seed>,
    pub auto: AutoSeeds,
    pub config: TrackConfig,
}

/// A tracking run's outcome, for the command to print.
#[derive(Debug, Clone, Serialize)]
pub struct TrackSummary {
    pub frame_names: Vec<String>,
    pub objects: Vec<ObjectReport>,
    /// Against ground truth, when every frame has a mask.
    pub scores: Option<Vec<ObjectScore>>,
}

/// Frames of every split, ordered by time (ties keep train, val, test order).
fn time_ordered(ds: &scene::Dataset) -> Vec<&scene::Frame> {
    let mut frames: Vec<&scene::Frame> = ds.all_frames().collect();
    frames.sort_by(|a, b| a.time.total_cmp(&b.time));
    frames
}

/// Seeds from the automatic mask generator on the first frame: named by CLIP against the
/// dictionary when CLIP weights are given (the best mask per prompt), else `object-1`, ….
fn auto_seeds(
    sam: &Sam,
    first: &scene::Frame,
    opts: &SegmentOptions,
    spec: &TrackSpec,
    gen: &MaskGenConfig,
) -> Result<Vec<Seed>, SegmentError> {
    let img = &first.image;
    let (w, h) = (img.width as usize, img.height as usize);
    let am = generate_from_embedding(sam, &sam.embed(&img.data, h, w)?, gen)?;
    let objects = super::auto::object_masks(&am, &spec.auto);
    let seed = |name: String, region| Seed {
        name,
        shape: SeedShape::Mask(region),
        frame: None,
    };
    let seeds: Vec<Seed> = match (&opts.clip, opts.labels) {
        (Some(clip), LabelSource::Clip) => {
            let labeler = ClipLabeler::load(clip, &opts.dictionary, opts.tau)?;
            let labels = labeler.labels(img, &am)?;
            opts.dictionary
                .iter()
                .enumerate()
                .filter_map(|(d, name)| {
                    let (_, r) = objects
                        .iter()
                        .filter(|(i, _)| labels[*i] == Some(d as u8))
                        .max_by_key(|(_, r)| r.area())?;
                    Some(seed(name.clone(), r.clone()))
                })
                .collect()
        }
        _ => objects
            .into_iter()
            .enumerate()
            .map(|(k, (_, r))| seed(format!("object-{}", k + 1), r))
            .collect(),
    };
    if seeds.is_empty() {
        return Err(SegmentError::Input(format!(
            "{}: the automatic mask generator found no object-like mask on the first frame ({} \
             masks, none between {:.1} % and {:.0} % of the image touching at most {} side(s)): \
             choose objects with --prompt NAME@x,y or --box NAME@x0,y0,x1,y1",
            first.file_path,
            am.masks.len(),
            100.0 * spec.auto.min_area,
            100.0 * spec.auto.max_area,
            spec.auto.max_borders
        )));
    }
    Ok(seeds)
}

/// Ground-truth ID maps of every frame, when all exist at the frames' sizes.
fn ground_truth(root: &Path, frames: &[&scene::Frame]) -> Option<Vec<Vec<u8>>> {
    frames
        .iter()
        .map(|f| {
            let m = scene::load_mask(&scene::mask_path(root, &f.file_path)).ok()?;
            ((m.width, m.height) == (f.image.width, f.image.height)).then_some(m.data)
        })
        .collect()
}

/// Track the objects of `spec` through the scene at `root` and write its object-ID maps.
pub fn track_scene(
    root: &Path,
    opts: &SegmentOptions,
    spec: &TrackSpec,
    gen: &MaskGenConfig,
    force: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SegmentReport, SegmentError> {
    let ds = scene::load_dataset(root, &scene::LoadOptions::default())?;
    let frames = time_ordered(&ds);
    if frames.is_empty() {
        return Err(SegmentError::Input(format!(
            "{}: the scene has no frames",
            root.display()
        )));
    }
    let names: Vec<String> = frames.iter().map(|f| f.file_path.clone()).collect();
    if !force {
        if let Some(r) = cached_report(root, opts, &names) {
            tracing::info!(
                "semantics cache in {} is up to date",
                record_path(root).display()
            );
            return Ok(r);
        }
    }
    let sam = Sam::load(&opts.sam)?;
    let seeds = if spec.seeds.is_empty() {
        auto_seeds(&sam, frames[0], opts, spec, gen)?
    } else {
        spec.seeds.clone()
    };
    let rgb: Vec<FrameRgb> = frames
        .iter()
        .map(|f| FrameRgb {
            name: &f.file_path,
            width: f.image.width as usize,
            height: f.image.height as usize,
            rgb: &f.image.data,
        })
        .collect();
    let tracked = track_sequence(&sam, &rgb, &seeds, &spec.config, progress)
        .map_err(|e| SegmentError::Input(e.to_string()))?;
    let mut reports = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let mask = scene::MaskU8 {
            width: f.image.width,
            height: f.image.height,
            data: tracked.ids[i].clone(),
        };
        scene::save_mask(&scene::semantics_path(root, &f.file_path), &mask)?;
        preview(&f.image, &mask.data).save_png(&preview_path(root, &f.file_path))?;
        let present = (0..seeds.len() as u8)
            .filter(|&k| mask.data.contains(&k))
            .count();
        reports.push(FrameReport {
            file_path: f.file_path.clone(),
            masks: present,
            labelled: present,
            seconds: tracked.seconds[i],
        });
    }
    debug_assert!(seeds.len() < BACKGROUND as usize);
    let summary = TrackSummary {
        frame_names: names,
        objects: tracked.objects.clone(),
        scores: ground_truth(root, &frames).map(|gt| against_gt(&tracked, &gt)),
    };
    let mut record = record_json(opts, &reports);
    record["track"] = serde_json::to_value(&summary).unwrap_or_default();
    let json = serde_json::to_string_pretty(&record).unwrap_or_default();
    scene::io::write_atomic(&record_path(root), |w| w.write_all(json.as_bytes()))?;
    Ok(SegmentReport {
        cached: false,
        frames: reports,
        track: Some(summary),
    })
}
