//! `DIR/report.html`: self-contained apart from the relative image paths (`images/*.png`,
//! `plots/*.svg`) beside it, so the folder can be copied or zipped as is.

use super::figure::Figure;
use super::table::{all_tables, escape};
use super::Report;

const STYLE: &str = "body{font-family:sans-serif;margin:2em;max-width:1400px}\
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}\
caption{font-weight:bold;text-align:left;padding:4px 0}tr.block th{background:#eee;text-align:center}\
table.fig td{padding:2px;text-align:center;vertical-align:middle}table.fig img{max-width:200px;display:block}\
div.fig{overflow-x:auto}\
code,pre{background:#f5f5f5}";

/// The whole HTML document.
pub fn render(report: &Report) -> String {
    let r = report.results;
    let mut out = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>{title}: {scene}</title><style>{STYLE}</style></head><body>\n\
         <h1>{title}: <code>{scene}</code></h1>\n",
        title = escape(&super::title(r)),
        scene = escape(&r.scene)
    );
    out.push_str(&protocol(report));
    out.push_str("<h2>Tables</h2>\n");
    for t in all_tables(r) {
        out.push_str(&t.to_html());
    }
    out.push_str(&figure(report.figure));
    out.push_str("<h2>Plots</h2>\n");
    for p in report.plots {
        out.push_str(&format!(
            "<figure><img src=\"{}\" alt=\"{t}\"><figcaption>{t}</figcaption></figure>\n",
            escape(&p.path),
            t = escape(&p.title)
        ));
    }
    out.push_str("<h2>Commands</h2>\n<pre>");
    for c in &r.commands {
        out.push_str(&escape(c));
        out.push('\n');
    }
    out.push_str(
        "</pre>\n<p>All numbers, the crop boxes and every run's configuration: \
                  <a href=\"results.json\">results.json</a>.</p>\n</body></html>\n",
    );
    out
}

fn protocol(report: &Report) -> String {
    let p = &report.results.protocol;
    let mut out = String::from("<h2>Protocol</h2>\n<ul>\n");
    let items = [
        format!("Split scored: <b>{}</b>; time 0→1 spans {} s; crop tables at t = {:?} s, each the nearest frame of the split.", escape(&p.split), p.duration_s, p.t_seconds),
        format!("Moving objects: <b>{}</b>. Crops: {}.", escape(&super::moving_list(p)), escape(&p.crop_policy)),
        format!("SSIM: {}. LPIPS: {}.", escape(&p.ssim_variant), escape(&p.lpips)),
        format!("Object-ID maps shown: {}.", escape(report.id_map_source)),
    ];
    let notes = report.results.notes.iter().map(|n| escape(n));
    for item in items.into_iter().chain(notes) {
        out.push_str(&format!("<li>{item}</li>\n"));
    }
    out.push_str("</ul>\n");
    out
}

fn figure(fig: &Figure) -> String {
    let mut out = format!(
        "<h2>Qualitative comparison</h2>\n<p>{}</p>\n\
         <div class=\"fig\"><table class=\"fig\">\n<tr><th>t</th>",
        escape(&super::figure_caption(fig))
    );
    for c in &fig.columns {
        out.push_str(&format!("<th>{}</th>", escape(c)));
    }
    out.push_str("</tr>\n");
    for row in &fig.rows {
        out.push_str(&format!(
            "<tr><th>{} s<br><small>{}</small></th>",
            row.t_seconds,
            escape(&row.frame)
        ));
        for (img, col) in row.images.iter().zip(&fig.columns) {
            match img {
                Some(src) => out.push_str(&format!(
                    "<td><img src=\"{}\" alt=\"{} at {} s\"></td>",
                    escape(src),
                    escape(col),
                    row.t_seconds
                )),
                None => out.push_str("<td>—</td>"),
            }
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</table></div>\n");
    out
}
