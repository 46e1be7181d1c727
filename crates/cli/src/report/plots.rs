//! Line plots as SVG with `plotters`' SVG backend. Text is written as SVG `<text>`
//! elements and sized by plotters' built-in estimate, so no font files or fontconfig are
//! needed (checked on a machine without the `ttf` feature); the browser renders the text.

use anyhow::{anyhow, Result};
use plotters::prelude::*;

/// One named curve.
#[derive(Clone, Debug)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// Axis titles and the chart caption.
pub struct ChartText<'a> {
    pub title: &'a str,
    pub x: &'a str,
    pub y: &'a str,
}

const COLORS: [RGBColor; 4] = [
    RGBColor(214, 39, 40),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

/// Data range of all finite points, widened by 5% (and to a unit span when flat).
fn bounds(series: &[Series]) -> ((f64, f64), (f64, f64)) {
    let finite = series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|(x, y)| x.is_finite() && y.is_finite());
    let mut b = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in finite {
        b = (b.0.min(x), b.1.max(x), b.2.min(y), b.3.max(y));
    }
    if b.0 > b.1 {
        return ((0.0, 1.0), (0.0, 1.0));
    }
    let widen = |lo: f64, hi: f64| {
        let span = if hi - lo > 1e-12 { hi - lo } else { 1.0 };
        (lo - 0.05 * span, hi + 0.05 * span)
    };
    (widen(b.0, b.1), widen(b.2, b.3))
}

/// Renders the curves as an SVG document (640×400) with markers at each point.
pub fn line_chart_svg(text: &ChartText, series: &[Series]) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (640, 400)).into_drawing_area();
        draw(&root, text, series).map_err(|e| anyhow!("drawing plot '{}': {e}", text.title))?;
        root.present()
            .map_err(|e| anyhow!("finishing plot '{}': {e}", text.title))?;
    }
    Ok(svg)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    text: &ChartText,
    series: &[Series],
) -> std::result::Result<(), Box<dyn std::error::Error + 'static>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let ((x0, x1), (y0, y1)) = bounds(series);
    let mut chart = ChartBuilder::on(root)
        .caption(text.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(text.x)
        .y_desc(text.y)
        .draw()?;
    for (i, s) in series.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        let pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(s.label.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        if pts.len() <= 50 {
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_contains_title_axes_and_legend() {
        let series = vec![
            Series {
                label: "baseline".into(),
                points: vec![(0.0, 24.0), (1.0, 27.5), (2.0, f64::NAN)],
            },
            Series {
                label: "SemDynReg".into(),
                points: vec![(0.0, 29.0), (1.0, 31.7)],
            },
        ];
        let text = ChartText {
            title: "Crop PSNR",
            x: "t (s)",
            y: "PSNR (dB)",
        };
        let svg = line_chart_svg(&text, &series).unwrap();
        for needle in [
            "<svg",
            "Crop PSNR",
            "t (s)",
            "PSNR (dB)",
            "baseline",
            "SemDynReg",
            "<polyline",
        ] {
            assert!(svg.contains(needle), "missing {needle}");
        }
    }

    #[test]
    fn empty_and_flat_series_still_plot() {
        let text = ChartText {
            title: "empty",
            x: "x",
            y: "y",
        };
        assert!(line_chart_svg(&text, &[]).unwrap().contains("empty"));
        let flat = [Series {
            label: "f".into(),
            points: vec![(1.0, 2.0)],
        }];
        let ((x0, x1), (y0, y1)) = bounds(&flat);
        for (got, want) in [(x0, 0.95), (x1, 1.05), (y0, 1.95), (y1, 2.05)] {
            assert!((got - want).abs() < 1e-12, "{got} vs {want}");
        }
    }
}
