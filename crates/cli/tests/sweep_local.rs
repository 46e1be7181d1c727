//! `semdynreg sweep` with the local backend on a tiny grid (a baseline and two SemDynReg
//! runs forked from it): every run trained, scored and collected; a second invocation
//! trains nothing; a run that lost its results is scored again without training; bad
//! grids are refused before anything runs, naming the file and the key.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::SystemTime;

fn semdynreg(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_semdynreg"))
        .args(args)
        .env("SEMDYNREG_OFFLINE", "1")
        .env("SEMDYNREG_WEIGHTS", "/nonexistent-weights-dir")
        .output()
        .expect("run semdynreg")
}

fn ok(args: &[&str]) -> String {
    let out = semdynreg(args);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "semdynreg {args:?} failed:\n{text}");
    text
}

/// A tiny toycars recipe: 32×24, 6 frames, 30 iterations, 300 initial Gaussians.
const TINY: &str = r#"
modes = ["baseline", "semdynreg"]
iters = 30
[[scenes]]
name = "tiny"
synth = { width = 32, height = 24, frames = 6 }
[config.init]
random_points = 300
[[sweep]]
reg.k = [1, 3]
"#;

fn mtime(p: &Path) -> SystemTime {
    std::fs::metadata(p)
        .and_then(|m| m.modified())
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn json(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

#[test]
fn local_sweep_runs_forks_resumes_and_collects() {
    let tmp = tempfile::tempdir().unwrap();
    let grid = tmp.path().join("grid.toml");
    std::fs::write(&grid, TINY).unwrap();
    let out = tmp.path().join("sw");
    let (g, o) = (grid.to_str().unwrap(), out.to_str().unwrap());
    ok(&["sweep", g, "--out", o]);

    let names = [
        "tiny_baseline_s0",
        "tiny_semdynreg_k=1_s0",
        "tiny_semdynreg_k=3_s0",
    ];
    let runs: Vec<PathBuf> = names.iter().map(|n| out.join("runs").join(n)).collect();
    for (name, run) in names.iter().zip(&runs) {
        let r = json(&run.join("results.json"));
        let mode = if name.contains("baseline") {
            "baseline"
        } else {
            "semdynreg"
        };
        assert!(
            r[mode]["full_frame"]["psnr"].as_f64().unwrap().is_finite(),
            "{name}"
        );
        let commands = r["commands"].to_string();
        // The forks start from the shared baseline's checkpoint (`compare`'s machinery).
        assert_eq!(
            commands.contains("--fork"),
            mode == "semdynreg",
            "{name}: {commands}"
        );
    }
    let table = json(&out.join("table.json"));
    assert_eq!(table["rows"].as_array().unwrap().len(), 3);
    assert_eq!(table["columns"], serde_json::json!(["reg.k"]));
    assert_eq!(table["rows"][2]["params"]["reg.k"], 3);
    assert!(std::fs::read_to_string(out.join("table.md"))
        .unwrap()
        .contains("| tiny_semdynreg_k=1_s0 | tiny | semdynreg | 0 | 1 |"));
    assert_eq!(
        std::fs::read_to_string(out.join("table.csv"))
            .unwrap()
            .lines()
            .count(),
        4
    );
    assert!(out.join("plots").join("reg.k.svg").is_file());

    // A second invocation trains nothing: no run's timings or checkpoints change.
    let stamps = |f: &str| -> Vec<SystemTime> { runs.iter().map(|r| mtime(&r.join(f))).collect() };
    let before = (
        stamps("timings.json"),
        stamps("checkpoints/latest"),
        stamps("results.json"),
    );
    let log = ok(&["sweep", g, "--out", o]);
    assert_eq!(log.matches("finished already").count(), 3, "{log}");
    assert!(!log.contains("running: semdynreg train"), "{log}");
    assert_eq!(
        before,
        (
            stamps("timings.json"),
            stamps("checkpoints/latest"),
            stamps("results.json")
        )
    );

    // A run whose training finished but whose results are gone is rendered and scored again,
    // not trained again.
    std::fs::remove_file(runs[2].join("results.json")).unwrap();
    let log = ok(&["sweep", g, "--out", o]);
    assert!(log.contains("reusing the finished run"), "{log}");
    assert!(!log.contains("running: semdynreg train"), "{log}");
    assert_eq!(mtime(&runs[2].join("timings.json")), before.0[2]);
    assert!(runs[2].join("results.json").is_file());

    // A changed grid in the same folder is refused, naming the run.
    std::fs::write(&grid, TINY.replace("300", "301")).unwrap();
    let bad = semdynreg(&["sweep", g, "--out", o]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && err.contains("tiny_baseline_s0"),
        "{err}"
    );
}

/// `sweep BAD --out DIR` fails, and nothing was made in DIR.
fn refused(grid_text: &str) -> String {
    let tmp = tempfile::tempdir().unwrap();
    let grid = tmp.path().join("bad_grid.toml");
    std::fs::write(&grid, grid_text).unwrap();
    let out = tmp.path().join("sw");
    let o = semdynreg(&[
        "sweep",
        grid.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "accepted:\n{grid_text}");
    assert!(
        err.contains(grid.to_str().unwrap()) || err.contains("bad_grid.toml"),
        "{err}"
    );
    assert!(
        !out.join("sweep.json").exists() && !out.join("scenes").exists(),
        "{err}"
    );
    err
}

#[test]
fn bad_grids_are_refused_before_anything_runs() {
    let e = refused(&TINY.replace("reg.k = [1, 3]", "reg.kk = [1, 3]"));
    assert!(e.contains("sweep[0]: unknown config key `reg.kk`"), "{e}");
    let e = refused(&TINY.replace("iters = 30", "iterz = 30"));
    assert!(e.contains("unknown field `iterz`"), "{e}");
    let e = refused(&TINY.replace("reg.k = [1, 3]", "reg.k = []"));
    assert!(e.contains("sweep[0]: `reg.k` is an empty list"), "{e}");
    let e = refused(&format!("seeds = []\n{TINY}"));
    assert!(e.contains("`seeds` is an empty list"), "{e}");
    let e = refused(&TINY.replace("[\"baseline\", \"semdynreg\"]", "[\"semdynreg\"]"));
    assert!(
        e.contains("`modes`: `semdynreg` forks from `baseline`"),
        "{e}"
    );
}
