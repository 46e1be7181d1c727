//! PNG round trips of images and object-ID masks, and the refusal of non-grayscale masks.

use scene::{load_mask, save_mask, ImageU8, MaskU8};

#[test]
fn image_and_mask_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let img = ImageU8 {
        width: 3,
        height: 2,
        data: (0..18).map(|v| v * 14).collect(),
    };
    let p = dir.path().join("sub/img.png");
    img.save_png(&p).unwrap();
    assert_eq!(ImageU8::load(&p, [0.0; 3]).unwrap(), img);
    let mask = MaskU8 {
        width: 3,
        height: 2,
        data: vec![0, 1, 2, 255, 255, 0],
    };
    let m = dir.path().join("masks/train/r_000.png");
    save_mask(&m, &mask).unwrap();
    assert_eq!(load_mask(&m).unwrap(), mask);
    // Only the final file remains: the temporary file was renamed, not left behind.
    assert_eq!(std::fs::read_dir(m.parent().unwrap()).unwrap().count(), 1);
}

#[test]
fn colour_mask_is_refused_with_file_name() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("rgb.png");
    ImageU8 {
        width: 1,
        height: 1,
        data: vec![1, 2, 3],
    }
    .save_png(&p)
    .unwrap();
    let e = load_mask(&p).unwrap_err().to_string();
    assert!(
        e.contains("rgb.png") && e.contains("8-bit grayscale"),
        "{e}"
    );
}
