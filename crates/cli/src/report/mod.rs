//! Evaluation and paper-style report of `semdynreg compare` (issue 6, items 3–4): scores
//! two runs' rendered test frames (full frame and per-object crops at t = 0…5 s), writes
//! `results.json`, `report.md` and `report.html` with figures and plots, and prints the
//! paper's tables.

pub mod consistency;
pub mod crops;
pub mod evaluate;
pub mod figure;
mod html;
pub mod images;
pub mod inputs;
pub mod io;
mod markdown;
pub mod plots;
pub mod results;
pub mod runs;
pub mod scorer;
pub mod table;
pub mod trainlog;

use anyhow::{Context, Result};
use figure::FigureRow;
use plots::{line_chart_svg, ChartText, Series};
use results::{CropSeries, Results};
use std::path::{Path, PathBuf};
use trainlog::TrainLog;

/// A plot written beside the report.
#[derive(Clone, Debug)]
pub struct Plot {
    pub title: String,
    /// Relative to the report directory.
    pub path: String,
}

/// What the Markdown and HTML reports show.
pub struct Report<'a> {
    pub results: &'a Results,
    pub rows: &'a [FigureRow],
    /// Where the object-ID maps in the figure come from (SAM + CLIP, or ground truth).
    pub id_map_source: &'a str,
    pub plots: &'a [Plot],
}

/// Paths of the files [`write_report`] produced.
pub struct ReportPaths {
    pub results_json: PathBuf,
    pub markdown: PathBuf,
    pub html: PathBuf,
}

/// Writes `results.json`, `report.md` and `report.html` into `dir`.
pub fn write_report(dir: &Path, report: &Report) -> Result<ReportPaths> {
    let paths = ReportPaths {
        results_json: dir.join("results.json"),
        markdown: dir.join("report.md"),
        html: dir.join("report.html"),
    };
    let json = serde_json::to_string_pretty(report.results).context("serializing results")?;
    io::write_atomic(&paths.results_json, json.as_bytes())?;
    io::write_atomic(&paths.markdown, markdown::render(report).as_bytes())?;
    io::write_atomic(&paths.html, html::render(report).as_bytes())?;
    Ok(paths)
}

/// The paper-style tables as terminal text.
pub fn text_tables(results: &Results) -> String {
    table::all_tables(results)
        .iter()
        .map(|t| t.to_text())
        .collect::<Vec<_>>()
        .join("\n")
}

fn crop_psnr_series(label: &str, s: &CropSeries) -> Series {
    Series {
        label: label.into(),
        points: s
            .per_time
            .iter()
            .filter_map(|p| Some((p.t_seconds as f64, p.psnr?)))
            .collect(),
    }
}

fn write_svg(dir: &Path, name: &str, text: &ChartText, series: &[Series]) -> Result<Plot> {
    let rel = format!("plots/{name}.svg");
    io::write_atomic(&dir.join(&rel), line_chart_svg(text, series)?.as_bytes())?;
    Ok(Plot {
        title: text.title.to_string(),
        path: rel,
    })
}

/// Crop PSNR over time for both runs, and each training-log key in `curves` (e.g. `loss`,
/// `psnr`) over iterations for both runs. `logs` are (label, log) pairs; a key no log
/// holds is left out.
pub fn write_plots(
    dir: &Path,
    results: &Results,
    logs: &[(&str, TrainLog)],
    curves: &[(&str, &str)],
) -> Result<Vec<Plot>> {
    let title = format!(
        "Moving object ({}) crop PSNR over time",
        results.protocol.moving_object
    );
    let text = ChartText {
        title: &title,
        x: "t (s)",
        y: "PSNR (dB)",
    };
    let series = [
        crop_psnr_series("baseline", &results.baseline.moving_object_crop),
        crop_psnr_series("SemDynReg", &results.semdynreg.moving_object_crop),
    ];
    let mut plots = vec![write_svg(dir, "crop_psnr", &text, &series)?];
    for &(key, axis) in curves {
        let series: Vec<Series> = logs
            .iter()
            .map(|(label, log)| Series {
                label: label.to_string(),
                points: log.series(key),
            })
            .filter(|s| !s.points.is_empty())
            .collect();
        if series.is_empty() {
            continue;
        }
        let title = format!("Training: {axis} vs iteration");
        let text = ChartText {
            title: &title,
            x: "iteration",
            y: axis,
        };
        plots.push(write_svg(dir, &format!("train_{key}"), &text, &series)?);
    }
    Ok(plots)
}
