//! `semdynreg sweep DIR --collect`: every finished run's `results.json` (and its
//! `timings.json`) as one table with the grid's columns — `DIR/table.md`, `table.csv`,
//! `table.json` — and one plot per swept key of the main metric against it
//! (`DIR/plots/<key>.svg`). Unfinished runs are listed, not guessed.

use super::plan::{Plan, RunSpec, RESULTS_FILE};
use super::plot;
use crate::report::io::write_atomic;
use crate::report::results::{mean_of, MethodResults, Results};
use anyhow::{Context, Result};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One metric column: header, JSON/CSV key, decimals in Markdown, and how to read it.
struct Metric {
    header: &'static str,
    key: &'static str,
    decimals: usize,
    get: fn(&MethodResults) -> Option<f64>,
}

fn static_psnr(m: &MethodResults) -> Option<f64> {
    mean_of(m.static_object_crops.values().map(|c| c.mean.psnr))
}

fn follow(m: &MethodResults) -> Option<f64> {
    mean_of(m.deformation_follow_per_object.values().map(|&v| Some(v)))
}

fn follow_in_node(m: &MethodResults) -> Option<f64> {
    mean_of(m.follow_in_node_per_object.values().map(|&v| Some(v)))
}

fn least_scale_confidence(m: &MethodResults) -> Option<f64> {
    m.scale_confidence_per_object
        .values()
        .copied()
        .reduce(f64::min)
}

/// How many objects the rigid start gave `decision`; `None` for runs without rigid objects.
fn decided(m: &MethodResults, decision: &str) -> Option<f64> {
    let d = &m.rigid_decision_per_object;
    (!d.is_empty()).then(|| d.values().filter(|v| *v == decision).count() as f64)
}

/// The columns of the regularizer's ablation tables (docs/regularizer.md), then the full
/// frame's, follow, the rigid objects' (docs/objects.md) and time.
const METRICS: [Metric; 13] = [
    Metric {
        header: "moving crop PSNR",
        key: "moving_crop_psnr",
        decimals: 2,
        get: |m| m.moving_object_crop.mean.psnr,
    },
    Metric {
        header: "SSIM",
        key: "moving_crop_ssim",
        decimals: 3,
        get: |m| m.moving_object_crop.mean.ssim,
    },
    Metric {
        header: "LPIPS",
        key: "moving_crop_lpips",
        decimals: 3,
        get: |m| m.moving_object_crop.mean.lpips,
    },
    Metric {
        header: "static crop PSNR (mean)",
        key: "static_crop_psnr",
        decimals: 2,
        get: static_psnr,
    },
    Metric {
        header: "consistency RMS",
        key: "consistency_rms",
        decimals: 3,
        get: |m| m.deformation_consistency_rms,
    },
    Metric {
        header: "follow",
        key: "follow",
        decimals: 3,
        get: follow,
    },
    Metric {
        header: "full-frame PSNR",
        key: "full_psnr",
        decimals: 2,
        get: |m| m.full_frame.psnr,
    },
    Metric {
        header: "full SSIM",
        key: "full_ssim",
        decimals: 3,
        get: |m| m.full_frame.ssim,
    },
    Metric {
        header: "full LPIPS",
        key: "full_lpips",
        decimals: 3,
        get: |m| m.full_frame.lpips,
    },
    Metric {
        header: "follow in node",
        key: "follow_in_node",
        decimals: 3,
        get: follow_in_node,
    },
    Metric {
        header: "least scale confidence",
        key: "scale_confidence_min",
        decimals: 2,
        get: least_scale_confidence,
    },
    Metric {
        header: "objects static",
        key: "objects_static",
        decimals: 0,
        get: |m| decided(m, "static"),
    },
    Metric {
        header: "objects left to the field",
        key: "objects_field",
        decimals: 0,
        get: |m| decided(m, "field"),
    },
];

/// One finished run's row.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub run: String,
    pub scene: String,
    pub mode: String,
    pub seed: u64,
    /// The swept keys this run sets (absent: its mode ignores the key, e.g. `reg.*` of a
    /// baseline).
    pub params: BTreeMap<String, serde_json::Value>,
    pub metrics: BTreeMap<String, Option<f64>>,
    /// Training time over all its segments (`timings.json`'s `total_train_s`).
    pub train_s: Option<f64>,
}

/// The whole collected table (`table.json`).
#[derive(Clone, Debug, Serialize)]
pub struct Table {
    pub columns: Vec<String>,
    /// The metric the plots show: the moving object's crop PSNR, or the full frame's when
    /// no run has a moving object.
    pub main_metric: String,
    pub rows: Vec<Row>,
    /// Runs of the plan without results (not run yet, running, or failed).
    pub unfinished: Vec<String>,
}

/// Paths written by [`collect`].
pub struct Collected {
    pub table: Table,
    pub markdown: PathBuf,
    pub plots: Vec<PathBuf>,
}

/// Reads every run of the plan in `dir` and writes the table and plots.
pub fn collect(dir: &Path) -> Result<Collected> {
    let plan = Plan::read(dir)?;
    let table = build(&plan)?;
    let md = markdown(&table);
    let markdown_path = dir.join("table.md");
    write_atomic(&markdown_path, md.as_bytes())?;
    write_atomic(&dir.join("table.csv"), csv(&table)?.as_bytes())?;
    let json = serde_json::to_string_pretty(&table).context("serializing the table")?;
    write_atomic(&dir.join("table.json"), json.as_bytes())?;
    let plots = plot::write_plots(dir, &table)?;
    Ok(Collected {
        table,
        markdown: markdown_path,
        plots,
    })
}

fn build(plan: &Plan) -> Result<Table> {
    let mut rows = Vec::new();
    let mut unfinished = Vec::new();
    for r in &plan.runs {
        match read_row(plan, r)? {
            Some(row) => rows.push(row),
            None => unfinished.push(r.name.clone()),
        }
    }
    let has_moving = rows.iter().any(|r| r.metrics["moving_crop_psnr"].is_some());
    Ok(Table {
        columns: plan.columns.clone(),
        main_metric: if has_moving {
            "moving_crop_psnr"
        } else {
            "full_psnr"
        }
        .into(),
        rows,
        unfinished,
    })
}

fn read_row(plan: &Plan, r: &RunSpec) -> Result<Option<Row>> {
    let dir = plan.run_dir(&r.name);
    let path = dir.join(RESULTS_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let results: Results =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let m = results
        .by_method
        .get(&r.mode)
        .with_context(|| format!("{} has no `{}` results", path.display(), r.mode))?;
    Ok(Some(Row {
        run: r.name.clone(),
        scene: r.scene.clone(),
        mode: r.mode.clone(),
        seed: r.seed,
        params: r.overrides.clone(),
        metrics: METRICS
            .iter()
            .map(|x| (x.key.to_string(), (x.get)(m)))
            .collect(),
        train_s: train_seconds(&dir),
    }))
}

/// `total_train_s` of the run's `timings.json`, when it has one.
fn train_seconds(run: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(run.join("timings.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    v.get("total_train_s")?.as_f64()
}

/// A parameter value as a table cell: TOML's text, `–` where the run does not use it.
pub fn param_text(v: Option<&serde_json::Value>) -> String {
    match v {
        None => "–".into(),
        Some(serde_json::Value::String(s)) => s.clone(),
        Some(v) => v.to_string(),
    }
}

fn header(t: &Table) -> Vec<String> {
    let mut h: Vec<String> = ["run", "scene", "mode", "seed"].map(String::from).to_vec();
    h.extend(t.columns.iter().cloned());
    h.extend(METRICS.iter().map(|m| m.header.to_string()));
    h.push("train s".into());
    h
}

fn cells(t: &Table, r: &Row, number: impl Fn(Option<f64>, usize) -> String) -> Vec<String> {
    let mut c = vec![
        r.run.clone(),
        r.scene.clone(),
        r.mode.clone(),
        r.seed.to_string(),
    ];
    c.extend(t.columns.iter().map(|k| param_text(r.params.get(k))));
    c.extend(METRICS.iter().map(|m| number(r.metrics[m.key], m.decimals)));
    c.push(number(r.train_s, 1));
    c
}

/// The Markdown table, then the unfinished runs.
pub fn markdown(t: &Table) -> String {
    let h = header(t);
    let mut s = format!("| {} |\n|{}\n", h.join(" | "), "---|".repeat(h.len()));
    for r in &t.rows {
        let c = cells(t, r, |v, d| match v {
            Some(v) if v.is_finite() => format!("{v:.d$}"),
            _ => "n/a".into(),
        });
        s += &format!("| {} |\n", c.join(" | "));
    }
    if !t.unfinished.is_empty() {
        s += &format!(
            "\nNot finished ({}): {}\n",
            t.unfinished.len(),
            t.unfinished.join(", ")
        );
    }
    s
}

/// The CSV table: full precision, empty cells for missing values.
fn csv(t: &Table) -> Result<String> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(header(t))?;
    for r in &t.rows {
        w.write_record(cells(t, r, |v, _| {
            v.filter(|v| v.is_finite())
                .map_or(String::new(), |v| v.to_string())
        }))?;
    }
    let bytes = w.into_inner().context("finishing the CSV")?;
    String::from_utf8(bytes).context("the CSV is UTF-8")
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn row(run: &str, mode: &str, k: Option<i64>, psnr: f64) -> Row {
        Row {
            run: run.into(),
            scene: "a".into(),
            mode: mode.into(),
            seed: 0,
            params: k
                .map(|k| ("reg.k".to_string(), serde_json::json!(k)))
                .into_iter()
                .collect(),
            metrics: METRICS
                .iter()
                .map(|m| {
                    (
                        m.key.to_string(),
                        (m.key == "moving_crop_psnr").then_some(psnr),
                    )
                })
                .collect(),
            train_s: Some(1.5),
        }
    }

    #[test]
    fn rigid_runs_report_their_objects() {
        let mut m = MethodResults::default();
        assert_eq!(decided(&m, "static"), None);
        assert_eq!(least_scale_confidence(&m), None);
        for (o, d) in [("a", "static"), ("b", "moving"), ("c", "field")] {
            m.rigid_decision_per_object.insert(o.into(), d.into());
        }
        m.scale_confidence_per_object.insert("b".into(), 1.0);
        m.scale_confidence_per_object.insert("c".into(), 1.0 / 3.0);
        m.follow_in_node_per_object.insert("b".into(), 0.8);
        m.follow_in_node_per_object.insert("c".into(), 0.6);
        assert_eq!(decided(&m, "static"), Some(1.0));
        assert_eq!(decided(&m, "moving"), Some(1.0));
        assert_eq!(least_scale_confidence(&m), Some(1.0 / 3.0));
        assert!((follow_in_node(&m).unwrap() - 0.7).abs() < 1e-12);
    }

    #[test]
    fn markdown_and_csv_hold_the_grid_columns() {
        let t = Table {
            columns: vec!["reg.k".into()],
            main_metric: "moving_crop_psnr".into(),
            rows: vec![
                row("b", "baseline", None, 17.114),
                row("f", "semdynreg", Some(3), 17.2),
            ],
            unfinished: vec!["g".into()],
        };
        let md = markdown(&t);
        assert!(
            md.starts_with("| run | scene | mode | seed | reg.k | moving crop PSNR |"),
            "{md}"
        );
        assert!(
            md.contains("| b | a | baseline | 0 | – | 17.11 | n/a |"),
            "{md}"
        );
        assert!(md.contains("| f | a | semdynreg | 0 | 3 | 17.20 |"), "{md}");
        assert!(md.contains("Not finished (1): g"), "{md}");
        let c = csv(&t).unwrap();
        assert_eq!(c.lines().count(), 3);
        assert!(
            c.lines()
                .nth(2)
                .unwrap()
                .starts_with("f,a,semdynreg,0,3,17.2,,"),
            "{c}"
        );
    }
}
