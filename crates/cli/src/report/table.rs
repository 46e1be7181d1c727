//! The paper's tables (Tables 1–2: SSIM, PSNR, LPIPS of a zoomed crop at t = 0…5 s and
//! their average, baseline vs ours) as plain data, rendered as terminal text, Markdown
//! and HTML.

use super::results::{CropSeries, Results, Scores};

/// One metric block: a title row then a baseline row and an ours row.
pub struct Block {
    pub title: &'static str,
    pub rows: [(&'static str, Vec<String>); 2],
}

/// A table with a header (first cell is empty) and blocks.
pub struct PaperTable {
    pub caption: String,
    pub header: Vec<String>,
    pub blocks: Vec<Block>,
}

/// Three decimals as in the paper; `n/a` for a missing value.
pub fn fmt(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.3}"),
        _ => "n/a".into(),
    }
}

/// Reads one metric out of a score record.
type Getter = fn(&Scores) -> Option<f64>;

const METRICS: [(&str, Getter); 3] = [
    ("SSIM ↑", |s| s.ssim),
    ("PSNR (dB) ↑", |s| s.psnr),
    ("LPIPS ↓", |s| s.lpips),
];

/// The crop table of one object, baseline vs ours, per time step and averaged.
pub fn crop_table(caption: String, base: &CropSeries, ours: &CropSeries) -> PaperTable {
    let mut header = vec![String::new()];
    header.extend(base.per_time.iter().map(|p| format!("t={}s", p.t_seconds)));
    header.push("Avg.".into());
    let row = |s: &CropSeries, get: Getter| {
        let mut cells: Vec<String> = s.per_time.iter().map(|p| fmt(get(&p.scores()))).collect();
        cells.push(fmt(get(&s.mean)));
        cells
    };
    let blocks = METRICS
        .iter()
        .map(|&(title, get)| Block {
            title,
            rows: [("Baseline", row(base, get)), ("Ours", row(ours, get))],
        })
        .collect();
    PaperTable {
        caption,
        header,
        blocks,
    }
}

/// Full-frame scores and deformation consistency (all vehicles pooled, then the moving
/// one alone, then the share of its motion its Gaussians follow), baseline vs ours.
pub fn summary_table(r: &Results) -> PaperTable {
    let moving = &r.protocol.moving_object;
    let cells = |m: &super::results::MethodResults| {
        let s = &m.full_frame;
        vec![
            fmt(s.psnr),
            fmt(s.ssim),
            fmt(s.lpips),
            fmt(m.deformation_consistency_rms),
            fmt(m.deformation_consistency_per_object.get(moving).copied()),
            fmt(m.deformation_follow_per_object.get(moving).copied()),
        ]
    };
    let moving_header = format!("consistency RMS, {moving} ↓");
    let follow_header = format!("motion followed, {moving} ↑");
    PaperTable {
        caption: "Full-frame test metrics and deformation consistency".into(),
        header: vec![
            String::new(),
            "PSNR (dB) ↑".into(),
            "SSIM ↑".into(),
            "LPIPS ↓".into(),
            "consistency RMS ↓".into(),
            moving_header,
            follow_header,
        ],
        blocks: vec![Block {
            title: "",
            rows: [
                ("Baseline", cells(&r.baseline)),
                ("Ours", cells(&r.semdynreg)),
            ],
        }],
    }
}

/// Every table of a results file: summary, moving object, then each static object.
pub fn all_tables(r: &Results) -> Vec<PaperTable> {
    let mut tables = vec![summary_table(r)];
    tables.push(crop_table(
        format!(
            "Zoomed moving object ({}) across time",
            r.protocol.moving_object
        ),
        &r.baseline.moving_object_crop,
        &r.semdynreg.moving_object_crop,
    ));
    for (name, base) in &r.baseline.static_object_crops {
        if let Some(ours) = r.semdynreg.static_object_crops.get(name) {
            tables.push(crop_table(
                format!("Static object ({name}) across time"),
                base,
                ours,
            ));
        }
    }
    tables
}

impl PaperTable {
    /// Aligned plain text for the terminal.
    pub fn to_text(&self) -> String {
        let width = |i: usize| {
            let mut w = self.header[i].chars().count();
            for b in &self.blocks {
                for (label, cells) in &b.rows {
                    let c = if i == 0 {
                        label.to_string()
                    } else {
                        cells[i - 1].clone()
                    };
                    w = w.max(c.chars().count());
                }
            }
            w
        };
        let widths: Vec<usize> = (0..self.header.len()).map(width).collect();
        let line = |cells: Vec<&str>| {
            let parts: Vec<String> = cells
                .iter()
                .zip(&widths)
                .map(|(c, &w)| format!("{c:>w$}"))
                .collect();
            parts.join("  ")
        };
        let total = widths.iter().sum::<usize>() + 2 * widths.len().saturating_sub(1);
        let mut out = format!(
            "{}\n{}\n",
            self.caption,
            line(self.header.iter().map(String::as_str).collect())
        );
        for b in &self.blocks {
            out.push_str(&"-".repeat(total));
            out.push('\n');
            if !b.title.is_empty() {
                out.push_str(&format!("{}\n", b.title));
            }
            for (label, cells) in &b.rows {
                let mut row = vec![*label];
                row.extend(cells.iter().map(String::as_str));
                out.push_str(&line(row));
                out.push('\n');
            }
        }
        out
    }

    /// A GitHub-flavoured Markdown table (metric titles as bold separator rows).
    pub fn to_markdown(&self) -> String {
        let n = self.header.len();
        let mut out = format!(
            "**{}**\n\n| {} |\n|{}\n",
            self.caption,
            self.header.join(" | "),
            "---|".repeat(n)
        );
        for b in &self.blocks {
            if !b.title.is_empty() {
                out.push_str(&format!("| **{}** |{}\n", b.title, " |".repeat(n - 1)));
            }
            for (label, cells) in &b.rows {
                out.push_str(&format!("| {label} | {} |\n", cells.join(" | ")));
            }
        }
        out
    }

    /// An HTML `<table>` with a caption.
    pub fn to_html(&self) -> String {
        let n = self.header.len();
        let mut out = format!(
            "<table>\n<caption>{}</caption>\n<tr>",
            escape(&self.caption)
        );
        for h in &self.header {
            out.push_str(&format!("<th>{}</th>", escape(h)));
        }
        out.push_str("</tr>\n");
        for b in &self.blocks {
            if !b.title.is_empty() {
                out.push_str(&format!(
                    "<tr class=\"block\"><th colspan=\"{n}\">{}</th></tr>\n",
                    escape(b.title)
                ));
            }
            for (label, cells) in &b.rows {
                out.push_str(&format!("<tr><th>{label}</th>"));
                for c in cells {
                    out.push_str(&format!("<td>{}</td>", escape(c)));
                }
                out.push_str("</tr>\n");
            }
        }
        out.push_str("</table>\n");
        out
    }
}

/// Escapes text for HTML element content and attribute values.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}
