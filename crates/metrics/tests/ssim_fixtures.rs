//! SSIM (both variants) and PSNR against values computed independently with scikit-image and
//! a numpy transcription of 3DGS's `ssim`, stored by `scripts/make_ssim_fixtures.py`.

use metrics::{load_rgb, psnr, SsimVariant, SsimWorkspace};
use std::path::PathBuf;

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

#[test]
fn ssim_and_psnr_match_independent_values() {
    let text = std::fs::read_to_string(fixtures().join("ssim_expected.json")).unwrap();
    let expected: serde_json::Value = serde_json::from_str(&text).unwrap();
    let cases = expected.as_object().unwrap();
    assert_eq!(cases.len(), 4);
    let mut ws = SsimWorkspace::new();
    for (name, want) in cases {
        let a = load_rgb(&fixtures().join(format!("{name}_a.png"))).unwrap();
        let b = load_rgb(&fixtures().join(format!("{name}_b.png"))).unwrap();
        assert_eq!(a.width as u64, want["width"].as_u64().unwrap());
        let (w, h) = (a.width, a.height);
        let get = |k: &str| want[k].as_f64().unwrap();
        let g = ws
            .ssim_variant(&a.data, &b.data, w, h, SsimVariant::Gs3d)
            .unwrap() as f64;
        let s = ws
            .ssim_variant(&a.data, &b.data, w, h, SsimVariant::Skimage)
            .unwrap() as f64;
        let p = psnr(&a.data, &b.data);
        assert!(
            (g - get("ssim_3dgs")).abs() < 2e-5,
            "{name}: 3dgs {g} vs {}",
            get("ssim_3dgs")
        );
        assert!(
            (s - get("ssim_skimage")).abs() < 2e-5,
            "{name}: skimage {s} vs {}",
            get("ssim_skimage")
        );
        assert!(
            (p - get("psnr")).abs() < 1e-4,
            "{name}: psnr {p} vs {}",
            get("psnr")
        );
    }
}
