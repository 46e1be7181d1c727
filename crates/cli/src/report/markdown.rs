//! `DIR/report.md`: the same content as the HTML report, in GitHub-flavoured Markdown with
//! relative image links.

use super::table::all_tables;
use super::Report;

/// The whole Markdown document.
pub fn render(report: &Report) -> String {
    let r = report.results;
    let p = &r.protocol;
    let mut out = format!("# {}: `{}`\n\n## Protocol\n\n", super::title(r), r.scene);
    out.push_str(&format!(
        "- Split scored: **{}**; time 0→1 spans {} s; crop tables at t = {:?} s, each the nearest frame of the split.\n\
         - Moving objects: **{}**. Crops: {}.\n- SSIM: {}. LPIPS: {}.\n- Object-ID maps shown: {}.\n",
        p.split, p.duration_s, p.t_seconds, super::moving_list(p), p.crop_policy, p.ssim_variant, p.lpips,
        report.id_map_source
    ));
    for n in &r.notes {
        out.push_str(&format!("- {n}\n"));
    }
    out.push_str("\n## Tables\n\n");
    for t in all_tables(r) {
        out.push_str(&t.to_markdown());
        out.push('\n');
    }
    out.push_str(&figure(report));
    out.push_str("\n## Plots\n\n");
    for plot in report.plots {
        out.push_str(&format!("![{t}]({p})\n\n", t = plot.title, p = plot.path));
    }
    out.push_str("## Commands\n\n```\n");
    for c in &r.commands {
        out.push_str(c);
        out.push('\n');
    }
    out.push_str("```\n\nAll numbers, the crop boxes and every run's configuration: [results.json](results.json).\n");
    out
}

/// The qualitative figure as a table of image links.
fn figure(report: &Report) -> String {
    let fig = report.figure;
    let mut out = format!(
        "## Qualitative comparison\n\n{}\n\n| t |",
        super::figure_caption(fig)
    );
    for c in &fig.columns {
        out.push_str(&format!(" {c} |"));
    }
    out.push_str(&format!("\n|{}\n", "---|".repeat(fig.columns.len() + 1)));
    for row in &fig.rows {
        out.push_str(&format!("| {} s (`{}`) |", row.t_seconds, row.frame));
        for (img, col) in row.images.iter().zip(&fig.columns) {
            match img {
                Some(src) => out.push_str(&format!(" ![{col}]({src}) |")),
                None => out.push_str(" — |"),
            }
        }
        out.push('\n');
    }
    out
}
