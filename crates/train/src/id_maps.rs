//! The object-ID maps training reads (made by `semdynreg segment`): one per training frame,
//! at the training resolution, and the names of the objects they hold.

use crate::error::{Result, TrainError};
use scene::Dataset;

/// `SCENE/semantics/<file_path>.png` for every training frame; maps made at another
/// resolution are resampled (nearest) to the frame's size, since `--downscale` may differ
/// from the segmentation's.
pub fn load(dataset: &Dataset) -> Result<Vec<Vec<u8>>> {
    let mut id_maps = Vec::with_capacity(dataset.train.len());
    for frame in &dataset.train {
        let path = dataset.semantics_path(frame);
        if !path.is_file() {
            return Err(TrainError::Data(format!(
                "object-ID map {} is missing: run `semdynreg segment {}` first (or train without --reg/--objects)",
                path.display(),
                dataset.root.display()
            )));
        }
        let mask = scene::load_mask(&path).map_err(|e| TrainError::Data(e.to_string()))?;
        let (w, h) = (frame.image.width, frame.image.height);
        id_maps.push(resample_nearest(&mask.data, mask.width, mask.height, w, h));
    }
    Ok(id_maps)
}

/// A name per object ID: `objects.json`'s names when the scene has one (toycars), else the
/// tracked objects' names (`segment --track`) or the dictionary prompt the segmentation
/// labelled ID i with (`semantics/semantics.json`), else none (callers say `object-<id>`).
pub fn names(dataset: &Dataset) -> Vec<(u8, String)> {
    let objects = dataset.root.join("objects.json");
    if let Ok(f) = scene::objects::ObjectsFile::load(&objects) {
        return f.objects.iter().map(|o| (o.id, o.name.clone())).collect();
    }
    let record = dataset.root.join("semantics").join("semantics.json");
    let Ok(text) = std::fs::read_to_string(record) else {
        return Vec::new();
    };
    let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) else {
        return Vec::new();
    };
    // Tracking records its objects' names (automatic ones included) under `track`.
    if let Some(objects) = v["track"]["objects"].as_array() {
        return objects
            .iter()
            .enumerate()
            .filter_map(|(i, o)| Some((u8::try_from(i).ok()?, slug(o["name"].as_str()?))))
            .collect();
    }
    let dict = v["options"]["dictionary"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    dict.iter()
        .enumerate()
        .filter_map(|(i, p)| Some((u8::try_from(i).ok()?, slug(p.as_str()?))))
        .collect()
}

/// `white SUV` → `white-suv`.
fn slug(s: &str) -> String {
    let mut out = String::new();
    for w in s
        .split(|c: char| !c.is_alphanumeric())
        .filter(|w| !w.is_empty())
    {
        if !out.is_empty() {
            out.push('-');
        }
        out.push_str(&w.to_lowercase());
    }
    out
}

/// Nearest-neighbour resampling of an 8-bit label map (labels must not be blended).
pub fn resample_nearest(src: &[u8], sw: u32, sh: u32, dw: u32, dh: u32) -> Vec<u8> {
    if (sw, sh) == (dw, dh) {
        return src.to_vec();
    }
    let mut out = Vec::with_capacity((dw * dh) as usize);
    for i in 0..dh {
        let si = (((i as f32 + 0.5) * sh as f32 / dh as f32) as u32).min(sh - 1);
        for j in 0..dw {
            let sj = (((j as f32 + 0.5) * sw as f32 / dw as f32) as u32).min(sw - 1);
            out.push(src[(si * sw + sj) as usize]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_resampling_keeps_labels() {
        // 2×2 → 4×4: every label is replicated, none is invented.
        let src = [0u8, 1, 2, 255];
        let out = resample_nearest(&src, 2, 2, 4, 4);
        assert_eq!(out[0], 0);
        assert_eq!(out[3], 1);
        assert_eq!(out[12], 2);
        assert_eq!(out[15], 255);
        assert!(out.iter().all(|v| src.contains(v)));
        // Same size is a copy.
        assert_eq!(resample_nearest(&src, 2, 2, 2, 2), src.to_vec());
    }

    #[test]
    fn names_are_slugs() {
        assert_eq!(slug("white SUV"), "white-suv");
        assert_eq!(slug("  a  toy_crate! "), "a-toy-crate");
    }
}
