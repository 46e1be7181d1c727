//! Tests of the rigid fit on hand-made cases (rotations, one displaced point, reflections,
//! degenerate inputs) and of its gradient by finite differences.

use super::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Rotation by `angle` radians about `axis` (Rodrigues).
fn rotation(axis: Point, angle: f64) -> [[f64; 3]; 3] {
    let n = norm2(axis).sqrt();
    let [x, y, z] = axis.map(|v| v / n);
    let (s, c) = angle.sin_cos();
    let k = 1.0 - c;
    [
        [c + x * x * k, x * y * k - z * s, x * z * k + y * s],
        [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
        [z * x * k - y * s, z * y * k + x * s, c + z * z * k],
    ]
}

fn motion(axis: Point, angle: f64, t: Point) -> RigidTransform {
    RigidTransform {
        rotation: rotation(axis, angle),
        translation: t,
    }
}

/// Corners and mid-points of a car-sized box: not coplanar, not symmetric.
fn body() -> Vec<Point> {
    vec![
        [-0.6, -0.25, 0.0],
        [0.6, -0.25, 0.0],
        [0.6, 0.25, 0.0],
        [-0.6, 0.25, 0.1],
        [-0.4, 0.0, 0.4],
        [0.3, 0.1, 0.35],
        [0.0, -0.2, 0.2],
    ]
}

fn moved(m: &RigidTransform, x: &[Point]) -> Vec<Point> {
    x.iter().map(|&p| m.apply(p)).collect()
}

fn assert_close(a: &[f64], b: &[f64], tol: f64) {
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol,
            "entry {i}: {x} vs {y} ({a:?} vs {b:?})"
        );
    }
}

fn assert_recovers(fit: &RigidFit, m: &RigidTransform) {
    assert_eq!(fit.kind, FitKind::Rotation);
    assert!(fit.residual < 1e-20, "{fit:?}");
    let flat = |r: &[[f64; 3]; 3]| r.concat();
    assert_close(&flat(&fit.transform.rotation), &flat(&m.rotation), 1e-10);
    assert_close(&fit.transform.translation, &m.translation, 1e-10);
    assert!((fit.transform.det() - 1.0).abs() < 1e-12);
}

#[test]
fn rotations_and_motions_have_zero_residual_and_are_recovered() {
    let x = body();
    // A car yawing 105° in place, then a general motion, then a half turn (quaternion w = 0).
    for m in [
        motion([0.0, 0.0, 1.0], 105f64.to_radians(), [0.0; 3]),
        motion([1.0, 2.0, -0.5], 2.5, [1.0, -2.0, 0.5]),
        motion([0.0, 1.0, 0.0], std::f64::consts::PI, [0.3, 0.0, -0.1]),
    ] {
        let y = moved(&m, &x);
        let fit = fit_rigid(&x, &y, None).unwrap();
        assert_recovers(&fit, &m);
        let g = fit.gradient(&x, &y, None).unwrap();
        assert!(g.iter().flatten().all(|v| v.abs() < 1e-10), "{g:?}");
    }
}

/// An octahedron `±a·e_k` plus its centre; the centre is displaced by `d` after a rigid
/// motion. The cross-covariance stays `2a²·Rᵀ`, so the motion is still the optimum, the
/// centroid moves by `d/7`, and `E* = (‖d − d/7‖² + 6‖d/7‖²)/7 = 6/49·‖d‖²`.
#[test]
fn one_displaced_point_is_found() {
    let a = 0.7;
    let mut x: Vec<Point> = (0..6)
        .map(|k| {
            let mut p = [0.0; 3];
            p[k / 2] = if k % 2 == 0 { a } else { -a };
            p
        })
        .collect();
    x.push([0.0; 3]);
    let m = motion([0.3, -1.0, 0.2], 1.2, [0.5, 1.0, -2.0]);
    let mut y = moved(&m, &x);
    let d = [0.1, -0.2, 0.3];
    for c in 0..3 {
        y[6][c] += d[c];
    }
    let fit = fit_rigid(&x, &y, None).unwrap();
    let want = 6.0 / 49.0 * norm2(d);
    assert!(
        (fit.residual - want).abs() < 1e-14,
        "{} vs {want}",
        fit.residual
    );
    let flat = |r: &[[f64; 3]; 3]| r.concat();
    assert_close(&flat(&fit.transform.rotation), &flat(&m.rotation), 1e-12);
    // dE*/dy = 2/7·(y_i − ŷ_i): 12/49·d on the displaced point, −2/49·d on the others.
    let g = fit.gradient(&x, &y, None).unwrap();
    assert_close(&g[6], &d.map(|v| 12.0 / 49.0 * v), 1e-14);
    for gi in &g[..6] {
        assert_close(gi, &d.map(|v| -2.0 / 49.0 * v), 1e-14);
    }
    // Descending the gradient pulls the point back towards the rigid motion.
    let step: Vec<Point> = y
        .iter()
        .zip(&g)
        .map(|(p, gi)| [0, 1, 2].map(|c| p[c] - gi[c]))
        .collect();
    assert!(fit_rigid(&x, &step, None).unwrap().residual < fit.residual);
}

/// Residual of the rotation `q` with its best translation (`t = ȳ − q x̄`).
fn residual_with(q: &[[f64; 3]; 3], x: &[Point], y: &[Point]) -> f64 {
    let n = x.len() as f64;
    let mean = |p: &[Point]| [0, 1, 2].map(|c| p.iter().map(|v| v[c]).sum::<f64>() / n);
    let mut m = RigidTransform {
        rotation: *q,
        translation: [0.0; 3],
    };
    let qx = m.apply(mean(x));
    m.translation = sub(mean(y), qx);
    x.iter()
        .zip(y)
        .map(|(a, b)| norm2(sub(*b, m.apply(*a))))
        .sum::<f64>()
        / n
}

#[test]
fn reflections_are_not_returned_as_rotations() {
    // A mirror image of a non-planar body is no rotation: the fit stays proper and its
    // residual is the best any rotation achieves (checked against random rotations).
    let x = body();
    let y: Vec<Point> = x.iter().map(|p| [p[0], p[1], -p[2]]).collect();
    let fit = fit_rigid(&x, &y, None).unwrap();
    assert!((fit.transform.det() - 1.0).abs() < 1e-12);
    assert!(fit.residual > 1e-3, "{fit:?}");
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..2000 {
        let axis = [0; 3].map(|_| rng.gen_range(-1.0..1.0));
        let q = rotation(axis, rng.gen_range(0.0..std::f64::consts::PI));
        assert!(residual_with(&q, &x, &y) >= fit.residual - 1e-12);
    }
    // The mirror image of a planar set is a half turn about an axis in its plane.
    let x: Vec<Point> = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.2, 0.0],
        [0.3, 0.8, 0.0],
        [-0.5, 0.4, 0.0],
    ];
    let y: Vec<Point> = x.iter().map(|p| [p[0], -p[1], p[2]]).collect();
    let fit = fit_rigid(&x, &y, None).unwrap();
    assert!(
        fit.residual < 1e-20 && (fit.transform.det() - 1.0).abs() < 1e-12,
        "{fit:?}"
    );
}

#[test]
fn degenerate_inputs_are_defined() {
    let none: [Point; 0] = [];
    let fit = fit_rigid(&none, &none, None).unwrap();
    assert_eq!((fit.kind, fit.residual), (FitKind::Empty, 0.0));
    assert_eq!(fit.transform, RigidTransform::IDENTITY);
    let fit = fit_rigid(&[[1.0; 3]], &[[2.0; 3]], Some(&[0.0])).unwrap();
    assert_eq!(fit.kind, FitKind::Empty, "zero total weight");
    // One point: translation only.
    let (x, y) = ([[0.1, 0.2, 0.3]], [[1.0, -1.0, 0.5]]);
    let fit = fit_rigid(&x, &y, None).unwrap();
    assert_eq!((fit.kind, fit.residual), (FitKind::Translation, 0.0));
    assert_close(&fit.transform.translation, &[0.9, -1.2, 0.2], 1e-15);
    assert_eq!(fit.gradient(&x, &y, None).unwrap(), vec![[0.0; 3]]);
    // Coincident sources: E* is the targets' spread, whatever the rotation.
    let x = [[0.1, 0.2, 0.3]; 3];
    let y = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
    let fit = fit_rigid(&x, &y, None).unwrap();
    assert_eq!(fit.kind, FitKind::Translation);
    assert!((fit.residual - 2.0 / 3.0).abs() < 1e-12, "{fit:?}");
    // Coincident targets: E* is the sources' spread.
    let fit = fit_rigid(&y, &x, None).unwrap();
    assert_eq!(fit.kind, FitKind::Translation);
    assert!((fit.residual - 2.0 / 3.0).abs() < 1e-12, "{fit:?}");
    // Two points (collinear): the segments are aligned, only their lengths differ.
    let x = [[0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]];
    let y = [[1.0, 1.8, 0.0], [1.0, 0.2, 0.0]];
    let fit = fit_rigid(&x, &y, None).unwrap();
    assert!((fit.residual - 0.09).abs() < 1e-12, "{fit:?}");
    assert!((fit.transform.det() - 1.0).abs() < 1e-12);
    // A rod turned and moved: rigid, whatever the spin about its axis.
    let x: Vec<Point> = (0..4)
        .map(|i| [0.2 * i as f64, 0.1 * i as f64, 0.0])
        .collect();
    let y = moved(&motion([1.0, 1.0, 0.0], 0.8, [0.0, 2.0, 1.0]), &x);
    let fit = fit_rigid(&x, &y, None).unwrap();
    assert!(fit.residual < 1e-20, "{fit:?}");
    let g = fit.gradient(&x, &y, None).unwrap();
    assert!(g.iter().flatten().all(|v| v.is_finite() && v.abs() < 1e-10));
}

#[test]
fn bad_inputs_are_typed_errors() {
    let x = body();
    let err = fit_rigid(&x, &x[..3], None).unwrap_err();
    assert_eq!(err, FitError::Length { x: 7, y: 3 });
    let mut y = x.clone();
    y[4][1] = f64::NAN;
    let err = fit_rigid(&x, &y, None).unwrap_err();
    assert_eq!(
        err,
        FitError::NonFinite {
            set: "target",
            index: 4
        }
    );
    let w = [1.0, 1.0, -1.0, 1.0, 1.0, 1.0, 1.0];
    assert!(matches!(
        fit_rigid(&x, &x, Some(&w)),
        Err(FitError::Weight { index: 2, .. })
    ));
    let err = fit_rigid(&x, &x, Some(&w[..2])).unwrap_err();
    assert_eq!(
        err,
        FitError::WeightLength {
            weights: 2,
            points: 7
        }
    );
}

#[test]
fn weights_act_as_multiplicities() {
    let x = body();
    let m = motion([0.0, 0.0, 1.0], 0.4, [0.1, 0.0, 0.0]);
    let mut y = moved(&m, &x);
    y[2][0] += 0.2;
    y[5][2] -= 0.1;
    let mut w = vec![1.0; x.len()];
    w[2] = 2.0;
    w[4] = 0.0;
    let weighted = fit_rigid(&x, &y, Some(&w)).unwrap();
    let pick = |p: &[Point]| -> Vec<Point> {
        let mut v: Vec<Point> = p
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != 4)
            .map(|(_, q)| *q)
            .collect();
        v.push(p[2]);
        v
    };
    let plain = fit_rigid(&pick(&x), &pick(&y), None).unwrap();
    assert!((weighted.residual - plain.residual).abs() < 1e-14);
}

/// Central differences of `E*(y)` against [`RigidFit::gradient`], weighted and not.
#[test]
fn gradient_matches_finite_differences() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let x: Vec<Point> = (0..9)
        .map(|_| [0; 3].map(|_| rng.gen_range(-1.0..1.0)))
        .collect();
    let m = motion([0.2, 0.5, 1.0], 1.8, [0.4, -0.3, 0.2]);
    let y: Vec<Point> = moved(&m, &x)
        .into_iter()
        .map(|p| p.map(|v| v + rng.gen_range(-0.2..0.2)))
        .collect();
    let mut w: Vec<f64> = (0..9).map(|_| rng.gen_range(0.1..2.0)).collect();
    w[3] = 0.0;
    for weights in [None, Some(w.as_slice())] {
        let fit = fit_rigid(&x, &y, weights).unwrap();
        assert!(fit.residual > 1e-3);
        let g = fit.gradient(&x, &y, weights).unwrap();
        let h = 1e-6;
        for i in 0..x.len() {
            for c in 0..3 {
                let e = |delta: f64| {
                    let mut yy = y.clone();
                    yy[i][c] += delta;
                    fit_rigid(&x, &yy, weights).unwrap().residual
                };
                let fd = (e(h) - e(-h)) / (2.0 * h);
                let tol = 1e-8 + 1e-6 * fd.abs();
                assert!(
                    (fd - g[i][c]).abs() < tol,
                    "y[{i}][{c}]: fd {fd} vs {}",
                    g[i][c]
                );
            }
        }
    }
}
