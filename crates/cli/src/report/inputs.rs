//! Loads what the evaluation needs from a scene folder: the test frames (composited over
//! the background the runs trained with), their ground-truth masks, the objects of
//! `objects.json`, and the object-ID maps the figure shows.

use super::crops::CropPolicy;
use super::evaluate::{EvalFrame, EvalSet, ObjectSpec};
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
    Ok(EvalSet {
        frames,
        objects: load_objects(&ds.root)?,
        duration_s,
        t_seconds: PAPER_SECONDS.to_vec(),
        policy,
    })
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
        semantic.push(optional_mask(&ds.semantics_path(f), f)?);
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
