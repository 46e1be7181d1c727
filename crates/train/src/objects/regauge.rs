//! The occlusion gauge applied again during training (`[objects] rescale_at`): by then the
//! background behind each moving object's path has been fitted from the views in which
//! the object was elsewhere, so its depth is sharper than at `start_iter`, and the object's
//! shape is its trained one. Each moving object is scaled about the viewing rays of its
//! knots' views (its image does not change; see `gauge.rs`).

use super::gauge::{self, GaugeView};
use super::lift::{self, DepthMap};
use super::{RigidObject, RigidObjects, NO_OBJECT};
use crate::deform::Deformed;
use crate::model::GaussianModel;
use crate::state::GaussianState;
use scene::Dataset;
use splat::Rasterizer;

/// Places the rest of the scene (the nodes before the objects') at time t, every row.
pub type PlaceBackground<'a> = dyn FnMut(&GaussianState, f32, &mut Deformed) + 'a;

/// Background depth (object Gaussians left out) in training view `f`, placed at its time.
fn background_depth(
    state: &GaussianState,
    background: &mut PlaceBackground<'_>,
    ds: &Dataset,
    f: usize,
    raster: &mut Rasterizer,
) -> Result<DepthMap, splat::SplatError> {
    let frame = &ds.train[f];
    let m = &state.model;
    let mut d = Deformed::default();
    background(state, frame.time, &mut d);
    let opacity: Vec<f32> = m
        .opacity_logits
        .iter()
        .zip(&state.object)
        .map(|(&o, &id)| if id == NO_OBJECT { o } else { -30.0 })
        .collect();
    lift::render_depth(
        raster,
        &d.means,
        &d.quats,
        &d.scales,
        &opacity,
        &frame.camera,
    )
}

/// The object's Gaussians as a model of their own (object frame).
fn object_model(state: &GaussianState, id: u8) -> (Vec<usize>, GaussianModel) {
    let rows: Vec<usize> = (0..state.len())
        .filter(|&i| state.object[i] == id)
        .collect();
    let m = state.model.gather(&rows);
    (rows, m)
}

/// Training views at the knots of `o` (a knot's view: the first training frame at its time).
fn knot_frames(o: &RigidObject, ds: &Dataset) -> Option<Vec<usize>> {
    o.trajectory
        .times
        .iter()
        .map(|&t| ds.train.iter().position(|f| f.time == t))
        .collect()
}

/// Re-applies the occlusion gauge to every moving object; returns (name, factor) pairs.
pub fn regauge(
    node: &mut RigidObjects,
    state: &mut GaussianState,
    background: &mut PlaceBackground<'_>,
    ds: &Dataset,
) -> Result<Vec<(String, f32)>, splat::SplatError> {
    let mut raster = Rasterizer::new();
    let mut depths: Vec<Option<DepthMap>> = vec![None; ds.train.len()];
    let mut applied = Vec::new();
    for o in node.objects.iter_mut().filter(|o| !o.is_static) {
        let Some(frames) = knot_frames(o, ds) else {
            continue; // knots without a view of their own: nothing to scale about
        };
        for &f in &frames {
            if depths[f].is_none() {
                depths[f] = Some(background_depth(state, background, ds, f, &mut raster)?);
            }
        }
        let views: Vec<GaugeView> = frames
            .iter()
            .map(|&f| GaugeView {
                cam: &ds.train[f].camera,
                time: ds.train[f].time,
                id_map: &node.id_maps[f],
                background: depths[f].as_ref().expect("rendered above"),
            })
            .collect();
        let (rows, mut model) = object_model(state, o.id);
        let q = node.cfg.scale_quantile;
        let Some(s) = gauge::occlusion_scale(&views, o, &model, q, &mut raster)? else {
            continue;
        };
        let s = s.clamp(0.5, 2.0);
        let centres: Vec<[f32; 3]> = frames
            .iter()
            .map(|&f| ds.train[f].camera.center())
            .collect();
        gauge::apply_scale(&mut model, &mut o.trajectory, &centres, s);
        for (j, &i) in rows.iter().enumerate() {
            state.model.means[i * 3..i * 3 + 3].copy_from_slice(&model.means[j * 3..j * 3 + 3]);
            state.model.log_scales[i * 3..i * 3 + 3]
                .copy_from_slice(&model.log_scales[j * 3..j * 3 + 3]);
        }
        applied.push((o.name.clone(), s));
    }
    Ok(applied)
}
