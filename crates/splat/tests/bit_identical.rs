//! Results do not depend on how the work is run: every vector level of the tile kernels
//! (portable, AVX2, AVX-512; picked at run time) and every thread count give bit-identical
//! images, alphas, top-k lists and gradients. The kernels use no FMA contraction and sum
//! lanes in one fixed order; the backward pass sums each Gaussian's tiles in a fixed order
//! (`grad_slots`), whichever thread ran them. The projection run sixteen Gaussians at a
//! time equals its one-at-a-time scalar reference bit for bit.

mod common;
use common::{Case, Scene, CASES};
use splat::{
    cpu_simd_level, simd_level, Camera, Gaussians, Gradients, Rasterizer, RenderOptions, Simd,
};

struct Result {
    image: Vec<f32>,
    alpha: Vec<f32>,
    topk: Vec<u32>,
    grads: Gradients,
}

fn run(level: Simd, s: &Scene, opts: &RenderOptions) -> Result {
    let mut r = Rasterizer::new();
    r.set_simd_cap(level);
    assert_eq!(r.simd(), level);
    render(&mut r, &s.gaussians(), &s.cam, opts)
}

/// Forward, then backward of fixed pseudo-random image and alpha gradients.
fn render(r: &mut Rasterizer, g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Result {
    let out = r.forward(g, cam, opts).expect("forward");
    let (image, alpha, topk) = (
        out.image.to_vec(),
        out.alpha.to_vec(),
        out.topk_ids.to_vec(),
    );
    let dl: Vec<f32> = (0..image.len())
        .map(|i| ((i * 37) % 11) as f32 / 11.0 - 0.5)
        .collect();
    let da: Vec<f32> = (0..alpha.len())
        .map(|i| ((i * 13) % 5) as f32 / 5.0 - 0.4)
        .collect();
    let mut grads = Gradients::default();
    r.backward(g, cam, opts, &dl, Some(&da), &mut grads)
        .expect("backward");
    Result {
        image,
        alpha,
        topk,
        grads,
    }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn assert_same(got: &Result, want: &Result, what: &str) {
    assert_eq!(bits(&got.image), bits(&want.image), "{what}: image");
    assert_eq!(bits(&got.alpha), bits(&want.alpha), "{what}: alpha");
    assert_eq!(got.topk, want.topk, "{what}: top-k");
    let (a, b) = (&got.grads, &want.grads);
    for (name, x, y) in [
        ("means", &a.means, &b.means),
        ("quats", &a.quats, &b.quats),
        ("scales", &a.scales, &b.scales),
        ("opacity", &a.opacity_logits, &b.opacity_logits),
        ("colors", &a.colors, &b.colors),
    ] {
        assert_eq!(bits(x), bits(y), "{what}: gradient of {name}");
    }
    assert_eq!(a.means2d, b.means2d, "{what}: gradient of the 2D means");
}

fn scene() -> (Scene, RenderOptions) {
    let s = Scene::random(11, 400, 97, 71, Some(2));
    let opts = RenderOptions {
        topk: 4,
        background: [0.2, 0.5, 0.9],
        ..Default::default()
    };
    (s, opts)
}

/// The vector levels this CPU has (all of them, whatever `SEMDYNREG_SIMD` says).
fn levels() -> Vec<Simd> {
    [Simd::Portable, Simd::Avx2, Simd::Avx512]
        .into_iter()
        .filter(|&l| l <= cpu_simd_level())
        .collect()
}

#[test]
fn all_vector_levels_agree_bit_for_bit() {
    let levels = levels();
    eprintln!("levels on this CPU: {levels:?}");
    let (s, opts) = scene();
    let want = run(levels[0], &s, &opts);
    assert!(want.alpha.iter().any(|&a| a > 0.5), "scene too empty");
    for &level in &levels[1..] {
        assert_same(&run(level, &s, &opts), &want, &format!("{level:?}"));
    }
}

/// Many small tiles on 1, 2 and 5 threads: tile jobs land on different threads each run.
#[test]
fn thread_count_does_not_change_results() {
    let (s, opts) = scene();
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| run(simd_level(), &s, &opts))
    };
    let want = on(1);
    for threads in [2, 5, 5] {
        assert_same(&on(threads), &want, &format!("{threads} threads"));
    }
}

/// The five reference cases (SH 0–3, RGB, Gaussians behind the camera, off-centre principal
/// point) and a random scene, at every vector level.
#[test]
fn batched_projection_equals_the_scalar_reference() {
    let levels = levels();
    let cases: Vec<Case> = CASES.iter().map(|c| Case::load(c).0).collect();
    let (s, opts) = scene();
    let mut inputs: Vec<(&str, Gaussians, &Camera, RenderOptions)> = cases
        .iter()
        .map(|c| (c.name.as_str(), c.gaussians(), &c.cam, c.opts.clone()))
        .collect();
    inputs.push(("random", s.gaussians(), &s.cam, opts));
    for (name, g, cam, opts) in &inputs {
        let mut reference = Rasterizer::new();
        reference.set_scalar_projection(true);
        let want = render(&mut reference, g, cam, opts);
        for &level in &levels {
            let mut r = Rasterizer::new();
            r.set_simd_cap(level);
            assert_same(
                &render(&mut r, g, cam, opts),
                &want,
                &format!("{name}, {level:?}"),
            );
        }
    }
}
