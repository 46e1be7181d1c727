//! Loads what the evaluation needs from a scene folder: the test frames (composited over
//! the background the runs trained with), their masks and objects (the ground truth's
//! `masks/` and `objects.json`, else the tracked object-ID maps of `segment --track`), and
//! the object-ID maps the figure shows.

use super::crops::CropPolicy;
use super::evaluate::{EvalFrame, EvalSet, MaskSource, ObjectSpec};
use super::images::from_rgb_bytes;
use anyhow::{ensure, Context, Result};
use scene::objects::ObjectsFile;
use scene::{load_mask, Dataset, Frame};
use std::path::Path;

/// Seconds of the paper's tables: t = 0, 1, …, 5 s.
pub const PAPER_SECONDS: [u32; 6] = [0, 1, 2, 3, 4, 5];

/// Objects of `ROOT/objects.json`, or none when the scene has no such file.
pub fn load_objects(root: &Path) -> Result<Vec<ObjectSpec>> {
    let path = root.join("objects.json");
    if !path.is_file() {
        return Ok(Vec::new());
    }
    let file = ObjectsFile::load(&path)?;
    Ok(file
        .objects
        .into_iter()
        .map(|o| ObjectSpec {
            id: o.id,
            name: o.name,
            moving: o.moving,
        })
        .collect())
}

/// An `H·W` ID map if the file exists; an existing but unreadable or mis-sized map is an
/// error naming it.
fn optional_mask(path: &Path, frame: &Frame) -> Result<Option<Vec<u8>>> {
    if !path.is_file() {
        return Ok(None);
    }
    let m = load_mask(path)?;
    ensure!(
        (m.width, m.height) == (frame.image.width, frame.image.height),
        "{} is {}×{} but frame {} is {}×{}",
        path.display(),
        m.width,
        m.height,
        frame.file_path,
        frame.image.width,
        frame.image.height
    );
    Ok(Some(m.data))
}

/// The evaluation set over the test split (the val split when test is empty).
pub fn eval_set(ds: &Dataset, duration_s: f32, policy: CropPolicy) -> Result<EvalSet> {
    let split = if ds.test.is_empty() {
        &ds.val
    } else {
        &ds.test
    };
    ensure!(
        !split.is_empty(),
        "{} has no test or val frames to evaluate",
        ds.root.display()
    );
    let mut frames = Vec::with_capacity(split.len());
    for f in split {
        frames.push(EvalFrame {
            file_path: f.file_path.clone(),
            time: f.time,
            gt: from_rgb_bytes(f.image.width, f.image.height, f.image.data.clone())
                .with_context(|| format!("ground truth of {}", f.file_path))?,
            mask: optional_mask(&ds.gt_mask_path(f), f)?,
        });
    }
    let mut objects = load_objects(&ds.root)?;
    let mut masks = if frames.iter().any(|f| f.mask.is_some()) {
        MaskSource::GroundTruth
    } else {
        MaskSource::Absent
    };
    if masks == MaskSource::Absent && objects.is_empty() {
        if let Some(tracked) = tracked_objects(ds) {
            for (frame, f) in frames.iter_mut().zip(split) {
                frame.mask = semantic_map(ds, f)?;
            }
            objects = tracked;
            masks = MaskSource::Tracked;
        }
    }
    Ok(EvalSet {
        frames,
        objects,
        duration_s,
        t_seconds: PAPER_SECONDS.to_vec(),
        policy,
        masks,
    })
}

/// The objects `segment --track` followed (`semantics/semantics.json`'s `track` section),
/// or `None` when the scene's maps were not tracked: per-frame SAM + CLIP labels change
/// from frame to frame, so they do not make a crop. Tracked objects are the ones the user
/// pointed at, so each counts as moving (each gets its crop series).
fn tracked_objects(ds: &Dataset) -> Option<Vec<ObjectSpec>> {
    let record = ds.root.join("semantics").join("semantics.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(record).ok()?).ok()?;
    v["track"]["objects"].as_array()?;
    let objects: Vec<ObjectSpec> = train::id_maps::names(ds)
        .into_iter()
        .map(|(id, name)| ObjectSpec {
            id,
            name,
            moving: true,
        })
        .collect();
    (!objects.is_empty()).then_some(objects)
}

/// The frame's object-ID map (`semantics/`) resampled (nearest) to the frame's size:
/// `segment` ran at the scene's full size, the evaluation may be downscaled. `None` if it
/// is missing; an unreadable one is an error naming it.
fn semantic_map(ds: &Dataset, f: &Frame) -> Result<Option<Vec<u8>>> {
    let path = ds.semantics_path(f);
    if !path.is_file() {
        return Ok(None);
    }
    let m = load_mask(&path)
        .with_context(|| format!("reading the object-ID map {}", path.display()))?;
    let (w, h) = (f.image.width, f.image.height);
    Ok(Some(train::id_maps::resample_nearest(
        &m.data, m.width, m.height, w, h,
    )))
}

/// The object-ID map shown for each picked frame: the cached SAM + CLIP map
/// (`semantics/<file_path>.png`) when present for every picked frame, else the
/// ground-truth mask. Returns the maps and a sentence saying which was used.
pub fn figure_id_maps(ds: &Dataset, set: &EvalSet) -> Result<(Vec<Option<Vec<u8>>>, String)> {
    let split = if ds.test.is_empty() {
        &ds.val
    } else {
        &ds.test
    };
    let picked = set.picked_frames()?;
    let mut semantic = Vec::with_capacity(picked.len());
    for &i in &picked {
        let f = &split[i];
        semantic.push(semantic_map(ds, f)?);
    }
    if semantic.iter().all(Option::is_some) {
        return Ok((
            semantic,
            "SAM + CLIP object-ID maps (semantics/<frame>.png)".into(),
        ));
    }
    let gt: Vec<Option<Vec<u8>>> = picked.iter().map(|&i| set.frames[i].mask.clone()).collect();
    let source = if gt.iter().any(Option::is_some) {
        "ground-truth instance masks (no SAM + CLIP object-ID map cached for these test frames)"
    } else {
        "none available (no semantics/ maps and no ground-truth masks)"
    };
    Ok((gt, source.into()))
}
