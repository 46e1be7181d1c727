//! Cutting an object's Gaussians into spatial clusters, the candidate parts: k-means
//! (Lloyd) on their object-frame means from a farthest-point start, so the result needs no
//! random stream and repeats exactly. SC-GS seeds its control points the same way
//! (farthest-point sampling of the Gaussians).

/// Labels `0..k'` (k' ≤ k: clusters that end empty are dropped and the labels packed) of
/// the `N·3` points `means`, after `iters` Lloyd iterations.
pub fn kmeans(means: &[f32], k: usize, iters: usize) -> Vec<u32> {
    let n = means.len() / 3;
    if n == 0 || k <= 1 {
        return vec![0; n];
    }
    let pt = |i: usize| [means[i * 3], means[i * 3 + 1], means[i * 3 + 2]];
    let mut centres = farthest_points(means, k.min(n));
    let mut labels = vec![0u32; n];
    for _ in 0..iters {
        for (i, l) in labels.iter_mut().enumerate() {
            *l = nearest(&centres, pt(i)) as u32;
        }
        let mut sum = vec![[0.0f64; 4]; centres.len()];
        for (i, &l) in labels.iter().enumerate() {
            let p = pt(i);
            let s = &mut sum[l as usize];
            for c in 0..3 {
                s[c] += f64::from(p[c]);
            }
            s[3] += 1.0;
        }
        for (c, s) in centres.iter_mut().zip(&sum) {
            if s[3] > 0.0 {
                *c = [0, 1, 2].map(|k| (s[k] / s[3]) as f32);
            }
        }
    }
    pack(&mut labels);
    labels
}

/// `k` points of `means`: the farthest from the centroid, then each the farthest from those
/// chosen so far.
fn farthest_points(means: &[f32], k: usize) -> Vec<[f32; 3]> {
    let n = means.len() / 3;
    let pt = |i: usize| [means[i * 3], means[i * 3 + 1], means[i * 3 + 2]];
    let c = super::super::track::centroid(means);
    let mut dist: Vec<f32> = (0..n).map(|i| dist2(pt(i), c)).collect();
    let mut out = Vec::with_capacity(k);
    while out.len() < k {
        let far = argmax(&dist);
        let p = pt(far);
        out.push(p);
        for (i, d) in dist.iter_mut().enumerate() {
            *d = if out.len() == 1 {
                dist2(pt(i), p)
            } else {
                d.min(dist2(pt(i), p))
            };
        }
    }
    out
}

fn argmax(v: &[f32]) -> usize {
    let mut best = 0;
    for (i, &x) in v.iter().enumerate() {
        if x > v[best] {
            best = i;
        }
    }
    best
}

fn nearest(centres: &[[f32; 3]], p: [f32; 3]) -> usize {
    let mut best = (0, f32::INFINITY);
    for (k, c) in centres.iter().enumerate() {
        let d = dist2(p, *c);
        if d < best.1 {
            best = (k, d);
        }
    }
    best.0
}

pub fn dist2(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// Renumbers labels to `0..k'` in order of first appearance of each used label's value.
pub fn pack(labels: &mut [u32]) {
    let max = labels.iter().copied().max().unwrap_or(0) as usize;
    let mut used = vec![false; max + 1];
    for &l in labels.iter() {
        used[l as usize] = true;
    }
    let mut map = vec![0u32; max + 1];
    let mut next = 0;
    for (l, u) in used.iter().enumerate() {
        if *u {
            map[l] = next;
            next += 1;
        }
    }
    for l in labels.iter_mut() {
        *l = map[*l as usize];
    }
}

/// Renumbers labels by cluster size, largest first (ties: lower label first), so label 0
/// is the body.
pub fn by_size(labels: &mut [u32]) {
    let k = labels.iter().copied().max().map_or(0, |m| m as usize + 1);
    let mut count = vec![0usize; k];
    for &l in labels.iter() {
        count[l as usize] += 1;
    }
    let mut order: Vec<usize> = (0..k).collect();
    order.sort_by(|&a, &b| count[b].cmp(&count[a]).then(a.cmp(&b)));
    let mut map = vec![0u32; k];
    for (new, &old) in order.iter().enumerate() {
        map[old] = new as u32;
    }
    for l in labels.iter_mut() {
        *l = map[*l as usize];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two blobs far apart: two clusters, one per blob, whatever k-means starts from.
    #[test]
    fn separates_two_blobs_and_repeats() {
        let mut means = Vec::new();
        for i in 0..40 {
            let j = (i % 7) as f32 * 0.01;
            means.extend_from_slice(&[j, (i % 5) as f32 * 0.01, 0.0]);
            means.extend_from_slice(&[2.0 + j, 1.0, (i % 3) as f32 * 0.01]);
        }
        let l = kmeans(&means, 2, 10);
        for i in 0..40 {
            assert_ne!(l[2 * i], l[2 * i + 1], "blobs apart");
            assert_eq!(l[2 * i], l[0], "one blob one label");
        }
        assert_eq!(l, kmeans(&means, 2, 10), "no random stream");
        // More clusters than points: every label used once at most, packed.
        let few = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        let l = kmeans(&few, 5, 3);
        let mut s = l.clone();
        s.sort();
        assert_eq!(s, vec![0, 1]);
    }

    #[test]
    fn by_size_puts_the_largest_first() {
        let mut l = vec![2, 0, 2, 1, 2, 1];
        by_size(&mut l);
        assert_eq!(l, vec![0, 2, 0, 1, 0, 1]);
        let mut p = vec![5, 5, 9, 3];
        pack(&mut p);
        assert_eq!(p, vec![1, 1, 2, 0]);
    }
}
