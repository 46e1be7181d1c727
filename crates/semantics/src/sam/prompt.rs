//! SAM's prompt encoder for point prompts (`segment_anything/modeling/prompt_encoder.py`):
//! random-Fourier positional encoding of the points and of the 64×64 embedding grid, learned
//! point-type embeddings, and the "no mask" dense embedding.

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
        let mut out = vec![0.0f32; 2 * EMBED_DIM];
        let s = IMAGE_SIZE as f32;
        self.encode((x + 0.5) / s, (y + 0.5) / s, &mut out[..EMBED_DIM]);
        for (o, e) in out[..EMBED_DIM].iter_mut().zip(&self.point_embed[1]) {
            *o += e;
        }
        out[EMBED_DIM..].copy_from_slice(&self.not_a_point);
        out
    }
}
