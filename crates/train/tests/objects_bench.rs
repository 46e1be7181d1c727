//! A small subset of the objects benchmark (`examples/objects_bench.rs`, docs/objects.md):
//! generated scenes at a small size and a short schedule, ground-truth masks as ID maps,
//! the rigid objects' start scored against the truth (`train::objects::truth`). Every
//! object must get the right static/moving decision, and each mover a path of about the
//! right length.

use scene::toycars::{generate, ground_truth_id_maps, varied};
use train::objects::truth::Decision;
use train::TrainConfig;

/// The demo's schedule rescaled to `iters`, with fewer points and shorter tracking.
fn config(iters: u32) -> TrainConfig {
    let mut c = TrainConfig::for_run(None, Some(iters)).unwrap();
    c.init.random_points = 4000;
    c.objects.lift_points = 800;
    c.objects.track_refine_iters = 300;
    c
}

fn check_seed(seed: u64) {
    let dir = tempfile::tempdir().unwrap();
    let s = varied(seed, 96, 72, 40).unwrap();
    generate(&s.config, dir.path(), &|_, _| {}).unwrap();
    ground_truth_id_maps(dir.path()).unwrap();
    let scores = train::objects_bench::start_and_score(dir.path(), config(1200), 0).unwrap();
    eprintln!("seed {seed}: synth toycars {}", s.args.join(" "));
    for o in &scores {
        eprintln!(
            "  {}: truly moving {} ({:.2}), {:?}, path ratio {:?}, follow {:?}, depth ratio {:?}; \
             static test: motion {:?}, turn {:?}° moving its points {:?}, ring offset {:?}",
            o.name,
            o.truly_moving,
            o.true_path,
            o.decision,
            o.path_ratio,
            o.follow,
            o.depth_ratio,
            o.residual_motion,
            o.residual_angle_deg,
            o.residual_turn,
            o.ring_offset
        );
    }
    assert_eq!(
        scores.len(),
        s.config.adds.len() + 3,
        "one score per object"
    );
    for o in &scores {
        assert!(o.correct, "seed {seed}: {} called {:?}", o.name, o.decision);
        if o.decision == Decision::Moving {
            let r = o.path_ratio.expect("a mover has a path ratio");
            assert!(
                (0.7..1.4).contains(&r),
                "seed {seed}: {} path ×{r:.2}",
                o.name
            );
        }
    }
}

/// Two parked cars, one driving, a still barrel beside its path (which the track spins
/// about its axis and wobbles in depth: still by what the cameras see).
#[test]
fn generated_scene_decisions_and_paths() {
    check_seed(2);
}

/// Slow movers (0.14 and 0.25 units in the 6 s) that the track barely follows come out
/// static, and a still barrel stands off the scene around it (docs/objects.md, "The
/// benchmark"): the static test's open cases.
#[test]
#[ignore = "known failure: slow movers called static (docs/objects.md)"]
fn slow_movers_stay_movers() {
    check_seed(7);
}
