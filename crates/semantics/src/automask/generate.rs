//! The generator's driver: decode prompts in parallel (one shared [`ImageContext`], one
//! [`Scratch`] per worker), filter and upscale their masks, NMS, clean-up, non-overlap.

use std::time::Instant;

use rayon::prelude::*;

use super::regions::{non_overlapping, remove_small_regions};
use super::upsample::Upsampler;
use super::{
    point_grid, AutoMasks, BoxMask, Candidate, GenStats, MaskGenConfig, MaskInfo, Sampling,
};
use crate::sam::prompt::{GRID, IMAGE_SIZE};
use crate::sam::{ImageContext, ImageEmbedding, Sam, SamError, Scratch};

/// SAM's `calculate_stability_score`: IoU of the masks thresholded at ±offset.
pub fn stability_score(logits: &[f32], threshold: f32, offset: f32) -> f32 {
    let (hi, lo) = (threshold + offset, threshold - offset);
    let (mut inter, mut union) = (0usize, 0usize);
    for &v in logits {
        inter += usize::from(v > hi);
        union += usize::from(v > lo);
    }
    inter as f32 / union as f32
}

struct Shared<'a> {
    sam: &'a Sam,
    ctx: &'a ImageContext,
    emb: &'a ImageEmbedding,
    up: &'a Upsampler,
    cfg: &'a MaskGenConfig,
    tokens: (usize, usize),
}

#[derive(Default)]
struct Worker {
    scratch: Scratch,
    tmp: Vec<f32>,
    full: Vec<f32>,
}

/// Decode one prompt (original-image pixel coordinates) and return its accepted masks.
fn decode_point(sh: &Shared, wk: &mut Worker, (px, py): (f32, f32)) -> (bool, Vec<Candidate>) {
    let (ix, iy) = Sam::to_input_frame(sh.emb, px, py);
    let sparse = sh.sam.prompt.point_tokens(ix, iy);
    let cfg = sh.cfg;
    let out = sh.sam.decoder.decode(
        sh.ctx,
        &sparse,
        sh.tokens,
        cfg.pred_iou_thresh,
        &mut wk.scratch,
    );
    let Some(logits) = out.logits else {
        return (false, Vec::new());
    };
    let plane = out.rows * out.cols;
    let (h, w) = (sh.up.height(), sh.up.width());
    let mut found = Vec::new();
    for (k, &iou) in out.iou_pred.iter().enumerate() {
        if iou <= cfg.pred_iou_thresh {
            continue;
        }
        sh.up.apply(
            &logits[k * plane..(k + 1) * plane],
            out.cols,
            &mut wk.tmp,
            &mut wk.full,
        );
        let stability = stability_score(&wk.full, cfg.mask_threshold, cfg.stability_score_offset);
        // NaN (empty at −offset) fails this comparison too, as in SAM.
        if stability.is_nan() || stability < cfg.stability_score_thresh {
            continue;
        }
        let full = &wk.full;
        if let Some(mask) = BoxMask::from_fn(h, w, |i| full[i] > cfg.mask_threshold) {
            found.push(Candidate {
                mask,
                pred_iou: iou,
                stability,
                point: (px, py),
            });
        }
    }
    (true, found)
}

fn decode_points(sh: &Shared, points: &[(f32, f32)], stats: &mut GenStats) -> Vec<Candidate> {
    let results: Vec<(bool, Vec<Candidate>)> = points
        .par_iter()
        .map_init(Worker::default, |wk, &p| decode_point(sh, wk, p))
        .collect();
    stats.prompts += points.len();
    stats.upscaled_prompts += results.iter().filter(|r| r.0).count();
    results.into_iter().flat_map(|r| r.1).collect()
}

/// Points to prompt, in original-image pixels.
fn scaled_grid(n: usize, h: usize, w: usize) -> Vec<(f32, f32)> {
    point_grid(n)
        .into_iter()
        .map(|(x, y)| (x * w as f32, y * h as f32))
        .collect()
}

/// Run the generator on an embedding computed by [`Sam::embed`].
pub fn generate_from_embedding(
    sam: &Sam,
    emb: &ImageEmbedding,
    cfg: &MaskGenConfig,
) -> Result<AutoMasks, SamError> {
    let (h, w) = emb.original;
    let t0 = Instant::now();
    let ctx = sam.prepare(emb);
    let up = Upsampler::new(emb.original, emb.input, 4 * GRID, IMAGE_SIZE);
    let tokens = (
        up.low_rows.div_ceil(4).min(GRID),
        up.low_cols.div_ceil(4).min(GRID),
    );
    let sh = Shared {
        sam,
        ctx: &ctx,
        emb,
        up: &up,
        cfg,
        tokens,
    };
    let mut stats = GenStats::default();
    let mut cands = match cfg.sampling {
        Sampling::Grid(n) => decode_points(&sh, &scaled_grid(n, h, w), &mut stats),
        Sampling::Adaptive { coarse, fine } => {
            let mut c = decode_points(&sh, &scaled_grid(coarse, h, w), &mut stats);
            let covered =
                |&(x, y): &(f32, f32)| c.iter().any(|m| m.mask.contains(x as usize, y as usize));
            let rest: Vec<_> = scaled_grid(fine, h, w)
                .into_iter()
                .filter(|p| !covered(p))
                .collect();
            c.extend(decode_points(&sh, &rest, &mut stats));
            c
        }
    };
    stats.decode_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    stats.candidates = cands.len();
    let boxes: Vec<_> = cands.iter().map(|c| c.mask.bbox).collect();
    let scores: Vec<f32> = cands.iter().map(|c| c.pred_iou).collect();
    let keep = super::nms::nms(&boxes, &scores, cfg.box_nms_thresh);
    stats.after_nms = keep.len();
    let mut kept: Vec<Candidate> = keep
        .into_iter()
        .map(|i| std::mem::replace(&mut cands[i], placeholder()))
        .collect();
    if cfg.min_region_area > 0 {
        kept = kept
            .into_par_iter()
            .filter_map(|c| {
                remove_small_regions(&c.mask, cfg.min_region_area)
                    .map(|mask| Candidate { mask, ..c })
            })
            .collect();
    }
    let masks: Vec<BoxMask> = kept.iter().map(|c| c.mask.clone()).collect();
    let scores: Vec<f32> = kept.iter().map(|c| c.stability * c.pred_iou).collect();
    let (labels, order) = non_overlapping(&masks, &scores, h, w, cfg.min_mask_area);
    let infos = order
        .into_iter()
        .map(|(i, area)| {
            let c = &kept[i];
            MaskInfo {
                bbox: c.mask.bbox,
                area,
                pred_iou: c.pred_iou,
                stability: c.stability,
                point: c.point,
            }
        })
        .collect();
    stats.post_s = t1.elapsed().as_secs_f64();
    Ok(AutoMasks {
        height: h,
        width: w,
        labels,
        masks: infos,
        stats,
    })
}

fn placeholder() -> Candidate {
    Candidate {
        mask: BoxMask {
            bbox: [0; 4],
            bits: Vec::new(),
            area: 0,
        },
        pred_iou: 0.0,
        stability: 0.0,
        point: (0.0, 0.0),
    }
}

/// Encode an interleaved RGB8 image (h×w) and generate its masks.
pub fn generate(
    sam: &Sam,
    rgb: &[u8],
    h: usize,
    w: usize,
    cfg: &MaskGenConfig,
) -> Result<AutoMasks, SamError> {
    let emb = sam.embed(rgb, h, w)?;
    generate_from_embedding(sam, &emb, cfg)
}
