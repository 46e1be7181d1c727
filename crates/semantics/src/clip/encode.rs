//! The two encodings the segmentation pipeline needs: every mask of a frame (batched
//! through the image tower) and the dictionary with LERF's canonical phrases.

use image::RgbImage;

use super::model::ClipModel;
use super::preprocess::{batch_pixels, masked_crop};
use super::ClipError;
use crate::relevance::{DictionaryEmbeddings, CANONICAL_PHRASES};

/// Crops per image-tower call: batching shares each weight matrix across crops (the
/// measured per-crop time at 8 is ~20-40% below batch 1, docs/performance.md).
pub const MASK_BATCH: usize = 8;

impl ClipModel {
    /// Normalized embedding of each mask's crop (docs/architecture.md item 2); `masks` are
    /// row-major booleans of the image's size. An empty mask is an error.
    pub fn encode_masks<M: AsRef<[bool]>>(
        &self,
        image: &RgbImage,
        masks: &[M],
    ) -> Result<Vec<Vec<f32>>, ClipError> {
        let size = self.image_size();
        let mut out = Vec::with_capacity(masks.len());
        for chunk in masks.chunks(MASK_BATCH) {
            let crops = chunk
                .iter()
                .map(|m| masked_crop(image, m.as_ref(), size as u32))
                .collect::<Result<Vec<_>, _>>()?;
            out.extend(self.encode_images(&batch_pixels(&crops, size)?)?);
        }
        Ok(out)
    }

    /// Normalized embeddings of the dictionary prompts and the canonical phrases
    /// `object, things, stuff, texture`.
    pub fn encode_dictionary<S: AsRef<str>>(
        &self,
        prompts: &[S],
    ) -> Result<DictionaryEmbeddings, ClipError> {
        let prompts: Vec<&str> = prompts.iter().map(AsRef::as_ref).collect();
        Ok(DictionaryEmbeddings {
            prompts: self.encode_texts(&prompts)?,
            canonical: self.encode_texts(&CANONICAL_PHRASES)?,
        })
    }
}
