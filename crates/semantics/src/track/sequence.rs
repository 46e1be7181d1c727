//! Tracking over a sequence of frames: every frame is embedded once; objects start on their
//! seed frames and are followed forward to the end, and backward to the start for objects
//! seeded after the first frame (those frames are embedded a second time).

use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use super::region::Region;
use super::seed::{frame_index, Seed};
use super::tracker::{Found, ObjectTrack, TrackConfig};
use super::TrackError;
use crate::idmap::BACKGROUND;
use crate::sam::{Predictor, Sam, Scratch};

/// One object's record over the sequence.
#[derive(Debug, Clone, Serialize)]
pub struct ObjectReport {
    pub name: String,
    /// What chose it (`"car" (click at 10,20 on train/r_000)`).
    pub seed: String,
    pub seed_frame: usize,
    /// Frames (indices into the sequence) where it was not found.
    pub lost_frames: Vec<usize>,
    /// Frames where it was found again by re-detection after its prompt failed.
    pub recovered_frames: Vec<usize>,
}

/// What tracking made: an object-ID map per frame (object i = seed i, 255 = background).
#[derive(Debug, Clone)]
pub struct Tracked {
    pub ids: Vec<Vec<u8>>,
    pub objects: Vec<ObjectReport>,
    /// Seconds spent on each frame (both passes).
    pub seconds: Vec<f64>,
}

/// A frame: its name (for messages) and interleaved RGB8 pixels.
pub struct FrameRgb<'a> {
    pub name: &'a str,
    pub width: usize,
    pub height: usize,
    pub rgb: &'a [u8],
}

/// Each pixel goes to the object with the largest positive logit (SAM masks of different
/// objects may overlap at their borders); pixels already painted are kept when `keep` is set.
fn paint(ids: &mut [u8], found: &[(usize, Found)], keep: bool) {
    for (i, px) in ids.iter_mut().enumerate() {
        if keep && *px != BACKGROUND {
            continue;
        }
        let mut best = (0.0f32, BACKGROUND);
        for (k, f) in found {
            let v = f.logits[i];
            if f.region.on[i] && v > best.0 {
                best = (v, *k as u8);
            }
        }
        if best.1 != BACKGROUND {
            *px = best.1;
        }
    }
}

/// The seed's mask as logits (+1 inside, −1 outside) for painting.
fn seed_found(region: Region) -> Found {
    Found {
        logits: region
            .on
            .iter()
            .map(|&b| if b { 1.0 } else { -1.0 })
            .collect(),
        region,
    }
}

/// Track `seeds` through `frames` (time order); `progress(done, total)` after each frame
/// of either pass.
pub fn track_sequence(
    sam: &Sam,
    frames: &[FrameRgb],
    seeds: &[Seed],
    cfg: &TrackConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Tracked, TrackError> {
    if seeds.is_empty() {
        return Err(TrackError::Prompt("no object to track".into()));
    }
    if seeds.len() > BACKGROUND as usize {
        return Err(TrackError::Prompt(format!(
            "{} objects: object-ID maps hold at most {}",
            seeds.len(),
            BACKGROUND
        )));
    }
    let names: Vec<String> = frames.iter().map(|f| f.name.to_string()).collect();
    let starts = seeds
        .iter()
        .map(|s| frame_index(s, &names))
        .collect::<Result<Vec<_>, _>>()?;
    let n = frames.len();
    let first = *starts.iter().min().expect("seeds");
    let latest = *starts.iter().max().expect("seeds");
    let total = (n - first) + latest;
    let mut ids: Vec<Vec<u8>> = frames
        .iter()
        .map(|f| vec![BACKGROUND; f.width * f.height])
        .collect();
    let mut seconds = vec![0.0f64; n];
    let mut seed_regions: Vec<Option<Region>> = vec![None; seeds.len()];
    let mut forward: Vec<Option<ObjectTrack>> = (0..seeds.len()).map(|_| None).collect();
    let mut done = 0;
    for f in first..n {
        let t0 = Instant::now();
        let fr = &frames[f];
        let pred = Predictor::new(sam, fr.rgb, fr.height, fr.width)?;
        let mut found = step_all(&pred, fr, f, &mut forward, cfg);
        for (k, seed) in seeds.iter().enumerate().filter(|(k, _)| starts[*k] == f) {
            let others: Vec<[f32; 2]> = (0..seeds.len())
                .filter(|&o| o != k && starts[o] == f)
                .filter_map(|o| seeds[o].anchor())
                .collect();
            let region = seed.resolve(&pred, fr.name, cfg.max_area, &others)?;
            forward[k] = ObjectTrack::start(&seed.name, region.clone(), fr.rgb, f);
            seed_regions[k] = Some(region.clone());
            found.push((k, seed_found(region)));
        }
        paint(&mut ids[f], &found, false);
        seconds[f] += t0.elapsed().as_secs_f64();
        done += 1;
        progress(done, total);
    }
    // Backward from each late seed's frame to the start: pixels the forward pass gave to
    // another object stay that object's.
    let mut backward: Vec<Option<ObjectTrack>> = (0..seeds.len()).map(|_| None).collect();
    for f in (0..latest).rev() {
        let t0 = Instant::now();
        for k in (0..seeds.len()).filter(|&k| starts[k] == f + 1) {
            let (fr, region) = (&frames[f + 1], seed_regions[k].clone().expect("seeded"));
            backward[k] = ObjectTrack::start(&seeds[k].name, region, fr.rgb, f + 1);
        }
        let fr = &frames[f];
        let pred = Predictor::new(sam, fr.rgb, fr.height, fr.width)?;
        let found = step_all(&pred, fr, f, &mut backward, cfg);
        paint(&mut ids[f], &found, true);
        seconds[f] += t0.elapsed().as_secs_f64();
        done += 1;
        progress(done, total);
    }
    let objects = seeds
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let mut lost = Vec::new();
            let mut recovered = Vec::new();
            for t in [&forward[k], &backward[k]].into_iter().flatten() {
                lost.extend(&t.lost_frames);
                recovered.extend(&t.recovered_frames);
            }
            lost.sort_unstable();
            recovered.sort_unstable();
            ObjectReport {
                name: s.name.clone(),
                seed: s.describe(&names[starts[k]]),
                seed_frame: starts[k],
                lost_frames: lost,
                recovered_frames: recovered,
            }
        })
        .collect();
    Ok(Tracked {
        ids,
        objects,
        seconds,
    })
}

/// Every started object's step on one frame, objects in parallel.
fn step_all(
    pred: &Predictor,
    fr: &FrameRgb,
    f: usize,
    tracks: &mut [Option<ObjectTrack>],
    cfg: &TrackConfig,
) -> Vec<(usize, Found)> {
    tracks
        .par_iter_mut()
        .enumerate()
        .filter_map(|(k, t)| {
            let t = t.as_mut()?;
            let mut sc = Scratch::default();
            t.step(pred, fr.rgb, f, cfg, &mut sc)
                .map(|found| (k, found))
        })
        .collect()
}
