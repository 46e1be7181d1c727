//! Objects taken over from the deformation field (`[objects] source = "field"`): for
//! scenes with no static background to lift an object against, such as D-NeRF's, whose
//! object is the whole scene. Until `field_start_iter` the field learns every object as it
//! learns the rest; then, per object of the ID maps:
//!
//! 1. **Members**: the field's Gaussians whose deformed mean, projected into the training
//!    views, lands on the object's mask in more than half of the views that see it.
//! 2. **Tracks**: where the field puts each member at every training time.
//! 3. **Fits** ([`parts::from_tracks`]): one rigid motion for all members, and at most
//!    `objects.parts` rigid parts found by motion segmentation of the tracks. The parts
//!    replace the single body when two or more remain and they lower the mean squared
//!    distance to the tracks by `parts_min_gain`; a part whose tracks stay within its own
//!    fit's residual (plus 1 % of the size) of rest is held still.
//! 4. **Selection**: an object whose kept fit leaves an RMS distance above
//!    `field_max_residual` of its size is not rigid, not even piecewise: the field keeps it.
//!    Each decision is logged with both fits' residuals and kept in the start report.
//! 5. **Take-over**: the members' object column is set to their part; the object frame is
//!    the field's canonical frame, so no parameter changes and each part's knots are its
//!    fitted poses. Neighbouring parts are held at joints (`parts::joints`) and, with
//!    `objects.skin`, skinned (the node's start does that for both sources).

use super::parts::{from_tracks, joints, Joint, PartsEvidence};
use super::start::{free_ids, median, object_ids, StartReport};
use super::track::StillEvidence;
use super::trajectory::Trajectory;
use super::{knots::KnotAdam, RigidObject, RigidObjects, NO_OBJECT};
use crate::deform::Deformed;
use crate::node::{place_state, Node};
use crate::quat;
use crate::state::GaussianState;
use scene::Dataset;

/// A member lands on its object's mask in more than this share of the views that see it.
const MEMBER_SHARE: f32 = 0.5;
/// Joints are looked for among at most this many members (evenly spaced): the search is
/// quadratic.
const JOINT_SAMPLE: usize = 4000;
/// A part is held still when rest explains its tracks within its own fit's residual plus
/// this fraction of the object's size.
const STILL_SLACK: f32 = 0.01;
/// Two parts that one rigid motion explains within this fraction of the object's size
/// (RMS) are one, whatever the gain: below it the field's tracks are noise.
const MERGE_FLOOR: f32 = 0.002;

/// Takes every object of the ID maps over from the field (module docs); fills
/// `node.objects`, `node.joints` and `node.start_reports`.
pub fn adopt(
    node: &mut RigidObjects,
    (state, ds, earlier): (&mut GaussianState, &Dataset, &mut [Box<dyn Node>]),
    iteration: u32,
) {
    let ids = object_ids(&node.id_maps);
    let members = members(node, state, ds, earlier, &ids, iteration);
    let times = distinct_times(ds);
    let tracks = tracks(state, earlier, &members, &times, iteration);
    let mut free = free_ids(&node.id_maps);
    let mut reports = Vec::new();
    for ((&id, rows), tracks) in ids.iter().zip(&members).zip(tracks) {
        let sightings = node
            .id_maps
            .iter()
            .filter(|m| m.iter().filter(|&&v| v == id).count() >= node.cfg.min_pixels as usize)
            .count();
        if rows.len() < from_tracks::MIN_POINTS {
            tracing::warn!(object = %node.name_of(id), gaussians = rows.len(),
                "too few of the field's Gaussians on its masks: the field keeps it");
            reports.push(unfitted(node, id, sightings));
            continue;
        }
        let x: Vec<f32> = rows
            .iter()
            .flat_map(|&r| state.model.means[r * 3..r * 3 + 3].to_vec())
            .collect();
        let choice = choose(node, id, &x, &tracks.means, &times);
        reports.push(report(node, id, sightings, rows.len(), &choice));
        if !choice.left_to_field {
            take_over(node, state, (id, rows, &x), choice, &mut free);
            bake(node, state, rows, (&tracks, &times));
        }
    }
    node.started = true;
    node.start_reports = reports;
}

/// For each object of `ids`, the field's rows that land on its mask (module docs, step 1).
fn members(
    node: &RigidObjects,
    state: &GaussianState,
    ds: &Dataset,
    earlier: &mut [Box<dyn Node>],
    ids: &[u8],
    iteration: u32,
) -> Vec<Vec<usize>> {
    let n = state.len();
    let mut slot = [usize::MAX; 256];
    for (s, &id) in ids.iter().enumerate() {
        slot[id as usize] = s;
    }
    let k = ids.len();
    let (mut seen, mut votes) = (vec![0u32; n], vec![0u32; n * k]);
    let mut out = Deformed::default();
    for (f, frame) in ds.train.iter().enumerate() {
        place_state(earlier, state, (frame.time, iteration), &mut out);
        let (w, h) = (frame.image.width as usize, frame.image.height as usize);
        let map = &node.id_maps[f];
        for i in (0..n).filter(|&i| state.object[i] == NO_OBJECT) {
            let p = [out.means[i * 3], out.means[i * 3 + 1], out.means[i * 3 + 2]];
            let Some((px, _)) = frame.camera.project(p) else {
                continue;
            };
            let (x, y) = (px[0].floor(), px[1].floor());
            if x < 0.0 || y < 0.0 || x >= w as f32 || y >= h as f32 {
                continue;
            }
            seen[i] += 1;
            let s = slot[map[y as usize * w + x as usize] as usize];
            if s != usize::MAX {
                votes[i * k + s] += 1;
            }
        }
    }
    (0..k)
        .map(|s| {
            (0..n)
                .filter(|&i| seen[i] > 0 && votes[i * k + s] as f32 > MEMBER_SHARE * seen[i] as f32)
                .collect()
        })
        .collect()
}

/// The training frames' times, ascending, each once: the knots.
fn distinct_times(ds: &Dataset) -> Vec<f32> {
    let mut t: Vec<f32> = ds.train.iter().map(|f| f.time).collect();
    t.sort_by(f32::total_cmp);
    t.dedup();
    t
}

/// Where the field puts an object's members at each time: `means[t]` (`members·3`), and
/// the placed rotations and scales (`members·4`, `members·3`) that the take-over bakes in.
#[derive(Default)]
struct Tracks {
    means: Vec<Vec<f32>>,
    quats: Vec<Vec<f32>>,
    scales: Vec<Vec<f32>>,
}

/// Per object, its members' [`Tracks`] at every time of `times`.
fn tracks(
    state: &GaussianState,
    earlier: &mut [Box<dyn Node>],
    members: &[Vec<usize>],
    times: &[f32],
    iteration: u32,
) -> Vec<Tracks> {
    let mut per_object: Vec<Tracks> = members.iter().map(|_| Tracks::default()).collect();
    let mut out = Deformed::default();
    let pick = |v: &[f32], rows: &[usize], k: usize| -> Vec<f32> {
        rows.iter()
            .flat_map(|&r| v[r * k..r * k + k].to_vec())
            .collect()
    };
    for &t in times {
        place_state(earlier, state, (t, iteration), &mut out);
        for (rows, tr) in members.iter().zip(&mut per_object) {
            tr.means.push(pick(&out.means, rows, 3));
            tr.quats.push(pick(&out.quats, rows, 4));
            tr.scales.push(pick(&out.scales, rows, 3));
        }
    }
    per_object
}

/// What the fits of one object found and what was chosen.
struct Choice {
    size: f32,
    rigid: from_tracks::TrackFit,
    /// The parts' fit, when `objects.parts` > 1.
    split: Option<from_tracks::TrackFit>,
    parts_kept: bool,
    left_to_field: bool,
}

impl Choice {
    fn kept(&self) -> &from_tracks::TrackFit {
        match &self.split {
            Some(s) if self.parts_kept => s,
            _ => &self.rigid,
        }
    }
}

/// Both fits of one object and the choice between them and the field (steps 3–4).
fn choose(node: &RigidObjects, id: u8, x: &[f32], tracks: &[Vec<f32>], times: &[f32]) -> Choice {
    let cfg = &node.cfg;
    let size = robust_extent(x).max(1e-6);
    let merge = from_tracks::Merge {
        min_gain: cfg.parts_min_gain,
        floor: MERGE_FLOOR * size,
    };
    let rigid = from_tracks::fit(x, tracks, times, 1, merge);
    let split = (cfg.parts > 1).then(|| from_tracks::fit(x, tracks, times, cfg.parts, merge));
    let parts_kept = split.as_ref().is_some_and(|s| {
        s.parts() >= 2 && s.rms.powi(2) <= (1.0 - cfg.parts_min_gain) * rigid.rms.powi(2)
    });
    let mut c = Choice {
        size,
        rigid,
        split,
        parts_kept,
        left_to_field: false,
    };
    let residual = c.kept().rms / size;
    c.left_to_field = residual > cfg.field_max_residual;
    let name = node.name_of(id);
    tracing::info!(object = %name, gaussians = x.len() / 3, size,
        rigid_residual = c.rigid.rms / size,
        parts_residual = c.split.as_ref().map(|s| s.rms / size),
        parts = c.split.as_ref().map(|s| s.parts()), parts_kept,
        "fits to the field's motion (RMS distance over the object's size)");
    if c.left_to_field {
        tracing::warn!(object = %name, residual, max = cfg.field_max_residual,
            "not rigid, not even in parts: the field's motion of it leaves a residual above \
             objects.field_max_residual, so the field keeps it");
    }
    c
}

/// The largest side of the box holding the middle 96 % of the points on each axis: the
/// object's size, not swayed by a few stray Gaussians.
fn robust_extent(x: &[f32]) -> f32 {
    (0..3)
        .map(|c| {
            let mut v: Vec<f32> = x.chunks_exact(3).map(|p| p[c]).collect();
            v.sort_by(f32::total_cmp);
            let at = |q: f32| v[((v.len() - 1) as f32 * q).round() as usize];
            at(0.98) - at(0.02)
        })
        .fold(0.0, f32::max)
}

/// Whether each part of the kept fit is held still (module docs, step 3).
fn still_parts(c: &Choice) -> Vec<bool> {
    let f = c.kept();
    (0..f.parts())
        .map(|p| f.still_rms[p] <= f.part_rms[p] + STILL_SLACK * c.size)
        .collect()
}

fn report(
    node: &RigidObjects,
    id: u8,
    sightings: usize,
    gaussians: usize,
    c: &Choice,
) -> StartReport {
    let still = still_parts(c);
    let f = c.kept();
    StartReport {
        id,
        name: node.name_of(id),
        sightings,
        is_static: still.iter().all(|&s| s),
        residual_motion: median(f.still_rms.clone()),
        size: c.size,
        still: StillEvidence::default(),
        gaussians: if c.left_to_field { 0 } else { gaussians },
        scale: 1.0,
        mask_iou: f32::NAN,
        left_to_field: c.left_to_field,
        cues: None,
        gauge: None,
        parts: c.split.as_ref().map(|s| PartsEvidence {
            clusters: node.cfg.parts,
            parts: s.parts(),
            body_still: still.first().copied().unwrap_or(false),
            loss_rigid: c.rigid.rms / c.size,
            loss_parts: s.rms / c.size,
            iou_parts: f32::NAN,
            kept: c.parts_kept,
        }),
    }
}

/// The report of an object with too few members to fit: left to the field.
fn unfitted(node: &RigidObjects, id: u8, sightings: usize) -> StartReport {
    StartReport {
        id,
        name: node.name_of(id),
        sightings,
        is_static: false,
        residual_motion: f32::NAN,
        size: f32::NAN,
        still: StillEvidence::default(),
        gaussians: 0,
        scale: 1.0,
        mask_iou: f32::NAN,
        left_to_field: true,
        cues: None,
        gauge: None,
        parts: None,
    }
}

/// Step 5: the members move to their parts' columns; the parts, their knots and joints
/// join the node. The body (column = the object's ID) is the largest still part, else the
/// largest part.
fn take_over(
    node: &mut RigidObjects,
    state: &mut GaussianState,
    (id, rows, x): (u8, &[usize], &[f32]),
    c: Choice,
    free: &mut Vec<u8>,
) {
    let still = still_parts(&c);
    let size = c.size;
    let f = match c.split {
        Some(s) if c.parts_kept => s,
        _ => c.rigid,
    };
    let count = |p: usize| f.labels.iter().filter(|&&l| l as usize == p).count();
    let mut order: Vec<usize> = (0..f.parts()).collect();
    order.sort_by_key(|&p| (!still[p], std::cmp::Reverse(count(p))));
    let name = node.name_of(id);
    let mut col_of = vec![NO_OBJECT; f.parts()];
    for (rank, &p) in order.iter().enumerate() {
        let Some(col) = (if rank == 0 { Some(id) } else { free.pop() }) else {
            tracing::warn!(object = %name, "no free object IDs left for its parts: the rest stay with the field");
            break;
        };
        col_of[p] = col;
        let trajectory = if still[p] {
            Trajectory::constant(f.trajectories[p].times[0], [0.0; 3], [1.0, 0.0, 0.0, 0.0])
        } else {
            f.trajectories[p].clone()
        };
        let label = if rank == 0 {
            name.clone()
        } else {
            format!("{name}/part-{rank}")
        };
        tracing::info!(object = %name, part = rank, id = col, gaussians = count(p),
            is_static = still[p], residual = f.part_rms[p] / size,
            residual_still = f.still_rms[p] / size,
            "part taken over from the field");
        let mut body = RigidObject::new(col, label, trajectory, still[p]);
        body.mask = id;
        node.knot_adam.push(KnotAdam::zeros(body.trajectory.len()));
        node.objects.push(body);
    }
    for (&r, &l) in rows.iter().zip(&f.labels) {
        state.object[r] = col_of[l as usize];
    }
    node.joints.extend(joints_of(
        x,
        &f.labels,
        &col_of,
        node.cfg.joint_weight / (size * size),
    ));
}

/// Ball joints between neighbouring parts (`parts::joints::find` on an even sample of the
/// members), by column ID.
fn joints_of(x: &[f32], labels: &[u32], col_of: &[u8], weight: f32) -> Vec<Joint> {
    if col_of.len() < 2 {
        return Vec::new();
    }
    let n = labels.len();
    let step = n.div_ceil(JOINT_SAMPLE).max(1);
    let sample: Vec<usize> = (0..n).step_by(step).collect();
    let xs: Vec<f32> = sample
        .iter()
        .flat_map(|&i| x[i * 3..i * 3 + 3].to_vec())
        .collect();
    let ls: Vec<u32> = sample.iter().map(|&i| labels[i]).collect();
    let reach = 3.0 * joints::spacing(&xs);
    joints::find(&xs, &ls, reach)
        .into_iter()
        .filter(|&(a, b, _)| col_of[a as usize] != NO_OBJECT && col_of[b as usize] != NO_OBJECT)
        .map(|(a, b, point)| Joint {
            a: col_of[a as usize],
            b: col_of[b as usize],
            point,
            weight,
        })
        .collect()
}

/// The field's time-varying shape, which a rigid part cannot carry, baked into the
/// members' object-frame parameters as its mean over the times: each mean where its part's
/// poses take its track back to (`T(t)⁻¹ y(t)`, averaged), each rotation likewise
/// (`q_T(t)* ⊗ q(t)`, signs aligned to the first), each scale the mean placed scale.
fn bake(
    node: &RigidObjects,
    state: &mut GaussianState,
    rows: &[usize],
    (tracks, times): (&Tracks, &[f32]),
) {
    for (j, &r) in rows.iter().enumerate() {
        let Some(body) = node.objects.iter().find(|o| o.id == state.object[r]) else {
            continue;
        };
        let (mut x, mut q, mut s) = ([0.0f64; 3], [0.0f64; 4], [0.0f64; 3]);
        let mut first: Option<[f32; 4]> = None;
        for (t, &time) in times.iter().enumerate() {
            let pose = body.trajectory.pose(time);
            let y: [f32; 3] = std::array::from_fn(|c| tracks.means[t][j * 3 + c]);
            let d = [y[0] - pose.p[0], y[1] - pose.p[1], y[2] - pose.p[2]];
            let xo = quat::rotate_inv(&pose.r, d);
            let qp = quat::normalize(&tracks.quats[t][j * 4..j * 4 + 4]).0;
            let mut qo = quat::mul(quat::conj(pose.q), qp);
            let f = *first.get_or_insert(qo);
            if (0..4).map(|c| f[c] * qo[c]).sum::<f32>() < 0.0 {
                qo = qo.map(|v| -v);
            }
            for c in 0..3 {
                x[c] += f64::from(xo[c]);
                s[c] += f64::from(tracks.scales[t][j * 3 + c]);
            }
            for c in 0..4 {
                q[c] += f64::from(qo[c]);
            }
        }
        let inv = 1.0 / times.len().max(1) as f64;
        let q = quat::normalize(&q.map(|v| (v * inv) as f32)).0;
        let m = &mut state.model;
        for c in 0..3 {
            m.means[r * 3 + c] = (x[c] * inv) as f32;
            m.log_scales[r * 3 + c] = ((s[c] * inv) as f32).max(1e-8).ln();
        }
        m.quats[r * 4..r * 4 + 4].copy_from_slice(&q);
    }
}
