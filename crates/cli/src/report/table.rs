//! The paper's tables (Tables 1–2: SSIM, PSNR, LPIPS of a zoomed crop at t = 0…5 s and
//! their average), one row per compared method in display order, as plain data, rendered
//! as terminal text, Markdown and HTML.

use super::results::{CropSeries, MethodResults, Results, Scores};

/// One metric block: a title row then one row per method (display name, cells).
pub struct Block {
    pub title: &'static str,
    pub rows: Vec<(String, Vec<String>)>,
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

/// The crop table of one object: per time step and averaged, one row per (method, series).
pub fn crop_table(caption: String, methods: &[(&str, &CropSeries)]) -> PaperTable {
    let mut header = vec![String::new()];
    if let Some((_, first)) = methods.first() {
        header.extend(first.per_time.iter().map(|p| format!("t={}s", p.t_seconds)));
    }
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
            rows: methods
                .iter()
                .map(|(name, s)| (name.to_string(), row(s, get)))
                .collect(),
        })
        .collect();
    PaperTable {
        caption,
        header,
        blocks,
    }
}

/// Full-frame scores, deformation consistency and rigidity residual (all vehicles pooled,
/// then each moving one alone: consistency, the share of its motion its Gaussians follow,
/// and their rigidity residual), one row per method.
pub fn summary_table(r: &Results) -> PaperTable {
    let moving = &r.protocol.moving_objects;
    let cells = |m: &MethodResults| {
        let s = &m.full_frame;
        let mut cells = vec![
            fmt(s.psnr),
            fmt(s.ssim),
            fmt(s.lpips),
            fmt(m.deformation_consistency_rms),
            fmt(m.rigidity_rms),
        ];
        for name in moving {
            cells.push(fmt(m.deformation_consistency_per_object.get(name).copied()));
            cells.push(fmt(m.deformation_follow_per_object.get(name).copied()));
            cells.push(fmt(m.rigidity_rms_per_object.get(name).copied()));
        }
        cells
    };
    let mut header: Vec<String> = [
        "",
        "PSNR (dB) ↑",
        "SSIM ↑",
        "LPIPS ↓",
        "consistency RMS ↓",
        "rigidity RMS ↓",
    ]
    .map(String::from)
    .to_vec();
    for name in moving {
        header.push(format!("consistency RMS, {name} ↓"));
        header.push(format!("motion followed, {name} ↑"));
        header.push(format!("rigidity RMS, {name} ↓"));
    }
    PaperTable {
        caption: "Full-frame test metrics and deformation consistency".into(),
        header,
        blocks: vec![Block {
            title: "",
            rows: r
                .ordered()
                .map(|(name, m)| (name.to_string(), cells(m)))
                .collect(),
        }],
    }
}

/// What the start of each run with rigid objects decided for each object and how well
/// the object's own node follows it (docs/objects.md, "What follows and what does not"):
/// one row per (method, object). `None` when no run has rigid objects.
pub fn objects_table(r: &Results) -> Option<PaperTable> {
    let mut rows = Vec::new();
    for (method, m) in r.ordered() {
        for (object, decision) in &m.rigid_decision_per_object {
            let get = |map: &std::collections::BTreeMap<String, f64>| fmt(map.get(object).copied());
            rows.push((
                format!("{method}: {object}"),
                vec![
                    decision.clone(),
                    get(&m.scale_confidence_per_object),
                    get(&m.node_share_per_object),
                    get(&m.follow_in_node_per_object),
                    get(&m.deformation_follow_per_object),
                ],
            ));
        }
    }
    if rows.is_empty() {
        return None;
    }
    let header = [
        "",
        "decision",
        "scale confidence ↑",
        "node share ↑",
        "motion followed in node ↑",
        "motion followed, pooled ↑",
    ];
    Some(PaperTable {
        caption: "Rigid objects: the start's decision and how each node follows".into(),
        header: header.map(String::from).to_vec(),
        blocks: vec![Block { title: "", rows }],
    })
}

/// Articulated objects: the share of each part's true motion that each method's
/// Gaussians follow (`report::parts`), one column per method.
pub fn parts_table(r: &Results) -> Option<PaperTable> {
    let methods: Vec<(&str, &MethodResults)> = r.ordered().collect();
    let parts: std::collections::BTreeSet<&String> = methods
        .iter()
        .flat_map(|(_, m)| m.follow_per_part.keys())
        .collect();
    if parts.is_empty() {
        return None;
    }
    let rows = parts
        .into_iter()
        .map(|p| {
            let cells = methods
                .iter()
                .map(|(_, m)| fmt(m.follow_per_part.get(p).copied()))
                .collect();
            (p.clone(), cells)
        })
        .collect();
    let mut header = vec![String::new()];
    header.extend(methods.iter().map(|(name, _)| format!("{name} ↑")));
    Some(PaperTable {
        caption: "Articulated objects: share of each part's motion its Gaussians follow".into(),
        header,
        blocks: vec![Block { title: "", rows }],
    })
}

/// The crop series `pick` finds for each method that has it, with the method's name.
fn crops_of<'a>(
    r: &'a Results,
    pick: impl Fn(&'a MethodResults) -> Option<&'a CropSeries>,
) -> Vec<(&'a str, &'a CropSeries)> {
    r.ordered()
        .filter_map(|(name, m)| Some((name, pick(m)?)))
        .collect()
}

/// Every table of a results file: summary, the rigid objects' decisions (when a run has
/// them), the articulated objects' parts (when the scene has them), each moving object,
/// then each static object.
pub fn all_tables(r: &Results) -> Vec<PaperTable> {
    let mut tables = vec![summary_table(r)];
    tables.extend(objects_table(r));
    tables.extend(parts_table(r));
    for name in &r.protocol.moving_objects {
        let crops = crops_of(r, |m| m.moving_object_crops.get(name));
        if !crops.is_empty() {
            let caption = format!("Zoomed moving object ({name}) across time");
            tables.push(crop_table(caption, &crops));
        }
    }
    let statics = r.ordered().next().map(|(_, m)| &m.static_object_crops);
    for name in statics.into_iter().flat_map(|s| s.keys()) {
        let crops = crops_of(r, |m| m.static_object_crops.get(name));
        tables.push(crop_table(
            format!("Static object ({name}) across time"),
            &crops,
        ));
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
                        label.clone()
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
                let mut row = vec![label.as_str()];
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
                out.push_str(&format!("<tr><th>{}</th>", escape(label)));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::methods::MethodName;
    use crate::report::results::TimedScores;

    fn series(psnr: f64) -> CropSeries {
        let per_time = (0..6)
            .map(|t| TimedScores {
                t_seconds: t,
                psnr: Some(psnr),
                ssim: None,
                lpips: None,
                frame: format!("test/r_{t:03}"),
                time: t as f32 / 6.0,
                crop: None,
            })
            .collect();
        CropSeries {
            per_time,
            mean: Scores {
                psnr: Some(psnr),
                ..Scores::default()
            },
        }
    }

    /// `methods` (key, name) with two moving objects (`a`, `b`) and one static (`s`).
    fn results(methods: &[(&str, &str)]) -> Results {
        let mut r = Results::default();
        r.protocol.moving_objects = vec!["a".into(), "b".into()];
        for (i, &(key, name)) in methods.iter().enumerate() {
            let mut m = MethodResults::default();
            for obj in ["a", "b"] {
                m.moving_object_crops.insert(obj.into(), series(i as f64));
            }
            m.static_object_crops.insert("s".into(), series(10.0));
            m.deformation_follow_per_object.insert("b".into(), 0.5);
            m.rigidity_rms = Some(0.125);
            m.rigidity_rms_per_object.insert("a".into(), 0.25);
            r.by_method.insert(key.into(), m);
            r.methods.push(MethodName {
                key: key.into(),
                name: name.into(),
            });
        }
        r
    }

    #[test]
    fn every_method_has_a_row_and_every_moving_object_a_table() {
        let r = results(&[("baseline", "B"), ("semdynreg", "S"), ("rigid", "R")]);
        let tables = all_tables(&r);
        let captions: Vec<&str> = tables.iter().map(|t| t.caption.as_str()).collect();
        assert_eq!(captions.len(), 4, "{captions:?}");
        assert!(captions[1].contains("(a)") && captions[2].contains("(b)"));
        assert!(captions[3].starts_with("Static object (s)"));
        let summary = &tables[0];
        assert_eq!(summary.header.len(), 6 + 3 * 2);
        assert_eq!(summary.header[5], "rigidity RMS ↓");
        assert_eq!(summary.header[8], "rigidity RMS, a ↓");
        let rows = &summary.blocks[0].rows;
        let labels: Vec<&str> = rows.iter().map(|(l, _)| l.as_str()).collect();
        assert_eq!(labels, ["B", "S", "R"]);
        let r_cells = &rows[2].1;
        assert_eq!(r_cells[4], "0.125", "pooled rigidity");
        assert_eq!(r_cells[9], "0.500", "b's motion followed");
        assert_eq!(r_cells[7], "0.250", "a's rigidity");
        assert_eq!(r_cells[10], "n/a", "b's rigidity not measured");
        for t in &tables[1..] {
            for b in &t.blocks {
                assert_eq!(b.rows.len(), 3);
            }
        }
        // Rows follow the method order: the PSNR block of object a, rigid last.
        assert_eq!(tables[1].blocks[1].rows[2].1[0], "2.000");
        let text = tables[1].to_text();
        assert!(text.contains("t=5s"), "{text}");
        assert!(text.lines().any(|l| l.starts_with("R  ")), "{text}");
    }

    #[test]
    fn the_objects_table_lists_each_rigid_runs_objects() {
        let mut r = results(&[("baseline", "B"), ("rigid", "R")]);
        assert!(objects_table(&r).is_none(), "no run has rigid objects");
        let m = r.by_method.get_mut("rigid").unwrap();
        m.rigid_decision_per_object
            .insert("a".into(), "field".into());
        m.rigid_decision_per_object
            .insert("b".into(), "moving".into());
        m.scale_confidence_per_object.insert("b".into(), 2.0 / 3.0);
        m.follow_in_node_per_object.insert("b".into(), 0.9);
        let tables = all_tables(&r);
        assert_eq!(tables.len(), 5);
        let rows = &tables[1].blocks[0].rows;
        let labels: Vec<&str> = rows.iter().map(|(l, _)| l.as_str()).collect();
        assert_eq!(labels, ["R: a", "R: b"]);
        assert_eq!(rows[0].1, ["field", "n/a", "n/a", "n/a", "n/a"]);
        assert_eq!(rows[1].1, ["moving", "0.667", "n/a", "0.900", "0.500"]);
        assert!(tables[1].to_markdown().contains("| R: b | moving |"));
    }

    #[test]
    fn the_parts_table_has_a_column_per_method() {
        let mut r = results(&[("baseline", "B"), ("rigid", "R")]);
        assert!(parts_table(&r).is_none(), "no scene with parts");
        let m = r.by_method.get_mut("baseline").unwrap();
        m.follow_per_part.insert("crane/boom".into(), 0.25);
        m.follow_per_part.insert("crane/bucket".into(), 0.125);
        let m = r.by_method.get_mut("rigid").unwrap();
        m.follow_per_part.insert("crane/boom".into(), 0.5);
        let t = parts_table(&r).unwrap();
        assert_eq!(t.header, ["", "B ↑", "R ↑"]);
        let rows = &t.blocks[0].rows;
        assert_eq!(
            rows[0],
            ("crane/boom".into(), vec!["0.250".into(), "0.500".into()])
        );
        assert_eq!(
            rows[1],
            ("crane/bucket".into(), vec!["0.125".into(), "n/a".into()])
        );
        assert_eq!(all_tables(&r).len(), 5);
    }

    #[test]
    fn two_methods_give_two_rows() {
        let r = results(&[("baseline", "B"), ("semdynreg", "S")]);
        for t in all_tables(&r) {
            for b in &t.blocks {
                assert_eq!(b.rows.len(), 2, "{}", t.caption);
            }
            let md = t.to_markdown();
            assert!(md.contains("| B |") && md.contains("| S |"), "{md}");
        }
    }
}
