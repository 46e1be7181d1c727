//! Tracked object-ID maps against ground-truth instance masks: each tracked object is matched
//! to the ground-truth object it overlaps most on its seed frame, then scored by mask IoU in
//! every frame where either shows it.

use serde::Serialize;

use super::sequence::Tracked;
use crate::idmap::BACKGROUND;

/// One object's IoU over the sequence.
#[derive(Debug, Clone, Serialize)]
pub struct ObjectScore {
    pub name: String,
    /// The ground-truth ID it was matched to; `None` when it overlaps none on its seed frame.
    pub gt_id: Option<u8>,
    /// IoU per frame; `None` where neither the tracked nor the ground-truth map shows it.
    pub per_frame: Vec<Option<f32>>,
    pub min_iou: f32,
    pub mean_iou: f32,
    /// The frame of `min_iou`.
    pub worst_frame: usize,
}

fn iou(track: &[u8], gt: &[u8], k: u8, g: u8) -> Option<f32> {
    let (mut inter, mut union) = (0usize, 0usize);
    for (&t, &m) in track.iter().zip(gt) {
        let (a, b) = (t == k, m == g);
        inter += usize::from(a && b);
        union += usize::from(a || b);
    }
    (union > 0).then(|| inter as f32 / union as f32)
}

/// Score `tracked` against `gt` (one ground-truth ID map per frame, same sizes).
pub fn against_gt(tracked: &Tracked, gt: &[Vec<u8>]) -> Vec<ObjectScore> {
    tracked
        .objects
        .iter()
        .enumerate()
        .map(|(k, obj)| {
            let k = k as u8;
            let f = obj.seed_frame;
            let mut counts = [0usize; 256];
            for (&t, &m) in tracked.ids[f].iter().zip(&gt[f]) {
                if t == k && m != BACKGROUND {
                    counts[m as usize] += 1;
                }
            }
            let best = (0..255u8).max_by_key(|&g| (counts[g as usize], std::cmp::Reverse(g)));
            let gt_id = best.filter(|&g| counts[g as usize] > 0);
            let per_frame: Vec<Option<f32>> = match gt_id {
                Some(g) => tracked
                    .ids
                    .iter()
                    .zip(gt)
                    .map(|(t, m)| iou(t, m, k, g))
                    .collect(),
                None => vec![Some(0.0); gt.len()],
            };
            let scored: Vec<(usize, f32)> = per_frame
                .iter()
                .enumerate()
                .filter_map(|(i, v)| v.map(|v| (i, v)))
                .collect();
            let (worst_frame, min_iou) = scored
                .iter()
                .copied()
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap_or((0, 0.0));
            let mean_iou = scored.iter().map(|s| s.1).sum::<f32>() / scored.len().max(1) as f32;
            ObjectScore {
                name: obj.name.clone(),
                gt_id,
                per_frame,
                min_iou,
                mean_iou,
                worst_frame,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::ObjectReport;

    #[test]
    fn matches_by_seed_overlap_and_scores_each_frame() {
        let obj = |name: &str| ObjectReport {
            name: name.into(),
            seed: String::new(),
            seed_frame: 0,
            lost_frames: vec![],
            recovered_frames: vec![],
        };
        // Tracked object 0 sits on ground-truth object 3; frame 1 half right; frame 2 absent
        // in both.
        let tracked = Tracked {
            ids: vec![vec![0, 0, 255, 255], vec![0, 255, 255, 255], vec![255; 4]],
            objects: vec![obj("a"), obj("b")],
            seconds: vec![0.0; 3],
        };
        let gt = vec![
            vec![3, 3, 255, 1],
            vec![3, 3, 255, 1],
            vec![255, 255, 255, 1],
        ];
        let s = against_gt(&tracked, &gt);
        assert_eq!(s[0].gt_id, Some(3));
        assert_eq!(s[0].per_frame, vec![Some(1.0), Some(0.5), None]);
        assert_eq!((s[0].min_iou, s[0].worst_frame), (0.5, 1));
        assert!((s[0].mean_iou - 0.75).abs() < 1e-6);
        // Object 1 never appears: no match, scored 0.
        assert_eq!(s[1].gt_id, None);
        assert_eq!(s[1].min_iou, 0.0);
    }
}
