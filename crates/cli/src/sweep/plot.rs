//! The collected table's plots: per swept key, the main metric against the key's value
//! (`DIR/plots/<key>.svg`, `report::plots`' SVG line charts). Runs that differ in
//! anything but that key and the seed are separate lines (seeds averaged); runs that do not
//! use the key (a baseline under `reg.*`) are a flat reference line across the plot.

use super::collect::{param_text, Row, Table};
use crate::report::io::write_atomic;
use crate::report::plots::{line_chart_svg, ChartText, Series};
use anyhow::Result;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Writes one SVG per swept key with numeric values; returns their paths.
pub fn write_plots(dir: &Path, t: &Table) -> Result<Vec<PathBuf>> {
    let mut paths = Vec::new();
    for key in &t.columns {
        let Some((series, x_label)) = key_series(t, key) else {
            tracing::info!("no plot against {key}: its values are not numbers");
            continue;
        };
        let title = format!("{} vs {key}", metric_label(&t.main_metric));
        let text = ChartText {
            title: &title,
            x: &x_label,
            y: metric_label(&t.main_metric),
        };
        let path = dir.join("plots").join(format!("{key}.svg"));
        write_atomic(&path, line_chart_svg(&text, &series)?.as_bytes())?;
        paths.push(path);
    }
    Ok(paths)
}

fn metric_label(key: &str) -> &'static str {
    match key {
        "moving_crop_psnr" => "moving-object crop PSNR (dB)",
        _ => "full-frame PSNR (dB)",
    }
}

/// A number from a parameter value (booleans as 0/1), else `None`.
fn number(v: &serde_json::Value) -> Option<f64> {
    v.as_f64()
        .or_else(|| v.as_bool().map(|b| f64::from(u8::from(b))))
}

/// The lines of the plot against `key`, and the x axis title (log10 when the values span
/// two decades or more, as λ does); `None` when no run has a number there.
fn key_series(t: &Table, key: &str) -> Option<(Vec<Series>, String)> {
    let y = |r: &Row| {
        r.metrics
            .get(&t.main_metric)
            .copied()
            .flatten()
            .filter(|v| v.is_finite())
    };
    let xs: Vec<f64> = t
        .rows
        .iter()
        .filter_map(|r| number(r.params.get(key)?))
        .collect();
    if xs.is_empty() {
        return None;
    }
    let (lo, hi) = xs
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    let log = lo > 0.0 && hi / lo >= 100.0;
    let tx = |x: f64| if log { x.log10() } else { x };
    // (line label) → x → metric values over seeds.
    let mut lines: BTreeMap<String, BTreeMap<u64, (f64, Vec<f64>)>> = BTreeMap::new();
    let mut flat: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in &t.rows {
        let Some(v) = y(r) else { continue };
        let label = line_label(t, r, key);
        match r.params.get(key).and_then(number) {
            Some(x) => lines
                .entry(label)
                .or_default()
                .entry(tx(x).to_bits())
                .or_insert((tx(x), Vec::new()))
                .1
                .push(v),
            None => flat.entry(label).or_default().push(v),
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let mut series: Vec<Series> = lines
        .into_iter()
        .map(|(label, pts)| {
            let mut points: Vec<(f64, f64)> =
                pts.into_values().map(|(x, v)| (x, mean(&v))).collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            Series { label, points }
        })
        .collect();
    series.extend(flat.into_iter().map(|(label, v)| Series {
        label,
        points: vec![(tx(lo), mean(&v)), (tx(hi), mean(&v))],
    }));
    let x_label = if log {
        format!("log10({key})")
    } else {
        key.to_string()
    };
    Some((series, x_label))
}

/// What a line stands for: scene, mode and the run's other swept values.
fn line_label(t: &Table, r: &Row, key: &str) -> String {
    let mut label = format!("{} {}", r.scene, r.mode);
    for k in t.columns.iter().filter(|k| *k != key) {
        if let Some(v) = r.params.get(k) {
            let short = k.rsplit('.').next().unwrap_or(k);
            label += &format!(" {short}={}", param_text(Some(v)));
        }
    }
    label
}

#[cfg(test)]
mod tests {
    use super::super::collect::tests::row;
    use super::*;

    #[test]
    fn one_line_per_other_setting_and_a_flat_baseline() {
        let mut rows = vec![
            row("b", "baseline", None, 17.0),
            row("k1", "semdynreg", Some(1), 17.1),
            row("k3", "semdynreg", Some(3), 17.3),
        ];
        let mut other_seed = row("k3s1", "semdynreg", Some(3), 17.5);
        other_seed.seed = 1;
        rows.push(other_seed);
        let t = Table {
            columns: vec!["reg.k".into()],
            main_metric: "moving_crop_psnr".into(),
            rows,
            unfinished: vec![],
        };
        let (series, x) = key_series(&t, "reg.k").unwrap();
        assert_eq!(x, "reg.k");
        assert_eq!(series.len(), 2);
        assert_eq!(series[0].label, "a semdynreg");
        // The two seeds at k = 3 are averaged.
        assert_eq!(series[0].points, vec![(1.0, 17.1), (3.0, 17.4)]);
        assert_eq!(series[1].label, "a baseline");
        assert_eq!(series[1].points, vec![(1.0, 17.0), (3.0, 17.0)]);
        let dir = tempfile::tempdir().unwrap();
        let paths = write_plots(dir.path(), &t).unwrap();
        let svg = std::fs::read_to_string(&paths[0]).unwrap();
        assert!(svg.contains("<svg") && svg.contains("a baseline"));
    }
}
