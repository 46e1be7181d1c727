//! Rigid objects scored against a scene's ground truth (`objects.json` of the toycars
//! generator): for each object, whether the start's static/moving decision matches, and for
//! a mover how well its trajectory matches the true one. Used by the objects benchmark
//! (`cargo run --release -p train --example objects_bench`, docs/objects.md, run by
//! `crate::objects_bench`) and its test.
//!
//! A rigid object's frame is its own (the lift's), so trajectories are compared through a
//! point: the centroid `c` of the object's Gaussians, carried by the fitted trajectory
//! (`P(t) = T(t)·c`), against the centre of the true box carried by the true one (`G(t)`).
//! - path ratio: length of `P` over length of `G` (1: the right scale; a monocular track
//!   fixes a path only up to a factor about the cameras, so a wrong depth shows here);
//! - displacement error: mean over time of `|(P(t) − P(t₀)) − (G(t) − G(t₀))|`, over the
//!   length of `G`;
//! - depth ratio: median over the training views of the camera depth of `P(t)` over that
//!   of `G(t)` (1: placed at the right distance; the centroid of the visible surface sits
//!   a little in front of the box's centre, so a few percent below 1 is exact);
//! - rotation error: the largest angle between the fitted and the true rotation since t₀;
//! - follow: how much of the true motion the object's own Gaussians follow under the fitted
//!   trajectory, `1 − rms(error) / rms(error if still)` over its knots ([`follow`]; the
//!   node-level figure, where `eval`'s pools every Gaussian drawn inside the mask).

use super::contact::median;
use super::{track, RigidObject, RigidObjects};
use crate::state::GaussianState;
use scene::objects::{apply, ObjectsFile};
use scene::Dataset;
use serde::Serialize;

/// A true path shorter than this (world units) or a turn below 2° is a still object.
pub const STILL_PATH: f32 = 0.02;
const STILL_TURN_DEG: f32 = 2.0;

/// What the objects' start made of an object.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Decision {
    Static,
    Moving,
    /// Left to the deformation field (`min_rigid_iou`).
    Field,
    /// Never sighted (too few pixels in every view).
    Unseen,
}

/// One object against the truth.
#[derive(Clone, Debug, Serialize)]
pub struct ObjectScore {
    pub id: u8,
    pub name: String,
    pub truly_moving: bool,
    /// Length of the true path of the box's centre, world units.
    pub true_path: f32,
    pub decision: Decision,
    /// Whether the decision is right (static for a still object, moving for a mover).
    pub correct: bool,
    pub path_ratio: Option<f32>,
    pub displacement_error: Option<f32>,
    pub depth_ratio: Option<f32>,
    pub rotation_error_deg: Option<f32>,
    /// [`follow`] of the object's Gaussians (movers only).
    pub follow: Option<f64>,
    /// The gauge the start applied and the rigid fit's median mask IoU.
    pub scale: Option<f32>,
    /// The static test's measures: the tracked path's RMS motion under the gauge that makes
    /// it move least over the object's extent, its largest turn (degrees) and the ring
    /// offset (`track::StillEvidence`).
    pub residual_motion: Option<f32>,
    pub residual_angle_deg: Option<f32>,
    /// How far the turn moves its Gaussians, over its extent.
    pub residual_turn: Option<f32>,
    pub ring_offset: Option<f32>,
    /// Median mask IoU of its track and of one pose held still, when the motion measures
    /// called it still.
    pub iou_tracked: Option<f32>,
    pub iou_still: Option<f32>,
    pub mask_iou: Option<f32>,
    /// The start's readings of the gauge (`scale.rs`) and its choice, a mover's.
    pub cues: Option<super::scale::ScaleCues>,
    pub gauge: Option<super::scale::GaugeChoice>,
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt()
}

fn path_length(points: &[[f32; 3]]) -> f32 {
    points.windows(2).map(|w| dist(w[0], w[1])).sum()
}

fn rotation(m: &[[f32; 4]; 4]) -> [[f32; 3]; 3] {
    std::array::from_fn(|r| [m[r][0], m[r][1], m[r][2]])
}

/// `a · bᵀ` for rotation matrices.
fn mul_t(a: &[[f32; 3]; 3], b: &[[f32; 3]; 3]) -> [[f32; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[j][k]).sum()))
}

/// The angle of rotation `r`, degrees.
fn angle_deg(r: &[[f32; 3]; 3]) -> f32 {
    let tr = r[0][0] + r[1][1] + r[2][2];
    ((tr - 1.0) * 0.5).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Scores every object of `truth` against the started node `node` of a run whose rows
/// are `state` and whose training views are `ds`.
pub fn score(
    node: &RigidObjects,
    state: &GaussianState,
    ds: &Dataset,
    truth: &ObjectsFile,
) -> Vec<ObjectScore> {
    let mut frames: Vec<_> = truth.frames.iter().collect();
    frames.sort_by(|a, b| a.time.total_cmp(&b.time));
    frames.dedup_by(|a, b| a.time == b.time);
    truth
        .objects
        .iter()
        .enumerate()
        .map(|(k, info)| {
            let [lo, hi] = info.bbox_local;
            let centre = std::array::from_fn(|c| 0.5 * (lo[c] + hi[c]));
            let g: Vec<[f32; 3]> = frames
                .iter()
                .map(|f| apply(&f.object_to_world[k], centre))
                .collect();
            let r0 = rotation(&frames[0].object_to_world[k]);
            let turn = frames
                .iter()
                .map(|f| angle_deg(&mul_t(&rotation(&f.object_to_world[k]), &r0)))
                .fold(0.0f32, f32::max);
            let true_path = path_length(&g);
            let truly_moving = true_path >= STILL_PATH || turn >= STILL_TURN_DEG;
            let report = node.start_reports.iter().find(|r| r.id == info.id);
            let object = node.objects.iter().find(|o| o.id == info.id);
            let decision = match (report, object) {
                (Some(r), _) if r.left_to_field => Decision::Field,
                (_, Some(o)) if o.is_static => Decision::Static,
                (_, Some(_)) => Decision::Moving,
                _ => Decision::Unseen,
            };
            let correct = match decision {
                Decision::Static => !truly_moving,
                Decision::Moving => truly_moving,
                Decision::Field | Decision::Unseen => false,
            };
            let mut s = ObjectScore {
                id: info.id,
                name: info.name.clone(),
                truly_moving,
                true_path,
                decision,
                correct,
                path_ratio: None,
                displacement_error: None,
                depth_ratio: None,
                rotation_error_deg: None,
                follow: None,
                scale: report.map(|r| r.scale),
                residual_motion: report.map(|r| r.still.motion),
                residual_angle_deg: report.map(|r| r.still.angle_deg),
                residual_turn: report.map(|r| r.still.turn),
                ring_offset: report.and_then(|r| r.still.ring_offset),
                iou_tracked: report.and_then(|r| r.still.iou_tracked),
                iou_still: report.and_then(|r| r.still.iou_still),
                mask_iou: report.map(|r| r.mask_iou),
                cues: report.and_then(|r| r.cues),
                gauge: report.and_then(|r| r.gauge),
            };
            let local = local_means(state, info.id);
            if let Some(o) = object.filter(|_| !local.is_empty()) {
                let c = track::centroid(local.as_flattened());
                let poses: Vec<_> = frames.iter().map(|f| o.trajectory.pose(f.time)).collect();
                let p: Vec<[f32; 3]> = poses.iter().map(|q| q.apply(c)).collect();
                if true_path >= STILL_PATH {
                    s.path_ratio = Some(path_length(&p) / true_path);
                    let err: f32 = (0..p.len())
                        .map(|i| {
                            let dp: [f32; 3] = std::array::from_fn(|c| p[i][c] - p[0][c]);
                            let dg: [f32; 3] = std::array::from_fn(|c| g[i][c] - g[0][c]);
                            dist(dp, dg)
                        })
                        .sum();
                    s.displacement_error = Some(err / p.len() as f32 / true_path);
                }
                let pr0 = poses[0].r;
                s.rotation_error_deg = Some(
                    frames
                        .iter()
                        .zip(&poses)
                        .map(|(f, q)| {
                            let fit = mul_t(&q.r, &pr0);
                            let tru = mul_t(&rotation(&f.object_to_world[k]), &r0);
                            angle_deg(&mul_t(&fit, &tru))
                        })
                        .fold(0.0f32, f32::max),
                );
                s.depth_ratio = depth_ratio(ds, o, c, truth, k, centre);
                if truly_moving {
                    s.follow = follow(o, &local, truth, k);
                }
            }
            s
        })
        .collect()
}

/// `1 − rms/rms_if_still` between where the trajectory moves the object's Gaussians `x`
/// (its own frame) and where the true motion moves them, over the trajectory's knot times
/// (the true pose of the nearest frame), anchored at the first knot. 1: the true motion; 0:
/// no better than standing still. None for a still object.
pub fn follow(o: &RigidObject, x: &[[f32; 3]], truth: &ObjectsFile, index: usize) -> Option<f64> {
    let pose_at = |t: f32| {
        truth
            .frames
            .iter()
            .min_by(|a, b| (a.time - t).abs().total_cmp(&(b.time - t).abs()))
            .map(|f| f.object_to_world[index])
    };
    let tr = &o.trajectory;
    let t0 = *tr.times.first()?;
    let (p0, g0) = (tr.pose(t0), pose_at(t0)?);
    let (mut err, mut still) = (0.0f64, 0.0f64);
    for &t in &tr.times {
        let (p, g) = (tr.pose(t), pose_at(t)?);
        for xi in x {
            let a = p0.apply(*xi);
            let ours = p.apply(*xi);
            // The true motion of the anchor: g · g0⁻¹ · a.
            let truth = apply(&g, inv_apply(&g0, a));
            let sq = |u: [f32; 3], v: [f32; 3]| -> f64 {
                (0..3).map(|c| f64::from(u[c] - v[c]).powi(2)).sum()
            };
            err += sq(ours, truth);
            still += sq(a, truth);
        }
    }
    (still > 1e-9).then(|| 1.0 - (err / still).sqrt())
}

/// `m⁻¹ · p` for a rigid row-major 4×4 `m`.
pub fn inv_apply(m: &[[f32; 4]; 4], p: [f32; 3]) -> [f32; 3] {
    let d = [p[0] - m[0][3], p[1] - m[1][3], p[2] - m[2][3]];
    std::array::from_fn(|k| m[0][k] * d[0] + m[1][k] * d[1] + m[2][k] * d[2])
}

/// The means of the object's Gaussians, in its own frame.
fn local_means(state: &GaussianState, id: u8) -> Vec<[f32; 3]> {
    let m = &state.model.means;
    (0..state.object.len())
        .filter(|&row| state.object[row] == id)
        .map(|row| [m[3 * row], m[3 * row + 1], m[3 * row + 2]])
        .collect()
}

/// Median over the training views of the fitted point's camera depth over the true one's.
fn depth_ratio(
    ds: &Dataset,
    o: &RigidObject,
    c: [f32; 3],
    truth: &ObjectsFile,
    k: usize,
    centre: [f32; 3],
) -> Option<f32> {
    let mut ratios: Vec<f32> = ds
        .train
        .iter()
        .filter_map(|f| {
            let tf = truth.frames.iter().find(|t| t.file_path == f.file_path)?;
            let zp = f.camera.to_camera(o.trajectory.pose(f.time).apply(c))[2];
            let zg = f.camera.to_camera(apply(&tf.object_to_world[k], centre))[2];
            (zg > 0.0).then(|| zp / zg)
        })
        .collect();
    median(&mut ratios)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::GaussianModel;
    use crate::quat;

    #[test]
    fn rotation_angles() {
        let q = quat::from_rotvec([0.0, 0.0, 30f32.to_radians()]);
        let r = quat::to_matrix(q);
        assert!((angle_deg(&r) - 30.0).abs() < 1e-3);
        assert!(angle_deg(&mul_t(&r, &r)) < 1e-2);
    }

    fn translation(x: f32) -> [[f32; 4]; 4] {
        [
            [1.0, 0.0, 0.0, x],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// Object 0 slides 1 unit along x, object 1 stands, object 2 is never sighted; the
    /// node fits object 0 at `fitted` times its true path and calls object 1 `static_1`.
    fn scored(fitted: f32, static_1: bool) -> Vec<ObjectScore> {
        use scene::objects::{ObjectFrame, ObjectInfo};
        let times = [0.0f32, 0.5, 1.0];
        let info = |id: u8| ObjectInfo {
            id,
            name: format!("o{id}"),
            prompt: String::new(),
            moving: id == 0,
            bbox_local: [[-0.1; 3], [0.1; 3]],
            parts: Vec::new(),
        };
        let truth = ObjectsFile {
            objects: (0..3).map(info).collect(),
            frames: times
                .iter()
                .map(|&t| ObjectFrame {
                    file_path: format!("train/{t}"),
                    time: t,
                    object_to_world: vec![translation(t), translation(2.0), translation(-2.0)],
                    part_to_world: Vec::new(),
                })
                .collect(),
            extra: Default::default(),
        };
        let mut node = RigidObjects::new(Default::default(), Vec::new(), Vec::new());
        let slide = super::super::Trajectory {
            times: times.to_vec(),
            translations: times.iter().map(|&t| [fitted * t, 0.0, 0.0]).collect(),
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; 3],
        };
        let still = super::super::Trajectory::constant(0.5, [2.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
        node.objects
            .push(RigidObject::new(0, "o0".into(), slide.clone(), false));
        node.objects.push(RigidObject::new(
            1,
            "o1".into(),
            if static_1 { still } else { slide },
            static_1,
        ));
        let model = GaussianModel {
            means: vec![0.05, 0.0, 0.0, -0.05, 0.0, 0.0, 0.0, 0.0, 0.0],
            opacity_logits: vec![0.0; 3],
            ..Default::default()
        };
        let mut state = GaussianState::new(model);
        state.object = vec![0, 0, 1];
        let ds = Dataset {
            root: Default::default(),
            train: Vec::new(),
            val: Vec::new(),
            test: Vec::new(),
            background: [0.0; 3],
            kind: scene::DatasetKind::DNerf,
            point_cloud: None,
            point_colors: None,
        };
        score(&node, &state, &ds, &truth)
    }

    #[test]
    fn an_exact_fit_scores_exactly() {
        let s = scored(1.0, true);
        assert_eq!(s.len(), 3);
        let m = &s[0];
        assert!(m.truly_moving && m.correct && m.decision == Decision::Moving);
        assert!((m.true_path - 1.0).abs() < 1e-5);
        assert!((m.path_ratio.unwrap() - 1.0).abs() < 1e-4);
        assert!(m.displacement_error.unwrap() < 1e-4);
        assert!(m.rotation_error_deg.unwrap() < 1e-2);
        assert!((m.follow.unwrap() - 1.0).abs() < 1e-4);
        assert!(!s[1].truly_moving && s[1].correct && s[1].decision == Decision::Static);
        assert!(s[1].follow.is_none());
        assert_eq!(s[2].decision, Decision::Unseen);
        assert!(!s[2].correct);
    }

    #[test]
    fn a_path_at_twice_the_scale_and_a_still_object_called_moving_are_caught() {
        let s = scored(2.0, false);
        let m = &s[0];
        assert!((m.path_ratio.unwrap() - 2.0).abs() < 1e-4);
        // Twice the motion: the error equals the motion itself, so nothing is followed.
        assert!(m.follow.unwrap().abs() < 1e-4);
        assert!(
            (m.displacement_error.unwrap() - 0.5).abs() < 1e-4,
            "{:?}",
            m.displacement_error
        );
        assert_eq!(s[1].decision, Decision::Moving);
        assert!(!s[1].correct);
    }

    #[test]
    fn path_lengths_add_segments() {
        let p = [[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [3.0, 4.0, 1.0]];
        assert_eq!(path_length(&p), 6.0);
    }
}
