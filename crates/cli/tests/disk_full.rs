//! Writing into a folder that fails mid-write ends with a clear error and leaves no partial
//! file under its final name: `train` (checkpoints), `render` (PNGs) and
//! `export` (PLY) into a small tmpfs that fills up, and into a read-only one.
//!
//! The tmpfs is mounted in a private user + mount namespace (`unshare --user
//! --map-root-user --mount`), so the test needs no root and leaves no mount behind; where
//! namespaces are unavailable it says so and skips. Free space is set with a filler file.
#![cfg(target_os = "linux")]

use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_semdynreg");

/// Runs `script` under `sh` with a fresh tmpfs mounted at `$D` (`opts` as `mount -o`) and
/// `$OUT` a normal folder to copy results into. `None` when namespaces are unavailable.
fn in_tmpfs(tmp: &Path, opts: &str, script: &str) -> Option<(bool, String)> {
    let d = tmp.join("mnt");
    let out = tmp.join("out");
    std::fs::create_dir_all(&d).unwrap();
    std::fs::create_dir_all(&out).unwrap();
    let full = format!("set -e\nmount -t tmpfs -o {opts} tmpfs \"$D\"\n{script}");
    let o = Command::new("unshare")
        .args(["--user", "--map-root-user", "--mount", "sh", "-c", &full])
        .env("D", &d)
        .env("OUT", &out)
        .env("BIN", BIN)
        .env("RUST_BACKTRACE", "0")
        .env("SEMDYNREG_OFFLINE", "1")
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&o.stderr).into_owned();
    if text.contains("unshare:") || text.contains("mount:") {
        eprintln!("SKIPPED: no private mount namespace here ({})", text.trim());
        return None;
    }
    Some((o.status.success(), text))
}

/// Fills the tmpfs at `$D` until `free` bytes are left.
fn fill(free: u64) -> String {
    format!(
        "avail=$(df --output=avail -B1 \"$D\" | tail -1)\n\
         head -c $((avail - {free})) /dev/zero > \"$D/filler\"\n"
    )
}

fn toycars(tmp: &Path) -> PathBuf {
    let scene = tmp.join("scene");
    let cfg = scene::toycars::ToycarsConfig {
        width: 32,
        height: 24,
        frames: 16,
        supersample: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, &scene, &|_, _| {}).unwrap();
    let toml = "iterations = 40\n[init]\nrandom_points = 1500\n[log]\ncheckpoint_interval = 5\n\
                eval_interval = 0\nkeep_checkpoints = 2\n";
    std::fs::write(tmp.join("small.toml"), toml).unwrap();
    scene
}

/// Every checkpoint folder under `run/checkpoints` loads and verifies; `latest` names one;
/// no temporary is left.
fn checkpoints_intact(run: &Path) -> usize {
    let root = run.join("checkpoints");
    let mut n = 0;
    for e in std::fs::read_dir(&root).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        assert!(
            !name.starts_with('.'),
            "temporary {name} left in {}",
            root.display()
        );
        if name.starts_with("iter_") {
            train::checkpoint::load_model(&e.path())
                .unwrap_or_else(|err| panic!("{name} is not intact: {err}"));
            n += 1;
        }
    }
    assert!(train::checkpoint::latest(run).is_ok());
    n
}

#[test]
fn a_full_disk_stops_train_with_every_checkpoint_intact() {
    let tmp = tempfile::tempdir().unwrap();
    let run = trained_run(tmp.path());
    let scene = tmp.path().join("scene");
    let cfg = tmp.path().join("small.toml");
    // Room for about two checkpoints, not for the whole run (keep 2 + one in flight).
    let one = du(&train::checkpoint::latest(&run).unwrap());
    let script = format!(
        "{}set +e\n\"$BIN\" train {} --out \"$D/run\" --config {}\nrc=$?\ncp -a \"$D/run\" \"$OUT/run\"\nexit $rc\n",
        fill(one * 5 / 2),
        scene.display(),
        cfg.display()
    );
    let Some((ok, err)) = in_tmpfs(tmp.path(), "size=16m", &script) else {
        return;
    };
    assert!(!ok, "train into a full disk succeeded:\n{err}");
    assert!(
        err.contains("No space left on device") && err.contains("/run/"),
        "{err}"
    );
    let n = checkpoints_intact(&tmp.path().join("out/run"));
    assert!(n >= 1, "no checkpoint was written before the disk filled");
}

/// A small trained run on normal disk, for render and export.
fn trained_run(tmp: &Path) -> PathBuf {
    let scene = toycars(tmp);
    let run = tmp.join("run");
    let o = Command::new(BIN)
        .args([
            "train",
            scene.to_str().unwrap(),
            "--out",
            run.to_str().unwrap(),
        ])
        .args(["--config", tmp.join("small.toml").to_str().unwrap()])
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    run
}

#[test]
fn a_full_disk_stops_render_and_export_with_no_partial_file() {
    let tmp = tempfile::tempdir().unwrap();
    let run = trained_run(tmp.path());
    // The run copied onto the tmpfs; room for a few PNG renders, not for a 1500-vertex PLY.
    let script = format!(
        "cp -a {} \"$D/run\"\n{}set +e\n\"$BIN\" render \"$D/run\" --split train\nr1=$?\n\
         \"$BIN\" export \"$D/run\" --time 0.5 --out \"$D/x.ply\"\nr2=$?\n\
         cp -a \"$D/run\" \"$OUT/run\"\nls -a \"$D\" > \"$OUT/listing\"\n\
         echo \"render=$r1 export=$r2\" >&2\n[ $r1 -ne 0 ] && [ $r2 -ne 0 ]\n",
        run.display(),
        fill(6_000)
    );
    let Some((ok, err)) = in_tmpfs(tmp.path(), "size=16m", &script) else {
        return;
    };
    assert!(ok, "render or export succeeded on a full disk:\n{err}");
    assert!(err.contains("No space left on device"), "{err}");
    assert!(
        err.contains("x.ply"),
        "the export error names its file: {err}"
    );
    let listing = std::fs::read_to_string(tmp.path().join("out/listing")).unwrap();
    let names: Vec<&str> = listing
        .lines()
        .filter(|n| *n != "." && *n != "..")
        .collect();
    assert_eq!(names, ["filler", "run"], "left on the full disk: {names:?}");
    let renders = tmp.path().join("out/run/renders");
    for e in walk(&renders) {
        let name = e.file_name().unwrap().to_string_lossy().into_owned();
        assert!(!name.starts_with('.'), "temporary {} left", e.display());
        if name.ends_with(".png") {
            image::open(&e).unwrap_or_else(|err| panic!("{} is partial: {err}", e.display()));
        }
    }
}

/// Bytes of the files under `dir`.
fn du(dir: &Path) -> u64 {
    walk(dir).iter().map(|p| p.metadata().unwrap().len()).sum()
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    rd.flatten()
        .flat_map(|e| {
            let p = e.path();
            if p.is_dir() {
                walk(&p)
            } else {
                vec![p]
            }
        })
        .collect()
}

#[test]
fn a_read_only_folder_is_a_clear_error_and_stays_empty() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = toycars(tmp.path());
    let script = format!(
        "set +e\n\"$BIN\" train {} --out \"$D/run\" --iters 5\nr1=$?\n\
         \"$BIN\" synth toycars --out \"$D/scene\" --width 32 --height 24 --frames 8\nr2=$?\n\
         ls -A \"$D\" > \"$OUT/listing\"\n[ $r1 -ne 0 ] && [ $r2 -ne 0 ]\n",
        scene.display()
    );
    let Some((ok, err)) = in_tmpfs(tmp.path(), "ro", &script) else {
        return;
    };
    assert!(ok, "writing into a read-only folder succeeded:\n{err}");
    assert!(
        err.contains("Read-only file system") && err.contains("/run"),
        "{err}"
    );
    let listing = std::fs::read_to_string(tmp.path().join("out/listing")).unwrap();
    assert!(
        listing.trim().is_empty(),
        "read-only folder holds: {listing}"
    );
}
