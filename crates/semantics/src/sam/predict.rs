//! Prompted segmentation of one image, as SAM's `SamPredictor`: the image is embedded once,
//! then each prompt (points and / or a box, in original-image pixels) is mapped to the resized
//! frame (`ResizeLongestSide.apply_coords` / `apply_boxes`), decoded, and its low-resolution
//! logits are upsampled to the original size (`postprocess_masks`).

use super::decoder::{ImageContext, Outputs, Scratch};
use super::model::{ImageEmbedding, Sam};
use super::prompt::{Prompt, GRID, IMAGE_SIZE};
use crate::automask::upsample::Upsampler;

/// One output mask of a prompt at the original image size.
#[derive(Debug, Clone)]
pub struct Prediction {
    /// Mask logits, height×width row-major; the mask is `logits > 0`.
    pub logits: Vec<f32>,
    /// The decoder's predicted IoU for this mask.
    pub pred_iou: f32,
}

/// An embedded image ready for prompts.
pub struct Predictor<'a> {
    sam: &'a Sam,
    emb: ImageEmbedding,
    ctx: ImageContext,
    up: Upsampler,
    tokens: (usize, usize),
}

impl<'a> Predictor<'a> {
    /// Embed an interleaved RGB8 image (h×w) with SAM's image encoder.
    pub fn new(sam: &'a Sam, rgb: &[u8], h: usize, w: usize) -> Result<Self, super::SamError> {
        Ok(Self::from_embedding(sam, sam.embed(rgb, h, w)?))
    }

    /// Use an embedding computed by [`Sam::embed`].
    pub fn from_embedding(sam: &'a Sam, emb: ImageEmbedding) -> Self {
        let ctx = sam.prepare(&emb);
        let up = Upsampler::new(emb.original, emb.input, 4 * GRID, IMAGE_SIZE);
        let tokens = (
            up.low_rows.div_ceil(4).min(GRID),
            up.low_cols.div_ceil(4).min(GRID),
        );
        Self {
            sam,
            emb,
            ctx,
            up,
            tokens,
        }
    }

    /// (height, width) of the original image.
    pub fn size(&self) -> (usize, usize) {
        self.emb.original
    }

    /// `prompt` (original-image pixels) in the resized frame the decoder reads
    /// (`ResizeLongestSide.apply_coords` / `apply_boxes`).
    pub fn to_input(&self, prompt: &Prompt) -> Prompt {
        let map = |x: f32, y: f32| Sam::to_input_frame(&self.emb, x, y);
        Prompt {
            points: prompt
                .points
                .iter()
                .map(|&(x, y, pos)| {
                    let (ix, iy) = map(x, y);
                    (ix, iy, pos)
                })
                .collect(),
            bbox: prompt.bbox.map(|[x0, y0, x1, y1]| {
                let ((a, b), (c, d)) = (map(x0, y0), map(x1, y1));
                [a, b, c, d]
            }),
        }
    }

    /// Decode `prompt`, given in original-image pixels, into the chosen outputs (three masks
    /// for [`Outputs::Multimask`], one for [`Outputs::Single`]).
    pub fn predict(&self, prompt: &Prompt, outputs: Outputs, sc: &mut Scratch) -> Vec<Prediction> {
        self.predict_above(prompt, outputs, f32::NEG_INFINITY, sc)
    }

    /// As [`Predictor::predict`], keeping only the masks whose predicted IoU exceeds `gate`
    /// (the others are never upsampled; none are decoded past the IoU head when all fail).
    pub fn predict_above(
        &self,
        prompt: &Prompt,
        outputs: Outputs,
        gate: f32,
        sc: &mut Scratch,
    ) -> Vec<Prediction> {
        let input = self.to_input(prompt);
        let sparse = self.sam.prompt.tokens(&input);
        let out =
            self.sam
                .decoder
                .decode_prompt(&self.ctx, &sparse, outputs, self.tokens, gate, sc);
        let Some(logits) = out.logits else {
            return Vec::new();
        };
        let plane = out.rows * out.cols;
        let mut tmp = Vec::new();
        out.iou_pred
            .iter()
            .enumerate()
            .filter(|(_, &pred_iou)| pred_iou > gate)
            .map(|(k, &pred_iou)| {
                let mut full = Vec::new();
                self.up.apply(
                    &logits[k * plane..(k + 1) * plane],
                    out.cols,
                    &mut tmp,
                    &mut full,
                );
                Prediction {
                    logits: full,
                    pred_iou,
                }
            })
            .collect()
    }
}
