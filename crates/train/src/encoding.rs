//! NeRF positional encoding as in Deformable-3DGS's `get_embedder` (include_input, log
//! sampling): `[x, sin(2⁰x), cos(2⁰x), …, sin(2^(L−1)x), cos(2^(L−1)x)]`, each term
//! vector-valued. The field's input is `[γ(mean), γ(t)]`.

use rayon::prelude::*;

/// Width of the encoding of a `dim`-vector with `freqs` frequencies.
pub fn encoded_dim(dim: usize, freqs: usize) -> usize {
    dim * (1 + 2 * freqs)
}

fn encode_into(x: &[f32], freqs: usize, out: &mut [f32]) {
    let d = x.len();
    out[..d].copy_from_slice(x);
    for f in 0..freqs {
        let scale = (1u32 << f) as f32;
        let base = d * (1 + 2 * f);
        for (k, &v) in x.iter().enumerate() {
            let (s, c) = (v * scale).sin_cos();
            out[base + k] = s;
            out[base + d + k] = c;
        }
    }
}

/// Encodes the rows `idx` of `means (N·3)` with time `t` into `out` (`idx.len() × width`).
pub fn encode_rows(
    means: &[f32],
    idx: &[u32],
    t: f32,
    pos_freqs: usize,
    time_freqs: usize,
    out: &mut Vec<f32>,
) {
    let px = encoded_dim(3, pos_freqs);
    let width = px + encoded_dim(1, time_freqs);
    let mut t_enc = vec![0.0; width - px];
    encode_into(&[t], time_freqs, &mut t_enc);
    out.resize(idx.len() * width, 0.0);
    out.par_chunks_mut(width * 256)
        .zip(idx.par_chunks(256))
        .for_each(|(o, ids)| {
            for (row, &i) in o.chunks_exact_mut(width).zip(ids) {
                let i = i as usize;
                encode_into(&means[i * 3..i * 3 + 3], pos_freqs, &mut row[..px]);
                row[px..].copy_from_slice(&t_enc);
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_matches_nerf_embedder() {
        let means = [0.5f32, -1.0, 2.0];
        let mut out = Vec::new();
        encode_rows(&means, &[0], 0.25, 2, 1, &mut out);
        assert_eq!(out.len(), 15 + 3);
        assert_eq!(&out[..3], &means);
        assert!((out[3] - 0.5f32.sin()).abs() < 1e-6);
        assert!((out[6] - 0.5f32.cos()).abs() < 1e-6);
        assert!((out[9] - 1.0f32.sin()).abs() < 1e-6);
        assert!((out[14] - 4.0f32.cos()).abs() < 1e-6);
        assert_eq!(out[15], 0.25);
        assert!((out[16] - 0.25f32.sin()).abs() < 1e-6);
        assert!((out[17] - 0.25f32.cos()).abs() < 1e-6);
    }
}
