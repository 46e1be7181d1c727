//! Articulated objects (`objects::parts`) on a synthetic object with known part motion: a
//! still base with an arm hinged on top that swings ±60°, seen by a moving camera. From its
//! masks and images alone, the split must keep the parts, and each recovered part's
//! Gaussians must follow the motion of the true part they lie on. A box that moves as one
//! must stay one rigid body.

mod synthetic;

use rand::SeedableRng;
use splat::Rasterizer;
use synthetic::{checkered_box, look_at, render_frame, Frame};
use train::model::GaussianModel;
use train::objects::parts::{split, Articulated, Part};
use train::objects::track::{fit, TrackView, Tracked};
use train::objects::trajectory::{Pose, Trajectory};
use train::objects::ObjectsConfig;
use train::quat;

const FRAMES: usize = 40;

fn pose(p: [f32; 3], yaw_deg: f32) -> Pose {
    let q = quat::from_rotvec([0.0, 0.0, yaw_deg.to_radians()]);
    Trajectory::constant(0.0, p, q).pose(0.0)
}

/// The arm's pose at time t: hinged at the top of the base, yawing 60°·sin(2πt).
fn arm_pose(t: f32) -> Pose {
    pose([0.0, 0.0, 0.2], 60.0 * (std::f32::consts::TAU * t).sin())
}

fn camera(t: f32) -> splat::Camera {
    look_at(-100.0 + 30.0 * t, 35.0, 2.2, [0.0, 0.0, 0.1])
}

fn views(frames: &[Frame]) -> Vec<TrackView<'_>> {
    frames
        .iter()
        .map(|f| TrackView {
            cam: &f.cam,
            time: f.time,
            image: &f.image,
            id_map: &f.id_map,
            background: Some(&f.ground),
        })
        .collect()
}

fn config() -> ObjectsConfig {
    ObjectsConfig {
        lift_thickness: vec![0.25],
        parts: 4,
        ..ObjectsConfig::default()
    }
}

/// The rigid fit and the split of the object seen in `frames`, lifted at its true depth.
fn track(
    frames: &[Frame],
    depth_at: [f32; 3],
) -> (
    Tracked,
    train::objects::parts::PartsEvidence,
    Option<Articulated>,
) {
    let cfg = config();
    let v = views(frames);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let image0 = frames[0].image.to_f32();
    let inp = train::objects::lift::LiftInput {
        cam: &frames[0].cam,
        image: &image0,
        id_map: &frames[0].id_map,
        id: 7,
        depth: frames[0].cam.to_camera(depth_at)[2],
    };
    let mut lift_rng = rand_chacha::ChaCha8Rng::seed_from_u64(6);
    let mut lift = |th: f32| train::objects::lift::lift(&inp, cfg.lift_points, th, &mut lift_rng);
    let tracked = fit(&v, 7, "object", &mut lift, &cfg, &mut rng).unwrap();
    let (e, a) = split(&v, 7, "object", &tracked, &cfg, &mut rng)
        .unwrap()
        .expect("parts > 1");
    (tracked, e, a)
}

/// The share of `part`'s Gaussians that frame 0 shows on the pixels `on` (an ID map
/// with 7 there): which true part a recovered one lies on, whatever its depth.
fn share_on(part: &Part, frame: &Frame, on: &[u8]) -> f32 {
    let p0 = part.trajectory.pose(frame.time);
    let w = frame.cam.width as usize;
    let hits = part
        .model
        .means
        .chunks(3)
        .filter(|x| {
            let Some((px, _)) = frame.cam.project(p0.apply([x[0], x[1], x[2]])) else {
                return false;
            };
            let (i, j) = (px[1] as usize, px[0] as usize);
            j < w && i < on.len() / w && on[i * w + j] == 7
        })
        .count();
    hits as f32 / part.model.len().max(1) as f32
}

/// IoU of two ID maps' pixels of 7.
fn iou(a: &[u8], b: &[u8]) -> f32 {
    let both = a
        .iter()
        .zip(b)
        .filter(|(x, y)| **x == 7 && **y == 7)
        .count();
    let either = a
        .iter()
        .zip(b)
        .filter(|(x, y)| **x == 7 || **y == 7)
        .count();
    both as f32 / either.max(1) as f32
}

/// Median over the frames of the IoU between `part` rendered alone and the true part
/// rendered alone (`truth(t)` its pose), with the part on its recovered trajectory and, for
/// comparison, held at its first pose: a part that follows its true motion keeps covering
/// it; one that stands still loses it as the true part moves away.
fn follow_iou(
    raster: &mut Rasterizer,
    part: &Part,
    truth: (&GaussianModel, &dyn Fn(f32) -> Pose),
    times: &[f32],
) -> (f32, f32) {
    let mut ious = (Vec::new(), Vec::new());
    let p0 = part.trajectory.pose(times[0]);
    for &t in times {
        let want = render_frame(raster, camera(t), t, &[(truth.0, truth.1(t))], 7).id_map;
        let ours = render_frame(
            raster,
            camera(t),
            t,
            &[(&part.model, part.trajectory.pose(t))],
            7,
        );
        let held = render_frame(raster, camera(t), t, &[(&part.model, p0)], 7);
        ious.0.push(iou(&ours.id_map, &want));
        ious.1.push(iou(&held.id_map, &want));
    }
    let median = |mut v: Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    (median(ious.0), median(ious.1))
}

#[test]
fn a_hinged_arm_becomes_a_part_that_follows_its_swing() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let base = checkered_box([0.2, 0.15, 0.08], [0.0, 0.0, 0.08], 1500, &mut rng);
    let arm = checkered_box([0.22, 0.04, 0.04], [0.22, 0.0, 0.0], 800, &mut rng);
    let still = pose([0.0; 3], 0.0);
    let mut raster = Rasterizer::new();
    let frames: Vec<Frame> = (0..FRAMES)
        .map(|i| {
            let t = i as f32 / (FRAMES - 1) as f32;
            let parts: [(&GaussianModel, Pose); 2] = [(&base, still), (&arm, arm_pose(t))];
            render_frame(&mut raster, camera(t), t, &parts, 7)
        })
        .collect();
    let (rigid, e, a) = track(&frames, [0.0, 0.0, 0.1]);
    eprintln!("rigid IoU {:.3}, {e:?}", rigid.mask_iou);
    let a = a.expect("the parts explain the views better than one rigid body");
    assert!(e.parts >= 2, "{e:?}");
    let times: Vec<f32> = frames.iter().map(|f| f.time).collect();
    // Which pixels of frame 0 each true part covers, seen alone.
    let mut alone = |m: &GaussianModel, p: Pose| {
        render_frame(&mut raster, camera(0.0), 0.0, &[(m, p)], 7).id_map
    };
    let (on_base, on_arm) = (alone(&base, still), alone(&arm, arm_pose(0.0)));
    let lies_on = |on: &[u8]| {
        let share = |p: &Part| share_on(p, &frames[0], on);
        let best = a.parts.iter().max_by(|x, y| share(x).total_cmp(&share(y)));
        best.expect("parts")
    };
    let (arm_part, base_part) = (lies_on(&on_arm), lies_on(&on_base));
    let shares = (
        share_on(arm_part, &frames[0], &on_arm),
        share_on(base_part, &frames[0], &on_base),
    );
    assert!(
        shares.0 > 0.6 && shares.1 > 0.6,
        "parts on arm / base: {shares:?}"
    );
    assert!(!std::ptr::eq(arm_part, base_part), "one part for both");
    let arm_truth = |t: f32| arm_pose(t);
    let (ours, held) = follow_iou(&mut raster, arm_part, (&arm, &arm_truth), &times);
    eprintln!("the arm's part covers the arm with median IoU {ours:.3} ({held:.3} held still)");
    assert!(
        ours > 0.6 && ours > held + 0.2,
        "arm IoU {ours} ({held} held still)"
    );
    let (ours, _) = follow_iou(&mut raster, base_part, (&base, &|_| still), &times);
    eprintln!("the base's part covers the base with median IoU {ours:.3}");
    assert!(ours > 0.6, "base IoU {ours}");
}

#[test]
fn a_box_that_moves_as_one_stays_one_rigid_body() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let obj = checkered_box([0.25, 0.15, 0.1], [0.0; 3], 2300, &mut rng);
    let mut raster = Rasterizer::new();
    let path = |t: f32| {
        pose(
            [-0.4 + 0.8 * t, 0.2 * (std::f32::consts::PI * t).sin(), 0.1],
            60.0 * t,
        )
    };
    let frames: Vec<Frame> = (0..FRAMES)
        .map(|i| {
            let t = i as f32 / (FRAMES - 1) as f32;
            render_frame(&mut raster, camera(t), t, &[(&obj, path(t))], 7)
        })
        .collect();
    let (_, e, a) = track(&frames, path(0.0).p);
    eprintln!("{e:?}");
    assert!(a.is_none() && !e.kept, "{e:?}");
}
