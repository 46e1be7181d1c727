//! The paper's qualitative figure (Figs. 3–4): one row per time step with the ground
//! truth, the object-ID map, the baseline and ours, then zoomed crops of the moving object
//! (ground truth, baseline, ours). Written as PNGs under `DIR/images/`, referenced by
//! relative paths from the HTML and Markdown reports.

use super::crops::CropBox;
use super::evaluate::{EvalSet, RunEval};
use super::images::{colorize_ids, crop, draw_box, save_png, zoom};
use anyhow::Result;
use image::{Rgb, RgbImage};
use std::path::Path;

/// Columns of a figure row, in display order.
pub const COLUMNS: [&str; 7] = [
    "ground truth",
    "object-ID map",
    "baseline",
    "SemDynReg (ours)",
    "zoom: ground truth",
    "zoom: baseline",
    "zoom: ours",
];

/// One row of the figure: image paths relative to the report directory.
#[derive(Clone, Debug)]
pub struct FigureRow {
    pub t_seconds: u32,
    pub frame: String,
    /// One path per entry of [`COLUMNS`]; `None` where there is nothing to show (no ID
    /// map, or the moving object is not visible so there is no zoom).
    pub images: Vec<Option<String>>,
}

/// Colour of the crop outline drawn on the full frames.
const BOX_COLOR: Rgb<u8> = Rgb([255, 0, 255]);
/// Height the zoomed crops are enlarged towards (integer nearest-neighbour factor).
const ZOOM_HEIGHT: u32 = 240;

/// Writes the figure's PNGs under `out_dir/images/` and returns its rows.
/// `id_maps[i]` is the object-ID map shown for time step i (`H·W`, 255 = background).
pub fn write_figure(
    out_dir: &Path,
    set: &EvalSet,
    baseline: &RunEval,
    ours: &RunEval,
    id_maps: &[Option<Vec<u8>>],
) -> Result<Vec<FigureRow>> {
    let picked = set.picked_frames()?;
    let mut rows = Vec::with_capacity(picked.len());
    for (step, (&t, &i)) in set.t_seconds.iter().zip(&picked).enumerate() {
        let frame = &set.frames[i];
        let (w, h) = frame.gt.dimensions();
        let bbox = baseline
            .results
            .moving_object_crop
            .per_time
            .get(step)
            .and_then(|p| p.crop);
        let bbox = bbox.map(|[x, y, width, height]| CropBox {
            x,
            y,
            width,
            height,
        });
        let renders = [
            &frame.gt,
            &baseline.picked_renders[step],
            &ours.picked_renders[step],
        ];
        let cell = |name: &str, img: &RgbImage| -> Result<Option<String>> {
            let rel = format!("images/t{t}s_{name}.png");
            save_png(img, &out_dir.join(&rel))?;
            Ok(Some(rel))
        };
        let mut images = Vec::with_capacity(COLUMNS.len());
        let outlined = |img: &RgbImage| {
            let mut img = img.clone();
            if let Some(b) = bbox {
                draw_box(&mut img, b, BOX_COLOR, 2);
            }
            img
        };
        images.push(cell("gt", &outlined(renders[0]))?);
        images.push(match id_maps.get(step).and_then(|m| m.as_ref()) {
            Some(ids) => cell("ids", &colorize_ids(ids, w, h)?)?,
            None => None,
        });
        images.push(cell("baseline", &outlined(renders[1]))?);
        images.push(cell("ours", &outlined(renders[2]))?);
        for (name, img) in ["zoom_gt", "zoom_baseline", "zoom_ours"]
            .iter()
            .zip(renders)
        {
            images.push(match bbox {
                Some(b) => cell(name, &zoom(&crop(img, b), ZOOM_HEIGHT))?,
                None => None,
            });
        }
        rows.push(FigureRow {
            t_seconds: t,
            frame: frame.file_path.clone(),
            images,
        });
    }
    Ok(rows)
}
