//! NeRF positional encoding as in Deformable-3DGS's `get_embedder` (include_input, log
//! sampling): `[x, sin(2⁰x), cos(2⁰x), …, sin(2^(L−1)x), cos(2^(L−1)x)]`, each term
//! vector-valued. The field's input is `[γ(mean), γ(t)]`; γ(t) is the same in every row, so
//! the field normally passes it to the MLP once (`Mlp::forward`'s shared columns) and
//! encodes only γ(mean) per row.

use rayon::prelude::*;

/// Width of the encoding of a `dim`-vector with `freqs` frequencies.
pub fn encoded_dim(dim: usize, freqs: usize) -> usize {
    dim * (1 + 2 * freqs)
}

/// One row of the encoding (`encoded_dim(x.len(), freqs)` values) into `out`.
pub fn encode_one(x: &[f32], freqs: usize, out: &mut [f32]) {
    let d = x.len();
    out[..d].copy_from_slice(x);
    for (k, &v) in x.iter().enumerate() {
        // One `sin_cos` per coordinate, then the double-angle identities for 2x, 4x, …:
        // sin 2a = 2 sin a cos a, cos 2a = (cos a − sin a)(cos a + sin a). In f64 the
        // error after 9 doublings is ~1e-13, far below f32 rounding of the argument 2⁹x
        // that the reference (torch.sin on f32) itself incurs, and one libm call replaces
        // `freqs` of them (see "Training" in docs/performance.md).
        let (mut s, mut c) = (v as f64).sin_cos();
        for f in 0..freqs {
            let base = d * (1 + 2 * f);
            out[base + k] = s as f32;
            out[base + d + k] = c as f32;
            (s, c) = (2.0 * s * c, (c - s) * (c + s));
        }
    }
}

/// The same encoding with one `sin_cos` per term, as Deformable-3DGS computes it: the
/// reference the fast version is tested and timed against (`examples/encoding_speed.rs`).
pub fn encode_reference(x: &[f32], freqs: usize, out: &mut [f32]) {
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

/// γ(t) with `freqs` frequencies.
pub fn encode_time(t: f32, freqs: usize) -> Vec<f32> {
    let mut out = vec![0.0; encoded_dim(1, freqs)];
    encode_one(&[t], freqs, &mut out);
    out
}

/// Encodes the rows `idx` of `means (N·3)` into `out` (`idx.len() × width`), each row
/// `[γ(mean), t_feat]` with the time features `t_feat` repeated in every row (γ(t), or the
/// time network's output; empty when the MLP takes them as shared columns).
pub fn encode_rows(
    means: &[f32],
    idx: &[u32],
    t_feat: &[f32],
    pos_freqs: usize,
    out: &mut Vec<f32>,
) {
    let px = encoded_dim(3, pos_freqs);
    let width = px + t_feat.len();
    out.resize(idx.len() * width, 0.0);
    out.par_chunks_mut(width * 256)
        .zip(idx.par_chunks(256))
        .for_each(|(o, ids)| {
            for (row, &i) in o.chunks_exact_mut(width).zip(ids) {
                let i = i as usize;
                encode_one(&means[i * 3..i * 3 + 3], pos_freqs, &mut row[..px]);
                row[px..].copy_from_slice(t_feat);
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
        encode_rows(&means, &[0], &encode_time(0.25, 1), 2, &mut out);
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

    #[test]
    fn doubling_recurrence_matches_direct_sin_cos() {
        let means: Vec<f32> = (0..300).map(|i| (i as f32 * 0.731).sin() * 1.6).collect();
        let idx: Vec<u32> = (0..100).collect();
        let mut out = Vec::new();
        encode_rows(&means, &idx, &encode_time(0.7, 6), 10, &mut out);
        let width = encoded_dim(3, 10) + encoded_dim(1, 6);
        for (i, row) in out.chunks_exact(width).enumerate() {
            for f in 0..10 {
                for k in 0..3 {
                    let a = means[i * 3 + k] as f64 * (1u32 << f) as f64;
                    assert!((row[3 * (1 + 2 * f) + k] as f64 - a.sin()).abs() < 2e-7);
                    assert!((row[3 * (2 + 2 * f) + k] as f64 - a.cos()).abs() < 2e-7);
                }
            }
        }
    }
}
