//! Contact with the static scene: how far each view of an object is from touching what is
//! behind it, and the correction of its distance to the camera that this implies.
//!
//! A monocular video fixes an object's distance from the camera in each view only through
//! its apparent size, which needs its 3D shape; its shape in turn is learnt from views
//! whose distances are right. Tracked from a guessed first shape, the two drift together
//! (measured on a synthetic box with the tracker alone: 13 % deeper after a 90° turn, and
//! photometric refinement does not undo it; docs/objects.md). The static background adds
//! what the images of the object cannot: in view k the object is seen in front of the
//! background, `r = background depth / object depth ≥ 1` over its pixels, and an object
//! that touches the scene somewhere (wheels on a road, a box on a table) has `r ≈ 1` at
//! its lowest quantile. Let `q_k` be that quantile in view k.
//!
//! Correction. `log q_k` is fitted by a robust line in time (Theil–Sen: the median of
//! pairwise slopes, so a stretch of views in which the object leaves the scene — a jump —
//! does not bend it). Its level is one factor common to all views, applied as the gauge
//! (`gauge.rs`, shape and distances scaled together: the images do not change); its slope
//! is the drift, and each view's distance is pulled towards `d_k · exp(slope·(t_k − t̄))`
//! by a spring while shape, appearance and poses are refined, so that the shape adapts to
//! distances that keep the contact. What remains of the contact profile after the line
//! (a jump) is left to the images. An object that never comes near the scene behind it
//! has no contact to read; the line then only keeps its clearance from drifting.

use super::lift::{render_depth, DepthMap};
use super::place;
use super::{RigidObject, NO_OBJECT};
use crate::deform::{self, Deformed};
use crate::model::GaussianModel;
use splat::{Camera, Rasterizer};

/// `q`-quantile, over the background pixels within `ring` pixels of the object's mask, of
/// their background depth over the object's depth at the nearest mask pixel, in one view
/// (None with fewer than `min_pixels` such pairs). The background next to the object is
/// seen in this very view, so its depth is as good as the reconstruction gets; where the
/// object touches the scene, the two depths meet (ratio ≈ 1).
#[allow(clippy::too_many_arguments)]
pub fn view_ratio(
    raster: &mut Rasterizer,
    object: &RigidObject,
    model: &GaussianModel,
    cam: &Camera,
    time: f32,
    id_map: &[u8],
    background: &DepthMap,
    q: f32,
    ring: u32,
    min_pixels: usize,
) -> Result<Option<f32>, splat::SplatError> {
    let rows = vec![(0..model.len() as u32).collect::<Vec<u32>>()];
    let mut d = Deformed::default();
    deform::apply(model, None, &mut d);
    let objects = std::slice::from_ref(object);
    place::place(
        objects,
        &rows,
        place::Shape::of(model),
        time,
        &mut d,
        &mut Vec::new(),
    );
    let depth = render_depth(
        raster,
        &d.means,
        &d.quats,
        &d.scales,
        &model.opacity_logits,
        cam,
    )?;
    let mut ratios = ring_ratios(&depth, background, id_map, object.id, ring);
    if ratios.len() < min_pixels {
        return Ok(None);
    }
    let k = ((ratios.len() - 1) as f32 * q).round() as usize;
    ratios.select_nth_unstable_by(k, f32::total_cmp);
    Ok(Some(ratios[k]))
}

/// Background depth over the object's depth at the nearest pixel of its mask, for every
/// background pixel within `ring` pixels of object `id`'s mask (`object`: its depth
/// rendered alone).
pub fn ring_ratios(
    object: &DepthMap,
    background: &DepthMap,
    id_map: &[u8],
    id: u8,
    ring: u32,
) -> Vec<f32> {
    let (w, h) = (object.width as i64, object.height as i64);
    let r = ring.max(1) as i64;
    let mut ratios = Vec::new();
    for (p, &m) in id_map.iter().enumerate() {
        let zb = background.depth[p];
        if m != NO_OBJECT || !zb.is_finite() {
            continue;
        }
        let (x, y) = (p as i64 % w, p as i64 / w);
        let mut best: Option<(i64, f32)> = None;
        for dy in -r..=r {
            for dx in -r..=r {
                let (u, v) = (x + dx, y + dy);
                if u < 0 || v < 0 || u >= w || v >= h {
                    continue;
                }
                let k = (v * w + u) as usize;
                let zo = object.depth[k];
                let d2 = dx * dx + dy * dy;
                if id_map[k] == id && zo.is_finite() && best.is_none_or(|b| d2 < b.0) {
                    best = Some((d2, zo));
                }
            }
        }
        if let Some((_, zo)) = best {
            ratios.push(zb / zo);
        }
    }
    ratios
}

/// Theil–Sen line `y ≈ level + slope·(t − t̄)` through `(t, y)` points; `(level, slope, t̄)`.
pub fn robust_line(points: &[(f32, f32)]) -> Option<(f32, f32, f32)> {
    if points.is_empty() {
        return None;
    }
    let t_mean = points.iter().map(|p| p.0).sum::<f32>() / points.len() as f32;
    let mut slopes = Vec::new();
    for (i, a) in points.iter().enumerate() {
        for b in &points[i + 1..] {
            if (b.0 - a.0).abs() > 1e-6 {
                slopes.push((b.1 - a.1) / (b.0 - a.0));
            }
        }
    }
    let slope = median(&mut slopes).unwrap_or(0.0);
    let mut levels: Vec<f32> = points
        .iter()
        .map(|p| p.1 - slope * (p.0 - t_mean))
        .collect();
    Some((median(&mut levels)?, slope, t_mean))
}

/// The median of `v` (reordered), None when it is empty.
pub(super) fn median(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    v.select_nth_unstable_by(mid, f32::total_cmp);
    Some(v[mid])
}

/// Gradient of the spring `w·(ln d − ln target)²` on the distance `d = ‖p − c‖` from the
/// camera centre `c`, w.r.t. the object's position `p`.
pub fn spring_grad(p: [f32; 3], c: [f32; 3], target: f32, w: f32) -> [f64; 3] {
    let v: [f64; 3] = std::array::from_fn(|k| f64::from(p[k] - c[k]));
    let d2 = v.iter().map(|x| x * x).sum::<f64>().max(1e-12);
    let e = 0.5 * d2.ln() - f64::from(target).ln();
    v.map(|x| 2.0 * f64::from(w) * e * x / d2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_line_ignores_a_stretch_of_outliers() {
        // A drift of 0.2 per unit time, and a "jump" of +1 on 20 % of the points.
        let pts: Vec<(f32, f32)> = (0..50)
            .map(|i| {
                let t = i as f32 / 49.0;
                let jump = if (20..30).contains(&i) { 1.0 } else { 0.0 };
                (t, 0.1 + 0.2 * (t - 0.5) + jump)
            })
            .collect();
        let (level, slope, t_mean) = robust_line(&pts).unwrap();
        assert!((slope - 0.2).abs() < 0.05, "{slope}");
        assert!(
            (level + slope * (0.5 - t_mean) - 0.1).abs() < 0.05,
            "{level}"
        );
    }

    #[test]
    fn spring_pulls_along_the_ray() {
        let (p, c) = ([0.0, 0.0, 2.0], [0.0; 3]);
        let g = spring_grad(p, c, 1.0, 1.0);
        // Too far: descending the gradient brings it closer, along the ray only.
        assert!(g[2] > 0.0 && g[0] == 0.0 && g[1] == 0.0);
        let at_target = spring_grad(p, c, 2.0, 1.0);
        assert!(at_target.iter().all(|v| v.abs() < 1e-9));
        // Finite differences of the spring.
        let f = |z: f32| (f64::from(z).ln() - 1.0f64.ln()).powi(2);
        let fd = (f(2.001) - f(1.999)) / 0.002;
        assert!((fd - g[2]).abs() < 1e-4);
    }
}
