//! Greedy box non-maximum suppression (torchvision `batched_nms` with a single category, as
//! SAM's `_process_crop` calls it: scores are the predicted IoUs).

use super::mask::{box_iou, BoxXyxy};

/// Indices kept, in decreasing score order. Ties keep the earlier index (stable sort).
pub fn nms(boxes: &[BoxXyxy], scores: &[f32], iou_thresh: f32) -> Vec<usize> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]));
    let mut keep: Vec<usize> = Vec::new();
    for i in order {
        if keep
            .iter()
            .all(|&k| box_iou(&boxes[k], &boxes[i]) <= iou_thresh)
        {
            keep.push(i);
        }
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suppresses_overlapping_lower_scores() {
        let boxes = [
            [0, 0, 10, 10],
            [1, 0, 11, 10],
            [20, 20, 30, 30],
            [0, 0, 10, 10],
        ];
        let scores = [0.9, 0.95, 0.5, 0.1];
        assert_eq!(nms(&boxes, &scores, 0.7), vec![1, 2]);
        // Threshold 1.0 keeps everything (IoU never exceeds 1).
        assert_eq!(nms(&boxes, &scores, 1.0).len(), 4);
    }
}
