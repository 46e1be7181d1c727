//! The rigid-aware consistency loss (`[reg] consistency = "rigid"`) beside the paper's: a
//! turning car costs nothing, a Gaussian off the rigid motion is pulled back, static objects
//! are not skipped, and the config key parses.

use train::config::TrainConfig;
use train::regularizer::{
    evaluate, evaluate_rigid, ConsistencyMode, DeformGradMut, DeformView, ObjectGroups,
    ObjectStats, RegConfig, RegError, RegLoss, Regularizer, TopKView,
};

/// Canonical means of a car-sized body (not coplanar) and one road Gaussian (index 6).
const MEANS: [f32; 21] = [
    -0.6, -0.25, 0.0, 0.6, -0.25, 0.0, 0.6, 0.25, 0.05, -0.6, 0.25, 0.1, -0.3, 0.0, 0.4, 0.3, 0.1,
    0.35, 2.0, 2.0, 0.0,
];
const N: usize = 7;

/// The car (object 4) is Gaussians 0..6, seen one per pixel; the road is background.
fn car_groups() -> ObjectGroups {
    let ids: Vec<u32> = (0..N as u32).collect();
    let mut map = vec![4u8; 6];
    map.push(255);
    let mut g = ObjectGroups::new();
    g.build(
        TopKView {
            ids: &ids,
            stride: 1,
        },
        1,
        &map,
        N,
    )
    .unwrap();
    g
}

fn cfg(consistency: ConsistencyMode) -> RegConfig {
    RegConfig {
        lambda: 0.5,
        lambda_x: 2.0,
        consistency,
        ..RegConfig::default()
    }
}

/// `δx` of a yaw by `deg` degrees about the body's origin plus a drive `t`:
/// `δx_i = (R − I) x_i + t` (the road Gaussian stays).
fn turn(deg: f32, t: [f32; 3]) -> Vec<f32> {
    let (s, c) = deg.to_radians().sin_cos();
    let mut dx = vec![0.0; N * 3];
    for i in 0..6 {
        let [x, y, z] = [0, 1, 2].map(|k| MEANS[i * 3 + k]);
        let moved = [c * x - s * y + t[0], s * x + c * y + t[1], z + t[2]];
        for k in 0..3 {
            dx[i * 3 + k] = moved[k] - MEANS[i * 3 + k];
        }
    }
    dx
}

/// Loss, dL/dδx and stats of one mode on `dx` (δr, δs zero).
fn run(mode: ConsistencyMode, dx: &[f32]) -> (RegLoss, Vec<f32>, Vec<ObjectStats>) {
    let (dr, ds) = (vec![0.0; N * 4], vec![0.0; N * 3]);
    let (mut gx, mut gr, mut gs) = (vec![0.0; N * 3], vec![0.0; N * 4], vec![0.0; N * 3]);
    let d = DeformView {
        dx,
        dr: &dr,
        ds: &ds,
    };
    let mut grad = DeformGradMut {
        dx: &mut gx,
        dr: &mut gr,
        ds: &mut gs,
    };
    let (g, c, mut stats) = (car_groups(), cfg(mode), Vec::new());
    let loss = match mode {
        ConsistencyMode::Paper => evaluate(&g, d, &c, Some(&mut grad), &mut stats),
        ConsistencyMode::Rigid => evaluate_rigid(&g, &MEANS, d, &c, Some(&mut grad), &mut stats),
    }
    .unwrap();
    assert!(
        gr.iter().chain(&gs).all(|&v| v == 0.0),
        "δr, δs untouched here"
    );
    (loss, gx, stats)
}

#[test]
fn a_turning_car_is_free_under_rigid_but_not_under_paper() {
    let dx = turn(105.0, [0.3, 0.1, 0.0]);
    let (rigid, grad, stats) = run(ConsistencyMode::Rigid, &dx);
    assert_eq!((rigid.active, rigid.skipped), (1, 0));
    assert!(rigid.l_reg.abs() < 1e-10, "{rigid:?}");
    assert!(grad.iter().all(|g| g.abs() < 1e-6), "{grad:?}");
    let s = stats[0];
    assert_eq!((s.object, s.group_size), (4, 6));
    assert!(s.rigid_residual.unwrap() < 1e-10);
    assert!(
        s.dev_x > 0.1,
        "the paper's deviation is still logged: {s:?}"
    );
    let (paper, paper_grad, paper_stats) = run(ConsistencyMode::Paper, &dx);
    assert!(paper.l_reg > 0.1, "{paper:?}");
    assert!(paper_grad.iter().any(|g| g.abs() > 0.01));
    assert_eq!(paper_stats[0].rigid_residual, None);
}

#[test]
fn a_gaussian_off_the_rigid_motion_is_pulled_back() {
    let mut dx = turn(40.0, [0.2, -0.1, 0.0]);
    let off = [0.05f32, -0.03, 0.04];
    for k in 0..3 {
        dx[2 * 3 + k] += off[k];
    }
    let (loss, grad, stats) = run(ConsistencyMode::Rigid, &dx);
    assert!(loss.l_reg > 1e-4, "{loss:?}");
    let r = stats[0].rigid_residual.unwrap();
    assert!((loss.l_reg - 2.0 * r).abs() < 1e-7, "λx·residual");
    assert!((loss.weighted - 0.5 * loss.l_reg).abs() < 1e-7);
    // The displaced Gaussian's gradient points along its offset (descent pulls it back) and
    // is the largest; the road Gaussian gets none.
    let g2 = &grad[6..9];
    let along: f32 = g2.iter().zip(&off).map(|(g, o)| g * o).sum();
    assert!(along > 0.0, "{g2:?}");
    let norm = |i: usize| grad[i * 3..i * 3 + 3].iter().map(|v| v * v).sum::<f32>();
    assert!((0..6).filter(|&i| i != 2).all(|i| norm(i) < norm(2)));
    assert_eq!(&grad[18..21], &[0.0; 3]);
    // A small step down the gradient lowers the loss.
    let stepped: Vec<f32> = dx.iter().zip(&grad).map(|(d, g)| d - 0.5 * g).collect();
    assert!(run(ConsistencyMode::Rigid, &stepped).0.l_reg < loss.l_reg);
}

/// Central differences of the weighted loss against dL/dδx (f32 buffers, coarse tolerance;
/// `rigid_fit`'s unit tests check the fit's gradient in f64).
#[test]
fn rigid_gradient_matches_finite_differences() {
    let mut dx = turn(70.0, [0.1, 0.0, 0.05]);
    dx[0] += 0.04;
    dx[13] -= 0.03;
    dx[17] += 0.02;
    let (_, grad, _) = run(ConsistencyMode::Rigid, &dx);
    let h = 1e-3;
    for j in 0..18 {
        let at = |delta: f32| {
            let mut d = dx.clone();
            d[j] += delta;
            f64::from(run(ConsistencyMode::Rigid, &d).0.weighted)
        };
        let fd = (at(h) - at(-h)) / (2.0 * f64::from(h));
        let err = (fd - f64::from(grad[j])).abs();
        assert!(err < 2e-4, "δx[{j}]: fd {fd} vs {}", grad[j]);
    }
}

#[test]
fn static_objects_are_not_skipped_under_rigid() {
    // The car barely moves (‖δx̄‖ < τ_d) but one Gaussian wobbles.
    let mut dx = vec![0.0; N * 3];
    dx[4 * 3 + 2] = 0.03;
    let (paper, paper_grad, _) = run(ConsistencyMode::Paper, &dx);
    assert_eq!((paper.active, paper.skipped, paper.l_reg), (0, 1, 0.0));
    assert!(paper_grad.iter().all(|&g| g == 0.0));
    let (rigid, grad, stats) = run(ConsistencyMode::Rigid, &dx);
    assert_eq!((rigid.active, rigid.skipped), (1, 0));
    assert!(!stats[0].skipped && rigid.l_reg > 0.0);
    assert!(grad[4 * 3 + 2] > 0.0);
}

#[test]
fn regularizer_dispatches_on_the_mode_and_checks_the_means() {
    let dx = turn(105.0, [0.3, 0.1, 0.0]);
    let (dr, ds) = (vec![0.0; N * 4], vec![0.0; N * 3]);
    let ids: Vec<u32> = (0..N as u32).collect();
    let mut map = vec![4u8; 6];
    map.push(255);
    let apply = |mode: ConsistencyMode, means: &[f32]| {
        let mut reg = Regularizer::new(RegConfig { k: 1, ..cfg(mode) }).unwrap();
        let (mut gx, mut gr, mut gs) = (vec![0.0; N * 3], vec![0.0; N * 4], vec![0.0; N * 3]);
        let mut grad = DeformGradMut {
            dx: &mut gx,
            dr: &mut gr,
            ds: &mut gs,
        };
        let d = DeformView {
            dx: &dx,
            dr: &dr,
            ds: &ds,
        };
        let topk = TopKView {
            ids: &ids,
            stride: 1,
        };
        reg.apply(topk, &map, means, d, &mut grad, None)
    };
    let rigid = apply(ConsistencyMode::Rigid, &MEANS).unwrap();
    assert!(rigid.l_reg < 1e-10 && rigid.active == 1);
    // The paper's loss does not read the means.
    let paper = apply(ConsistencyMode::Paper, &[]).unwrap();
    assert!(paper.l_reg > 0.1);
    let err = apply(ConsistencyMode::Rigid, &MEANS[..6]).unwrap_err();
    assert!(
        matches!(err, RegError::PositionLength { name: "means", .. }),
        "{err}"
    );
}

#[test]
fn the_key_parses_in_a_training_config() {
    let c: TrainConfig = toml::from_str("[reg]\nconsistency = \"rigid\"").unwrap();
    assert_eq!(c.reg.consistency, ConsistencyMode::Rigid);
    let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
    assert_eq!(back.reg.consistency, ConsistencyMode::Rigid);
    let d: TrainConfig = toml::from_str("[reg]\nk = 3").unwrap();
    assert_eq!(
        d.reg.consistency,
        ConsistencyMode::Paper,
        "the paper's loss by default"
    );
    let err = toml::from_str::<TrainConfig>("[reg]\nconsistency = \"kabsch\"").unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("`consistency`") && msg.contains("kabsch"),
        "{msg}"
    );
}
