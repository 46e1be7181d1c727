//! SAM's prompt encoder for point and box prompts (`segment_anything/modeling/prompt_encoder.py`):
//! random-Fourier positional encoding of the points and of the 64×64 embedding grid, learned
//! point-type embeddings (negative, positive, box corners), and the "no mask" dense embedding.
//! Mask prompts (`mask_downscaling`) are not implemented.

use candle_nn::VarBuilder;

use super::layers::get_vec;

/// Channels of the prompt / image embedding.
pub const EMBED_DIM: usize = 256;
/// Side of the image embedding grid (1024 / 16).
pub const GRID: usize = 64;
/// Side of the padded encoder input.
pub const IMAGE_SIZE: usize = 1024;

#[derive(Debug, Clone)]
pub struct PromptEncoder {
    /// `pe_layer.positional_encoding_gaussian_matrix`, 2×128 row-major.
    gauss: Vec<f32>,
    /// `point_embeddings.{0..3}` (negative point, positive point, box corners).
    point_embed: Vec<Vec<f32>>,
    not_a_point: Vec<f32>,
    pub no_mask: Vec<f32>,
}

impl PromptEncoder {
    pub fn load(vb: &VarBuilder) -> candle_core::Result<Self> {
        let point_embed = (0..4)
            .map(|i| get_vec(&vb.pp("point_embeddings").pp(i), &[1, EMBED_DIM], "weight"))
            .collect::<candle_core::Result<Vec<_>>>()?;
        Ok(Self {
            gauss: get_vec(
                &vb.pp("pe_layer"),
                &[2, EMBED_DIM / 2],
                "positional_encoding_gaussian_matrix",
            )?,
            point_embed,
            not_a_point: get_vec(&vb.pp("not_a_point_embed"), &[1, EMBED_DIM], "weight")?,
            no_mask: get_vec(&vb.pp("no_mask_embed"), &[1, EMBED_DIM], "weight")?,
        })
    }

    /// `PositionEmbeddingRandom._pe_encoding` of a point with coordinates normalized to [0, 1].
    fn encode(&self, x: f32, y: f32, out: &mut [f32]) {
        let half = EMBED_DIM / 2;
        let (cx, cy) = (2.0 * x - 1.0, 2.0 * y - 1.0);
        for i in 0..half {
            let v = 2.0 * std::f32::consts::PI * (cx * self.gauss[i] + cy * self.gauss[half + i]);
            out[i] = v.sin();
            out[half + i] = v.cos();
        }
    }

    /// Dense positional encoding of the embedding grid as tokens (GRID²×EMBED_DIM, row-major
    /// over (y, x)), sampled at cell centres as `PositionEmbeddingRandom.forward`.
    pub fn dense_pe(&self) -> Vec<f32> {
        let mut pe = vec![0.0f32; GRID * GRID * EMBED_DIM];
        for (t, row) in pe.chunks_exact_mut(EMBED_DIM).enumerate() {
            let (y, x) = (t / GRID, t % GRID);
            self.encode(
                (x as f32 + 0.5) / GRID as f32,
                (y as f32 + 0.5) / GRID as f32,
                row,
            );
        }
        pe
    }

    /// Sparse tokens (2×EMBED_DIM) for one positive point given in the resized (≤1024) frame:
    /// the point itself and the padding point SAM appends when no box is given.
    pub fn point_tokens(&self, x: f32, y: f32) -> Vec<f32> {
        self.tokens(&Prompt {
            points: vec![(x, y, true)],
            bbox: None,
        })
    }

    /// Sparse tokens for a prompt in the resized (≤1024) frame, in SAM's order
    /// (`PromptEncoder.forward`): the points, then a padding point when there is no box, then
    /// the box's two corners. Each point or corner is shifted to its pixel centre (+0.5) and
    /// encoded against the 1024² input; a point's label adds `point_embeddings[1]` (positive)
    /// or `[0]` (negative); the corners add `[2]` and `[3]`; the padding point is
    /// `not_a_point_embed` alone.
    pub fn tokens(&self, prompt: &Prompt) -> Vec<f32> {
        let pad = prompt.bbox.is_none();
        let n = prompt.n_tokens();
        let mut out = vec![0.0f32; n * EMBED_DIM];
        let mut rows = out.chunks_exact_mut(EMBED_DIM);
        let s = IMAGE_SIZE as f32;
        let put = |row: &mut [f32], x: f32, y: f32, kind: usize| {
            self.encode((x + 0.5) / s, (y + 0.5) / s, row);
            for (o, e) in row.iter_mut().zip(&self.point_embed[kind]) {
                *o += e;
            }
        };
        for &(x, y, positive) in &prompt.points {
            put(rows.next().expect("sized"), x, y, usize::from(positive));
        }
        if pad {
            rows.next()
                .expect("sized")
                .copy_from_slice(&self.not_a_point);
        }
        if let Some([x0, y0, x1, y1]) = prompt.bbox {
            put(rows.next().expect("sized"), x0, y0, 2);
            put(rows.next().expect("sized"), x1, y1, 3);
        }
        out
    }
}

/// A prompt in the resized (≤1024) input frame: labelled points (`true` = on the object) and
/// an optional box `[x0, y0, x1, y1]` (SAM's XYXY, pixel coordinates).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Prompt {
    pub points: Vec<(f32, f32, bool)>,
    pub bbox: Option<[f32; 4]>,
}

impl Prompt {
    /// Sparse tokens this prompt encodes to (points, padding point or box corners).
    pub fn n_tokens(&self) -> usize {
        self.points.len() + if self.bbox.is_some() { 2 } else { 1 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encoder() -> PromptEncoder {
        let v = |seed: f32| (0..EMBED_DIM).map(|i| seed + i as f32 * 1e-3).collect();
        PromptEncoder {
            gauss: (0..EMBED_DIM).map(|i| (i as f32 * 0.37).sin()).collect(),
            point_embed: (0..4).map(|k| v(k as f32)).collect(),
            not_a_point: v(-7.0),
            no_mask: v(0.5),
        }
    }

    #[test]
    fn token_layout_follows_sams_order() {
        let pe = encoder();
        // One positive point: the point, then the padding point.
        let one = pe.point_tokens(10.0, 20.0);
        assert_eq!(one.len(), 2 * EMBED_DIM);
        assert_eq!(&one[EMBED_DIM..], &pe.not_a_point[..]);
        // Negative point + box: no padding; corners carry embeddings 2 and 3.
        let p = Prompt {
            points: vec![(10.0, 20.0, false)],
            bbox: Some([1.0, 2.0, 30.0, 40.0]),
        };
        let t = pe.tokens(&p);
        assert_eq!(t.len(), 3 * EMBED_DIM);
        let mut enc = vec![0.0; EMBED_DIM];
        pe.encode(10.5 / 1024.0, 20.5 / 1024.0, &mut enc);
        let neg: Vec<f32> = enc
            .iter()
            .zip(&pe.point_embed[0])
            .map(|(a, b)| a + b)
            .collect();
        assert_eq!(&t[..EMBED_DIM], &neg[..]);
        // The positive variant differs from the negative one by exactly embed[1] − embed[0].
        let d = one[0] - t[0];
        assert!((d - (pe.point_embed[1][0] - pe.point_embed[0][0])).abs() < 1e-6);
        pe.encode(30.5 / 1024.0, 40.5 / 1024.0, &mut enc);
        let c1: Vec<f32> = enc
            .iter()
            .zip(&pe.point_embed[3])
            .map(|(a, b)| a + b)
            .collect();
        assert_eq!(&t[2 * EMBED_DIM..], &c1[..]);
        assert_eq!(p.n_tokens(), 3);
    }
}
