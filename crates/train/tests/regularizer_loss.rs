//! SemDynReg loss and gradient (paper Sec. 3.4) on hand-made cases and by finite differences.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use train::regularizer::{
    evaluate, DeformGradMut, DeformView, ObjectGroups, ObjectStats, RegConfig, RegError, RegLoss,
    TopKView, NO_GAUSSIAN,
};

/// Owned δ buffers and their gradients for `n` Gaussians.
#[derive(Clone)]
struct Deform {
    dx: Vec<f32>,
    dr: Vec<f32>,
    ds: Vec<f32>,
}

impl Deform {
    fn zeros(n: usize) -> Self {
        Self {
            dx: vec![0.0; n * 3],
            dr: vec![0.0; n * 4],
            ds: vec![0.0; n * 3],
        }
    }
    fn view(&self) -> DeformView<'_> {
        DeformView {
            dx: &self.dx,
            dr: &self.dr,
            ds: &self.ds,
        }
    }
}

fn cfg(lambda: f32, lx: f32, lr: f32, ls: f32, tau_d: f32) -> RegConfig {
    RegConfig {
        lambda,
        lambda_x: lx,
        lambda_r: lr,
        lambda_s: ls,
        tau_d,
        ..RegConfig::default()
    }
}

/// Groups from a one-entry-per-pixel top-k: pixel p shows Gaussian `ids[p]` with ID `map[p]`.
fn groups(ids: &[u32], map: &[u8], n: usize) -> ObjectGroups {
    let mut g = ObjectGroups::new();
    g.build(TopKView { ids, stride: 1 }, 1, map, n).unwrap();
    g
}

fn run(g: &ObjectGroups, d: &Deform, c: &RegConfig) -> (RegLoss, Deform, Vec<ObjectStats>) {
    let mut grad = Deform::zeros(g.n_gaussians());
    let mut stats = Vec::new();
    let loss = {
        let mut gm = DeformGradMut {
            dx: &mut grad.dx,
            dr: &mut grad.dr,
            ds: &mut grad.ds,
        };
        evaluate(g, d.view(), c, Some(&mut gm), &mut stats).unwrap()
    };
    (loss, grad, stats)
}

fn assert_close(a: &[f32], b: &[f32], tol: f32) {
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= tol, "index {i}: {x} vs {y}");
    }
}

/// Two moving objects with hand-computed loss and gradient.
/// Object 0 = {0, 1}: δx (1,0,0),(3,0,0) → mean (2,0,0), dev_x = 1; δs (0,0,0),(0,2,0) → dev_s = 1;
/// δr equal → dev_r = 0. L⁰ = λx·1 + λs·1 = 2 + 0.5 = 2.5.
/// Object 1 = {2, 3, 4}: δx (0,0,1),(0,0,1),(0,0,4) → mean (0,0,2), dev_x = (1+1+4)/3 = 2;
/// δr (0,1,0,0),(0,0,0,0),(0,-1,0,0) → mean 0, dev_r = 2/3. L¹ = 2·2 + 3·(2/3) = 6.
#[test]
fn hand_made_two_objects() {
    let g = groups(&[0, 1, 1, 2, 3, 4], &[0, 0, 0, 1, 1, 1], 5);
    let mut d = Deform::zeros(5);
    d.dx = vec![1., 0., 0., 3., 0., 0., 0., 0., 1., 0., 0., 1., 0., 0., 4.];
    d.ds[4] = 2.0; // Gaussian 1, y
    d.dr[2 * 4 + 1] = 1.0;
    d.dr[4 * 4 + 1] = -1.0;
    let c = cfg(0.5, 2.0, 3.0, 0.5, 0.01);
    let (loss, grad, stats) = run(&g, &d, &c);
    assert!((loss.l_reg - 8.5).abs() < 1e-5, "{loss:?}");
    assert!((loss.weighted - 4.25).abs() < 1e-5);
    assert_eq!((loss.active, loss.skipped), (2, 0));
    assert_eq!(stats.len(), 2);
    assert_eq!((stats[0].group_size, stats[1].group_size), (2, 3));
    assert!((stats[0].loss - 2.5).abs() < 1e-6 && (stats[1].loss - 6.0).abs() < 1e-5);
    // grad = 2·λ·λc/|G|·(δ − mean).  Object 0: 2·0.5·2/2 = 1 → ∓1 on x; δs: 2·.5·.5/2 = .25 → ∓.25.
    // Object 1: δx 2·.5·2/3 = 2/3 → (−1, −1, 2)·2/3 on z; δr 2·.5·3/3 = 1 → (1, 0, −1) on x.
    let t = 2.0 / 3.0;
    #[rustfmt::skip]
    let want_dx = [-1., 0., 0., 1., 0., 0., 0., 0., -t, 0., 0., -t, 0., 0., 2. * t];
    assert_close(&grad.dx, &want_dx, 1e-6);
    let mut want_ds = vec![0.0; 15];
    want_ds[1] = -0.25;
    want_ds[4] = 0.25;
    assert_close(&grad.ds, &want_ds, 1e-6);
    let mut want_dr = vec![0.0; 20];
    want_dr[2 * 4 + 1] = 1.0;
    want_dr[4 * 4 + 1] = -1.0;
    assert_close(&grad.dr, &want_dr, 1e-6);
}

/// An object whose mean translation is within τ_d is skipped entirely, however large its
/// rotation/scale deviations; a moving object beside it is still regularized.
#[test]
fn static_object_is_skipped() {
    let g = groups(&[0, 1, 2, 3], &[7, 7, 9, 9], 4);
    let mut d = Deform::zeros(4);
    d.dx[0] = 0.004; // object 7: mean δx = (0.002, 0, 0), norm 0.002 ≤ τ_d
    d.dr[0] = 5.0;
    d.ds[3] = -4.0;
    d.dx[2 * 3] = 1.0; // object 9: mean (0.5, 0, 0) → moving
    let c = cfg(1.0, 1.0, 1.0, 1.0, 0.01);
    let (loss, grad, stats) = run(&g, &d, &c);
    assert_eq!((loss.active, loss.skipped), (1, 1));
    let s7 = stats.iter().find(|s| s.object == 7).unwrap();
    assert!(s7.skipped && s7.loss == 0.0 && s7.dev_r > 1.0, "{s7:?}");
    assert!((s7.mean_dx_norm - 0.002).abs() < 1e-6);
    assert!(grad.dx[..6]
        .iter()
        .chain(&grad.dr[..8])
        .chain(&grad.ds[..6])
        .all(|&v| v == 0.0));
    // Object 9 dev_x = 0.25 → L = 0.25, its gradient ±0.5 on x.
    assert!((loss.l_reg - 0.25).abs() < 1e-6);
    assert_close(&grad.dx[6..], &[0.5, 0., 0., -0.5, 0., 0.], 1e-6);
    // τ_d = 0 regularizes it too (the boundary is inclusive: ‖δx̄‖ ≤ τ_d skips).
    let (loss, _, _) = run(&g, &d, &cfg(1.0, 1.0, 1.0, 1.0, 0.0));
    assert_eq!(loss.active, 2);
}

/// A Gaussian at the border of two objects is in both groups and gets both gradients.
#[test]
fn gaussian_in_two_groups_accumulates() {
    // Gaussian 1 is in the top-k of a pixel of object 0 and of a pixel of object 1.
    let g = groups(&[0, 1, 1, 2], &[0, 0, 1, 1], 3);
    assert_eq!(g.group(0).unwrap().members, &[0, 1]);
    assert_eq!(g.group(1).unwrap().members, &[1, 2]);
    let mut d = Deform::zeros(3);
    d.dx = vec![0., 0., 0., 2., 0., 0., 6., 0., 0.];
    let c = cfg(1.0, 1.0, 0.0, 0.0, 0.01);
    let (loss, grad, _) = run(&g, &d, &c);
    // Object 0: mean 1, dev 1, grad (−1, +1). Object 1: mean 4, dev 4, grad (−2, +2).
    assert!((loss.l_reg - 5.0).abs() < 1e-6);
    assert_close(&grad.dx, &[-1., 0., 0., 1. - 2., 0., 0., 2., 0., 0.], 1e-6);
}

#[test]
fn all_background_gives_zero_loss_and_gradient() {
    let g = groups(&[0, 1, NO_GAUSSIAN], &[255, 255, 255], 2);
    let mut d = Deform::zeros(2);
    d.dx = vec![1., 2., 3., -4., 5., 6.];
    let (loss, grad, stats) = run(&g, &d, &RegConfig::default());
    assert_eq!(loss, RegLoss::default());
    assert!(stats.is_empty());
    assert!(grad.dx.iter().all(|&v| v == 0.0));
    // An object whose pixels have no contributors forms an empty group: skipped, no NaN.
    let g = groups(&[NO_GAUSSIAN, NO_GAUSSIAN], &[3, 3], 2);
    let (loss, grad, stats) = run(&g, &d, &RegConfig::default());
    assert_eq!((loss.l_reg, loss.skipped), (0.0, 1));
    assert!(stats[0].skipped && stats[0].group_size == 0);
    assert!(grad.dx.iter().all(|&v| v == 0.0));
}

/// The analytic gradient matches central differences of `λ·L_reg` on a random scene with
/// overlapping groups (both the translation-mean and the deviation terms move).
#[test]
fn gradient_matches_finite_differences() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (n, pixels, k) = (40, 120, 3);
    let ids: Vec<u32> = (0..pixels * k)
        .map(|_| {
            if rng.gen_bool(0.1) {
                NO_GAUSSIAN
            } else {
                rng.gen_range(0..n as u32)
            }
        })
        .collect();
    let map: Vec<u8> = (0..pixels)
        .map(|_| [0, 1, 2, 255][rng.gen_range(0..4)])
        .collect();
    let mut g = ObjectGroups::new();
    g.build(
        TopKView {
            ids: &ids,
            stride: k,
        },
        k,
        &map,
        n,
    )
    .unwrap();
    let mut d = Deform::zeros(n);
    for v in d.dx.iter_mut().chain(&mut d.dr).chain(&mut d.ds) {
        *v = rng.gen_range(-1.0..1.0);
    }
    // Shift every δx so that no object sits near the τ_d boundary.
    d.dx.iter_mut().step_by(3).for_each(|v| *v += 2.0);
    let c = cfg(0.7, 1.3, 0.4, 2.1, 0.01);
    let (loss, grad, _) = run(&g, &d, &c);
    assert_eq!(loss.active, 3);
    let eps = 1e-2f32;
    let weighted = |d: &Deform| {
        let mut s = Vec::new();
        f64::from(evaluate(&g, d.view(), &c, None, &mut s).unwrap().weighted)
    };
    for (which, len) in [(0, n * 3), (1, n * 4), (2, n * 3)] {
        for i in 0..len {
            let mut p = d.clone();
            let mut m = d.clone();
            [&mut p.dx, &mut p.dr, &mut p.ds][which][i] += eps;
            [&mut m.dx, &mut m.dr, &mut m.ds][which][i] -= eps;
            let fd = (weighted(&p) - weighted(&m)) / (2.0 * f64::from(eps));
            let an = f64::from([&grad.dx, &grad.dr, &grad.ds][which][i]);
            assert!(
                (fd - an).abs() <= 2e-3 * (1.0 + an.abs()),
                "buffer {which} index {i}: fd {fd} vs analytic {an}"
            );
        }
    }
}

#[test]
fn mismatched_buffers_are_errors() {
    let g = groups(&[0, 1], &[0, 0], 2);
    let d = Deform::zeros(3);
    let mut s = Vec::new();
    let e = evaluate(&g, d.view(), &RegConfig::default(), None, &mut s);
    assert_eq!(
        e,
        Err(RegError::GaussianCount {
            groups_n: 2,
            deform_n: 3
        })
    );
    let mut d = Deform::zeros(2);
    d.dr.pop();
    let e = evaluate(&g, d.view(), &RegConfig::default(), None, &mut s);
    assert!(matches!(e, Err(RegError::DeformLength { name: "dr", .. })));
    let d = Deform::zeros(2);
    let mut short = vec![0.0; 5];
    let (mut gr, mut gs) = (vec![0.0; 8], vec![0.0; 6]);
    let mut gm = DeformGradMut {
        dx: &mut short,
        dr: &mut gr,
        ds: &mut gs,
    };
    let e = evaluate(&g, d.view(), &RegConfig::default(), Some(&mut gm), &mut s);
    assert!(matches!(
        e,
        Err(RegError::DeformLength {
            name: "grad dx",
            ..
        })
    ));
}
