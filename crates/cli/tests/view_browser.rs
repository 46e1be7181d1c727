//! `semdynreg view` in a real browser: two tiny runs (one plain, one trained with
//! --objects) side by side in headless Chromium drawing WebGL through SwiftShader. The page
//! must draw both panes, redraw when the time slider moves (the cars move), colour by
//! object, keep the time in its address, and a page told to draw nothing (`?blank=1`)
//! must be caught by the same pixel checks. Also the server's answers to bad requests and
//! the command's to bad runs and a port in use.
//!
//! Chromium is the system's (`/usr/bin/chromium`, or $SEMDYNREG_CHROMIUM); nothing is
//! downloaded. Without it the browser test is skipped with a message, except in CI
//! (CI_REQUIRE_SYSTEM=1), where it fails.
//!
//! `SEMDYNREG_VIEW_RUNS=RUN,RUN2 cargo test -p semdynreg --test view_browser -- --ignored
//! --nocapture` runs the same browser checks on trained runs of one's own and prints the
//! timings; with SEMDYNREG_VIEW_SCREENSHOT=FILE.png it keeps the side-by-side screenshot
//! (docs/img/view_side_by_side.png came from there).

mod cdp;

use cdp::Browser;
use serde_json::Value;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn semdynreg_out(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_semdynreg"))
        .env("SEMDYNREG_OFFLINE", "1")
        .env("SEMDYNREG_WEIGHTS", "/nonexistent-weights-dir")
        .args(args)
        .output()
        .expect("run semdynreg")
}

fn semdynreg(args: &[&str]) {
    let out = semdynreg_out(args);
    assert!(
        out.status.success(),
        "semdynreg {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn semdynreg_err(args: &[&str]) -> String {
    let out = semdynreg_out(args);
    assert!(!out.status.success(), "semdynreg {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Two tiny runs of one toycars scene: `plain` (no objects, no regularizer) and `objects`
/// (--objects, which start at iteration 48 of 120, so the cars have trajectories).
fn train_runs(tmp: &Path) -> (PathBuf, PathBuf) {
    let scene_dir = tmp.join("scene");
    let cfg = scene::toycars::ToycarsConfig {
        width: 64,
        height: 48,
        frames: 8,
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
    let config = tmp.join("tiny.toml");
    let toml = "[init]\nrandom_points = 3000\n[objects]\nstart_iter = 16000\nlift_points = 400\n\
                track_pose_iters = 10\ntrack_shape_iters = 3\ntrack_refine_iters = 20\n";
    std::fs::write(&config, toml).unwrap();
    let plain = tmp.join("plain");
    let objects = tmp.join("objects");
    for (run, extra) in [(&plain, "--no-objects"), (&objects, "--objects")] {
        semdynreg(&[
            "train",
            s(&scene_dir),
            "--out",
            s(run),
            "--config",
            s(&config),
            "--iters",
            "120",
            "--no-reg",
            extra,
        ]);
    }
    (plain, objects)
}

/// A running `semdynreg view`, stopped when dropped.
struct ViewServer {
    child: Child,
    url: String,
}

impl Drop for ViewServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_view(runs: &[&Path]) -> ViewServer {
    let mut args = vec!["view".to_string()];
    args.extend(runs.iter().map(|p| s(p).to_string()));
    args.extend(["--port".into(), "0".into()]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_semdynreg"))
        .args(&args)
        .stdout(Stdio::piped())
        .spawn()
        .expect("start semdynreg view");
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(i) = line.find("http://") {
                let url = line[i..].split_whitespace().next().unwrap().to_string();
                let _ = tx.send(url);
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(120))
        .expect("semdynreg view printed no URL");
    ViewServer { child, url }
}

/// A GET by hand (the test needs no HTTP client crate): (status, body).
fn http_get(base: &str, path: &str) -> (u16, String) {
    let host = base.trim_start_matches("http://").trim_end_matches('/');
    let mut conn = std::net::TcpStream::connect(host).unwrap();
    write!(
        conn,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut raw = Vec::new();
    conn.read_to_end(&mut raw).unwrap();
    let text = String::from_utf8_lossy(&raw).into_owned();
    let status = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let body = text
        .split_once("\r\n\r\n")
        .map_or("", |(_, b)| b)
        .to_string();
    (status, body)
}

/// The system Chromium; None (skip) when absent, a failure when CI requires it.
fn chromium() -> Option<PathBuf> {
    let candidates = [
        std::env::var("SEMDYNREG_CHROMIUM").unwrap_or_default(),
        "/usr/bin/chromium".into(),
        "/usr/bin/chromium-browser".into(),
    ];
    let found = candidates.iter().map(PathBuf::from).find(|p| p.is_file());
    if found.is_none() {
        let why = "no Chromium (apt-get install chromium, or set SEMDYNREG_CHROMIUM)";
        if std::env::var("CI_REQUIRE_SYSTEM").is_ok_and(|v| v == "1") {
            panic!("{why}; CI_REQUIRE_SYSTEM=1 requires it");
        }
        eprintln!("SKIPPED the browser test: {why}");
    }
    found
}

fn page_state(tab: &mut Browser) -> Value {
    let v = tab.eval("JSON.stringify(window.__semdynreg || null)");
    serde_json::from_str(v.as_str().unwrap_or("null")).unwrap()
}

/// Waits until the page has drawn time `t` in every pane; returns its state.
fn wait_drawn(tab: &mut Browser, t: f64) -> Value {
    let start = Instant::now();
    loop {
        let st = page_state(tab);
        if let Some(e) = st.get("error").and_then(Value::as_str) {
            panic!("the page failed: {e}");
        }
        let drawn_t = st.get("t").and_then(Value::as_f64);
        if st["ready"] == true && drawn_t.is_some_and(|d| (d - t).abs() < 1e-6) {
            return st;
        }
        assert!(
            start.elapsed() < Duration::from_secs(90),
            "the page did not draw t={t}: {st}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn screenshot(tab: &mut Browser) -> (Vec<u8>, image::RgbImage) {
    let png = tab.screenshot();
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    (png, img)
}

/// The panes' rectangles on the page (x, y, w, h in CSS pixels = screenshot pixels).
fn pane_rects(tab: &mut Browser) -> Vec<[u32; 4]> {
    let js = "JSON.stringify([...document.querySelectorAll('.pane')].map(p => { \
              const r = p.getBoundingClientRect(); \
              return [r.x, r.y, r.width, r.height].map(Math.round); }))";
    let v = tab.eval(js);
    serde_json::from_str(v.as_str().unwrap()).unwrap()
}

fn crop(img: &image::RgbImage, r: [u32; 4]) -> image::RgbImage {
    image::imageops::crop_imm(img, r[0], r[1], r[2], r[3]).to_image()
}

/// Fraction of a pane's pixels that differ clearly from the background colour (the pane's
/// label, top left, is left out).
fn drawn_fraction(pane: &image::RgbImage, bg: [u8; 3]) -> f64 {
    let (w, h) = pane.dimensions();
    let mut drawn = 0usize;
    let mut total = 0usize;
    for (x, y, p) in pane.enumerate_pixels() {
        if y < h / 6 && x < w * 3 / 4 {
            continue;
        }
        total += 1;
        let d: i32 = (0..3).map(|k| (p[k] as i32 - bg[k] as i32).abs()).sum();
        drawn += usize::from(d > 24);
    }
    drawn as f64 / total.max(1) as f64
}

/// A pane counts as drawn when at least 2 % of it is not background.
fn looks_drawn(pane: &image::RgbImage, bg: [u8; 3]) -> bool {
    drawn_fraction(pane, bg) > 0.02
}

/// Mean absolute difference per channel between two same-sized images.
fn mean_diff(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    let sum: u64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (*x as i32 - *y as i32).unsigned_abs() as u64)
        .sum();
    sum as f64 / a.as_raw().len().max(1) as f64
}

fn set_slider(tab: &mut Browser, end: &str) {
    let js = format!(
        "(() => {{ const s = document.getElementById('time'); s.value = {end}; \
         s.dispatchEvent(new Event('input')); return Number(s.value); }})()"
    );
    tab.eval(&js);
}

fn background(meta: &Value) -> [u8; 3] {
    let bg = meta["background"].as_array().unwrap();
    std::array::from_fn(|k| (bg[k].as_f64().unwrap() * 255.0).round() as u8)
}

/// The browser checks on two runs; the second must have objects when `objects_pane`.
fn check_in_browser(chrome: PathBuf, runs: [&Path; 2], objects_pane: bool, tmp: &Path) {
    let server = start_view(&runs);
    let (status, meta) = http_get(&server.url, "/api/meta");
    assert_eq!(status, 200, "{meta}");
    let meta: Value = serde_json::from_str(&meta).unwrap();
    let bg = background(&meta);
    let mut browser = Browser::launch(&chrome, &tmp.join("profile"), Duration::from_secs(90));
    let tab = &mut browser;

    let loaded = Instant::now();
    tab.navigate(&format!("{}?t=0", server.url));
    let st = wait_drawn(tab, 0.0);
    println!(
        "first frame: {:.0} ms from navigation start ({:.0} ms as the test saw it)",
        st["firstFrameMs"].as_f64().unwrap(),
        loaded.elapsed().as_secs_f64() * 1e3
    );
    let rects = pane_rects(tab);
    assert_eq!(rects.len(), 2, "two panes side by side");
    let (png, first) = screenshot(tab);
    std::fs::write(tmp.join("view_t0.png"), &png).unwrap();
    for (k, r) in rects.iter().enumerate() {
        let f = drawn_fraction(&crop(&first, *r), bg);
        println!("pane {k} at t=0: {:.1} % drawn", f * 100.0);
        assert!(looks_drawn(&crop(&first, *r), bg), "pane {k} is empty");
    }

    // The slider to its end: the panes redraw, the address keeps the time.
    set_slider(tab, "s.max");
    let st = wait_drawn(tab, 1.0);
    println!(
        "new time step drawn {:.0} ms after the slider moved, {:.0} ms of it fetching \
         (server: {} ms per frame made)",
        st["lastStepMs"].as_f64().unwrap(),
        st["lastFetchMs"].as_f64().unwrap(),
        st["serverMillis"]
    );
    let (png, last) = screenshot(tab);
    if let Ok(keep) = std::env::var("SEMDYNREG_VIEW_SCREENSHOT") {
        std::fs::write(&keep, &png).unwrap();
    }
    let changes: Vec<f64> = rects
        .iter()
        .map(|r| mean_diff(&crop(&first, *r), &crop(&last, *r)))
        .collect();
    println!("mean change t=0 → t=1 per pane: {changes:?}");
    assert!(
        changes.iter().any(|c| *c > 0.5),
        "moving the time slider changed no pane: {changes:?}"
    );
    let search = tab.eval("location.search");
    assert!(search.as_str().unwrap().contains("t=1.0000"), "{search}");

    // Back to the same time: cached, so at once; it must look as before.
    set_slider(tab, "0");
    let st = wait_drawn(tab, 0.0);
    println!(
        "cached step drawn in {:.0} ms ({:.0} ms fetching)",
        st["lastStepMs"].as_f64().unwrap(),
        st["lastFetchMs"].as_f64().unwrap()
    );

    if objects_pane {
        tab.eval("document.getElementById('objects').click()");
        std::thread::sleep(Duration::from_millis(100));
        wait_drawn(tab, 0.0);
        let (_, coloured) = screenshot(tab);
        let d = mean_diff(&crop(&first, rects[1]), &crop(&coloured, rects[1]));
        assert!(d > 0.5, "colouring by object changed nothing ({d})");
        let d0 = mean_diff(&crop(&first, rects[0]), &crop(&coloured, rects[0]));
        assert!(d0 < 0.5, "the run without objects keeps its colours ({d0})");
    }

    // The same checks must fail on a page that draws nothing.
    tab.navigate(&format!("{}?t=0&blank=1", server.url));
    wait_drawn(tab, 0.0);
    let (_, empty) = screenshot(tab);
    for r in &rects {
        assert!(
            !looks_drawn(&crop(&empty, *r), bg),
            "the blank page passes for drawn: the check cannot fail"
        );
    }
}

/// One pair of trained runs for both: the server's answers, then the browser's view.
#[test]
fn view_serves_two_runs_and_draws_them_in_a_browser() {
    let tmp = tempfile::tempdir().unwrap();
    let (plain, objects) = train_runs(tmp.path());
    check_bad_requests(&plain);
    let Some(chrome) = chromium() else { return };
    check_in_browser(chrome, [&plain, &objects], true, tmp.path());
}

/// On runs of one's own (SEMDYNREG_VIEW_RUNS=RUN,RUN2), e.g. for the timings of a large
/// model and docs/viewer.md's screenshot.
#[test]
#[ignore]
fn view_on_given_runs() {
    let runs = std::env::var("SEMDYNREG_VIEW_RUNS").expect("set SEMDYNREG_VIEW_RUNS=RUN,RUN2");
    let runs: Vec<PathBuf> = runs.split(',').map(PathBuf::from).collect();
    let chrome = chromium().expect("Chromium");
    let tmp = tempfile::tempdir().unwrap();
    let has_objects = std::env::var("SEMDYNREG_VIEW_OBJECTS").is_ok_and(|v| v == "1");
    check_in_browser(chrome, [&runs[0], &runs[1]], has_objects, tmp.path());
}

/// Bad requests get a 4xx status and a reason; the server goes on serving.
fn check_bad_requests(plain: &Path) {
    let server = start_view(&[plain]);
    let cases = [
        ("/api/splat?run=0&t=1.5", 400, "outside [0, 1]"),
        ("/api/splat?run=0&t=-0.1", 400, "outside [0, 1]"),
        ("/api/splat?run=0&t=soon", 400, "not a number"),
        ("/api/splat?run=3&t=0.5", 404, "no run 3"),
        (
            "/api/splat?run=0&t=0.5&colour=objects",
            400,
            "without --objects",
        ),
        ("/api/splat?run=0", 400, "needs t"),
        ("/etc/passwd", 404, "no page"),
    ];
    for (path, status, says) in cases {
        let (got, body) = http_get(&server.url, path);
        assert_eq!(got, status, "{path}: {body}");
        assert!(body.contains(says), "{path}: `{body}` should say `{says}`");
    }
    // A good request still works after the bad ones: 32 bytes a Gaussian.
    let (got, body) = http_get(&server.url, "/api/splat?run=0&t=0.5");
    assert_eq!(got, 200, "{body}");
}

#[test]
fn view_refuses_bad_runs_and_a_port_in_use() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("missing");
    let err = semdynreg_err(&["view", s(&missing), "--port", "0"]);
    assert!(err.contains("no such run folder"), "{err}");

    let not_run = tmp.path().join("not-a-run");
    std::fs::create_dir(&not_run).unwrap();
    let err = semdynreg_err(&["view", s(&not_run), "--port", "0"]);
    assert!(err.contains("not a run folder"), "{err}");

    // A run whose training has not saved a checkpoint yet: run.json and nothing else.
    let unfinished = tmp.path().join("unfinished");
    let info = train::run::RunInfo {
        scene: tmp.path().join("scene"),
        downscale: 1,
        background: [0.0; 3],
        seed: 0,
    };
    info.save(&unfinished).unwrap();
    let err = semdynreg_err(&["view", s(&unfinished), "--port", "0"]);
    assert!(err.contains("no checkpoint yet"), "{err}");

    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let err = semdynreg_err(&["view", s(&unfinished), "--port", &port]);
    assert!(err.contains("is in use"), "{err}");
}
