//! Seeded mutation fuzzing through the `semdynreg` binary
//! (docs/robustness.md): the rasterizer's `.npz` reference cases (`render-case`), and the
//! "no output after an error" property of `train` on a corrupted scene and `render` on a
//! corrupted checkpoint.
//!
//! Property per case: the process exits with a status (never a panic, exit code 101, nor a
//! signal) within a time bound; when it fails, its message names the corrupted file and it
//! has written nothing: no output under the final name, no temporary file left beside it.
//!
//! CI: `cargo test -p semdynreg --test fuzz_cli`. Long run (20× the CI counts, or
//! `FUZZ_CASES` per format; `FUZZ_SEED` for another stream):
//!
//! ```text
//! cargo test -p semdynreg --test fuzz_cli -- --ignored --nocapture
//! ```

#[macro_use]
#[path = "../../scene/tests/fuzz_common/mod.rs"]
mod fuzz_common;

// The rasterizer's reference cases, found by the helper splat's own tests use.
#[path = "../../splat/tests/common/fixtures.rs"]
mod fixtures;

use fuzz_common::{apply, finish, mutations, npy, runner, stored_zip, Kind, Mutation, Tally};
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::TestCaseError;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Runs the binary with `args`, killed after 120 s; (exit code, stderr).
fn semdynreg(args: &[&std::ffi::OsStr]) -> Result<(Option<i32>, String), TestCaseError> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_semdynreg"))
        .args(args)
        .env("RAYON_NUM_THREADS", "2")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| TestCaseError::fail(format!("cannot start semdynreg: {e}")))?;
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut stderr, &mut s);
        s
    });
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            let _ = child.wait();
            return Err(TestCaseError::fail("semdynreg ran past 120 s (a hang)"));
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let err = reader.join().unwrap_or_default();
    if status.code() == Some(101) || err.contains("panicked at") {
        return Err(TestCaseError::fail(format!("semdynreg panicked: {err}")));
    }
    if status.code().is_none() {
        return Err(TestCaseError::fail(format!(
            "semdynreg died of a signal ({status}): {err}"
        )));
    }
    Ok((status.code(), err))
}

/// Every file under `dir`, relative, sorted.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

// ---- render-case on mutated `.npz` cases

type Arrays = Vec<(String, Vec<u64>, Vec<f64>)>;

/// Every array of the seed case as f64 (its dtypes are f8, i8 and i4).
fn read_case(path: &Path) -> Arrays {
    let mut z = npyz::npz::NpzArchive::open(path).unwrap();
    let names: Vec<String> = z.array_names().map(str::to_string).collect();
    names
        .into_iter()
        .map(|name| {
            let f = z.by_name(&name).unwrap().unwrap();
            let shape = f.shape().to_vec();
            let data = match f.dtype().descr().trim_matches(|c| c == '\'' || c == '"') {
                "<f8" => f.into_vec::<f64>().unwrap(),
                "<i8" => f
                    .into_vec::<i64>()
                    .unwrap()
                    .into_iter()
                    .map(|v| v as f64)
                    .collect(),
                "<i4" => f
                    .into_vec::<i32>()
                    .unwrap()
                    .into_iter()
                    .map(f64::from)
                    .collect(),
                t => panic!("seed dtype {t}"),
            };
            (name, shape, data)
        })
        .collect()
}

/// How a case is changed.
#[derive(Clone, Debug)]
enum NpzEdit {
    /// Bytes of the whole archive.
    Zip(Vec<Mutation>),
    /// Bytes of one member `.npy` (number tokens of its header too: shapes that lie).
    Member(Index, Vec<Mutation>),
    /// One array's shape replaced (the data stays): a dimension doubled, zeroed, made huge,
    /// dropped or added.
    Shape(Index, Index, u64),
    /// One value replaced by an extreme one.
    Value(Index, Index, f64),
    /// One array removed.
    Remove(Index),
    /// One array stored with another dtype (values converted where it has a meaning).
    Dtype(Index, &'static str),
}

fn npz_edit() -> impl Strategy<Value = NpzEdit> {
    prop_oneof![
        1 => mutations(Kind::Binary).prop_map(NpzEdit::Zip),
        2 => (any::<Index>(), mutations(Kind::Text)).prop_map(|(i, m)| NpzEdit::Member(i, m)),
        1 => (any::<Index>(), any::<Index>(), prop_oneof![Just(0u64), Just(1), Just(2), Just(1 << 20), Just(1 << 40), Just(u64::MAX)])
            .prop_map(|(a, d, v)| NpzEdit::Shape(a, d, v)),
        1 => (any::<Index>(), any::<Index>(), prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(-1e300), Just(1e300), Just(0.0), Just(-1.0), Just(1e9), Just(70000.0)])
            .prop_map(|(a, i, v)| NpzEdit::Value(a, i, v)),
        1 => any::<Index>().prop_map(NpzEdit::Remove),
        1 => (any::<Index>(), prop_oneof![Just("<f4"), Just("<i4"), Just("<i8"), Just("|u1"), Just("|b1"), Just(">f8"), Just("<c16"), Just("<U3"), Just("|O")])
            .prop_map(|(a, d)| NpzEdit::Dtype(a, d)),
    ]
}

fn encode(descr: &str, data: &[f64]) -> Vec<u8> {
    match descr {
        "<f4" => data
            .iter()
            .flat_map(|v| (*v as f32).to_le_bytes())
            .collect(),
        "<i4" => data
            .iter()
            .flat_map(|v| (*v as i32).to_le_bytes())
            .collect(),
        "<i8" => data
            .iter()
            .flat_map(|v| (*v as i64).to_le_bytes())
            .collect(),
        "|u1" | "|b1" => data.iter().map(|v| *v as u8).collect(),
        ">f8" => data.iter().flat_map(|v| v.to_be_bytes()).collect(),
        "<c16" => data
            .iter()
            .flat_map(|v| [v.to_le_bytes(), 0f64.to_le_bytes()].concat())
            .collect(),
        "<U3" => data
            .iter()
            .flat_map(|_| [b'a', 0, 0, 0, b'b', 0, 0, 0, b'c', 0, 0, 0])
            .collect(),
        "|O" => b"\x80\x02N.".to_vec(),
        _ => data.iter().flat_map(|v| v.to_le_bytes()).collect(),
    }
}

fn npz_bytes(seed: &Arrays, edits: &[NpzEdit]) -> Vec<u8> {
    let mut arrays: Vec<(String, Vec<u64>, Vec<f64>, &'static str)> = seed
        .iter()
        .map(|(n, s, d)| (n.clone(), s.clone(), d.clone(), "<f8"))
        .collect();
    let mut member: Option<(usize, Vec<Mutation>)> = None;
    let mut zip_muts = Vec::new();
    for e in edits {
        let n = arrays.len().max(1);
        match e {
            NpzEdit::Zip(m) => zip_muts.extend(m.iter().cloned()),
            NpzEdit::Member(i, m) => member = Some((i.index(n), m.clone())),
            NpzEdit::Shape(a, d, v) if !arrays.is_empty() => {
                let s = &mut arrays[a.index(n)].1;
                let k = d.index(s.len() + 2);
                match k {
                    k if k < s.len() && *v == 2 => s[k] *= 2,
                    k if k < s.len() => s[k] = *v,
                    k if k == s.len() => s.push(*v),
                    _ => {
                        s.pop();
                    }
                }
            }
            NpzEdit::Value(a, i, v) if !arrays.is_empty() => {
                let d = &mut arrays[a.index(n)].2;
                if !d.is_empty() {
                    let k = i.index(d.len());
                    d[k] = *v;
                }
            }
            NpzEdit::Remove(a) if !arrays.is_empty() => {
                arrays.remove(a.index(n));
            }
            NpzEdit::Dtype(a, t) if !arrays.is_empty() => arrays[a.index(n)].3 = t,
            _ => {}
        }
    }
    let mut files: Vec<(String, Vec<u8>)> = arrays
        .iter()
        .map(|(name, shape, data, descr)| {
            (
                format!("{name}.npy"),
                npy(descr, shape, &encode(descr, data)),
            )
        })
        .collect();
    if let Some((k, m)) = member {
        if k < files.len() {
            files[k].1 = apply(&files[k].1, &m, Kind::Text);
        }
    }
    apply(&stored_zip(&files), &zip_muts, Kind::Binary)
}

fn render_case_npz(cases: u32) {
    let seed = read_case(&fixtures::cases_dir().join("01_tiny_sh3_offcentre_behind.npz"));
    let work = tempfile::tempdir().unwrap();
    let input = work.path().join("case_in.npz");
    let out_dir = work.path().join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    let output = out_dir.join("result.npz");
    let tally = Tally::new();
    let mut r = runner("render-case .npz", cases);
    let t = tally.clone();
    let strategy = prop::collection::vec(npz_edit(), 1..=3);
    let result = r.run(&strategy, |edits| {
        std::fs::write(&input, npz_bytes(&seed, &edits)).unwrap();
        let _ = std::fs::remove_file(&output);
        let (code, err) = semdynreg(&[
            "render-case".as_ref(),
            input.as_os_str(),
            output.as_os_str(),
            "--topk".as_ref(),
            "2".as_ref(),
        ])?;
        let left = files(&out_dir);
        if code == Some(0) {
            t.ok.fetch_add(1, Ordering::Relaxed);
            prop_assert_eq!(left, vec![PathBuf::from("result.npz")]);
        } else {
            t.err.fetch_add(1, Ordering::Relaxed);
            prop_assert!(err.contains("case_in.npz"), "error names no file: {}", err);
            prop_assert!(left.is_empty(), "failed but wrote {:?}: {}", left, err);
        }
        Ok(())
    });
    finish("render-case .npz", result, &tally);
}

// ---- train on a corrupted scene, render from a corrupted checkpoint

fn tiny_scene(dir: &Path) {
    let cfg = scene::toycars::ToycarsConfig {
        width: 32,
        height: 24,
        frames: 8,
        supersample: false,
        shadows: false,
        ..Default::default()
    };
    scene::toycars::generate(&cfg, dir, &|_, _| {}).unwrap();
}

const SMALL: &str = "iterations = 4\n[init]\nrandom_points = 100\n[field]\ndepth = 2\nwidth = 8\nskip = 1\nwarm_up = 2\n[log]\neval_interval = 0\ncheckpoint_interval = 4\nlog_interval = 2\n";

fn train_on_corrupted_scene(cases: u32) {
    let work = tempfile::tempdir().unwrap();
    let scene_dir = work.path().join("scene");
    tiny_scene(&scene_dir);
    let config = work.path().join("small.toml");
    std::fs::write(&config, SMALL).unwrap();
    let targets = [
        "transforms_train.json",
        "transforms_test.json",
        "train/r_002.png",
    ];
    let originals: Vec<Vec<u8>> = targets
        .iter()
        .map(|f| std::fs::read(scene_dir.join(f)).unwrap())
        .collect();
    let tally = Tally::new();
    let mut r = runner("train on a corrupted scene", cases);
    let t = tally.clone();
    let strategy = (0..targets.len(), mutations(Kind::Json));
    let result = r.run(&strategy, |(k, muts)| {
        let path = scene_dir.join(targets[k]);
        let kind = if targets[k].ends_with(".png") {
            Kind::Binary
        } else {
            Kind::Json
        };
        std::fs::write(&path, apply(&originals[k], &muts, kind)).unwrap();
        let run = work.path().join("run");
        let _ = std::fs::remove_dir_all(&run);
        let res = semdynreg(&[
            "train".as_ref(),
            scene_dir.as_os_str(),
            "--out".as_ref(),
            run.as_os_str(),
            "--config".as_ref(),
            config.as_os_str(),
        ]);
        std::fs::write(&path, &originals[k]).unwrap();
        let (code, err) = res?;
        let name = Path::new(targets[k])
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        if code == Some(0) {
            t.ok.fetch_add(1, Ordering::Relaxed);
        } else {
            t.err.fetch_add(1, Ordering::Relaxed);
            prop_assert!(err.contains(&name), "error names no {}: {}", name, err);
            let left = files(&run);
            prop_assert!(left.is_empty(), "failed but wrote {:?}: {}", left, err);
        }
        Ok(())
    });
    finish("train on a corrupted scene", result, &tally);
}

fn render_from_corrupted_checkpoint(cases: u32) {
    let work = tempfile::tempdir().unwrap();
    let scene_dir = work.path().join("scene");
    tiny_scene(&scene_dir);
    let config = work.path().join("small.toml");
    std::fs::write(&config, SMALL).unwrap();
    let run = work.path().join("run");
    let (code, err) = semdynreg(&[
        "train".as_ref(),
        scene_dir.as_os_str(),
        "--out".as_ref(),
        run.as_os_str(),
        "--config".as_ref(),
        config.as_os_str(),
    ])
    .unwrap();
    assert_eq!(code, Some(0), "seed training failed: {err}");
    let ckpt = run.join("checkpoints/iter_0000004");
    let targets = [
        train::checkpoint::STATE_NAME,
        train::checkpoint::PLY_NAME,
        train::checkpoint::CONFIG_NAME,
    ];
    let originals: Vec<Vec<u8>> = targets
        .iter()
        .map(|f| std::fs::read(ckpt.join(f)).unwrap())
        .collect();
    let before = files(&run);
    let tally = Tally::new();
    let mut r = runner("render from a corrupted checkpoint", cases);
    let t = tally.clone();
    let strategy = (0..targets.len(), mutations(Kind::Json));
    let result = r.run(&strategy, |(k, muts)| {
        let path = ckpt.join(targets[k]);
        let bytes = match k {
            0 => fuzz_common::apply_safetensors(&originals[0], &muts),
            1 => apply(&originals[1], &muts, Kind::Text),
            _ => apply(&originals[2], &muts, Kind::Toml),
        };
        std::fs::write(&path, bytes).unwrap();
        let res = semdynreg(&["render".as_ref(), run.as_os_str()]);
        std::fs::write(&path, &originals[k]).unwrap();
        let (code, err) = res?;
        if code == Some(0) {
            t.ok.fetch_add(1, Ordering::Relaxed);
            std::fs::remove_dir_all(run.join("renders")).unwrap();
        } else {
            t.err.fetch_add(1, Ordering::Relaxed);
            prop_assert!(
                err.contains(targets[k]),
                "error names no {}: {}",
                targets[k],
                err
            );
            let now = files(&run);
            prop_assert_eq!(&now, &before, "failed but wrote files: {}", err);
        }
        Ok(())
    });
    finish("render from a corrupted checkpoint", result, &tally);
}

formats! {
    fuzz_render_case_npz: 48 => render_case_npz;
    fuzz_train_corrupted_scene: 16 => train_on_corrupted_scene;
    fuzz_render_corrupted_checkpoint: 16 => render_from_corrupted_checkpoint;
}
