//! SIGKILL during `semdynreg train` loses nothing: a run killed again and
//! again, at seeded random moments and at moments a checkpoint is being written, and
//! resumed each time, always resumes from an intact checkpoint and ends with exactly the
//! parameters, optimizer state and log of an uninterrupted run on the same thread count.
//! Unix only (`Child::kill` is SIGKILL there).
#![cfg(unix)]

use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

const ITERS: u32 = 200;

fn scene(tmp: &Path) -> (PathBuf, PathBuf) {
    let scene_dir = tmp.join("scene");
    let cfg = scene::toycars::ToycarsConfig {
        width: 32,
        height: 24,
        frames: 12,
        supersample: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, &scene_dir, &|_, _| {}).unwrap();
    let config = tmp.join("small.toml");
    // A checkpoint every 4 iterations: many saves to land in.
    let toml = format!(
        "iterations = {ITERS}\n[init]\nrandom_points = 600\n[log]\nlog_interval = 1\n\
         checkpoint_interval = 4\neval_interval = 0\nkeep_checkpoints = 2\n"
    );
    std::fs::write(&config, toml).unwrap();
    (scene_dir, config)
}

/// `train` into `run`: a fresh start while the folder holds no run yet, else `--resume`.
fn start(scene: &Path, config: &Path, run: &Path) -> Child {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_semdynreg"));
    cmd.arg("train").arg("--out").arg(run);
    if run.join("run.json").exists() {
        cmd.arg("--resume");
    } else {
        cmd.arg(scene).arg("--config").arg(config);
    }
    cmd.env("RAYON_NUM_THREADS", "2")
        .env("RUST_LOG", "warn")
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("start semdynreg train")
}

/// The hidden temporary entries in `checkpoints/` (a save in flight, or one a kill cut).
fn partial(run: &Path) -> Vec<String> {
    let Ok(rd) = std::fs::read_dir(run.join("checkpoints")) else {
        return Vec::new();
    };
    rd.flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect()
}

/// Whether a save is in flight now: a temporary entry that was not there at `before`.
fn saving(run: &Path, before: &[String]) -> bool {
    partial(run).iter().any(|n| !before.contains(n))
}

/// The iteration of the newest checkpoint in `run` (0 when there is none, or while a
/// prune races the listing).
fn newest_checkpoint(run: &Path) -> u32 {
    let held = train::checkpoint::iterations(run).unwrap_or_default();
    held.last().map_or(0, |(it, _)| *it)
}

/// Fails the test if `child` ended on its own with an error.
fn check_exit(child: Child) -> bool {
    let out = child.wait_with_output().unwrap();
    if out.status.code().is_some() {
        assert!(
            out.status.success(),
            "train failed after a kill:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        return true;
    }
    false
}

/// Runs `run` to the end, killing it `kills` times (random kills within `max_delay` of a
/// start); returns (kills sent, of which during a save).
///
/// The window for random kills halves whenever the run is further along than its share
/// of the kills sent: the reference timing that set `max_delay` is one noisy sample (a
/// busy CI machine ran a run to the end after 10 of 16 kills), and a smaller window
/// still kills at start-up, loading and training alike.
fn train_with_kills(
    scene: &Path,
    config: &Path,
    run: &Path,
    kills: usize,
    max_delay: Duration,
) -> (usize, usize) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(19);
    let (mut sent, mut in_save) = (0, 0);
    let mut window = max_delay;
    loop {
        if sent > 0 && newest_checkpoint(run) as usize * (kills + 1) > ITERS as usize * sent {
            window /= 2;
        }
        let left_over = partial(run);
        let mut child = start(scene, config, run);
        if sent < kills {
            let t0 = Instant::now();
            // Even kills: at a random moment; odd kills: as soon as a save is seen.
            let during_save = sent % 2 == 1;
            let delay = window.mul_f64(rng.gen_range(0.0..1.0));
            let fire = loop {
                if child.try_wait().unwrap().is_some() {
                    break false;
                }
                if (during_save && saving(run, &left_over))
                    || (!during_save && t0.elapsed() >= delay)
                {
                    break true;
                }
                std::hint::spin_loop();
            };
            if fire {
                let hit_save = saving(run, &left_over);
                let _ = child.kill();
                if check_exit(child) {
                    return (sent, in_save); // it had just finished
                }
                sent += 1;
                in_save += hit_save as usize;
                continue;
            }
        }
        if check_exit(child) {
            return (sent, in_save);
        }
    }
}

fn tensors(path: &Path) -> Vec<(String, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut v: Vec<(String, Vec<u8>)> = st
        .tensors()
        .into_iter()
        .map(|(n, t)| (n, t.data().to_vec()))
        .collect();
    v.sort();
    v
}

/// The metrics log without its wall-clock fields.
fn log_lines(run: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    text.lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            let o = v.as_object_mut().unwrap();
            o.remove("elapsed_s");
            o.remove("it_per_s");
            v
        })
        .collect()
}

#[test]
fn sigkill_at_any_moment_resumes_and_ends_bit_identical() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene_dir, config) = scene(tmp.path());
    let reference = tmp.path().join("reference");
    let t0 = Instant::now();
    let none = train_with_kills(&scene_dir, &config, &reference, 0, Duration::ZERO);
    assert_eq!(none, (0, 0));
    // Random kills within a sixth of a whole run's time: start-up, loading, training.
    let max_delay = t0.elapsed() / 6;

    let killed = tmp.path().join("killed");
    let (sent, in_save) = train_with_kills(&scene_dir, &config, &killed, 16, max_delay);
    assert_eq!(sent, 16, "the run ended before every kill was sent");
    assert!(
        in_save >= 4,
        "only {in_save} of {sent} kills landed during a save"
    );

    let last = format!("checkpoints/iter_{ITERS:07}");
    let (a, b) = (reference.join(&last), killed.join(&last));
    assert_eq!(
        std::fs::read(a.join("point_cloud.ply")).unwrap(),
        std::fs::read(b.join("point_cloud.ply")).unwrap(),
        "final Gaussians differ"
    );
    assert!(
        tensors(&a.join("state.safetensors")) == tensors(&b.join("state.safetensors")),
        "final field / optimizer / densification state differs"
    );
    assert_eq!(
        log_lines(&reference),
        log_lines(&killed),
        "metrics logs differ"
    );
    let left = partial(&killed);
    assert!(left.is_empty(), "partial saves left behind: {left:?}");
    eprintln!("{sent} SIGKILLs, {in_save} during a checkpoint save: resumed to the same end");
}
