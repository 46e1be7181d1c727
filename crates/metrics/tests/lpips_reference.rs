//! LPIPS on the LPIPS project's official example images (`lpips_2imgs.py` defaults: AlexNet,
//! v0.1): ex_ref vs ex_p0 = 0.722, ex_ref vs ex_p1 = 0.137 (three decimals, from the
//! PerceptualSimilarity README). We get 0.721881 and 0.137566: the README's 0.137 is older
//! than the released weights, with which the official `test_network.py` prints
//! "(0.722, 0.138)" (richzhang/PerceptualSimilarity issue #120), so both are checked to
//! round to those three decimals, and to stay within 2e-5 of the values that the earlier,
//! independent candle `conv2d` implementation gave (0.72188, 0.13757), which pins the
//! convolution, pooling and normalization code far tighter than three decimals do.
//! Needs the real weights (`semdynreg weights fetch lpips --dir DIR`, `SEMDYNREG_WEIGHTS=DIR`) and
//! the example images in `tests/fixtures/lpips` (README there: source and licence); skips
//! with a printed reason when the weights are absent (the images are always there).

use metrics::{load_rgb, Lpips, LpipsNet, RgbImage};
use std::path::PathBuf;

/// The LPIPS project's example images, kept in this crate.
fn reference_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/lpips")
}

fn model(net: LpipsNet) -> Option<Lpips> {
    match Lpips::from_env(net) {
        Ok(m) => Some(m),
        Err(e) => {
            eprintln!("SKIPPED: {e}");
            None
        }
    }
}

/// The three images; they are part of the repository, so a missing one is a failure.
fn images() -> [RgbImage; 3] {
    let dir = reference_dir();
    let load = |n: &str| {
        let path = dir.join(n);
        load_rgb(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    };
    [load("ex_ref.png"), load("ex_p0.png"), load("ex_p1.png")]
}

fn dist(m: &Lpips, a: &RgbImage, b: &RgbImage) -> f32 {
    m.distance(&a.data, &b.data, a.width, a.height).unwrap()
}

#[test]
fn alex_matches_official_example_values() {
    let [r, p0, p1] = images();
    let Some(m) = model(LpipsNet::Alex) else {
        return;
    };
    let d0 = dist(&m, &r, &p0);
    let d1 = dist(&m, &r, &p1);
    eprintln!("LPIPS-Alex: ref/p0 = {d0:.6}, ref/p1 = {d1:.6}");
    assert_eq!(format!("{d0:.3}"), "0.722", "ref vs p0: {d0}");
    assert_eq!(format!("{d1:.3}"), "0.138", "ref vs p1: {d1}");
    assert!((d0 - 0.72188).abs() < 2e-5, "ref vs p0 drifted: {d0}");
    assert!((d1 - 0.13757).abs() < 2e-5, "ref vs p1 drifted: {d1}");
    assert!(
        dist(&m, &r, &r).abs() < 1e-6,
        "identical images must give 0"
    );
}

#[test]
fn vgg_matches_published_pytorch_values() {
    let [r, p0, p1] = images();
    let Some(m) = model(LpipsNet::Vgg) else {
        return;
    };
    let d0 = dist(&m, &r, &p0);
    let d1 = dist(&m, &r, &p1);
    eprintln!("LPIPS-VGG: ref/p0 = {d0:.6}, ref/p1 = {d1:.6}");
    // The official PyTorch LPIPS-VGG values quoted by alexlee-gk/lpips-tensorflow's test:
    // ex_ref/ex_p0 = 0.569, ex_ref/ex_p1 = 0.422.
    assert!((d0 - 0.569).abs() < 5e-4, "ref vs p0: {d0}");
    assert!((d1 - 0.422).abs() < 5e-4, "ref vs p1: {d1}");
    assert!(dist(&m, &r, &r).abs() < 1e-6);
}

#[test]
fn small_images_are_rejected_with_an_error() {
    let Some(m) = model(LpipsNet::Alex) else {
        return;
    };
    let img = vec![0.5f32; 20 * 40 * 3];
    let err = m.distance(&img, &img, 20, 40).unwrap_err();
    assert!(err.to_string().contains("smaller than the 31 px"), "{err}");
}

#[test]
fn missing_weights_name_the_path() {
    let err = Lpips::load(
        LpipsNet::Alex,
        std::path::Path::new("/nonexistent/x.safetensors"),
    )
    .err()
    .unwrap();
    assert!(
        err.to_string().contains("/nonexistent/x.safetensors"),
        "{err}"
    );
}
