//! `semdynreg render-case`: a reference case round trip, bad input giving a clear error
//! that names the file and the key (never a panic), and `SEMDYNREG_SIMD`: every vector
//! level gives the same bytes, a misspelt level stops the binary before any work.

use npyz::npz::{NpzArchive, NpzWriter};
use npyz::WriterBuilder;
use std::path::{Path, PathBuf};
use std::process::Command;

// The rasterizer's reference cases, found by the helper splat's own tests use.
#[path = "../../splat/tests/common/fixtures.rs"]
mod fixtures;

fn case(stem: &str) -> PathBuf {
    fixtures::cases_dir().join(format!("{stem}.npz"))
}

type Arrays = Vec<(String, Vec<u64>, Vec<f64>)>;

/// Every array of an archive as f64.
fn read_all(path: &Path) -> Arrays {
    let mut z = NpzArchive::open(path).expect("open npz");
    let names: Vec<String> = z.array_names().map(str::to_string).collect();
    names
        .into_iter()
        .map(|name| {
            let f = z.by_name(&name).expect("read").expect("present");
            let shape = f.shape().to_vec();
            let descr = f.dtype().descr();
            let data = match descr.trim_matches(|c| c == '\'' || c == '"') {
                "<f8" => f.into_vec::<f64>().expect("f64"),
                "<i8" => f
                    .into_vec::<i64>()
                    .expect("i64")
                    .into_iter()
                    .map(|v| v as f64)
                    .collect(),
                "<i4" => f
                    .into_vec::<i32>()
                    .expect("i32")
                    .into_iter()
                    .map(f64::from)
                    .collect(),
                t => panic!("{name}: dtype {t}"),
            };
            (name, shape, data)
        })
        .collect()
}

fn write_all(path: &Path, arrays: &Arrays) {
    let mut z = NpzWriter::create(path).expect("create");
    for (name, shape, data) in arrays {
        let mut w = z
            .array::<f64>(name, Default::default())
            .expect("entry")
            .default_dtype()
            .shape(shape)
            .begin_nd()
            .expect("begin");
        w.extend(data.iter().copied()).expect("write");
        w.finish().expect("finish");
    }
    z.zip_writer().finish().expect("zip");
}

fn render_case(input: &Path, output: &Path, extra: &[&str]) -> std::process::Output {
    render_case_simd(input, output, extra, None)
}

/// `render-case` with `SEMDYNREG_SIMD` set to `simd` (unset when `None`).
fn render_case_simd(
    input: &Path,
    output: &Path,
    extra: &[&str],
    simd: Option<&str>,
) -> std::process::Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_semdynreg"));
    c.arg("render-case")
        .arg(input)
        .arg(output)
        .args(extra)
        .env_remove("SEMDYNREG_SIMD");
    if let Some(v) = simd {
        c.env("SEMDYNREG_SIMD", v);
    }
    c.output().expect("run semdynreg")
}

fn get<'a>(arrays: &'a Arrays, key: &str) -> &'a (String, Vec<u64>, Vec<f64>) {
    arrays
        .iter()
        .find(|a| a.0 == key)
        .unwrap_or_else(|| panic!("no {key}"))
}

#[test]
fn reference_case_round_trip() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out.npz");
    let run = render_case(
        &case("01_tiny_sh3_offcentre_behind"),
        &out,
        &["--topk", "3", "--repeat", "3"],
    );
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let got = read_all(&out);
    let expected = read_all(&case("01_tiny_sh3_offcentre_behind.expected"));
    for key in [
        "image",
        "alpha",
        "loss",
        "grad_means",
        "grad_sh",
        "grad_log_scales",
    ] {
        let (g, e) = (get(&got, key), get(&expected, key));
        assert_eq!(g.1, e.1, "{key} shape");
        let num: f64 = g.2.iter().zip(&e.2).map(|(a, b)| (a - b).powi(2)).sum();
        let den: f64 = e.2.iter().map(|b| b * b).sum();
        assert!((num / den.max(1e-30)).sqrt() < 1e-3, "{key} differs");
    }
    let ids = get(&got, "topk_ids");
    assert_eq!(ids.1, vec![20, 24, 3]);
    assert!(ids.2.iter().all(|&v| (-1.0..12.0).contains(&v)));
    assert!(get(&got, "seconds_forward").2[0] > 0.0);
    assert!(get(&got, "seconds_backward").2[0] > 0.0);
    assert!(!dir.path().join("out.npz.tmp").exists());
}

/// Runs render-case on case 01 altered by `edit`; returns stderr, asserting failure.
fn failing(edit: impl FnOnce(&mut Arrays)) -> (String, PathBuf, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut arrays = read_all(&case("01_tiny_sh3_offcentre_behind"));
    edit(&mut arrays);
    let input = dir.path().join("bad.npz");
    write_all(&input, &arrays);
    let out = dir.path().join("out.npz");
    let run = render_case(&input, &out, &[]);
    let stderr = String::from_utf8_lossy(&run.stderr).to_string();
    assert!(!run.status.success(), "bad input accepted");
    assert!(!stderr.contains("panicked"), "panic: {stderr}");
    assert!(!out.exists());
    (stderr, input, dir)
}

#[test]
fn missing_key_is_named() {
    let (err, input, _d) = failing(|a| a.retain(|x| x.0 != "means"));
    assert!(err.contains("missing key `means`"), "{err}");
    assert!(err.contains(&input.display().to_string()), "{err}");
}

#[test]
fn wrong_shape_is_named() {
    let (err, _, _d) = failing(|a| {
        let q = a.iter_mut().find(|x| x.0 == "quats").expect("quats");
        q.1 = vec![16, 3];
    });
    assert!(
        err.contains("`quats` has shape [16, 3], expected (12, 4)"),
        "{err}"
    );
}

#[test]
fn nan_is_named() {
    let (err, _, _d) = failing(|a| {
        let q = a
            .iter_mut()
            .find(|x| x.0 == "opacity_logits")
            .expect("logits");
        q.2[5] = f64::NAN;
    });
    assert!(
        err.contains("`opacity_logits` has a non-finite value"),
        "{err}"
    );
}

#[test]
fn not_an_npz_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join("junk.npz");
    std::fs::write(&input, b"not a zip").expect("write");
    let run = render_case(&input, &dir.path().join("o.npz"), &[]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success() && err.contains("junk.npz"), "{err}");
}

/// Forward and backward under each cap (the CPU's own limit applies, so on an AVX2 machine
/// `avx512` runs AVX2): every array but the timings is the same, bit for bit.
#[test]
fn every_simd_level_gives_the_same_arrays() {
    let dir = tempfile::tempdir().expect("tempdir");
    let input = case("01_tiny_sh3_offcentre_behind");
    let mut runs = Vec::new();
    for cap in [None, Some("portable"), Some("AVX2"), Some("avx512")] {
        let out = dir.path().join(format!("{}.npz", cap.unwrap_or("default")));
        let run = render_case_simd(&input, &out, &["--topk", "3"], cap);
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(run.status.success(), "{cap:?}: {err}");
        let mut arrays = read_all(&out);
        arrays.retain(|a| !a.0.starts_with("seconds_"));
        // The archive lists its entries in no set order.
        arrays.sort_by(|a, b| a.0.cmp(&b.0));
        runs.push((cap, arrays));
    }
    let (_, want) = &runs[0];
    assert!(want.iter().any(|a| a.0 == "grad_means"));
    for (cap, got) in &runs[1..] {
        assert_eq!(got.len(), want.len(), "{cap:?}");
        for (g, w) in got.iter().zip(want) {
            let same = g.0 == w.0
                && g.1 == w.1
                && g.2
                    .iter()
                    .zip(&w.2)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "SEMDYNREG_SIMD={cap:?} changed `{}`", g.0);
        }
    }
}

#[test]
fn a_misspelt_simd_level_is_refused_before_any_work() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out.npz");
    let run = render_case_simd(
        &case("01_tiny_sh3_offcentre_behind"),
        &out,
        &[],
        Some("avx-512"),
    );
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "accepted SEMDYNREG_SIMD=avx-512");
    assert!(
        err.contains("SEMDYNREG_SIMD") && err.contains("avx-512") && !err.contains("panicked"),
        "{err}"
    );
    assert!(!out.exists());
}
