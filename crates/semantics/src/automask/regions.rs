//! Mask clean-up after NMS: SAM's `remove_small_regions` (fill small holes, drop small islands,
//! 8-connectivity as its `cv2.connectedComponentsWithStats(…, 8)`), and the non-overlapping
//! assignment of docs/architecture.md, "SemDynReg" item 1 (a pixel goes to the mask with
//! the higher stability × predicted IoU; masks left under a minimum area are dropped).

use super::mask::BoxMask;

/// 8-connected component labels of `on` pixels in a w×h grid; returns (labels, sizes), label
/// `u32::MAX` for off pixels. Iterative flood fill, no recursion.
fn components(on: &[bool], w: usize, h: usize) -> (Vec<u32>, Vec<usize>) {
    let mut labels = vec![u32::MAX; on.len()];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..on.len() {
        if !on[start] || labels[start] != u32::MAX {
            continue;
        }
        let id = sizes.len() as u32;
        let mut size = 0;
        labels[start] = id;
        stack.push(start);
        while let Some(p) = stack.pop() {
            size += 1;
            let (x, y) = ((p % w) as isize, (p / w) as isize);
            for (dx, dy) in [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ] {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                    continue;
                }
                let q = ny as usize * w + nx as usize;
                if on[q] && labels[q] == u32::MAX {
                    labels[q] = id;
                    stack.push(q);
                }
            }
        }
        sizes.push(size);
    }
    (labels, sizes)
}

/// Fill holes and remove islands smaller than `min_area` pixels, within the mask's box
/// (off regions touching the box border belong to the outside, so they are never holes).
/// Returns `None` when nothing is left.
pub fn remove_small_regions(m: &BoxMask, min_area: usize) -> Option<BoxMask> {
    if min_area == 0 {
        return Some(m.clone());
    }
    let (w, h) = (m.box_width(), m.bits.len() / m.box_width());
    let mut bits = m.bits.clone();
    // Holes.
    let off: Vec<bool> = bits.iter().map(|b| !b).collect();
    let (lab, sizes) = components(&off, w, h);
    let mut touches = vec![false; sizes.len()];
    for (p, &l) in lab.iter().enumerate() {
        let (x, y) = (p % w, p / w);
        if l != u32::MAX && (x == 0 || y == 0 || x + 1 == w || y + 1 == h) {
            touches[l as usize] = true;
        }
    }
    for (p, &l) in lab.iter().enumerate() {
        if l != u32::MAX && !touches[l as usize] && sizes[l as usize] < min_area {
            bits[p] = true;
        }
    }
    // Islands; if all are small, keep the largest (as SAM does).
    let (lab, sizes) = components(&bits, w, h);
    let largest = sizes
        .iter()
        .enumerate()
        .max_by_key(|(_, &s)| s)
        .map(|(i, _)| i)?;
    let all_small = sizes.iter().all(|&s| s < min_area);
    for (p, &l) in lab.iter().enumerate() {
        if l != u32::MAX {
            let l = l as usize;
            bits[p] = if all_small {
                l == largest
            } else {
                sizes[l] >= min_area
            };
        }
    }
    let [x0, y0, ..] = m.bbox;
    // Re-crop to the new box, in full-image coordinates.
    let full_w = x0 + w;
    let on = |i: usize| {
        let (x, y) = (i % full_w, i / full_w);
        x >= x0 && y >= y0 && bits[(y - y0) * w + (x - x0)]
    };
    BoxMask::from_fn(y0 + h, full_w, on)
}

/// Paint masks into one label map, highest score first; pixels already taken stay with their
/// owner. Masks left with fewer than `min_area` pixels are dropped (their pixels become
/// background). Returns the label map (`u16::MAX` = none, other values index into the returned
/// list of kept mask indices) and the kept masks' indices and final areas.
pub fn non_overlapping(
    masks: &[BoxMask],
    scores: &[f32],
    h: usize,
    w: usize,
    min_area: usize,
) -> (Vec<u16>, Vec<(usize, usize)>) {
    let mut order: Vec<usize> = (0..masks.len()).collect();
    order.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]));
    let mut owner = vec![u32::MAX; h * w];
    let mut area = vec![0usize; masks.len()];
    for &i in &order {
        for p in masks[i].pixels(w) {
            if owner[p] == u32::MAX {
                owner[p] = i as u32;
                area[i] += 1;
            }
        }
    }
    let mut new_id = vec![u16::MAX; masks.len()];
    let mut kept = Vec::new();
    for &i in &order {
        if area[i] >= min_area.max(1) && kept.len() < u16::MAX as usize {
            new_id[i] = kept.len() as u16;
            kept.push((i, area[i]));
        }
    }
    let labels = owner
        .iter()
        .map(|&o| {
            if o == u32::MAX {
                u16::MAX
            } else {
                new_id[o as usize]
            }
        })
        .collect();
    (labels, kept)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from_ascii(rows: &[&str]) -> BoxMask {
        let w = rows[0].len();
        let flat: Vec<bool> = rows
            .iter()
            .flat_map(|r| r.chars().map(|c| c == '#'))
            .collect();
        BoxMask::from_fn(rows.len(), w, |i| flat[i]).unwrap()
    }

    #[test]
    fn fills_holes_and_drops_islands() {
        let m = from_ascii(&["#####...", "#.#.#...", "#####..#", "........"]);
        let r = remove_small_regions(&m, 2).unwrap();
        // Both 1-pixel holes filled, the lone island at (7, 2) removed.
        assert_eq!(r.bbox, [0, 0, 4, 2]);
        assert_eq!(r.area, 15);
    }

    #[test]
    fn all_small_islands_keep_the_largest() {
        let m = from_ascii(&["##..#", "....."]);
        let r = remove_small_regions(&m, 5).unwrap();
        assert_eq!(r.area, 2);
        assert_eq!(r.bbox, [0, 0, 1, 0]);
    }

    #[test]
    fn higher_score_wins_and_small_leftovers_drop() {
        let a = from_ascii(&["####", "####"]);
        let b = from_ascii(&["##..", "##.."]);
        let c = from_ascii(&["...#", "...."]);
        let (labels, kept) = non_overlapping(&[a, b, c], &[0.5, 0.9, 0.1], 2, 4, 2);
        // b (score 0.9) takes the left half; a keeps the remaining 4; c gets nothing.
        assert_eq!(kept, vec![(1, 4), (0, 4)]);
        assert_eq!(labels, vec![0, 0, 1, 1, 0, 0, 1, 1]);
    }
}
