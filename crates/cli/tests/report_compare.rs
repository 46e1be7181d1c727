//! End-to-end check of `semdynreg compare` in evaluation mode (`--baseline-renders`,
//! `--semdynreg-renders`, optionally `--rigid-renders`): a tiny toycars scene, synthetic
//! "renders" that differ from the ground truth by known amounts, and the produced
//! results.json / report files, with three methods and with two.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Writes renders = ground truth + `object_offset` on the moving object's pixels + a small
/// pattern everywhere (so no crop is identical and every PSNR is finite).
fn write_renders(ds: &scene::Dataset, moving_id: u8, object_offset: u8, dir: &Path) {
    for f in &ds.test {
        let mask = scene::load_mask(&ds.gt_mask_path(f)).unwrap();
        let (w, h) = (f.image.width, f.image.height);
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            let i = (y * w + x) as usize;
            let base = (x + y) % 3 == 0;
            let mut p = [0u8; 3];
            for (c, v) in p.iter_mut().enumerate() {
                let mut v2 = f.image.data[i * 3 + c];
                if base {
                    v2 = v2.saturating_add(4).min(250);
                }
                if mask.data[i] == moving_id {
                    v2 = if v2 > 127 {
                        v2 - object_offset
                    } else {
                        v2 + object_offset
                    };
                }
                *v = v2;
            }
            image::Rgb(p)
        });
        let path = dir.join(format!("{}.png", f.file_path));
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        img.save(&path).unwrap();
    }
}

fn tiny_scene(root: &Path) -> scene::Dataset {
    let cfg = scene::toycars::ToycarsConfig {
        width: 192,
        height: 144,
        frames: 48,
        supersample: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, root, &|_, _| {}).unwrap();
    scene::load_dataset(root, &scene::LoadOptions::default()).unwrap()
}

fn get<'a>(v: &'a Value, path: &str) -> &'a Value {
    path.split('.').fold(v, |v, k| {
        v.get(k).unwrap_or_else(|| panic!("missing key {path}"))
    })
}

/// Every `src="…"` / `](…)` target of a report, resolved against its folder.
fn linked_files(dir: &Path, text: &str, open: &str, close: char) -> Vec<PathBuf> {
    text.split(open)
        .skip(1)
        .map(|rest| dir.join(&rest[..rest.find(close).unwrap()]))
        .collect()
}

/// What one `compare` on renders left: results.json, report.html, report.md, stdout.
struct Compared {
    results: Value,
    html: String,
    md: String,
    stdout: String,
    out: PathBuf,
}

/// `compare SCENE --out TMP/cmp --<method>-renders DIR …` without LPIPS weights.
fn compare_renders(tmp: &Path, scene_dir: &Path, renders: &[(&str, &Path)]) -> Compared {
    let out = tmp.join("cmp");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_semdynreg"));
    cmd.env("SEMDYNREG_OFFLINE", "1");
    cmd.arg("compare").arg(scene_dir).arg("--out").arg(&out);
    for (method, dir) in renders {
        cmd.arg(format!("--{method}-renders")).arg(dir);
    }
    let output = cmd
        .env("SEMDYNREG_WEIGHTS", tmp.join("no-weights"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let read = |name: &str| std::fs::read_to_string(out.join(name)).unwrap();
    Compared {
        results: serde_json::from_str(&read("results.json")).unwrap(),
        html: read("report.html"),
        md: read("report.md"),
        stdout,
        out,
    }
}

/// Every image the reports link to exists; returns how many report.html links.
fn check_links(c: &Compared) -> usize {
    let html_links = linked_files(&c.out, &c.html, "src=\"", '"');
    let md_links = linked_files(&c.out, &c.md, "](", ')');
    for p in html_links.iter().chain(&md_links) {
        assert!(p.is_file(), "report links to missing {}", p.display());
    }
    html_links.len()
}

/// The `methods` list of results.json as (key, name) pairs.
fn methods(results: &Value) -> Vec<(String, String)> {
    get(results, "methods")
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            let s = |k: &str| m[k].as_str().unwrap().to_string();
            (s("key"), s("name"))
        })
        .collect()
}

/// The keys results.json promises for each method, and the six time steps of its moving
/// crop.
fn check_method_keys(results: &Value, method: &str, statics: usize) {
    let m = get(results, method);
    for k in [
        "full_frame.psnr",
        "full_frame.ssim",
        "full_frame.lpips",
        "moving_object_crop.mean.psnr",
        "moving_object_crop.mean.ssim",
        "moving_object_crop.mean.lpips",
        "deformation_consistency_rms",
        "rigidity_rms",
    ] {
        get(m, k);
    }
    let per_time = get(m, "moving_object_crop.per_time").as_array().unwrap();
    assert_eq!(per_time.len(), 6);
    for (t, entry) in per_time.iter().enumerate() {
        assert_eq!(entry["t_seconds"], t as u64);
        for k in ["psnr", "ssim", "lpips"] {
            assert!(entry.get(k).is_some(), "per_time[{t}] lacks {k}");
        }
    }
    let statics_found = get(m, "static_object_crops").as_object().unwrap();
    assert_eq!(statics_found.len(), statics, "{method}");
    for s in statics_found.values() {
        assert!(get(s, "mean.psnr").is_f64());
    }
}

/// Static crops that do not overlap the moving object's crop score the same in `a` and `b`
/// (the renders differ only on the moving object).
fn check_static_crops_agree(results: &Value, a: &str, b: &str) {
    let boxes = |m: &str, obj: &str| -> Vec<(Option<Vec<u64>>, Option<f64>)> {
        get(results, &format!("{m}.{obj}.per_time"))
            .as_array()
            .unwrap()
            .iter()
            .map(|e| {
                let b = e["crop"]
                    .as_array()
                    .map(|b| b.iter().map(|v| v.as_u64().unwrap()).collect());
                (b, e["psnr"].as_f64())
            })
            .collect()
    };
    let disjoint = |a: &[u64], b: &[u64]| {
        a[0] + a[2] <= b[0] || b[0] + b[2] <= a[0] || a[1] + a[3] <= b[1] || b[1] + b[3] <= a[1]
    };
    let moving_boxes = boxes(a, "moving_object_crop");
    let mut compared = 0;
    let statics = get(results, &format!("{a}.static_object_crops"));
    for name in statics.as_object().unwrap().keys() {
        let key = format!("static_object_crops.{name}");
        for ((bx, a_psnr), ((_, b_psnr), (m, _))) in boxes(a, &key)
            .into_iter()
            .zip(boxes(b, &key).into_iter().zip(&moving_boxes))
        {
            if let (Some(bx), Some(m)) = (bx, m) {
                if disjoint(&bx, m) {
                    assert_eq!(a_psnr, b_psnr, "static object {name}, {a} vs {b}");
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 0, "no static crop clear of the moving object");
}

fn moving_psnr(results: &Value, method: &str) -> f64 {
    get(results, &format!("{method}.moving_object_crop.mean.psnr"))
        .as_f64()
        .unwrap()
}

#[test]
fn compare_on_renders_writes_results_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let ds = tiny_scene(&scene_dir);
    let objects = scene::objects::ObjectsFile::load(&scene_dir.join("objects.json")).unwrap();
    let moving = objects.objects.iter().find(|o| o.moving).unwrap();
    let dirs = ["base", "ours", "rigid"].map(|d| tmp.path().join(d));
    for (dir, offset) in dirs.iter().zip([60, 15, 30]) {
        write_renders(&ds, moving.id, offset, dir);
    }
    let c = compare_renders(
        tmp.path(),
        &scene_dir,
        &[
            ("baseline", &dirs[0]),
            ("semdynreg", &dirs[1]),
            ("rigid", &dirs[2]),
        ],
    );
    assert!(
        c.stdout.contains("t=5s") && c.stdout.contains("report.html"),
        "{}",
        c.stdout
    );
    let names = ["baseline", "SemDynReg (paper)", "rigid objects"];
    for name in names {
        assert!(c.stdout.contains(name), "{name} missing in\n{}", c.stdout);
    }
    let listed = methods(&c.results);
    let keys: Vec<&str> = listed.iter().map(|(k, _)| k.as_str()).collect();
    assert_eq!(keys, ["baseline", "semdynreg", "rigid"]);
    let shown: Vec<&str> = listed.iter().map(|(_, n)| n.as_str()).collect();
    assert_eq!(shown, names);
    for method in keys {
        check_method_keys(&c.results, method, objects.objects.len() - 1);
        let crops = get(&c.results, &format!("{method}.moving_object_crops"));
        assert_eq!(
            crops[&moving.name],
            *get(&c.results, &format!("{method}.moving_object_crop"))
        );
    }
    // LPIPS weights are absent here: null, and the protocol says so.
    assert!(get(&c.results, "rigid.full_frame.lpips").is_null());
    assert!(get(&c.results, "protocol.lpips")
        .as_str()
        .unwrap()
        .contains("not computed"));
    // The smaller the perturbation on the moving object, the better its crop scores.
    let psnr = |m: &str| moving_psnr(&c.results, m);
    assert!(
        psnr("semdynreg") > psnr("rigid") + 3.0,
        "{} vs {}",
        psnr("semdynreg"),
        psnr("rigid")
    );
    assert!(
        psnr("rigid") > psnr("baseline") + 3.0,
        "{} vs {}",
        psnr("rigid"),
        psnr("baseline")
    );
    check_static_crops_agree(&c.results, "baseline", "semdynreg");
    check_static_crops_agree(&c.results, "baseline", "rigid");
    // 6 rows × 9 columns (the moving object is visible in every test frame) + the crop PSNR plot.
    let links = check_links(&c);
    assert_eq!(links, 6 * 9 + 1, "images in report.html");
    for name in names {
        assert!(c.html.contains(&format!("<th>zoom: {name}</th>")), "{name}");
        assert!(c.html.contains(&format!("<tr><th>{name}</th>")), "{name}");
        assert!(c.md.contains(&format!("| {name} |")), "{name}");
    }
    assert!(c.out.join("images/t0s_zoom_rigid.png").is_file());
}

#[test]
fn compare_on_two_renders_has_no_rigid_column() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let ds = tiny_scene(&scene_dir);
    let (base, ours) = (tmp.path().join("base"), tmp.path().join("ours"));
    write_renders(&ds, 0, 60, &base);
    write_renders(&ds, 0, 15, &ours);
    let c = compare_renders(
        tmp.path(),
        &scene_dir,
        &[("baseline", &base), ("semdynreg", &ours)],
    );
    let keys: Vec<String> = methods(&c.results).into_iter().map(|(k, _)| k).collect();
    assert_eq!(keys, ["baseline", "semdynreg"]);
    assert!(c.results.get("rigid").is_none(), "no rigid key");
    check_method_keys(&c.results, "semdynreg", 2);
    assert!(moving_psnr(&c.results, "semdynreg") > moving_psnr(&c.results, "baseline") + 5.0);
    let notes = get(&c.results, "notes").to_string();
    assert!(notes.contains("--rigid-renders"), "{notes}");
    // 6 rows × 7 columns + the crop PSNR plot; no rigid row, column or image.
    let links = check_links(&c);
    assert_eq!(links, 6 * 7 + 1, "images in report.html");
    assert!(!c.html.contains("<th>zoom: rigid objects</th>"));
    assert!(!c.html.contains("<tr><th>rigid objects</th>"));
    assert!(!c.stdout.contains("rigid objects"), "{}", c.stdout);
    assert!(!c.out.join("images/t0s_rigid.png").exists());
}

#[test]
fn every_moving_object_gets_its_crop_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let ds = tiny_scene(&scene_dir);
    // A second moving object, as `synth toycars --route` scenes have: the parked sedan
    // marked as moving scores its crops the same way (scoring reads only the masks).
    let path = scene_dir.join("objects.json");
    let mut objects = scene::objects::ObjectsFile::load(&path).unwrap();
    objects.objects[1].moving = true;
    objects.save(&path).unwrap();
    let names: Vec<String> = objects.objects.iter().map(|o| o.name.clone()).collect();
    let (base, ours) = (tmp.path().join("base"), tmp.path().join("ours"));
    write_renders(&ds, 0, 60, &base);
    write_renders(&ds, 0, 15, &ours);
    let c = compare_renders(
        tmp.path(),
        &scene_dir,
        &[("baseline", &base), ("semdynreg", &ours)],
    );
    let r = &c.results;
    let moving: Vec<&str> = get(r, "protocol.moving_objects")
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(moving, [&names[0], &names[1]]);
    assert_eq!(get(r, "protocol.moving_object"), &names[0]);
    for method in ["baseline", "semdynreg"] {
        let crops = get(r, &format!("{method}.moving_object_crops"));
        assert_eq!(crops.as_object().unwrap().len(), 2, "{method}");
        assert_eq!(
            crops[&names[0]],
            *get(r, &format!("{method}.moving_object_crop"))
        );
        let statics = get(r, &format!("{method}.static_object_crops"));
        let statics: Vec<&String> = statics.as_object().unwrap().keys().collect();
        assert_eq!(statics, [&names[2]], "{method}");
    }
    for name in &names[..2] {
        let caption = format!("Zoomed moving object ({name}) across time");
        assert!(c.stdout.contains(&caption), "{caption} in\n{}", c.stdout);
        assert!(c.html.contains(&caption), "{caption}");
        assert!(c
            .html
            .contains(&format!("Moving object ({name}) crop PSNR over time")));
    }
    check_links(&c);
}

#[test]
fn compare_names_a_missing_render() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let ds = tiny_scene(&scene_dir);
    let base = tmp.path().join("base");
    write_renders(&ds, 0, 10, &base);
    let output = Command::new(env!("CARGO_BIN_EXE_semdynreg"))
        .env("SEMDYNREG_OFFLINE", "1")
        .args(["compare", scene_dir.to_str().unwrap(), "--out"])
        .arg(tmp.path().join("cmp"))
        .arg("--baseline-renders")
        .arg(&base)
        .arg("--semdynreg-renders")
        .arg(tmp.path().join("empty"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("SemDynReg (paper) renders") && stderr.contains("test/r_000"),
        "{stderr}"
    );
}

/// A scene without ground truth (a real capture) whose maps `segment --track` made: the
/// crops come from the held-out frames' tracked maps, resampled when `segment` ran at
/// another size, with the same numbers as the ground truth's when the maps are the same.
#[test]
fn a_tracked_scene_without_ground_truth_scores_its_objects_crops() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let ds = tiny_scene(&scene_dir);
    let (base, ours) = (tmp.path().join("base"), tmp.path().join("ours"));
    write_renders(&ds, 0, 60, &base);
    write_renders(&ds, 0, 15, &ours);
    let renders = [("baseline", base.as_path()), ("semdynreg", ours.as_path())];
    let truth = compare_renders(&tmp.path().join("truth"), &scene_dir, &renders).results;

    // The ground truth becomes tracked maps at twice the size; masks/ and objects.json go.
    let objects = scene::objects::ObjectsFile::load(&scene_dir.join("objects.json")).unwrap();
    for f in ds.train.iter().chain(&ds.test) {
        let m = scene::load_mask(&ds.gt_mask_path(f)).unwrap();
        let big = image::GrayImage::from_fn(m.width * 2, m.height * 2, |x, y| {
            image::Luma([m.data[((y / 2) * m.width + x / 2) as usize]])
        });
        let to = ds.semantics_path(f);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        big.save(&to).unwrap();
    }
    let tracked: Vec<Value> = objects
        .objects
        .iter()
        .map(|o| serde_json::json!({ "name": o.name }))
        .collect();
    let record = serde_json::json!({ "track": { "objects": tracked } });
    std::fs::write(
        scene_dir.join("semantics/semantics.json"),
        record.to_string(),
    )
    .unwrap();
    std::fs::remove_dir_all(scene_dir.join("masks")).unwrap();
    std::fs::remove_file(scene_dir.join("objects.json")).unwrap();

    let c = compare_renders(&tmp.path().join("tracked"), &scene_dir, &renders);
    let r = &c.results;
    assert!(
        get(r, "protocol.crop_policy")
            .as_str()
            .unwrap()
            .starts_with("tracked object-ID map"),
        "{}",
        get(r, "protocol.crop_policy")
    );
    let moving = get(r, "protocol.moving_objects").as_array().unwrap();
    assert_eq!(
        moving.len(),
        objects.objects.len(),
        "every tracked object is scored"
    );
    let mover = &objects.objects[0].name;
    for method in ["baseline", "semdynreg"] {
        let key = format!("{method}.moving_object_crops");
        let (ours, theirs) = (
            &get(r, &key)[mover.as_str()],
            &get(&truth, &key)[mover.as_str()],
        );
        assert!(ours.is_object(), "{method}: no crop series for {mover}");
        assert_eq!(ours, theirs, "{method}: tracked crops of {mover} differ");
    }
    check_links(&c);
}
