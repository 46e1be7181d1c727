//! Finite-difference check of the whole chain the trainer differentiates: field (encoding →
//! MLP) → δ → deformed Gaussians → rasterizer → L = Σ image·W, for the field's weights and
//! the canonical means, quaternions and log-scales, on a tiny scene.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use splat::{Camera, Gradients, Rasterizer, RenderOptions};
use train::config::FieldConfig;
use train::deform::{self, CanonicalGrads, Deformed};
use train::{DeformField, DeformOutput, GaussianModel};

struct Scene {
    model: GaussianModel,
    field: DeformField,
    cam: Camera,
    w: Vec<f32>,
    t: f32,
    /// When set, δ is used as is instead of evaluating the field.
    frozen: Option<DeformOutput>,
}

fn scene() -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let n = 24;
    let mut model = train::init::from_points(
        &(0..n * 3)
            .map(|_| rng.gen_range(-0.6..0.6))
            .collect::<Vec<f32>>(),
        &(0..n * 3)
            .map(|_| rng.gen_range(0.1..0.9))
            .collect::<Vec<f32>>(),
        0.6,
    );
    model.quats = (0..n * 4).map(|_| rng.gen_range(-1.0..1.0)).collect();
    model.log_scales = (0..n * 3).map(|_| rng.gen_range(-2.6..-1.8)).collect();
    for (k, v) in model.sh.iter_mut().enumerate() {
        if k % 48 >= 3 && k % 48 < 12 {
            *v = rng.gen_range(-0.3..0.3);
        }
    }
    model.sh_degree = 1;
    let cfg = FieldConfig {
        depth: 2,
        width: 8,
        skip: 0,
        pos_freqs: 2,
        time_freqs: 2,
        head_init_scale: 1.0, // a nonzero δ for the check to see
        ..FieldConfig::default()
    };
    let mut field = DeformField::new(&cfg, &mut rng);
    // Keep δ small so the deformed scales stay positive and the view stays in frame.
    let p = field.mlp.num_params();
    for v in &mut field.mlp.params[p - (8 * 10 + 10)..] {
        *v *= 0.2;
    }
    let cam = Camera {
        width: 32,
        height: 24,
        fx: 30.0,
        fy: 30.0,
        cx: 16.0,
        cy: 12.0,
        viewmat: [
            [1., 0., 0., 0.],
            [0., 1., 0., 0.],
            [0., 0., 1., 3.],
            [0., 0., 0., 1.],
        ],
    };
    let w = (0..32 * 24 * 3).map(|_| rng.gen_range(-1.0..1.0)).collect();
    Scene {
        model,
        field,
        cam,
        w,
        t: 0.4,
        frozen: None,
    }
}

fn loss(s: &mut Scene, r: &mut Rasterizer) -> f64 {
    let rows: Vec<u32> = (0..s.model.len() as u32).collect();
    let mut delta = DeformOutput::default();
    match &s.frozen {
        Some(f) => delta = f.clone(),
        None => s.field.forward(&s.model.means, s.t, &rows, &mut delta),
    }
    let mut d = Deformed::default();
    deform::apply(&s.model, Some(&delta), &mut d);
    let out = r
        .forward(
            &train::deform::gaussians(&s.model, &d),
            &s.cam,
            &RenderOptions::default(),
        )
        .unwrap();
    out.image
        .iter()
        .zip(&s.w)
        .map(|(a, b)| (*a as f64) * (*b as f64))
        .sum()
}

#[test]
fn chain_matches_finite_differences() {
    let mut s = scene();
    let mut r = Rasterizer::new();
    // Analytic gradients, as Trainer::step computes them.
    let rows: Vec<u32> = (0..s.model.len() as u32).collect();
    let mut delta = DeformOutput::default();
    s.field.forward(&s.model.means, s.t, &rows, &mut delta);
    let mut d = Deformed::default();
    deform::apply(&s.model, Some(&delta), &mut d);
    let g = train::deform::gaussians(&s.model, &d);
    r.forward(&g, &s.cam, &RenderOptions::default()).unwrap();
    let mut grads = Gradients::default();
    r.backward(
        &g,
        &s.cam,
        &RenderOptions::default(),
        &s.w,
        None,
        &mut grads,
    )
    .unwrap();
    let mut canon = CanonicalGrads::default();
    deform::backward(
        &s.model,
        &grads.means,
        &grads.quats,
        &grads.scales,
        &mut canon,
    );
    let d_delta = DeformOutput {
        dx: grads.means.clone(),
        dr: grads.quats.clone(),
        ds: grads.scales.clone(),
    };
    let mut g_field = Vec::new();
    s.field.backward(&d_delta, &mut g_field);

    // The rasterizer is piecewise smooth (alpha < 1/255 skipped, 3.33σ boxes, early stop):
    // a difference quotient that straddles one of its jumps is off by jump/2h. Such
    // entries are recognized by disagreeing quotients at h and h/2 and left out; the rest
    // must match, and at least 85% of the entries must be usable.
    let (mut fd_all, mut an_all, mut skipped) = (Vec::new(), Vec::new(), 0usize);
    let mut check = |s: &mut Scene, get: &dyn Fn(&mut Scene) -> &mut f32, an: f32| {
        let p0 = *get(s);
        let mut q = [0.0f64; 2];
        for (k, h) in [1e-3f32, 5e-4].into_iter().enumerate() {
            *get(s) = p0 + h;
            let lp = loss(s, &mut r);
            *get(s) = p0 - h;
            let lm = loss(s, &mut r);
            *get(s) = p0;
            q[k] = (lp - lm) / (2.0 * h as f64);
        }
        if (q[0] - q[1]).abs() > 0.02 * (q[0].abs() + 0.05) {
            skipped += 1;
        } else {
            fd_all.push(q[0]);
            an_all.push(an as f64);
        }
    };
    let np = s.field.mlp.num_params();
    for i in (0..np).step_by(7) {
        check(
            &mut s,
            &move |s: &mut Scene| &mut s.field.mlp.params[i],
            g_field[i],
        );
    }
    // Deformable-3DGS feeds the field the canonical means detached: the canonical
    // parameters are differentiated with δ held fixed.
    s.frozen = Some(delta.clone());
    for i in 0..s.model.len() * 3 {
        check(
            &mut s,
            &move |s: &mut Scene| &mut s.model.means[i],
            canon.means[i],
        );
        check(
            &mut s,
            &move |s: &mut Scene| &mut s.model.log_scales[i],
            canon.log_scales[i],
        );
    }
    for i in 0..s.model.len() * 4 {
        check(
            &mut s,
            &move |s: &mut Scene| &mut s.model.quats[i],
            canon.quats[i],
        );
    }
    let diff: f64 = fd_all
        .iter()
        .zip(&an_all)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    let norm: f64 = fd_all.iter().map(|a| a * a).sum::<f64>().sqrt();
    assert!(norm > 1e-2, "degenerate scene: gradient norm {norm}");
    let total = fd_all.len() + skipped;
    assert!(
        skipped * 100 <= total * 15,
        "{skipped} of {total} difference quotients straddle a jump"
    );
    assert!(
        diff / norm < 0.03,
        "relative error {} over {} parameters",
        diff / norm,
        fd_all.len()
    );
}
