//! The paper's qualitative figure (Figs. 3–4): one row per time step with the ground
//! truth, the object-ID map and each method's render, then zoomed crops of the first moving
//! object (ground truth, then each method). Written as PNGs under `DIR/images/`, referenced
//! by relative paths from the HTML and Markdown reports.
//!
//! Only the first moving object is zoomed: with three methods a row already holds nine
//! images, and a second object's zooms would double the zoom columns.

use super::crops::CropBox;
use super::evaluate::{EvalFrame, EvalSet, RunEval};
use super::images::{colorize_ids, crop, draw_box, save_png, zoom};
use anyhow::Result;
use image::{Rgb, RgbImage};
use std::path::Path;

/// One method's renders in the figure.
pub struct FigureMethod<'a> {
    /// File-name part of its images (`t0s_<key>.png`).
    pub key: &'a str,
    /// Its column title.
    pub name: &'a str,
    pub eval: &'a RunEval,
}

/// The figure: column titles and one row per time step.
#[derive(Clone, Debug, Default)]
pub struct Figure {
    pub columns: Vec<String>,
    pub rows: Vec<FigureRow>,
    /// The object whose padded crop is outlined and zoomed, if any moves.
    pub zoomed: Option<String>,
}

/// One row of the figure: image paths relative to the report directory.
#[derive(Clone, Debug)]
pub struct FigureRow {
    pub t_seconds: u32,
    pub frame: String,
    /// One path per entry of [`Figure::columns`]; `None` where there is nothing to show
    /// (no ID map, or the moving object is not visible so there is no zoom).
    pub images: Vec<Option<String>>,
}

/// Colour of the crop outline drawn on the full frames.
const BOX_COLOR: Rgb<u8> = Rgb([255, 0, 255]);
/// Height the zoomed crops are enlarged towards (integer nearest-neighbour factor).
const ZOOM_HEIGHT: u32 = 240;

/// Column titles: ground truth, ID map, each method, then the zooms in the same order.
pub fn columns(methods: &[FigureMethod]) -> Vec<String> {
    let mut c = vec!["ground truth".to_string(), "object-ID map".to_string()];
    c.extend(methods.iter().map(|m| m.name.to_string()));
    c.push("zoom: ground truth".into());
    c.extend(methods.iter().map(|m| format!("zoom: {}", m.name)));
    c
}

/// Writes the figure's PNGs under `out_dir/images/` and returns it.
/// `id_maps[i]` is the object-ID map shown for time step i (`H·W`, 255 = background).
pub fn write_figure(
    out_dir: &Path,
    set: &EvalSet,
    methods: &[FigureMethod],
    id_maps: &[Option<Vec<u8>>],
) -> Result<Figure> {
    let picked = set.picked_frames()?;
    let mut rows = Vec::with_capacity(picked.len());
    for (step, (&t, &i)) in set.t_seconds.iter().zip(&picked).enumerate() {
        let cell = |name: &str, img: &RgbImage| -> Result<Option<String>> {
            let rel = format!("images/t{t}s_{name}.png");
            save_png(img, &out_dir.join(&rel))?;
            Ok(Some(rel))
        };
        let id_map = id_maps.get(step).and_then(|m| m.as_ref());
        let frame = &set.frames[i];
        let images = row_images(frame, step, methods, id_map, &cell)?;
        rows.push(FigureRow {
            t_seconds: t,
            frame: frame.file_path.clone(),
            images,
        });
    }
    Ok(Figure {
        columns: columns(methods),
        rows,
        zoomed: set.moving_object().map(|o| o.name.clone()),
    })
}

/// The images of one row, in [`columns`] order; `cell(name, image)` saves one.
fn row_images(
    frame: &EvalFrame,
    step: usize,
    methods: &[FigureMethod],
    id_map: Option<&Vec<u8>>,
    cell: &dyn Fn(&str, &RgbImage) -> Result<Option<String>>,
) -> Result<Vec<Option<String>>> {
    let (w, h) = frame.gt.dimensions();
    // The box comes from the ground-truth mask, so every method's record holds the same.
    let bbox = methods
        .first()
        .and_then(|m| m.eval.results.moving_object_crop.per_time.get(step))
        .and_then(|p| p.crop)
        .map(|[x, y, width, height]| CropBox {
            x,
            y,
            width,
            height,
        });
    let outlined = |img: &RgbImage| {
        let mut img = img.clone();
        if let Some(b) = bbox {
            draw_box(&mut img, b, BOX_COLOR, 2);
        }
        img
    };
    let renders: Vec<(&str, &RgbImage)> = std::iter::once(("gt", &frame.gt))
        .chain(
            methods
                .iter()
                .map(|m| (m.key, &m.eval.picked_renders[step])),
        )
        .collect();
    let mut images = Vec::with_capacity(2 * renders.len() + 1);
    images.push(cell("gt", &outlined(&frame.gt))?);
    images.push(match id_map {
        Some(ids) => cell("ids", &colorize_ids(ids, w, h)?)?,
        None => None,
    });
    for &(name, img) in &renders[1..] {
        images.push(cell(name, &outlined(img))?);
    }
    for &(name, img) in &renders {
        images.push(match bbox {
            Some(b) => cell(&format!("zoom_{name}"), &zoom(&crop(img, b), ZOOM_HEIGHT))?,
            None => None,
        });
    }
    Ok(images)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_list_each_method_then_its_zoom() {
        let eval = RunEval {
            results: Default::default(),
            picked_renders: Vec::new(),
        };
        let methods = ["A", "B", "C"].map(|name| FigureMethod {
            key: "k",
            name,
            eval: &eval,
        });
        assert_eq!(
            columns(&methods),
            [
                "ground truth",
                "object-ID map",
                "A",
                "B",
                "C",
                "zoom: ground truth",
                "zoom: A",
                "zoom: B",
                "zoom: C"
            ]
        );
        assert_eq!(columns(&methods[..2]).len(), 7, "the two-method figure");
    }
}
