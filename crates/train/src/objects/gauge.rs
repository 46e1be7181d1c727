//! The occlusion gauge: a moving object seen by one camera is reconstructed only up to a
//! common factor `s` of its size and its distance from the camera. Scaling the object's
//! Gaussians by `s` about its origin and moving its pose at every knot to
//! `p' = c + s·(p − c)` (`c` the camera centre of the knot's view) multiplies every
//! camera-space coordinate by `s`: the object's image is unchanged, only its depth moves.
//! The images cannot fix `s`; occlusion can: the object must be in front of the static
//! scene behind it. We place it as far away as that allows: `s` = the quantile `q` of
//! (background depth / object depth) over the object's pixels in its views. An object that
//! rests on or touches the scene somewhere along its trajectory then touches it there;
//! one that never comes near anything is placed against what is behind it (the limit of
//! this rule, docs/objects.md).

use super::lift::{render_depth, DepthMap};
use super::place;
use super::trajectory::Trajectory;
use super::RigidObject;
use crate::deform::{self, Deformed};
use crate::model::GaussianModel;
use splat::{Camera, Rasterizer};

/// One view for the gauge: its camera, time, ID map and the background's depth there.
pub struct GaugeView<'a> {
    pub cam: &'a Camera,
    pub time: f32,
    pub id_map: &'a [u8],
    pub background: &'a DepthMap,
}

/// The factor that puts the object as far away as its occlusions allow (None when no pixel
/// of the object has a background depth behind it).
pub fn occlusion_scale(
    views: &[GaugeView],
    object: &RigidObject,
    model: &GaussianModel,
    quantile: f32,
    raster: &mut Rasterizer,
) -> Result<Option<f32>, splat::SplatError> {
    let rows = vec![(0..model.len() as u32).collect::<Vec<u32>>()];
    let mut d = Deformed::default();
    let mut poses = Vec::new();
    let mut ratios = Vec::new();
    for v in views {
        deform::apply(model, None, &mut d);
        place::place(
            std::slice::from_ref(object),
            &rows,
            place::Shape::of(model),
            v.time,
            &mut d,
            &mut poses,
        );
        let depth = render_depth(
            raster,
            &d.means,
            &d.quats,
            &d.scales,
            &model.opacity_logits,
            v.cam,
        )?;
        for (p, &id) in v.id_map.iter().enumerate() {
            let (zo, zb) = (depth.depth[p], v.background.depth[p]);
            if id == object.id && zo.is_finite() && zb.is_finite() && zo > 0.0 {
                ratios.push(zb / zo);
            }
        }
    }
    if ratios.is_empty() {
        return Ok(None);
    }
    ratios.sort_by(f32::total_cmp);
    let q = |f: f32| ratios[((ratios.len() - 1) as f32 * f).round() as usize];
    tracing::debug!(
        q01 = q(0.01),
        q03 = q(0.03),
        q10 = q(0.1),
        q25 = q(0.25),
        q50 = q(0.5),
        pixels = ratios.len(),
        "occlusion ratios"
    );
    Ok(Some(q(quantile)))
}

/// The gauge under which the trajectory moves least, and the RMS distance of its origin
/// from its mean position under it: `p_s(t) = c(t) + s·(p(t) − c(t))` is affine in `s`, so
/// the variance `Σ‖p_s − p̄_s‖²` is a quadratic with a closed-form minimum. A static object
/// tracked at the wrong depth seems to move with the camera; under its own scale it stands
/// still, which is how [`super::start`] recognizes it.
pub fn least_motion_scale(tr: &Trajectory, centres: &[[f32; 3]]) -> (f32, f32) {
    let n = tr.len().min(centres.len());
    if n < 2 {
        return (1.0, 0.0);
    }
    let a: Vec<[f64; 3]> = centres[..n].iter().map(|c| c.map(f64::from)).collect();
    let b: Vec<[f64; 3]> = (0..n)
        .map(|k| std::array::from_fn(|c| f64::from(tr.translations[k][c]) - a[k][c]))
        .collect();
    let mean = |v: &[[f64; 3]]| -> [f64; 3] {
        std::array::from_fn(|c| v.iter().map(|x| x[c]).sum::<f64>() / n as f64)
    };
    let (am, bm) = (mean(&a), mean(&b));
    let (mut ab, mut bb) = (0.0, 0.0);
    for k in 0..n {
        for c in 0..3 {
            ab += (a[k][c] - am[c]) * (b[k][c] - bm[c]);
            bb += (b[k][c] - bm[c]).powi(2);
        }
    }
    let s = if bb > 0.0 { (-ab / bb).max(1e-3) } else { 1.0 };
    let var: f64 = (0..n)
        .map(|k| {
            (0..3)
                .map(|c| ((a[k][c] - am[c]) + s * (b[k][c] - bm[c])).powi(2))
                .sum::<f64>()
        })
        .sum::<f64>()
        / n as f64;
    (s as f32, var.sqrt() as f32)
}

/// Applies the gauge `s` (see the module docs); `centres[k]` is the camera centre of the
/// view at knot `k`.
pub fn apply_scale(model: &mut GaussianModel, tr: &mut Trajectory, centres: &[[f32; 3]], s: f32) {
    for v in &mut model.means {
        *v *= s;
    }
    let ls = s.ln();
    for v in &mut model.log_scales {
        *v += ls;
    }
    for (p, c) in tr.translations.iter_mut().zip(centres) {
        *p = std::array::from_fn(|k| c[k] + s * (p[k] - c[k]));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quat;

    /// A static point tracked at 0.7× its distance seems to move with the camera; the
    /// least-motion gauge finds 1/0.7 and no motion left.
    #[test]
    fn least_motion_scale_recovers_a_static_object() {
        let truth = [0.3f32, -0.2, 1.0];
        let centres: Vec<[f32; 3]> = (0..10)
            .map(|k| [k as f32 * 0.1, 0.05 * k as f32, -2.0])
            .collect();
        let tr = Trajectory {
            times: (0..10).map(|k| k as f32).collect(),
            translations: centres
                .iter()
                .map(|c| std::array::from_fn(|i| c[i] + 0.7 * (truth[i] - c[i])))
                .collect(),
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; 10],
        };
        let (s, rms) = least_motion_scale(&tr, &centres);
        assert!((s - 1.0 / 0.7).abs() < 1e-3, "{s}");
        assert!(rms < 1e-4, "{rms}");
    }

    /// Scaling by the gauge leaves every projected position unchanged and scales depth.
    #[test]
    fn gauge_keeps_the_image_and_scales_depth() {
        let cam = |x: f32| Camera {
            width: 64,
            height: 48,
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 24.0,
            viewmat: [
                [1., 0., 0., x],
                [0., 1., 0., 0.],
                [0., 0., 1., 3.],
                [0., 0., 0., 1.],
            ],
        };
        let cams = [cam(0.0), cam(-0.5)];
        let centres = [cams[0].center(), cams[1].center()];
        let mut tr = Trajectory {
            times: vec![0.0, 1.0],
            translations: vec![[0.1, 0.2, 0.3], [0.6, -0.1, 0.0]],
            rotations: vec![[1.0, 0.0, 0.0, 0.0], quat::from_rotvec([0.0, 0.3, 0.2])],
        };
        let mut model = GaussianModel {
            means: vec![0.2, -0.1, 0.05, -0.3, 0.1, 0.2],
            log_scales: vec![-3.0; 6],
            ..Default::default()
        };
        // Every Gaussian's pixel in every view.
        let pixels = |model: &GaussianModel, tr: &Trajectory| -> Vec<_> {
            (0..2)
                .flat_map(|k| {
                    let pose = tr.pose(k as f32);
                    (0..2)
                        .map(|i| {
                            let x = [0, 1, 2].map(|c| model.means[i * 3 + c]);
                            cams[k].project(pose.apply(x)).unwrap()
                        })
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        let before = pixels(&model, &tr);
        apply_scale(&mut model, &mut tr, &centres, 1.5);
        let after = pixels(&model, &tr);
        for (b, a) in before.iter().zip(&after) {
            assert!((b.0[0] - a.0[0]).abs() < 1e-3 && (b.0[1] - a.0[1]).abs() < 1e-3);
            assert!((a.1 - 1.5 * b.1).abs() < 1e-4);
        }
        assert!((model.log_scales[0] - (-3.0 + 1.5f32.ln())).abs() < 1e-6);
    }
}
