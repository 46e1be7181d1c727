//! Automatic seeds: SAM's automatic mask generator on the first frame, keeping the masks
//! that look like objects: neither tiny nor huge, and not running along the image border
//! (ground, sky and walls touch two or more sides; an object cut by one side is kept).

use serde::Serialize;

use super::region::Region;
use crate::automask::AutoMasks;

/// Which automatic masks count as objects.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct AutoSeeds {
    /// At most this many objects, the most confident (predicted IoU × stability) first.
    pub max_objects: usize,
    /// Least area, as a fraction of the image.
    pub min_area: f32,
    /// Largest area, as a fraction of the image.
    pub max_area: f32,
    /// Most image sides a mask may touch.
    pub max_borders: usize,
}

impl Default for AutoSeeds {
    fn default() -> Self {
        Self {
            max_objects: 8,
            min_area: 0.002,
            max_area: 0.25,
            max_borders: 1,
        }
    }
}

/// The generator's masks that pass `cfg`, as (mask index in `am.masks`, region), ordered
/// left to right by centroid so automatic names (`object-1`, …) read like the image.
pub fn object_masks(am: &AutoMasks, cfg: &AutoSeeds) -> Vec<(usize, Region)> {
    let image = (am.width * am.height) as f32;
    let mut kept: Vec<(usize, Region, f32)> = am
        .masks
        .iter()
        .enumerate()
        .filter_map(|(i, info)| {
            let on: Vec<bool> = am.labels.iter().map(|&l| l as usize == i).collect();
            let region = Region::new(am.width, am.height, on);
            let frac = region.area() as f32 / image;
            let ok = frac >= cfg.min_area
                && frac <= cfg.max_area
                && region.borders_touched() <= cfg.max_borders;
            ok.then_some((i, region, info.pred_iou * info.stability))
        })
        .collect();
    kept.sort_by(|a, b| b.2.total_cmp(&a.2));
    kept.truncate(cfg.max_objects);
    let x = |r: &Region| r.centroid().map_or(0.0, |c| c.0);
    kept.sort_by(|a, b| x(&a.1).total_cmp(&x(&b.1)));
    kept.into_iter().map(|(i, r, _)| (i, r)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::automask::{GenStats, MaskInfo};

    #[test]
    fn keeps_object_like_masks_left_to_right() {
        let (w, h) = (20usize, 10usize);
        // Mask 0: a blob on the right; 1: the bottom half (touches 3 sides); 2: a blob on the
        // left; 3: a single pixel (too small).
        let labels: Vec<u16> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if y >= 5 {
                    1
                } else if (14..18).contains(&x) && (1..4).contains(&y) {
                    0
                } else if (2..6).contains(&x) && (1..4).contains(&y) {
                    2
                } else if (x, y) == (10, 2) {
                    3
                } else {
                    u16::MAX
                }
            })
            .collect();
        let info = MaskInfo {
            bbox: [0; 4],
            area: 0,
            pred_iou: 0.9,
            stability: 0.9,
            point: (0.0, 0.0),
        };
        let am = AutoMasks {
            height: h,
            width: w,
            labels,
            masks: vec![info.clone(); 4],
            stats: GenStats::default(),
        };
        let cfg = AutoSeeds {
            min_area: 0.02,
            ..AutoSeeds::default()
        };
        let got: Vec<usize> = object_masks(&am, &cfg)
            .into_iter()
            .map(|(i, _)| i)
            .collect();
        assert_eq!(got, vec![2, 0]);
        let one = AutoSeeds {
            max_objects: 1,
            ..cfg
        };
        assert_eq!(object_masks(&am, &one).len(), 1);
    }
}
