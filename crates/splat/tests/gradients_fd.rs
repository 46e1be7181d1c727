//! Central finite differences of the float64 reference forward pass against the float32
//! backward on tiny random scenes (SH degrees 0–3 and RGB, background, alpha weights).

mod common;
use common::{rel_l2, Scene};
use splat::reference::{render, RefGaussians};
use splat::{Gradients, Rasterizer, RenderOptions};

/// Selects one parameter array of the reference Gaussians.
type Field = fn(&mut RefGaussians) -> &mut Vec<f64>;

fn loss(g: &RefGaussians, s: &Scene, opts: &RenderOptions, w: &[f64], aw: &[f64]) -> f64 {
    let out = render(g, &s.cam, opts);
    let li: f64 = out.image.iter().zip(w).map(|(a, b)| a * b).sum();
    li + out.alpha.iter().zip(aw).map(|(a, b)| a * b).sum::<f64>()
}

/// d loss / d field[i] for every i, by central differences in float64 with step `h`.
fn fd(
    base: &RefGaussians,
    field: Field,
    h: f64,
    s: &Scene,
    opts: &RenderOptions,
    w: &[f64],
    aw: &[f64],
) -> Vec<f64> {
    let len = field(&mut base.clone()).len();
    (0..len)
        .map(|i| {
            let (mut p, mut m) = (base.clone(), base.clone());
            field(&mut p)[i] += h;
            field(&mut m)[i] -= h;
            (loss(&p, s, opts, w, aw) - loss(&m, s, opts, w, aw)) / (2.0 * h)
        })
        .collect()
}

fn check(seed: u64, sh_degree: Option<usize>) {
    let s = Scene::random(seed, 12, 40, 32, sh_degree);
    let opts = RenderOptions {
        background: [0.2, 0.5, 0.9],
        ..Default::default()
    };
    let px = (s.cam.width * s.cam.height) as usize;
    let w: Vec<f64> = (0..px * 3)
        .map(|i| ((i * 7919) % 13) as f64 / 13.0 - 0.4)
        .collect();
    let aw: Vec<f64> = (0..px)
        .map(|i| ((i * 104_729) % 11) as f64 / 11.0 - 0.5)
        .collect();
    let g = s.gaussians();
    let mut r = Rasterizer::new();
    let out = r.forward(&g, &s.cam, &opts).expect("forward");
    let base = RefGaussians::from_gaussians(&g);
    let reference = render(&base, &s.cam, &opts);
    let img: Vec<f64> = out.image.iter().map(|&v| v as f64).collect();
    assert!(
        rel_l2(&img, &reference.image) < 1e-5,
        "forward differs from reference"
    );
    assert!(out.n_isects > 12, "scene too sparse to test anything");
    let mut grads = Gradients::default();
    let wf: Vec<f32> = w.iter().map(|&v| v as f32).collect();
    let awf: Vec<f32> = aw.iter().map(|&v| v as f32).collect();
    r.backward(&g, &s.cam, &opts, &wf, Some(&awf), &mut grads)
        .expect("backward");
    let up = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
    let fields: [(&str, Field, Vec<f64>); 5] = [
        ("means", |g| &mut g.means, up(&grads.means)),
        ("quats", |g| &mut g.quats, up(&grads.quats)),
        ("scales", |g| &mut g.scales, up(&grads.scales)),
        (
            "opacity_logits",
            |g| &mut g.opacity_logits,
            up(&grads.opacity_logits),
        ),
        ("colors", |g| &mut g.colors, up(&grads.colors)),
    ];
    for (name, field, analytic) in fields {
        // The loss is piecewise smooth: a (pixel, Gaussian) pair crossing a threshold
        // (alpha 1/255, T 1e-4, a tile box edge) inside the step makes a jump. Two step
        // sizes disagree there; such entries are left out, at most one per array.
        let coarse = fd(&base, field, 1e-6, &s, &opts, &w, &aw);
        let fine = fd(&base, field, 2.5e-7, &s, &opts, &w, &aw);
        let smooth: Vec<usize> = (0..coarse.len())
            .filter(|&i| (coarse[i] - fine[i]).abs() <= 1e-4 * (1.0 + coarse[i].abs()))
            .collect();
        assert!(
            coarse.len() - smooth.len() <= 1,
            "{name}: {} jumps",
            coarse.len() - smooth.len()
        );
        let pick = |v: &[f64]| smooth.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let e = rel_l2(&pick(&analytic), &pick(&coarse));
        assert!(
            e < 2e-3,
            "seed {seed} sh {sh_degree:?} {name}: relative L2 {e:e}"
        );
    }
}

#[test]
fn fd_sh0() {
    check(1, Some(0));
}

#[test]
fn fd_sh1() {
    check(2, Some(1));
}

#[test]
fn fd_sh3() {
    check(3, Some(3));
}

#[test]
fn fd_rgb() {
    check(4, None);
}
