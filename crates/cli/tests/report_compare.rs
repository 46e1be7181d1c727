//! End-to-end check of `semdynreg compare` in evaluation mode (`--baseline-renders`,
//! `--semdynreg-renders`): a tiny toycars scene, two synthetic "renders" that differ from
//! the ground truth by known amounts, and the produced results.json / report files.

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

#[test]
fn compare_on_renders_writes_results_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let ds = tiny_scene(&scene_dir);
    let objects = scene::objects::ObjectsFile::load(&scene_dir.join("objects.json")).unwrap();
    let moving = objects.objects.iter().find(|o| o.moving).unwrap();
    let (base, ours, out) = (
        tmp.path().join("base"),
        tmp.path().join("ours"),
        tmp.path().join("cmp"),
    );
    write_renders(&ds, moving.id, 60, &base);
    write_renders(&ds, moving.id, 15, &ours);

    let output = Command::new(env!("CARGO_BIN_EXE_semdynreg"))
        .arg("compare")
        .arg(&scene_dir)
        .arg("--out")
        .arg(&out)
        .arg("--baseline-renders")
        .arg(&base)
        .arg("--semdynreg-renders")
        .arg(&ours)
        .env("SEMDYNREG_WEIGHTS", tmp.path().join("no-weights"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains("t=5s") && stdout.contains("report.html"),
        "{stdout}"
    );

    let results: Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    for method in ["baseline", "semdynreg"] {
        let m = get(&results, method);
        for k in [
            "full_frame.psnr",
            "full_frame.ssim",
            "full_frame.lpips",
            "moving_object_crop.mean.psnr",
            "moving_object_crop.mean.ssim",
            "moving_object_crop.mean.lpips",
            "deformation_consistency_rms",
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
        let statics = get(m, "static_object_crops").as_object().unwrap();
        assert_eq!(statics.len(), objects.objects.len() - 1);
        for s in statics.values() {
            assert!(get(s, "mean.psnr").is_f64());
        }
    }
    // LPIPS weights are absent here: null, and the protocol says so.
    assert!(get(&results, "baseline.full_frame.lpips").is_null());
    assert!(get(&results, "protocol.lpips")
        .as_str()
        .unwrap()
        .contains("not computed"));
    // The smaller perturbation on the moving object scores better; static crops agree.
    let psnr = |m: &str| {
        get(&results, &format!("{m}.moving_object_crop.mean.psnr"))
            .as_f64()
            .unwrap()
    };
    assert!(
        psnr("semdynreg") > psnr("baseline") + 5.0,
        "{} vs {}",
        psnr("semdynreg"),
        psnr("baseline")
    );
    // Static crops that do not overlap the moving object's crop score the same in both.
    let boxes = |m: &str, obj: &str| -> Vec<(Option<Vec<u64>>, Option<f64>)> {
        get(&results, &format!("{m}.{obj}.per_time"))
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
    let moving_boxes = boxes("baseline", "moving_object_crop");
    let mut compared = 0;
    for name in get(&results, "baseline.static_object_crops")
        .as_object()
        .unwrap()
        .keys()
    {
        let key = format!("static_object_crops.{name}");
        for ((b, base_psnr), ((_, ours_psnr), (m, _))) in boxes("baseline", &key)
            .into_iter()
            .zip(boxes("semdynreg", &key).into_iter().zip(&moving_boxes))
        {
            if let (Some(b), Some(m)) = (b, m) {
                if disjoint(&b, m) {
                    assert_eq!(base_psnr, ours_psnr, "static object {name}");
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 0, "no static crop clear of the moving object");

    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let html_links = linked_files(&out, &html, "src=\"", '"');
    let md_links = linked_files(&out, &md, "](", ')');
    // 6 rows × 7 columns (the moving object is visible in every test frame) + the crop PSNR plot.
    assert!(
        html_links.len() >= 43,
        "{} images in report.html",
        html_links.len()
    );
    for p in html_links.iter().chain(&md_links) {
        assert!(p.is_file(), "report links to missing {}", p.display());
    }
}

#[test]
fn compare_names_a_missing_render() {
    let tmp = tempfile::tempdir().unwrap();
    let scene_dir = tmp.path().join("scene");
    let ds = tiny_scene(&scene_dir);
    let base = tmp.path().join("base");
    write_renders(&ds, 0, 10, &base);
    let output = Command::new(env!("CARGO_BIN_EXE_semdynreg"))
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
        stderr.contains("SemDynReg renders") && stderr.contains("test/r_000"),
        "{stderr}"
    );
}
