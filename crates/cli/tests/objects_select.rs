//! Objects as units a user acts on, end to end on a tiny toycars scene
//! trained briefly with `--objects`: `render --only/--without`, `export --only` and
//! `export --per-object` (one PLY per object in its own frame, its trajectory at every
//! frame, and the background), and the errors for unknown names, both flags at once and a
//! run without objects.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn semdynreg_out(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_semdynreg"))
        .env("SEMDYNREG_OFFLINE", "1")
        .args(args)
        .env("SEMDYNREG_WEIGHTS", "/nonexistent-weights-dir")
        .output()
        .expect("run semdynreg")
}

fn semdynreg(args: &[&str]) -> String {
    let out = semdynreg_out(args);
    assert!(
        out.status.success(),
        "semdynreg {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Runs `semdynreg ARGS`, which must fail; returns its stderr.
fn semdynreg_err(args: &[&str]) -> String {
    let out = semdynreg_out(args);
    assert!(!out.status.success(), "semdynreg {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn png(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    v.sort();
    v
}

#[test]
fn render_and_export_select_objects_and_export_them_one_by_one() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let cfg = scene::toycars::ToycarsConfig {
        width: 64,
        height: 48,
        frames: 16,
        supersample: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, &scene_dir, &|_, _| {}).unwrap();
    let dict = "white SUV,yellow sedan,green SUV";
    semdynreg(&[
        "segment",
        s(&scene_dir),
        "--dict",
        dict,
        "--masks",
        "gt",
        "--labels",
        "gt",
    ]);
    // A short schedule with a cheap start: the objects start at iteration 80 of 200 (16k of
    // the 40k schedule, rescaled), late enough for the background depth around the masks.
    let config = tmp.path().join("tiny.toml");
    let toml = "[init]\nrandom_points = 4000\n[objects]\nstart_iter = 16000\nlift_points = 600\n\
                track_pose_iters = 10\ntrack_shape_iters = 3\ntrack_refine_iters = 30\n";
    std::fs::write(&config, toml).unwrap();
    let run = tmp.path().join("run");
    semdynreg(&[
        "train",
        s(&scene_dir),
        "--out",
        s(&run),
        "--config",
        s(&config),
        "--iters",
        "200",
        "--no-reg",
        "--objects",
    ]);
    let loaded = train::checkpoint::load_model(&train::checkpoint::latest(&run).unwrap()).unwrap();
    let car = loaded
        .objects()
        .iter()
        .find(|o| o.name == "white-suv")
        .unwrap_or_else(|| panic!("no white-suv in {:?}", loaded.objects()));
    let car_rows = loaded.column.iter().filter(|&&c| c == car.id).count();
    assert!(car_rows > 0, "the car has Gaussians");
    let dataset = train::run::RunInfo::load(&run).unwrap().dataset().unwrap();
    let bg: [u8; 3] = dataset.background.map(|c| (c * 255.0).round() as u8);

    // Renders: full, without the car, the car alone, each in its own folder.
    semdynreg(&["render", s(&run)]);
    let out = semdynreg(&["render", s(&run), "--without", "white-suv"]);
    assert!(out.contains("without white-suv: "), "{out}");
    semdynreg(&["render", s(&run), "--only", "White-SUV"]);
    let renders = run.join("renders");
    let full = pngs(&renders.join("test"));
    let without = pngs(&renders.join("test_without-white-suv"));
    let only = pngs(&renders.join("test_only-white-suv"));
    assert_eq!(full.len(), dataset.test.len());
    assert_eq!(without.len(), full.len());
    assert_eq!(only.len(), full.len());
    let (mut car_px, mut differ_on_car, mut differ_off_car, mut off_car_px) = (0, 0, 0, 0);
    for ((f, w), o) in full.iter().zip(&without).zip(&only) {
        assert_eq!(f.file_name(), w.file_name());
        let (f, w, o) = (png(f), png(w), png(o));
        for ((pf, pw), po) in f.pixels().zip(w.pixels()).zip(o.pixels()) {
            let near = |a: [u8; 3], b: [u8; 3], tol: u8| (0..3).all(|c| a[c].abs_diff(b[c]) <= tol);
            let on_car = !near(po.0, bg, 2);
            let differ = !near(pf.0, pw.0, 3);
            if on_car {
                car_px += 1;
                differ_on_car += usize::from(differ);
            } else {
                off_car_px += 1;
                differ_off_car += usize::from(differ);
            }
        }
    }
    // The car alone covers a part of each image, the background colour elsewhere.
    assert!(car_px > 0, "the car is drawn in --only renders");
    assert!(
        off_car_px > 2 * car_px,
        "--only is background-coloured away from the car ({car_px} car pixels, {off_car_px} others)"
    );
    // Removing the car changes the image where it was, and (almost) only there.
    assert!(differ_on_car > 0, "--without differs from the full render");
    assert!(
        differ_off_car * 100 <= off_car_px,
        "{differ_off_car} of {off_car_px} pixels away from the car differ"
    );

    // `export --only`/`--without` at one time: the rows add up to the full export.
    let ply = |name: &str| tmp.path().join(name);
    let rows = |p: &Path| train::ply::read(p).unwrap().len();
    semdynreg(&[
        "export",
        s(&run),
        "--time",
        "0.5",
        "--out",
        s(&ply("all.ply")),
    ]);
    semdynreg(&[
        "export",
        s(&run),
        "--time",
        "0.5",
        "--out",
        s(&ply("car.ply")),
        "--only",
        "white-suv",
    ]);
    semdynreg(&[
        "export",
        s(&run),
        "--time",
        "0.5",
        "--out",
        s(&ply("rest.ply")),
        "--without",
        "white-suv",
    ]);
    let total = loaded.model.len();
    assert_eq!(rows(&ply("all.ply")), total);
    assert_eq!(rows(&ply("car.ply")), car_rows);
    assert_eq!(rows(&ply("rest.ply")), total - car_rows);

    // `export --per-object`: one PLY per object and the background, the rows add up, and
    // each trajectory file has the pose of every frame of the scene.
    let dir = tmp.path().join("objects");
    semdynreg(&["export", s(&run), "--per-object", "--out", s(&dir)]);
    let mut sum = rows(&dir.join("background.ply"));
    let frames = dataset.train.len() + dataset.val.len() + dataset.test.len();
    for o in loaded.objects() {
        let m = train::ply::read(&dir.join(format!("{}.ply", o.name))).unwrap();
        let n = loaded.column.iter().filter(|&&c| c == o.id).count();
        assert_eq!(m.len(), n, "{}", o.name);
        sum += n;
        let path = dir.join(format!("{}.trajectory.json", o.name));
        let t: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(t["name"], o.name.as_str());
        assert_eq!(t["id"], o.id);
        assert_eq!(t["gaussians"], n);
        let rows = t["frames"].as_array().unwrap();
        assert_eq!(rows.len(), frames, "{}", o.name);
        let mut last = f64::NEG_INFINITY;
        for r in rows {
            let time = r["time"].as_f64().unwrap();
            assert!(time >= last, "frames in time order");
            last = time;
            let pose = o.trajectory.pose(time as f32);
            let close = |v: &Value, want: &[f32]| {
                let got = v.as_array().unwrap();
                assert_eq!(got.len(), want.len());
                for (g, w) in got.iter().zip(want) {
                    assert!((g.as_f64().unwrap() - *w as f64).abs() < 1e-5, "{r}");
                }
            };
            close(&r["translation"], &pose.p);
            close(&r["quaternion_wxyz"], &pose.q);
            let m = pose.to_matrix();
            for (row, want) in r["object_to_world"].as_array().unwrap().iter().zip(&m) {
                close(row, want);
            }
            assert!(["train", "val", "test"].contains(&r["split"].as_str().unwrap()));
        }
    }
    assert_eq!(
        sum, total,
        "object and background PLYs hold every Gaussian once"
    );
    // The car's PLY is in its own frame: placed by its pose at t = 0.5, it is the car of
    // `export --only white-suv --time 0.5`.
    let local = train::ply::read(&dir.join("white-suv.ply")).unwrap();
    let world = train::ply::read(&ply("car.ply")).unwrap();
    let pose = car.trajectory.pose(0.5);
    for i in 0..local.len() {
        let x = [0, 1, 2].map(|c| local.means[i * 3 + c]);
        let y = pose.apply(x);
        for (a, b) in y.iter().zip(&world.means[i * 3..i * 3 + 3]) {
            assert!((a - b).abs() < 1e-4, "row {i}");
        }
    }

    // Errors: an unknown name lists the objects; both flags at once; a run without objects.
    let err = semdynreg_err(&["render", s(&run), "--only", "red-car"]);
    assert!(
        err.contains("`red-car`") && err.contains("white-suv (") && err.contains("background"),
        "{err}"
    );
    let err = semdynreg_err(&[
        "render",
        s(&run),
        "--only",
        "white-suv",
        "--without",
        "background",
    ]);
    assert!(err.contains("cannot be used with"), "{err}");
    let plain = tmp.path().join("plain");
    semdynreg(&[
        "train",
        s(&scene_dir),
        "--out",
        s(&plain),
        "--config",
        s(&config),
        "--iters",
        "4",
        "--no-reg",
        "--no-objects",
    ]);
    let err = semdynreg_err(&["render", s(&plain), "--without", "background"]);
    assert!(err.contains("trained with --objects"), "{err}");
    let err = semdynreg_err(&["export", s(&plain), "--per-object", "--out", s(&dir)]);
    assert!(err.contains("no rigid objects"), "{err}");
}
