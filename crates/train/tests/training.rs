//! End-to-end training on a generated tiny toycars scene: PSNR rises, a stopped and resumed
//! run ends bit-identical to an uninterrupted one, checkpoints round-trip.

mod common;

use train::field_node::FieldNode;
use train::objects::start::StartReport;
use train::objects::{ObjectsConfig, RigidObjects};
use train::{checkpoint, Trainer};

fn train_psnr(tr: &mut Trainer) -> f64 {
    let frames = tr.dataset.train.clone();
    let mut r = train::render::Renderer::default();
    let bg = tr.dataset.background;
    let scene = train::render::Scene {
        model: &tr.state.model,
        column: &tr.state.object,
        aux: &tr.state.aux,
        nodes: &mut tr.nodes,
        iteration: tr.iteration,
    };
    r.evaluate(scene, &frames, bg, None).unwrap().mean.psnr
}

fn field(t: &Trainer) -> &FieldNode {
    t.nodes.get::<FieldNode>().expect("every run has a field")
}

/// 300 iterations of the rescaled 40k schedule (field from 23, densification 4..113)
/// must gain at least 6 dB of training PSNR over the random init.
#[test]
fn short_training_raises_psnr() {
    let mut tr = Trainer::new(common::small_config(300), common::dataset(), 7).unwrap();
    let before = train_psnr(&mut tr);
    let mut densified = false;
    for _ in 0..300 {
        let s = tr.step().unwrap();
        densified |= s.densify.is_some_and(|d| d.cloned + d.split > 0);
    }
    let after = train_psnr(&mut tr);
    assert!(densified, "densification never added Gaussians");
    assert!(after > before + 6.0, "PSNR {before:.2} → {after:.2}");
    assert!(tr.state.is_aligned());
}

/// Stop at 40 (during densification, field active), save, reload, finish: every parameter,
/// moment and the field must equal the uninterrupted run bit for bit. The uninterrupted run
/// uses 2 rayon threads and the interrupted one 3: results must not depend on the thread
/// count either (`splat` sums each Gaussian's gradient over its tiles in a fixed order).
#[test]
fn resume_equals_uninterrupted() {
    resume_check_with(common::small_config(80));
}

/// The small schedule with MCMC density control: a cap just above the 4,000-point init,
/// so both relocation and growth happen within a few refinements.
fn mcmc_config(iters: u32) -> train::TrainConfig {
    let mut c = common::small_config(iters);
    c.densify.strategy = train::densify::Strategy::Mcmc;
    c.densify.mcmc.until = c.densify.until;
    c.densify.mcmc.cap = 4500;
    c.validate().unwrap();
    c
}

/// MCMC density control trains (≥ 5 dB over the init in 300 iterations; from its recipe's
/// init, a tenth of the 3DGS size, measured 11.0 → 16.5 dB), never holds more than its
/// cap, and both moves dead Gaussians and adds new ones.
#[test]
fn mcmc_training_raises_psnr_within_the_cap() {
    let cfg = mcmc_config(300);
    let cap = cfg.densify.mcmc.cap;
    let mut tr = Trainer::new(cfg, common::dataset(), 7).unwrap();
    let before = train_psnr(&mut tr);
    let (mut relocated, mut added) = (0, 0);
    for _ in 0..300 {
        let s = tr.step().unwrap();
        assert!(s.num_gaussians <= cap, "{} > cap {cap}", s.num_gaussians);
        if let Some(d) = s.densify {
            assert_eq!(
                d.cloned + d.split + d.pruned,
                0,
                "MCMC neither clones nor prunes"
            );
            (relocated, added) = (relocated + d.relocated, added + d.added);
        }
    }
    let after = train_psnr(&mut tr);
    assert_eq!(tr.state.len(), cap, "grown to the cap");
    assert!(
        relocated > 0 && added > 0,
        "relocated {relocated}, added {added}"
    );
    assert!(after > before + 5.0, "PSNR {before:.2} → {after:.2}");
    assert!(tr.state.is_aligned());
}

/// MCMC's noise and draws come from the run's RNG and a counter-based generator: a stopped
/// and resumed run ends bit-identical, on another thread count.
#[test]
fn mcmc_resume_equals_uninterrupted() {
    resume_check_with(mcmc_config(80));
}

fn resume_check_with(cfg: train::TrainConfig) {
    let pool = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let a = pool(2).install(|| {
        let mut a = Trainer::new(cfg.clone(), common::dataset(), 3).unwrap();
        for _ in 0..80 {
            a.step().unwrap();
        }
        a
    });
    pool(3).install(|| resume_and_compare(cfg, &a));
}

fn resume_and_compare(cfg: train::TrainConfig, a: &Trainer) {
    let mut b = Trainer::new(cfg, common::dataset(), 3).unwrap();
    for _ in 0..40 {
        b.step().unwrap();
    }
    let run = tempfile::tempdir().unwrap();
    let dir = checkpoint::save(&b, run.path()).unwrap();
    assert_eq!(checkpoint::latest(run.path()).unwrap(), dir);
    drop(b);
    let mut c = checkpoint::load_trainer(&dir, common::dataset()).unwrap();
    assert_eq!(c.iteration, 40);
    for _ in 0..40 {
        c.step().unwrap();
    }
    assert_bit_equal(a, &c);
}

/// Every parameter, moment, hook row and the field, bit for bit.
fn assert_bit_equal(a: &Trainer, c: &Trainer) {
    assert_eq!(a.state.len(), c.state.len(), "Gaussian counts differ");
    let named = |t: &Trainer| -> Vec<(String, Vec<f32>)> {
        let mut v: Vec<(String, Vec<f32>)> = ["means", "quats", "log_scales", "opacity", "sh"]
            .iter()
            .zip(t.state.model.arrays())
            .map(|(n, a)| (n.to_string(), a.clone()))
            .collect();
        for (g, ad) in t.state.adam.iter().enumerate() {
            v.push((format!("adam{g}.m"), ad.m.clone()));
            v.push((format!("adam{g}.v"), ad.v.clone()));
        }
        v.push(("stats.grad_accum".into(), t.state.stats.grad_accum.clone()));
        v.push(("field".into(), field(t).field.mlp.params.clone()));
        v.push(("field.adam.m".into(), field(t).adam.m.clone()));
        for r in &t.state.aux {
            v.push((format!("aux.{}", r.name), r.data.clone()));
        }
        v
    };
    let (x, y) = (named(a), named(c));
    assert_eq!(x.len(), y.len(), "hook rows differ");
    for ((name, x), (_, y)) in x.into_iter().zip(y) {
        let first = x
            .iter()
            .zip(&y)
            .position(|(p, q)| p.to_bits() != q.to_bits());
        assert!(first.is_none(), "{name} differs first at {first:?}");
    }
    assert_eq!(a.state.model.sh_degree, c.state.model.sh_degree);
    assert_eq!(field(a).adam.step, field(c).adam.step);
}

/// The tiny scene with its ground-truth instance masks as object-ID maps (what
/// `semdynreg segment --masks gt --labels gt` writes: the same IDs, 255 = background).
fn scene_with_id_maps() -> scene::Dataset {
    // Once per process: the tests run in parallel on the shared scene, and a copy in
    // progress would hand another test a truncated ID map.
    static COPIED: std::sync::OnceLock<()> = std::sync::OnceLock::new();
    let ds = common::dataset();
    COPIED.get_or_init(|| {
        let root = common::tiny_scene();
        for f in &ds.train {
            let dst = ds.semantics_path(f);
            std::fs::create_dir_all(dst.parent().unwrap()).unwrap();
            std::fs::copy(scene::mask_path(&root, &f.file_path), dst).unwrap();
        }
    });
    ds
}

/// Persistent membership keeps per-Gaussian votes in the trainer's hook rows: they are
/// densified with the Gaussians, saved in checkpoints, and a run stopped and resumed (with a
/// fresh hook) ends bit-identical to an uninterrupted one.
#[test]
fn persistent_membership_votes_survive_densify_and_resume() {
    use train::regularizer::{Membership, SemanticHook, VOTES_NAME};
    let mut cfg = common::small_config(80);
    cfg.reg.enabled = true;
    cfg.reg.membership = Membership::Persistent;
    (cfg.reg.start_iter, cfg.reg.end_iter) = (25, 80);
    (cfg.reg.lambda, cfg.reg.tau_d, cfg.reg.persist_min_weight) = (1.0, 0.0, 0.05);
    let ds = scene_with_id_maps();
    let run_steps = |t: &mut Trainer, n: usize, max_persistent: &mut u32| {
        let mut hook = SemanticHook::load(t.cfg.reg.clone(), &t.dataset).unwrap();
        for _ in 0..n {
            t.step_with(Some(&mut hook)).unwrap();
            let p = hook.stats().iter().map(|s| s.persistent).max().unwrap_or(0);
            *max_persistent = (*max_persistent).max(p);
        }
    };
    let mut persistent = 0;
    let mut a = Trainer::new(cfg.clone(), ds.clone(), 5).unwrap();
    run_steps(&mut a, 80, &mut persistent);
    let votes = &a.state.aux.iter().find(|r| r.name == VOTES_NAME).unwrap();
    assert!(votes.data.iter().any(|&v| v > 0.0), "no votes recorded");
    assert!(
        persistent > 0,
        "no Gaussian ever became a persistent member"
    );
    assert!(a.state.is_aligned());

    let mut b = Trainer::new(cfg, ds.clone(), 5).unwrap();
    run_steps(&mut b, 50, &mut 0);
    b.train_seconds = 12.5;
    let run = tempfile::tempdir().unwrap();
    let dir = checkpoint::save(&b, run.path()).unwrap();
    drop(b);
    let mut c = checkpoint::load_trainer(&dir, ds).unwrap();
    assert_eq!(
        c.train_seconds, 12.5,
        "training time is carried across a resume"
    );
    run_steps(&mut c, 30, &mut 0);
    assert_bit_equal(&a, &c);
}

/// A SemDynReg run forked from the baseline's checkpoint just before the regularizer's start
/// ends bit-identical to one trained from scratch (persistent membership, so hook rows are
/// created after the fork). Checkpoint pruning keeps the fork point, and a checkpoint past
/// the start is refused with a message that says why.
#[test]
fn fork_at_the_regularizer_start_equals_training_from_scratch() {
    use train::regularizer::{Membership, SemanticHook};
    let mut cfg = common::small_config(80);
    cfg.reg.membership = Membership::Persistent;
    (cfg.reg.start_iter, cfg.reg.end_iter) = (25, 80);
    (cfg.reg.lambda, cfg.reg.tau_d, cfg.reg.persist_min_weight) = (1.0, 0.0, 0.05);
    cfg.log.keep_checkpoints = 1;
    let ds = scene_with_id_maps();
    let mut reg_cfg = cfg.clone();
    reg_cfg.reg.enabled = true;
    let with_hook = |t: &mut Trainer, n: usize| {
        let mut hook = SemanticHook::load(t.cfg.reg.clone(), &t.dataset).unwrap();
        for _ in 0..n {
            t.step_with(Some(&mut hook)).unwrap();
        }
    };
    let mut scratch = Trainer::new(reg_cfg.clone(), ds.clone(), 9).unwrap();
    with_hook(&mut scratch, 80);

    let run = tempfile::tempdir().unwrap();
    let mut base = Trainer::new(cfg, ds.clone(), 9).unwrap();
    for target in [24, 30] {
        while base.iteration < target {
            base.step().unwrap();
        }
        checkpoint::save(&base, run.path()).unwrap();
    }
    let (it, dir) = train::fork::checkpoint_at_or_before(run.path(), 24)
        .unwrap()
        .expect("the fork point survives pruning");
    assert_eq!(it, 24);
    let late = run.path().join("checkpoints/iter_0000030");
    let err = train::fork::load_fork(&late, ds.clone(), reg_cfg.clone())
        .err()
        .expect("a checkpoint past the start cannot be forked")
        .to_string();
    assert!(
        err.contains("iter_0000030") && err.contains("starts at 25"),
        "{err}"
    );

    let mut forked = train::fork::load_fork(&dir, ds, reg_cfg).unwrap();
    assert!(forked.cfg.reg.enabled);
    with_hook(&mut forked, 56);
    assert_bit_equal(&scratch, &forked);
    // The regularizer mattered: the baseline, continued to 80, ends elsewhere.
    while base.iteration < 80 {
        base.step().unwrap();
    }
    assert_ne!(
        field(&base).field.mlp.params,
        field(&scratch).field.mlp.params
    );
}

/// A point cloud with colours (3DGS `fetchPly`) starts each Gaussian at its point's colour:
/// SH DC = RGB2SH(colour); without colours the start is grey.
#[test]
fn point_cloud_colours_initialize_sh_dc() {
    let mut ds = common::dataset();
    let pts = vec![
        [0.0, 0.0, 0.0],
        [0.1, 0.2, 0.0],
        [-0.2, 0.1, 0.05],
        [0.3, -0.1, 0.1],
    ];
    let rgb = vec![
        [1.0, 0.0, 0.2],
        [0.0, 1.0, 0.4],
        [0.5, 0.5, 0.5],
        [0.25, 0.75, 1.0],
    ];
    ds.point_cloud = Some(pts.clone());
    ds.point_colors = Some(rgb.clone());
    let mut cfg = common::small_config(10);
    cfg.init.use_point_cloud = true;
    let tr = Trainer::new(cfg.clone(), ds.clone(), 0).unwrap();
    let m = tr.model();
    assert_eq!(m.means.len(), 12);
    let stride = m.sh.len() / pts.len();
    for (i, c) in rgb.iter().enumerate() {
        for (k, &ck) in c.iter().enumerate() {
            let want = (ck - 0.5) / train::init::SH_C0;
            assert!(
                (m.sh[i * stride + k] - want).abs() < 1e-6,
                "point {i} channel {k}"
            );
        }
    }
    ds.point_colors = None;
    let tr = Trainer::new(cfg, ds, 0).unwrap();
    assert!(
        tr.model().sh.iter().step_by(stride).all(|&v| v == 0.0),
        "grey start"
    );
}

/// An 80-iteration run whose objects start at iteration 20 with a small, quick track,
/// after `tweak` changes the objects' settings.
fn objects_config(tweak: impl FnOnce(&mut ObjectsConfig)) -> train::TrainConfig {
    let mut cfg = common::small_config(80);
    cfg.objects.enabled = true;
    // At iteration 20 exactly: three passes over the 18 training views would be 54.
    (cfg.objects.start_iter, cfg.objects.min_start_passes) = (20, 0.0);
    (cfg.objects.lift_points, cfg.objects.lift_thickness) = (300, vec![0.25]);
    (cfg.objects.track_pose_iters, cfg.objects.track_shape_iters) = (5, 2);
    cfg.objects.track_refine_iters = 20;
    tweak(&mut cfg.objects);
    cfg.validate().unwrap();
    cfg
}

/// `iters` iterations of `cfg` on `ds` from seed 7.
fn trained(cfg: &train::TrainConfig, ds: &scene::Dataset, iters: u32) -> Trainer {
    let mut t = Trainer::new(cfg.clone(), ds.clone(), 7).unwrap();
    for _ in 0..iters {
        t.step().unwrap();
    }
    t
}

/// 40 iterations, a checkpoint, then 40 more from the loaded checkpoint.
fn stopped_and_resumed(cfg: &train::TrainConfig, ds: &scene::Dataset) -> Trainer {
    let b = trained(cfg, ds, 40);
    let run = tempfile::tempdir().unwrap();
    let dir = checkpoint::save(&b, run.path()).unwrap();
    drop(b);
    let mut c = checkpoint::load_trainer(&dir, ds.clone()).unwrap();
    for _ in 0..40 {
        c.step().unwrap();
    }
    c
}

/// Rigid objects (`objects`): a run stopped after the objects' start (during densification,
/// with votes transferring Gaussians) and resumed ends bit-identical to an uninterrupted
/// one: object column, trajectories and their moments included.
#[test]
fn rigid_objects_survive_densify_and_resume() {
    let cfg = objects_config(|_| {});
    let ds = scene_with_id_maps();
    let a = trained(&cfg, &ds, 80);
    let node = a.nodes.get::<RigidObjects>().expect("objects started");
    assert_eq!(node.objects.len(), 3, "one rigid body per vehicle");
    let owned = |t: &Trainer| t.state.object.iter().filter(|&&o| o != 255).count();
    assert!(owned(&a) > 0, "object Gaussians survive densification");
    assert!(a.state.is_aligned());

    let c = stopped_and_resumed(&cfg, &ds);
    assert_bit_equal(&a, &c);
    assert_eq!(a.state.object, c.state.object, "object column");
    let poses = |t: &Trainer| -> Vec<u32> {
        let node = t.nodes.get::<RigidObjects>().unwrap();
        node.objects
            .iter()
            .flat_map(|o| {
                o.trajectory
                    .translations
                    .iter()
                    .flatten()
                    .chain(o.trajectory.rotations.iter().flatten())
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    assert_eq!(poses(&a), poses(&c), "trajectories");
    // The start's report (decisions, the gauge's cues and confidence) is kept in the
    // checkpoint, so evaluation after a resume still reports it.
    let reports = |t: &Trainer| t.nodes.get::<RigidObjects>().unwrap().start_reports.clone();
    assert_eq!(reports(&c).len(), 3);
    assert_eq!(reports(&a), reports(&c), "start reports");
    for r in reports(&c).iter().filter(|r| !r.is_static) {
        let g = r.gauge.expect("a mover's gauge is chosen from its cues");
        assert!(
            (0.0..=1.0).contains(&g.confidence) && g.ln_factor == 0.0,
            "{g:?}"
        );
    }
}

/// Objects taken over from the deformation field (`source = "field"`): nothing is masked
/// out of the field's gradient before the take-over, which then gives every object's
/// member rows to its bodies without changing how many rows there are, logs both fits in
/// the start report, and a run stopped after it resumes bit-identically.
#[test]
fn objects_taken_over_from_the_field_survive_densify_and_resume() {
    let cfg = objects_config(|o| {
        o.source = train::objects::ObjectSource::Field;
        o.field_start_iter = 30;
        o.parts = 2;
    });
    let ds = scene_with_id_maps();
    let before = trained(&cfg, &ds, 29);
    assert!(
        before.state.object.iter().all(|&o| o == 255),
        "no object before the take-over"
    );
    let rows_before = before.state.len();
    drop(before);
    let a = trained(&cfg, &ds, 30);
    assert_eq!(a.state.len(), rows_before, "the take-over adds no rows");
    let node = a.nodes.get::<RigidObjects>().expect("objects started");
    assert!(node.started);
    let reports = &node.start_reports;
    assert_eq!(reports.len(), 3, "one report per vehicle: {reports:?}");
    assert!(
        reports.iter().filter(|r| !r.left_to_field).count() >= 2,
        "{reports:?}"
    );
    for r in reports {
        let Some(p) = r.parts else {
            assert!(
                r.left_to_field && r.gaussians == 0,
                "no fit, no take-over: {r:?}"
            );
            continue;
        };
        assert!(
            p.loss_rigid.is_finite() && p.loss_parts.is_finite(),
            "{r:?}"
        );
        assert!(p.loss_parts <= p.loss_rigid + 1e-6, "{r:?}");
        let owned = a
            .state
            .object
            .iter()
            .filter(|&&o| node.objects.iter().any(|b| b.id == o && b.mask == r.id))
            .count();
        assert_eq!(owned == 0, r.left_to_field, "{r:?}: {owned} rows");
    }
    assert!(a.state.is_aligned());
    let a = trained(&cfg, &ds, 80);
    let c = stopped_and_resumed(&cfg, &ds);
    assert_bit_equal(&a, &c);
    assert_eq!(a.state.object, c.state.object, "object column");
    let reports =
        |t: &Trainer| format!("{:?}", t.nodes.get::<RigidObjects>().unwrap().start_reports);
    assert_eq!(reports(&a), reports(&c), "start reports");
}

/// Objects with a residual field (`[objects] residual`): one field per object of the ID
/// maps, started at δ = 0 and learning from there; a run stopped after the start resumes
/// bit-identically, the fields' weights and Adam state included.
#[test]
fn objects_with_a_residual_field_learn_it_and_resume() {
    let cfg = objects_config(|o| o.residual = true);
    let ds = scene_with_id_maps();
    let a = trained(&cfg, &ds, 80);
    let node = a.nodes.get::<RigidObjects>().expect("objects started");
    let residual = node.residual.as_ref().expect("a residual node");
    let mut masks: Vec<u8> = residual.fields.iter().map(|f| f.mask).collect();
    masks.sort_unstable();
    let mut objects: Vec<u8> = node.objects.iter().map(|o| o.mask).collect();
    objects.sort_unstable();
    objects.dedup();
    assert_eq!(masks, objects, "one field per object");
    for f in &residual.fields {
        let head = f.field.mlp.head_range();
        let learned = f.field.mlp.params[head].iter().any(|&p| p != 0.0);
        assert!(learned, "object {}: the head left zero", f.mask);
        assert!(f.adam.step > 0);
    }
    let c = stopped_and_resumed(&cfg, &ds);
    assert_bit_equal(&a, &c);
    let fields = |t: &Trainer| {
        let r = t
            .nodes
            .get::<RigidObjects>()
            .unwrap()
            .residual
            .as_ref()
            .unwrap();
        let f = r.fields.iter();
        f.map(|f| (f.mask, f.field.mlp.params.clone(), f.adam.clone()))
            .collect::<Vec<_>>()
    };
    assert!(fields(&a) == fields(&c), "residual fields after resuming");
}

/// The start reports of a short run of [`objects_config`] with `tweak` (25 iterations).
fn start_reports(tweak: impl FnOnce(&mut ObjectsConfig)) -> Vec<StartReport> {
    let t = trained(&objects_config(tweak), &scene_with_id_maps(), 25);
    t.nodes
        .get::<RigidObjects>()
        .expect("objects started")
        .start_reports
        .clone()
}

/// `min_scale_confidence = 1` asks every cue to agree with a mover's gauge; a mover whose
/// cues do not is left to the deformation field (no Gaussians, no trajectory), and the
/// start's report says so.
#[test]
fn a_mover_without_an_agreed_depth_is_left_to_the_field() {
    let reports = start_reports(|o| o.min_scale_confidence = 1.0);
    assert_eq!(reports.len(), 3, "every object reported");
    for r in &reports {
        let doubted = !r.is_static && r.gauge.is_some_and(|g| g.confidence < 1.0);
        assert_eq!(r.left_to_field, doubted, "{r:?}");
        assert_eq!(r.gaussians == 0, doubted, "{r:?}");
    }
}

/// `min_rigid_iou` holds still objects to the same test as movers: an object whose one
/// rigid shape (under one pose or under its track) covers its masks below it is left to
/// the deformation field, still or moving, and the start's report says so.
#[test]
fn an_object_its_rigid_fit_does_not_cover_is_left_to_the_field_still_or_moving() {
    let reports = start_reports(|o| {
        o.min_rigid_iou = 0.9;
        // A static test that passes any finite motion and does not check the overlap: the
        // tiny scene's movers are held still, and one pose covers their masks badly.
        (o.static_image_motion, o.static_motion) = (1e6, 1e6);
        (o.static_ring_tolerance, o.static_iou_drop) = (1e6, 1.0);
    });
    assert_eq!(reports.len(), 3, "every object reported");
    assert!(
        reports.iter().any(|r| r.is_static && r.left_to_field),
        "a still pose that covers a mover's masks badly goes to the field: {reports:?}"
    );
    for r in &reports {
        assert_eq!(r.left_to_field, r.mask_iou < 0.9, "{r:?}");
        assert_eq!(r.gaussians == 0, r.left_to_field, "{r:?}");
    }
}

/// `static_iou_drop`: an object the motion measures call still stays a mover when one pose
/// covers its masks worse than its track by more than the drop; the start's report keeps
/// both IoUs. Without the check (1) the same objects are held still, with the same
/// evidence.
#[test]
fn holding_still_must_not_cost_the_masks_overlap() {
    let reports = |drop: f32| {
        start_reports(|o| {
            // Motion measures that call any finite motion still: the tiny scene's movers
            // reach the IoU check.
            (o.static_image_motion, o.static_motion) = (1e6, 1e6);
            (o.static_ring_tolerance, o.static_iou_drop) = (1e6, drop);
        })
    };
    let (checked, unchecked) = (reports(0.02), reports(1.0));
    let mut kept_moving = 0;
    for (r, u) in checked.iter().zip(&unchecked) {
        let (Some(tracked), Some(still)) = (r.still.iou_tracked, r.still.iou_still) else {
            assert!(!r.is_static, "a still object has both IoUs: {r:?}");
            continue;
        };
        assert_eq!(r.is_static, tracked - still <= 0.02, "{r:?}");
        assert!(u.is_static, "{u:?}");
        assert_eq!(
            (u.still.iou_tracked, u.still.iou_still),
            (Some(tracked), Some(still))
        );
        kept_moving += usize::from(!r.is_static);
    }
    assert!(
        kept_moving > 0,
        "a mover held still loses overlap: {checked:?}"
    );
}

/// Articulated objects in training: vehicles forced into two parts each (no merging, no
/// gain required) get skinning rows; a run stopped and resumed ends bit-identical to an
/// uninterrupted one (logits and their moments ride in the store's rows), the columns
/// stay on their objects' parts, and the checkpoint renders what the trainer renders.
#[test]
fn skinned_parts_survive_densify_resume_and_render_from_a_checkpoint() {
    let cfg = objects_config(|o| {
        (o.parts, o.parts_merge, o.parts_min_gain) = (2, 0.0, 0.0);
        o.arap_weight = 0.1;
    });
    let ds = scene_with_id_maps();
    let a = trained(&cfg, &ds, 80);
    let node = a.nodes.get::<RigidObjects>().expect("objects started");
    let groups = train::objects::parts::skin::groups(&node.objects);
    assert!(
        !groups.is_empty(),
        "some vehicle kept two parts: {:?}",
        node.start_reports
    );
    let skin = train::objects::parts::skin::rows_of(&a.state.aux).expect("skinning rows");
    assert_eq!(skin.cols, 6, "two logits and their moments");
    let ids: Vec<u8> = node.objects.iter().map(|o| o.id).collect();
    assert!(a.state.object.iter().all(|c| *c == 255 || ids.contains(c)));
    assert!(a.state.is_aligned());

    let mut c = stopped_and_resumed(&cfg, &ds);
    assert_bit_equal(&a, &c);
    assert_eq!(a.state.object, c.state.object, "object column");

    let run = tempfile::tempdir().unwrap();
    let dir = checkpoint::save(&c, run.path()).unwrap();
    let mut loaded = checkpoint::load_model(&dir).unwrap();
    let f = &ds.test[0];
    let mut r = train::render::Renderer::default();
    let scene = train::render::Scene {
        model: &c.state.model,
        column: &c.state.object,
        aux: &c.state.aux,
        nodes: &mut c.nodes,
        iteration: c.iteration,
    };
    let want = r.render(scene, &f.camera, f.time, ds.background).unwrap();
    let got = r
        .render(loaded.scene(), &f.camera, f.time, ds.background)
        .unwrap();
    assert_eq!(want, got, "checkpoint render equals the trainer's");
}
