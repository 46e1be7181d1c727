//! The rigid objects' start (lift, track, gauge) on a scene with ground-truth poses: how
//! much of each object's true motion its recovered trajectory follows (docs/objects.md,
//! "The start alone"). A diagnostic, not a pass/fail test: it prints, per object, whether it
//! was found static, the follow of its trajectory, the follow under the best common factor
//! (what a perfect gauge would give), and per-knot errors.
//!
//! `OBJECTS_SCENE=DIR` (a toycars scene with `semantics/` made by `semdynreg segment DIR
//! --masks gt --labels gt`), optionally `OBJECTS_ITERS` (the schedule, default 3000),
//! `OBJECTS_POINTS` (random init, default 20000), `OBJECTS_START` (start iteration),
//! `OBJECTS_SH`, `OBJECTS_THICK=a,b,c`, `OBJECTS_CONTACT`, `OBJECTS_POSE`/`SHAPE`/`REFINE`
//! (tracking iterations), `OBJECTS_CHECKPOINT=DIR` (start from a checkpoint),
//! `OBJECTS_DEPTH_CHECK=1` (rendered vs true ground depth behind each mask; with
//! `OBJECTS_EXPECTED_DEPTH=1` the alpha-weighted mean depth instead):
//! `cargo test --release -p train --test objects_start -- --ignored --nocapture`

use scene::objects::ObjectsFile;
use train::objects::truth::{follow, inv_apply};
use train::objects::RigidObject;
use train::{TrainConfig, Trainer};

fn env<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Per knot: the true and recovered rotation since the first knot, and how far the
/// Gaussians' centroid is from where the true motion puts it.
fn report_knots(o: &RigidObject, x: &[[f32; 3]], gt: &ObjectsFile, index: usize) {
    let n = x.len() as f32;
    let c: [f32; 3] = std::array::from_fn(|k| x.iter().map(|p| p[k]).sum::<f32>() / n);
    let trj = &o.trajectory;
    let pose_at = |t: f32| {
        gt.frames
            .iter()
            .min_by(|a, b| (a.time - t).abs().total_cmp(&(b.time - t).abs()))
            .map(|f| f.object_to_world[index])
            .unwrap()
    };
    let (p0, g0) = (trj.pose(trj.times[0]), pose_at(trj.times[0]));
    for k in (0..trj.len()).step_by(6) {
        let t = trj.times[k];
        let (p, g) = (trj.pose(t), pose_at(t));
        let truth = scene::objects::apply(&g, inv_apply(&g0, p0.apply(c)));
        let ours = p.apply(c);
        let err = (0..3)
            .map(|i| (ours[i] - truth[i]).powi(2))
            .sum::<f32>()
            .sqrt();
        let moved = (0..3)
            .map(|i| (p0.apply(c)[i] - truth[i]).powi(2))
            .sum::<f32>()
            .sqrt();
        let yaw_gt = g[1][0].atan2(g[0][0]) - g0[1][0].atan2(g0[0][0]);
        let ang = train::quat::angle_between(p.q, p0.q);
        let bb = gt.objects[index].bbox_local;
        let mid: [f32; 3] = std::array::from_fn(|i| 0.5 * (bb[0][i] + bb[1][i]));
        let centre_gt = scene::objects::apply(&g, mid);
        let off = (0..3)
            .map(|i| (ours[i] - centre_gt[i]).powi(2))
            .sum::<f32>()
            .sqrt();
        eprintln!("     ours {ours:.3?} true centre {centre_gt:.3?} off {off:.3}");
        eprintln!(
            "  t {t:.3}: moved {moved:.3}, centroid error {err:.3}, true turn {:.1}°, ours {:.1}°",
            yaw_gt.to_degrees(),
            ang.to_degrees()
        );
    }
}

/// The background's rendered depth against the true ground (z = 0) behind each object's
/// mask, in a few training views.
fn depth_check(tr: &Trainer) {
    let node = tr.nodes.get::<train::objects::RigidObjects>().unwrap();
    let m = &tr.state.model;
    let mut d = train::deform::Deformed::default();
    train::deform::apply(m, None, &mut d);
    let mut raster = splat::Rasterizer::new();
    let nt = tr.dataset.train.len();
    for f in [0usize, nt / 4, nt / 2, 3 * nt / 4] {
        let frame = &tr.dataset.train[f];
        let cam = &frame.camera;
        let mut depth = train::objects::lift::render_depth(
            &mut raster,
            &d.means,
            &d.quats,
            &d.scales,
            &m.opacity_logits,
            cam,
        )
        .unwrap();
        if std::env::var("OBJECTS_EXPECTED_DEPTH").is_ok() {
            let z: Vec<f32> = d
                .means
                .chunks(3)
                .flat_map(|p| [cam.to_camera([p[0], p[1], p[2]])[2]; 3])
                .collect();
            let g = splat::Gaussians {
                means: &d.means,
                quats: &d.quats,
                scales: &d.scales,
                opacity_logits: &m.opacity_logits,
                colors: splat::Colors::Rgb(&z),
            };
            let out = raster
                .forward(&g, cam, &splat::RenderOptions::default())
                .unwrap();
            depth.depth = out
                .image
                .chunks(3)
                .zip(out.alpha)
                .map(|(c, &a)| if a > 0.5 { c[0] / a } else { f32::NAN })
                .collect();
        }
        let c = cam.center();
        for id in [0u8, 1, 2, 255] {
            let mut r = Vec::new();
            for (p, &v) in node.id_maps[f].iter().enumerate() {
                if v != id || !depth.depth[p].is_finite() {
                    continue;
                }
                let (x, y) = (
                    (p as u32 % cam.width) as f32 + 0.5,
                    (p as u32 / cam.width) as f32 + 0.5,
                );
                let far = train::objects::lift::unproject(cam, x, y, 1.0);
                let s = -c[2] / (far[2] - c[2]);
                let g = [c[0] + s * (far[0] - c[0]), c[1] + s * (far[1] - c[1])];
                if g[0].abs() < 1.2 && g[1].abs() < 1.2 {
                    r.push(depth.depth[p] / s);
                }
            }
            r.sort_by(f32::total_cmp);
            if r.is_empty() {
                continue;
            }
            let q = |f: f32| r[((r.len() - 1) as f32 * f) as usize];
            eprintln!("view {f} object {id}: rendered/true ground depth behind the mask: q10 {:.3} q50 {:.3} q90 {:.3} (n {})", q(0.1), q(0.5), q(0.9), r.len());
        }
    }
}

#[test]
#[ignore]
fn recovered_trajectories_follow_the_true_motion() {
    let Ok(dir) = std::env::var("OBJECTS_SCENE") else {
        eprintln!("set OBJECTS_SCENE to a toycars scene with semantics/");
        return;
    };
    let dir = std::path::PathBuf::from(dir);
    let ds = scene::load_dataset(&dir, &scene::LoadOptions::default()).unwrap();
    let gt = ObjectsFile::load(&dir.join("objects.json")).unwrap();
    let mut cfg = TrainConfig::default()
        .rescaled(env("OBJECTS_ITERS", 3000))
        .unwrap();
    cfg.init.random_points = env("OBJECTS_POINTS", 20_000);
    cfg.objects.enabled = true;
    cfg.sh.max_degree = env("OBJECTS_SH", cfg.sh.max_degree);
    if let Ok(v) = std::env::var("OBJECTS_THICK") {
        cfg.objects.lift_thickness = v.split(',').map(|t| t.parse().unwrap()).collect();
    }
    cfg.objects.contact_rounds = env("OBJECTS_CONTACT", cfg.objects.contact_rounds);
    cfg.objects.track_shape_iters = env("OBJECTS_SHAPE", cfg.objects.track_shape_iters);
    cfg.objects.track_refine_iters = env("OBJECTS_REFINE", cfg.objects.track_refine_iters);
    cfg.objects.track_pose_iters = env("OBJECTS_POSE", cfg.objects.track_pose_iters);
    if let Ok(v) = std::env::var("OBJECTS_START") {
        cfg.objects.start_iter = v.parse().unwrap();
    }
    let start = cfg.objects.start_iter;
    let mut tr = match std::env::var("OBJECTS_CHECKPOINT") {
        Ok(dir) => train::checkpoint::load_trainer(std::path::Path::new(&dir), ds).unwrap(),
        Err(_) => Trainer::new(cfg, ds, 0).unwrap(),
    };
    let t0 = std::time::Instant::now();
    while tr.iteration + 1 < start {
        tr.step().unwrap();
    }
    if std::env::var("OBJECTS_DEPTH_CHECK").is_ok() {
        depth_check(&tr);
    }
    tr.step().unwrap();
    eprintln!(
        "{} iterations + start in {:.1} s",
        start,
        t0.elapsed().as_secs_f64()
    );
    let node = tr.nodes.get::<train::objects::RigidObjects>().unwrap();
    {
        // Camera check: the true box of each object projected with the data set's camera,
        // against its mask's bounding box.
        let f = &tr.dataset.train[0];
        let fr = gt.frame(&f.file_path).unwrap();
        for (i, o) in gt.objects.iter().enumerate() {
            let bb = o.bbox_local;
            let mut lo = [f32::MAX; 2];
            let mut hi = [f32::MIN; 2];
            for c in 0..8 {
                let l = [bb[c & 1][0], bb[(c >> 1) & 1][1], bb[(c >> 2) & 1][2]];
                let w = scene::objects::apply(&fr.object_to_world[i], l);
                let (px, _) = f.camera.project(w).unwrap();
                for k in 0..2 {
                    lo[k] = lo[k].min(px[k]);
                    hi[k] = hi[k].max(px[k]);
                }
            }
            let (_, mb) = train::objects::lift::mask_pixels(&node.id_maps[0], f.camera.width, o.id);
            eprintln!(
                "{}: projected box x {:.1}..{:.1} y {:.1}..{:.1}; mask box x {}..{} y {}..{}",
                o.name, lo[0], hi[0], lo[1], hi[1], mb[0], mb[2], mb[1], mb[3]
            );
        }
    }
    for o in node.objects.iter().filter(|o| !o.is_static) {
        // The object's rendered depth against the true ground behind it, at a few views.
        let rows: Vec<usize> = (0..tr.state.len())
            .filter(|&i| tr.state.object[i] == o.id)
            .collect();
        let m = tr.state.model.gather(&rows);
        let mut raster = splat::Rasterizer::new();
        let nt = tr.dataset.train.len();
        for f in [0usize, nt / 3, 2 * nt / 3, nt - 1] {
            let frame = &tr.dataset.train[f];
            let one = std::slice::from_ref(o);
            let mut rows = Vec::new();
            train::objects::place::rows_by_object(one, &vec![o.id; m.len()], &mut rows);
            let mut d = train::deform::Deformed::default();
            train::deform::apply(&m, None, &mut d);
            train::objects::place::place(
                one,
                &rows,
                train::objects::place::Shape::of(&m),
                frame.time,
                &mut d,
                &mut Vec::new(),
            );
            let depth = train::objects::lift::render_depth(
                &mut raster,
                &d.means,
                &d.quats,
                &d.scales,
                &m.opacity_logits,
                &frame.camera,
            )
            .unwrap();
            let c = frame.camera.center();
            let mut r = Vec::new();
            for (p, &v) in node.id_maps[f].iter().enumerate() {
                if v != o.id || !depth.depth[p].is_finite() {
                    continue;
                }
                let cam = &frame.camera;
                let (x, y) = (
                    (p as u32 % cam.width) as f32 + 0.5,
                    (p as u32 / cam.width) as f32 + 0.5,
                );
                let far = train::objects::lift::unproject(cam, x, y, 1.0);
                let s = -c[2] / (far[2] - c[2]);
                r.push(s / depth.depth[p]);
            }
            r.sort_by(f32::total_cmp);
            if r.is_empty() {
                continue;
            }
            let q = |f: f32| r[((r.len() - 1) as f32 * f) as usize];
            eprintln!(
                "{} view {f} t {:.2}: true ground / object depth q03 {:.3} q50 {:.3} (n {})",
                o.name,
                frame.time,
                q(0.03),
                q(0.5),
                r.len()
            );
        }
    }
    for r in &node.start_reports {
        eprintln!("{r:?}");
    }
    for o in &node.objects {
        let rows: Vec<usize> = (0..tr.state.len())
            .filter(|&i| tr.state.object[i] == o.id)
            .collect();
        let x: Vec<[f32; 3]> = rows
            .iter()
            .map(|&i| std::array::from_fn(|c| tr.state.model.means[i * 3 + c]))
            .collect();
        let index = gt.objects.iter().position(|g| g.id == o.id).unwrap();
        let moving = gt.objects[index].moving;
        let f = follow(o, &x, &gt, index);
        if !o.is_static {
            let tr = &o.trajectory;
            for k in 0..4 {
                eprintln!(
                    "  knot {k} t {:.4} p {:.4?}",
                    tr.times[k], tr.translations[k]
                );
            }
            eprintln!("  t 0 → {:.4?}", tr.pose(0.0).p);
            let k = tr.len();
            for j in k - 3..k {
                eprintln!(
                    "  knot {j} t {:.4} p {:.4?}",
                    tr.times[j], tr.translations[j]
                );
            }
            eprintln!("  t 1 → {:.4?}", tr.pose(1.0).p);
        }
        if o.is_static {
            let pose = o.trajectory.pose(0.5);
            let n = x.len() as f32;
            let c: [f32; 3] = std::array::from_fn(|k| x.iter().map(|p| p[k]).sum::<f32>() / n);
            let w = pose.apply(c);
            let bb = gt.objects[index].bbox_local;
            let mid: [f32; 3] = std::array::from_fn(|i| 0.5 * (bb[0][i] + bb[1][i]));
            let truth = scene::objects::apply(&gt.frames[0].object_to_world[index], mid);
            eprintln!(
                "{:>14}: static centroid {w:.3?}, true centre {truth:.3?}",
                o.name
            );
        }
        let (d, a) = o.trajectory.motion_extent();
        if !o.is_static {
            // What the gauge could have done: follow under the best common factor.
            let centres: Vec<[f32; 3]> = o
                .trajectory
                .times
                .iter()
                .map(|&t| {
                    tr.dataset
                        .train
                        .iter()
                        .find(|f| f.time == t)
                        .unwrap()
                        .camera
                        .center()
                })
                .collect();
            let best = (0..=60)
                .map(|k| 0.5f32 * 4f32.powf(k as f32 / 60.0))
                .map(|s| {
                    let mut o2 = o.clone();
                    let mut m = train::model::GaussianModel {
                        means: x.iter().flatten().copied().collect(),
                        log_scales: vec![0.0; x.len() * 3],
                        ..Default::default()
                    };
                    train::objects::gauge::apply_scale(&mut m, &mut o2.trajectory, &centres, s);
                    let x2: Vec<[f32; 3]> = m.means.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                    (s, follow(&o2, &x2, &gt, index).unwrap_or(f64::NAN))
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            eprintln!(
                "{:>14}: best further gauge factor {:.3} → follow {:.1} %",
                o.name,
                best.0,
                100.0 * best.1
            );
            let mut o2 = o.clone();
            let mut m = train::model::GaussianModel {
                means: x.iter().flatten().copied().collect(),
                log_scales: vec![0.0; x.len() * 3],
                ..Default::default()
            };
            train::objects::gauge::apply_scale(&mut m, &mut o2.trajectory, &centres, best.0);
            let x2: Vec<[f32; 3]> = m.means.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
            report_knots(&o2, &x2, &gt, index);
        }
        eprintln!(
            "{:>14}: moving (truth) {moving}, static (ours) {}, {} Gaussians, knots {}, travel {d:.3}, turn {:.1}°, follow {}",
            o.name,
            o.is_static,
            x.len(),
            o.trajectory.len(),
            a.to_degrees(),
            f.map_or("n/a".into(), |v| format!("{:.1} %", 100.0 * v))
        );
    }
}
