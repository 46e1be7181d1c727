//! `DIR/report.md`: the same content as the HTML report, in GitHub-flavoured Markdown with
//! relative image links.

use super::figure::COLUMNS;
use super::table::all_tables;
use super::Report;

/// The whole Markdown document.
pub fn render(report: &Report) -> String {
    let r = report.results;
    let p = &r.protocol;
    let mut out = format!("# SemDynReg vs baseline: `{}`\n\n## Protocol\n\n", r.scene);
    out.push_str(&format!(
        "- Split scored: **{}**; time 0→1 spans {} s; crop tables at t = {:?} s, each the nearest frame of the split.\n\
         - Moving object: **{}**. Crops: {}.\n- SSIM: {}. LPIPS: {}.\n- Object-ID maps shown: {}.\n",
        p.split, p.duration_s, p.t_seconds, p.moving_object, p.crop_policy, p.ssim_variant, p.lpips,
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
    out.push_str(
        "## Qualitative comparison\n\nRows are time steps; the magenta box is the moving \
                  object's padded crop, enlarged in the last three columns.\n\n| t |",
    );
    for c in COLUMNS {
        out.push_str(&format!(" {c} |"));
    }
    out.push_str(&format!("\n|{}\n", "---|".repeat(COLUMNS.len() + 1)));
    for row in report.rows {
        out.push_str(&format!("| {} s (`{}`) |", row.t_seconds, row.frame));
        for (img, col) in row.images.iter().zip(COLUMNS) {
            match img {
                Some(src) => out.push_str(&format!(" ![{col}]({src}) |")),
                None => out.push_str(" — |"),
            }
        }
        out.push('\n');
    }
    out.push_str("\n## Plots\n\n");
    for plot in report.plots {
        out.push_str(&format!("![{t}]({p})\n\n", t = plot.title, p = plot.path));
    }
    out.push_str("## Commands\n\n```\n");
    for c in &r.commands {
        out.push_str(c);
        out.push('\n');
    }
    out.push_str("```\n\nAll numbers, the crop boxes and both runs' configurations: [results.json](results.json).\n");
    out
}
