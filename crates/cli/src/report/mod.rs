//! Evaluation and paper-style report of `semdynreg compare`: scores
//! each compared method's rendered test frames (full frame and per-object crops at
//! t = 0…5 s), writes `results.json`, `report.md` and `report.html` with figures and plots,
//! and prints the paper's tables.

pub mod consistency;
pub mod crops;
pub mod evaluate;
pub mod figure;
mod html;
pub mod images;
pub mod inputs;
pub mod io;
mod markdown;
pub mod methods;
pub mod parts;
pub mod plots;
pub mod results;
pub mod runs;
pub mod scorer;
pub mod scoring;
pub mod table;
pub mod trainlog;

use anyhow::{Context, Result};
use figure::Figure;
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
    pub figure: &'a Figure,
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

/// The report's title: the compared methods' names, e.g. `baseline vs SemDynReg (paper)`.
fn title(results: &Results) -> String {
    let names: Vec<&str> = results.methods.iter().map(|m| m.name.as_str()).collect();
    names.join(" vs ")
}

/// The moving objects' names for the protocol, or `none`.
fn moving_list(p: &results::Protocol) -> String {
    if p.moving_objects.is_empty() {
        return "none".into();
    }
    p.moving_objects.join(", ")
}

/// The sentence above the figure, naming the zoomed object.
fn figure_caption(fig: &Figure) -> String {
    match &fig.zoomed {
        Some(object) => format!(
            "Rows are time steps; the magenta box is the padded crop of the first moving \
             object ({object}), enlarged in the zoom columns."
        ),
        None => "Rows are time steps; no object moves, so there is nothing to zoom.".into(),
    }
}

/// The paper-style tables as terminal text.
pub fn text_tables(results: &Results) -> String {
    table::all_tables(results)
        .iter()
        .map(|t| t.to_text())
        .collect::<Vec<_>>()
        .join("\n")
}

/// The crop PSNR of one object over time, for one method.
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

/// The plot file of moving object `index` (`crop_psnr` for the first, as before there
/// were several), its name kept to characters safe in a file name.
fn crop_plot_name(index: usize, object: &str) -> String {
    if index == 0 {
        return "crop_psnr".into();
    }
    let safe: String = object
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    format!("crop_psnr_{index}_{safe}")
}

/// Crop PSNR over time of each moving object, one line per method.
fn write_crop_plots(dir: &Path, results: &Results) -> Result<Vec<Plot>> {
    let mut plots = Vec::new();
    for (index, object) in results.protocol.moving_objects.iter().enumerate() {
        let title = format!("Moving object ({object}) crop PSNR over time");
        let text = ChartText {
            title: &title,
            x: "t (s)",
            y: "PSNR (dB)",
        };
        let series: Vec<Series> = results
            .ordered()
            .filter_map(|(name, m)| {
                Some(crop_psnr_series(name, m.moving_object_crops.get(object)?))
            })
            .collect();
        plots.push(write_svg(
            dir,
            &crop_plot_name(index, object),
            &text,
            &series,
        )?);
    }
    Ok(plots)
}

/// Crop PSNR over time for every method and moving object, and each training-log key in
/// `curves` (e.g. `loss`, `psnr`) over iterations, one line per method. `logs` are
/// (method name, log) pairs; a key no log holds is left out.
pub fn write_plots(
    dir: &Path,
    results: &Results,
    logs: &[(String, TrainLog)],
    curves: &[(&str, &str)],
) -> Result<Vec<Plot>> {
    let mut plots = write_crop_plots(dir, results)?;
    for &(key, axis) in curves {
        let series: Vec<Series> = logs
            .iter()
            .map(|(label, log)| Series {
                label: label.clone(),
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
