//! `semdynreg prepare`: a synthetic video with known cameras (a toycars scene rendered
//! along its smooth camera path, encoded with ffmpeg) must come back with its cameras
//! (after a similarity alignment: the median centre within 4 % of the camera path's
//! extent, 21 of 24 within 8 %; rotations within 1°), `--masks` must keep features off
//! the masked objects, and bad inputs (an unreadable video, a folder without images, frames COLMAP cannot
//! register, a missing tool) must fail with an error naming the cause and leave nothing
//! under `--out`.
//!
//! ffmpeg and COLMAP are the system's (`apt-get install ffmpeg colmap`): without them the
//! tests that run them are skipped with a message, except in CI (CI_REQUIRE_SYSTEM=1),
//! where they fail.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn semdynreg(args: &[&str], path_env: Option<&str>) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_semdynreg"));
    c.args(args).env("RUST_LOG", "warn");
    if let Some(p) = path_env {
        c.env("PATH", p);
    }
    c.output().expect("run semdynreg")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn on_path(name: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(name).is_file()))
}

/// Whether ffmpeg and colmap are installed; in CI their absence fails the test.
fn tools() -> bool {
    let missing: Vec<&str> = ["ffmpeg", "colmap"]
        .into_iter()
        .filter(|t| !on_path(t))
        .collect();
    if missing.is_empty() {
        return true;
    }
    let msg = format!(
        "{} not installed (apt-get install {})",
        missing.join(" and "),
        missing.join(" ")
    );
    if std::env::var("CI_REQUIRE_SYSTEM").is_ok_and(|v| v == "1") {
        panic!("{msg}; CI_REQUIRE_SYSTEM=1 requires them");
    }
    eprintln!("SKIPPED: {msg}");
    false
}

/// Nothing under `out`, and no temporary folder left beside it.
fn assert_nothing_written(out: &Path) {
    assert!(!out.exists(), "{} was written", out.display());
    let leftovers: Vec<PathBuf> = std::fs::read_dir(out.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .contains(".partial")
        })
        .collect();
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}

fn fail(args: &[&str], path_env: Option<&str>) -> String {
    let o = semdynreg(args, path_env);
    assert!(!o.status.success(), "semdynreg {args:?} should fail");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

const W: u32 = 256;
const H: u32 = 192;
const N: usize = 24;

/// A toycars scene and its frames in time order as an H.264 video at 24 fps.
fn synthetic_video(tmp: &Path) -> (PathBuf, PathBuf) {
    let scene_dir = tmp.join("toycars");
    let cfg = scene::toycars::ToycarsConfig {
        width: W,
        height: H,
        frames: N,
        supersample: true,
        drive: 0.25,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, &scene_dir, &|_, _| {}).unwrap();
    let seq = tmp.join("seq");
    std::fs::create_dir_all(&seq).unwrap();
    for i in 0..N {
        let (_, key) = scene::toycars::frame_key(i);
        let img = scene::ImageU8::load(&scene_dir.join(format!("{key}.png")), [0.0; 3]).unwrap();
        image::RgbImage::from_raw(img.width, img.height, img.data)
            .unwrap()
            .save(seq.join(format!("{i:05}.png")))
            .unwrap();
    }
    let video = tmp.join("toycars.mp4");
    let o = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "24", "-i"])
        .arg(seq.join("%05d.png"))
        .args(["-c:v", "libx264", "-crf", "12", "-pix_fmt", "yuv420p"])
        .arg(&video)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "ffmpeg: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    (scene_dir, video)
}

/// The generated scene's object-ID maps as one mask per video frame (`00000.png`…).
fn masks_per_frame(toycars: &Path, dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    for i in 0..N {
        let (_, key) = scene::toycars::frame_key(i);
        std::fs::copy(
            scene::mask_path(toycars, &key),
            dir.join(format!("{i:05}.png")),
        )
        .unwrap();
    }
    dir.to_path_buf()
}

/// `prepare` with the true intrinsics (and `extra` options), checked report and layout,
/// and the cameras' errors against the generator's.
fn prepare_and_score(video: &Path, out: &Path, extra: &[&str]) -> scene::align::PoseErrors {
    // The generated scene is a flat mat seen from one side: its focal length is not
    // observable (COLMAP's self-calibration lands 20-30 % off), so the true intrinsics are
    // given and held fixed and the test checks the poses. Self-calibration is measured on
    // the real capture (docs/real-data.md).
    let truth = scene::toycars::camera(W, H, 0.0);
    let params = format!("{},{},{},{}", truth.fx, truth.fy, truth.cx, truth.cy);
    let mut args = vec![
        "prepare",
        s(video),
        "--out",
        s(out),
        "--threads",
        "2",
        "--camera-model",
        "PINHOLE",
        "--camera-params",
        &params,
    ];
    args.extend(extra);
    let o = semdynreg(&args, None);
    assert!(
        o.status.success(),
        "prepare failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("prepare.json")).unwrap()).unwrap();
    assert_eq!(report["frames_extracted"], N, "{report:#}");
    assert_eq!(report["frames_registered"], N, "{report:#}");
    assert_eq!(report["failed"].as_array().unwrap().len(), 0);
    assert_eq!(report["time_source"], "video timestamps");
    assert_eq!(report["intrinsics_given"], true);
    let err = report["mean_reprojection_error_px"].as_f64().unwrap();
    assert!(err > 0.0 && err < 2.0, "mean reprojection error {err}");

    let ds = scene::load_dataset(out, &scene::LoadOptions::default()).unwrap();
    assert_eq!(ds.kind, scene::DatasetKind::DNerf);
    // Every 8th frame (0, 8, 16) held out.
    assert_eq!((ds.train.len(), ds.test.len()), (N - 3, 3));
    assert!(ds.point_cloud.as_ref().is_some_and(|p| p.len() > 50));
    // The given intrinsics are the scene's.
    let fx = ds.train[0].camera.fx;
    assert!(
        (fx / truth.fx - 1.0).abs() < 1e-4,
        "fx {fx} vs {}",
        truth.fx
    );
    let mut est = Vec::new();
    let mut gt = Vec::new();
    for f in ds.all_frames() {
        let k = (f.time * (N - 1) as f32).round() as usize;
        assert!(
            (f.time - k as f32 / (N - 1) as f32).abs() < 1e-4,
            "time {}",
            f.time
        );
        assert_eq!(f.image.width, f.camera.width);
        est.push(f.camera.clone());
        gt.push(scene::toycars::camera(W, H, k as f32 / (N - 1) as f32));
    }
    let e = scene::align::compare_cameras(&gt, &est).unwrap();
    eprintln!(
        "{extra:?}: centres: median {:.3} %, max {:.3} %; rotations: median {:.3}°, max {:.3}°",
        100.0 * e.centre_median_rel,
        100.0 * e.centre_max_rel,
        e.rotation_median_deg,
        e.rotation_max_deg
    );
    e
}

/// How many of `errs` are below `bound`.
fn within(errs: &[f64], bound: f64) -> usize {
    errs.iter().filter(|&&x| x < bound).count()
}

#[test]
fn a_synthetic_video_gives_back_its_cameras() {
    if !tools() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (toycars, video) = synthetic_video(tmp.path());

    // The extent is the camera path's (a 30° arc, 0.57 for a target 2.7 away): 4 % / 8 %
    // of it is 0.8 % / 1.7 % of the viewing distance, about one / two pixels' footprint on
    // the mat at 256×192, where SIFT finds only ~250 features per frame (measured over
    // ten runs: median 1.6-3.0 %; COLMAP's result varies with its threads, and a frame
    // can come out off: one of 24 at 27 % in one run). So the bounds hold for the median
    // and 21 of the 24 frames.
    let out = tmp.path().join("prepared");
    let e = prepare_and_score(&video, &out, &[]);
    let rel: Vec<f64> = e.centre_errors.iter().map(|x| x / e.extent).collect();
    assert!(
        e.centre_median_rel < 0.04 && within(&rel, 0.08) >= N - 3,
        "{e:?}"
    );
    assert!(
        e.rotation_median_deg < 1.0 && within(&e.rotation_errors_deg, 1.0) >= N - 3,
        "{e:?}"
    );

    // --masks: the vehicles' pixels (object-ID maps ≠ 255) get no features, so no point
    // of the model is observed on them, and the poses stay as good.
    let masks = masks_per_frame(&toycars, &tmp.path().join("masks"));
    let masked = tmp.path().join("masked");
    let e = prepare_and_score(&video, &masked, &["--masks", s(&masks)]);
    assert!(e.centre_median_rel < 0.04, "{e:?}");
    let model = scene::colmap::read_model(&masked.join("colmap/sparse/0")).unwrap();
    let mut observed = 0;
    for image in &model.images {
        let stem = image.name.trim_end_matches(".png");
        let m = scene::load_mask(&masks.join(format!("{stem}.png"))).unwrap();
        for &(x, y, id) in &image.points2d {
            if id == u64::MAX {
                continue;
            }
            observed += 1;
            let (px, py) = (x.floor() as usize, y.floor() as usize);
            let v = m.data[py.min(H as usize - 1) * W as usize + px.min(W as usize - 1)];
            assert_eq!(
                v,
                scene::MASK_BACKGROUND,
                "{} sees a point on object {v}",
                image.name
            );
        }
    }
    assert!(observed > 100, "{observed} observations");

    // The same check through the command, against the generated scene's own cameras.
    let o = semdynreg(
        &[
            "compare-poses",
            s(&out),
            "--reference",
            s(&toycars),
            "--max-centre",
            "0.5",
            "--max-rotation-deg",
            "1",
        ],
        None,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("paired by time"));

    // --out exists: refused without --force.
    let e = fail(&["prepare", s(&video), "--out", s(&out)], None);
    assert!(e.contains("already exists"), "{e}");
    // Masks that do not fit the frames: refused, naming the folder.
    let few = tmp.path().join("few-masks");
    std::fs::create_dir_all(&few).unwrap();
    std::fs::copy(masks.join("00000.png"), few.join("a.png")).unwrap();
    let o2 = tmp.path().join("o2");
    let e = fail(
        &["prepare", s(&video), "--out", s(&o2), "--masks", s(&few)],
        None,
    );
    assert!(e.contains("1 mask images for 24 frames"), "{e}");
    assert_nothing_written(&o2);
}

#[test]
fn bad_inputs_fail_clearly_and_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");

    // A folder without images (no tool needed to say so).
    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::write(empty.join("notes.txt"), "x").unwrap();
    let e = fail(&["prepare", s(&empty), "--out", s(&out)], None);
    assert!(e.contains("holds no images") && e.contains("empty"), "{e}");
    assert_nothing_written(&out);

    // A missing tool: one error that says how to install it.
    let frames = tmp.path().join("gray");
    std::fs::create_dir_all(&frames).unwrap();
    for k in 0..6 {
        image::RgbImage::from_pixel(64, 48, image::Rgb([128, 128, 128]))
            .save(frames.join(format!("{k:03}.png")))
            .unwrap();
    }
    let no_tools = tmp.path().join("no-tools");
    std::fs::create_dir_all(&no_tools).unwrap();
    let e = fail(
        &["prepare", s(&frames), "--out", s(&out)],
        Some(s(&no_tools)),
    );
    assert!(
        e.contains("`colmap` was not found") && e.contains("apt-get install colmap"),
        "{e}"
    );
    assert_nothing_written(&out);

    if !tools() {
        return;
    }
    // An unreadable video.
    let bad = tmp.path().join("broken.mp4");
    std::fs::write(&bad, b"this is not a video at all".repeat(100)).unwrap();
    let e = fail(&["prepare", s(&bad), "--out", s(&out)], None);
    assert!(
        e.contains("ffmpeg could not read") && e.contains("broken.mp4"),
        "{e}"
    );
    assert_nothing_written(&out);

    // Frames COLMAP cannot register (uniform gray: no features to match).
    let e = fail(
        &["prepare", s(&frames), "--out", s(&out), "--threads", "2"],
        None,
    );
    assert!(e.contains("COLMAP could not register"), "{e}");
    assert_nothing_written(&out);
}
