//! The rigid objects' start on generated scenes with ground truth: per object, the
//! static/moving decision and how well the fitted trajectory matches the true one
//! (`train::objects::truth`). Scenes are drawn from seeds (`scene::toycars::varied`: one to
//! three movers, routes of different lengths and turns, lifted and turning props, still
//! props near the movers); the object-ID maps are the scenes' ground-truth masks.
//!
//! ```text
//! cargo run --release -p train --example objects_bench -- OUT [--scenes 20] [--first 0]
//!     [--config FILE] [--tag NAME] [--iters 3000] [--points 20000]
//!     [--width 160] [--height 120] [--frames 96] [--seed 0]
//! ```
//!
//! Each scene trains the baseline's schedule (rescaled to `--iters`, rigid objects on,
//! `--config` applied) up to the objects' start and scores what the start made of each
//! object. Resumable: scenes are generated once into `OUT/scenes/`, each scene's result is
//! `OUT/TAG/seed-NNN.json` and is kept; rerunning scores only what is missing and rewrites
//! `OUT/TAG/summary.md` from every result there. `--config` with another `[objects]` (say
//! `ring_gauge = true`) under another `--tag` compares gauges on the same scenes; `--seed`
//! (the training's seed: initial points, view order) under another `--tag` measures how far
//! the counts move with nothing but the seed changed.

use scene::toycars::{generate, ground_truth_id_maps, varied};
use std::path::{Path, PathBuf};
use std::time::Instant;
use train::objects::truth::{Decision, ObjectScore};
use train::TrainConfig;

struct Opts {
    out: PathBuf,
    scenes: u64,
    first: u64,
    config: Option<PathBuf>,
    tag: String,
    iters: u32,
    points: usize,
    size: (u32, u32),
    frames: usize,
    seed: u64,
}

fn parse() -> Result<Opts, String> {
    let mut args = std::env::args().skip(1);
    let mut o = Opts {
        out: PathBuf::new(),
        scenes: 20,
        first: 0,
        config: None,
        tag: "default".into(),
        iters: 3000,
        points: 20_000,
        size: (160, 120),
        frames: 96,
        seed: 0,
    };
    let mut out = None;
    while let Some(a) = args.next() {
        let mut val = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        let num = |v: String, name: &str| v.parse::<u64>().map_err(|e| format!("{name} {v}: {e}"));
        match a.as_str() {
            "--scenes" => o.scenes = num(val(&a)?, &a)?,
            "--first" => o.first = num(val(&a)?, &a)?,
            "--config" => o.config = Some(val(&a)?.into()),
            "--tag" => o.tag = val(&a)?,
            "--iters" => o.iters = num(val(&a)?, &a)? as u32,
            "--points" => o.points = num(val(&a)?, &a)? as usize,
            "--width" => o.size.0 = num(val(&a)?, &a)? as u32,
            "--height" => o.size.1 = num(val(&a)?, &a)? as u32,
            "--frames" => o.frames = num(val(&a)?, &a)? as usize,
            "--seed" => o.seed = num(val(&a)?, &a)?,
            s if s.starts_with("--") => return Err(format!("unknown option {s}")),
            s => out = Some(PathBuf::from(s)),
        }
    }
    o.out = out.ok_or("usage: objects_bench OUT [options] (see the file's docs)")?;
    Ok(o)
}

fn main() {
    let o = match parse() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("objects_bench: {e}");
            std::process::exit(2);
        }
    };
    if let Err(e) = run(&o) {
        eprintln!("objects_bench: {e}");
        std::process::exit(1);
    }
}

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn run(o: &Opts) -> Res<()> {
    let results = o.out.join(&o.tag);
    std::fs::create_dir_all(&results)?;
    for seed in o.first..o.first + o.scenes {
        let file = results.join(format!("seed-{seed:03}.json"));
        if file.is_file() {
            continue;
        }
        let (dir, args) = scene_dir(o, seed)?;
        let t0 = Instant::now();
        let scores = start_and_score(o, &dir)?;
        let seconds = t0.elapsed().as_secs_f64();
        let line: Vec<String> = scores.iter().map(brief).collect();
        println!("seed {seed:3} ({seconds:.0} s): {}", line.join(", "));
        let v = serde_json::json!({ "seed": seed, "synth_args": args, "seconds": seconds, "objects": scores });
        let tmp = file.with_extension("json.tmp");
        std::fs::write(&tmp, serde_json::to_string_pretty(&v)?)?;
        std::fs::rename(&tmp, &file)?;
    }
    let summary = summarize(&results)?;
    std::fs::write(results.join("summary.md"), &summary)?;
    println!("{summary}");
    Ok(())
}

/// `OUT/scenes/seed-NNN`, generated (with the ID maps copied from its masks) if missing.
fn scene_dir(o: &Opts, seed: u64) -> Res<(PathBuf, Vec<String>)> {
    let s = varied(seed, o.size.0, o.size.1, o.frames)?;
    let dir = o.out.join("scenes").join(format!("seed-{seed:03}"));
    if !dir.join("semantics").is_dir() {
        let tmp = o.out.join("scenes").join(format!(".tmp-seed-{seed:03}"));
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp)?;
        }
        generate(&s.config, &tmp, &|_, _| {})?;
        ground_truth_id_maps(&tmp)?;
        if dir.exists() {
            std::fs::remove_dir_all(&dir)?;
        }
        std::fs::rename(&tmp, &dir)?;
    }
    Ok((dir, s.args))
}

/// Trains up to the objects' start and scores it.
fn start_and_score(o: &Opts, dir: &Path) -> Res<Vec<ObjectScore>> {
    let mut cfg = TrainConfig::for_run(o.config.as_deref(), Some(o.iters))?;
    cfg.init.random_points = o.points;
    Ok(train::objects_bench::start_and_score(dir, cfg, o.seed)?)
}

fn brief(s: &ObjectScore) -> String {
    let d = match s.decision {
        Decision::Static => "static",
        Decision::Moving => "moving",
        Decision::Field => "field",
        Decision::Unseen => "unseen",
    };
    let mark = if s.correct { "" } else { "✗" };
    match s.path_ratio {
        Some(r) if s.decision == Decision::Moving => format!("{} {d}{mark} path×{r:.2}", s.name),
        _ => format!("{} {d}{mark}", s.name),
    }
}

/// The static test's measures: motion / turn ° / turn motion / ring offset.
fn still_test(ob: &serde_json::Value) -> String {
    let f = |k: &str, d: usize| fmt(ob[k].as_f64(), d);
    let (m, a) = (f("residual_motion", 2), f("residual_angle_deg", 0));
    let (t, r) = (f("residual_turn", 2), f("ring_offset", 2));
    format!("{m} / {a} / {t} / {r}")
}

/// A mover's gauge readings relative to the lift (`ln`: lift / ring / surface) and the
/// chosen gauge's confidence.
fn readings(ob: &serde_json::Value) -> String {
    let c = &ob["cues"];
    if c.is_null() {
        return "–".into();
    }
    let r = |k: &str| fmt(c[k]["ln_factor"].as_f64(), 2);
    let conf = fmt(ob["gauge"]["confidence"].as_f64(), 2);
    format!("0 / {} / {} ({conf})", r("ring"), r("surface"))
}

/// Per reading of the gauge (the lift's, the ring's, the surface contact's, their median),
/// how many movers it would have placed within `ln 1.1` of their true depth: the truth's
/// factor relative to the lift is the chosen one over the measured depth ratio.
struct GaugeTally {
    movers: usize,
    within: [usize; 4],
}

impl GaugeTally {
    fn add(&mut self, ob: &serde_json::Value) {
        let (c, g) = (&ob["cues"], &ob["gauge"]);
        let (Some(depth), Some(chosen)) = (ob["depth_ratio"].as_f64(), g["ln_factor"].as_f64())
        else {
            return;
        };
        let truth = chosen - depth.ln();
        let read = |k: &str| c[k]["ln_factor"].as_f64();
        let mut all: Vec<f64> = [Some(0.0), read("ring"), read("surface")]
            .into_iter()
            .flatten()
            .collect();
        all.sort_by(f64::total_cmp);
        let median = if all.len() == 3 { all[1] } else { 0.0 };
        let each = [Some(0.0), read("ring"), read("surface"), Some(median)];
        self.movers += 1;
        for (n, r) in self.within.iter_mut().zip(each) {
            *n += usize::from(r.is_some_and(|r| (r - truth).abs() <= 1.1f64.ln()));
        }
    }

    fn line(&self) -> String {
        let [l, r, s, m] = self.within;
        let n = self.movers;
        format!(
            "gauge readings within 10 % of the true depth, movers called moving: lift {l}/{n}, ring {r}/{n}, surface {s}/{n}, their median {m}/{n}"
        )
    }
}

fn fmt(v: Option<f64>, digits: usize) -> String {
    v.map_or("–".into(), |v| format!("{v:.digits$}"))
}

/// The table of every result in `dir` and the totals the goals are stated in.
fn summarize(dir: &Path) -> Res<String> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    let mut rows = String::from(
        "| seed | object | truth | decision | true path | path ratio | displacement error | depth ratio | rotation error ° | follow | gauge | readings: lift / ring / surface (confidence) | still test: motion / turn ° / turn motion / ring | mask IoU |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let (mut movers, mut movers_ok, mut within10, mut still, mut still_ok) = (0, 0, 0, 0, 0);
    let mut follow90 = 0;
    let mut tally = GaugeTally {
        movers: 0,
        within: [0; 4],
    };
    for f in &files {
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(f)?)?;
        for ob in v["objects"].as_array().ok_or("objects")? {
            let moving = ob["truly_moving"].as_bool() == Some(true);
            let decision = ob["decision"].as_str().unwrap_or("?");
            let ratio = ob["path_ratio"].as_f64();
            if moving {
                movers += 1;
                movers_ok += usize::from(decision == "moving");
                within10 += usize::from(
                    decision == "moving" && ratio.is_some_and(|r| (r - 1.0).abs() <= 0.1),
                );
                follow90 += usize::from(ob["follow"].as_f64().is_some_and(|f| f >= 0.9));
                if decision == "moving" {
                    tally.add(ob);
                }
            } else {
                still += 1;
                still_ok += usize::from(decision == "static");
            }
            rows += &format!(
                "| {} | {} | {} | {} | {:.2} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                v["seed"],
                ob["name"].as_str().unwrap_or("?"),
                if moving { "moving" } else { "still" },
                decision,
                ob["true_path"].as_f64().unwrap_or(0.0),
                fmt(if moving { ratio } else { None }, 2),
                fmt(ob["displacement_error"].as_f64(), 2),
                fmt(ob["depth_ratio"].as_f64(), 2),
                fmt(ob["rotation_error_deg"].as_f64(), 1),
                fmt(ob["follow"].as_f64(), 2),
                fmt(ob["scale"].as_f64(), 2),
                readings(ob),
                still_test(ob),
                fmt(ob["mask_iou"].as_f64(), 2),
            );
        }
    }
    Ok(format!(
        "{} scenes: movers called moving {movers_ok}/{movers}, path length within 10 % {within10}/{movers}, following ≥ 90 % {follow90}/{movers}; still objects called static {still_ok}/{still}\n\n{}\n\n{rows}",
        files.len(),
        tally.line()
    ))
}
