//! Initial Gaussians as 3DGS `create_from_pcd`: scale = √(mean squared distance to the 3
//! nearest neighbours) (`distCUDA2`, clamped at 1e-7), identity rotation, opacity 0.1,
//! SH DC = RGB2SH(colour), SH rest 0. Random init as 3DGS/Deformable-3DGS on synthetic
//! scenes: points uniform in [−e, e]³ with colours uniform in [0, 1/255) read as SH.

use crate::error::{check, Result, TrainError};
use crate::model::{inverse_sigmoid, GaussianModel, SH_FLOATS};
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Most random points a config may ask for: keeps the allocation finite (a bad value is
/// refused, not an abort on a failed allocation; 3DGS uses 100k).
pub const MAX_RANDOM_POINTS: usize = 50_000_000;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitConfig {
    /// Use the scene's point cloud when it has one; otherwise random points.
    pub use_point_cloud: bool,
    /// Random init: number of points uniform in [−extent, extent]³ (3DGS synthetic: 100k, 1.3).
    pub random_points: usize,
    pub random_extent: f32,
    /// Initial opacity (3DGS: 0.1).
    pub opacity: f32,
}

impl Default for InitConfig {
    fn default() -> Self {
        Self {
            use_point_cloud: true,
            random_points: 100_000,
            random_extent: 1.3,
            opacity: 0.1,
        }
    }
}

impl InitConfig {
    /// `[init]`'s keys, named when wrong.
    pub fn validate(&self) -> Result<()> {
        check::positive("init.random_extent", self.random_extent)?;
        if self.random_points > MAX_RANDOM_POINTS {
            return Err(TrainError::config(
                "init.random_points",
                format!("must be ≤ {MAX_RANDOM_POINTS}, got {}", self.random_points),
            ));
        }
        if !(self.opacity > 0.0 && self.opacity < 1.0) {
            return Err(TrainError::config(
                "init.opacity",
                format!("must be in (0, 1), got {}", self.opacity),
            ));
        }
        Ok(())
    }
}

/// SH band-0 constant (3DGS `C0`).
pub const SH_C0: f32 = 0.282_094_8;

/// Gaussians at `positions (N·3)` with `colors (N·3, in [0,1])`.
pub fn from_points(positions: &[f32], colors: &[f32], opacity: f32) -> GaussianModel {
    let n = positions.len() / 3;
    let d2 = knn3_mean_sq_dist(positions);
    let mut sh = vec![0.0; n * SH_FLOATS];
    for i in 0..n {
        for c in 0..3 {
            sh[i * SH_FLOATS + c] = (colors[i * 3 + c] - 0.5) / SH_C0;
        }
    }
    GaussianModel {
        means: positions.to_vec(),
        quats: (0..n).flat_map(|_| [1.0, 0.0, 0.0, 0.0]).collect(),
        log_scales: d2
            .iter()
            .flat_map(|&d| [0.5 * d.max(1e-7).ln(); 3])
            .collect(),
        opacity_logits: vec![inverse_sigmoid(opacity); n],
        sh,
        sh_degree: 0,
    }
}

/// 3DGS synthetic random init (`readNerfSyntheticInfo`): SH DC uniform in [0, 1/255).
pub fn random(cfg: &InitConfig, rng: &mut impl Rng) -> GaussianModel {
    let n = cfg.random_points;
    let e = cfg.random_extent;
    let pos: Vec<f32> = (0..n * 3).map(|_| rng.gen_range(-e..e)).collect();
    let shs: Vec<f32> = (0..n * 3).map(|_| rng.gen::<f32>() / 255.0).collect();
    // Colours such that RGB2SH(colour) = shs, i.e. the SH DC values are `shs` themselves.
    let colors: Vec<f32> = shs.iter().map(|s| s * SH_C0 + 0.5).collect();
    from_points(&pos, &colors, cfg.opacity)
}

/// Mean squared distance of each point to its 3 nearest other points, on a uniform grid
/// of about 2 points per cell, searched in growing shells until the result is exact.
pub fn knn3_mean_sq_dist(p: &[f32]) -> Vec<f32> {
    let n = p.len() / 3;
    if n < 2 {
        return vec![1e-2; n];
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for q in p.chunks_exact(3) {
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    let vol: f32 = (0..3).map(|a| (hi[a] - lo[a]).max(1e-6)).product();
    let h = (vol * 2.0 / n as f32).cbrt().max(1e-6);
    let cell =
        |q: &[f32]| -> [i32; 3] { std::array::from_fn(|a| ((q[a] - lo[a]) / h).floor() as i32) };
    let mut grid: HashMap<[i32; 3], Vec<u32>> = HashMap::new();
    for (i, q) in p.chunks_exact(3).enumerate() {
        grid.entry(cell(q)).or_default().push(i as u32);
    }
    let max_r = (0..3)
        .map(|a| ((hi[a] - lo[a]) / h) as i32 + 1)
        .max()
        .unwrap_or(1);
    (0..n)
        .into_par_iter()
        .map(|i| {
            let q = &p[i * 3..i * 3 + 3];
            let c = cell(q);
            let mut best = [f32::INFINITY; 3];
            let mut r = 0;
            loop {
                shell(&grid, c, r, |j| {
                    if j as usize != i {
                        let d: f32 = (0..3).map(|a| (p[j as usize * 3 + a] - q[a]).powi(2)).sum();
                        insert3(&mut best, d);
                    }
                });
                // Points beyond shell r are at least r·h away.
                let reach = r as f32 * h;
                if (best[2] <= reach * reach) || r > max_r {
                    break;
                }
                r += 1;
            }
            let k = best.iter().filter(|d| d.is_finite()).count().max(1);
            best.iter().filter(|d| d.is_finite()).sum::<f32>() / k as f32
        })
        .collect()
}

fn insert3(best: &mut [f32; 3], d: f32) {
    if d < best[2] {
        best[2] = d;
        best.sort_by(|a, b| a.total_cmp(b));
    }
}

/// Visits the points of the cells at Chebyshev distance exactly `r` from `c`.
fn shell(grid: &HashMap<[i32; 3], Vec<u32>>, c: [i32; 3], r: i32, mut f: impl FnMut(u32)) {
    for dx in -r..=r {
        for dy in -r..=r {
            for dz in -r..=r {
                if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                    continue;
                }
                if let Some(v) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                    v.iter().for_each(|&j| f(j));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn knn_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let p: Vec<f32> = (0..600 * 3).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let fast = knn3_mean_sq_dist(&p);
        for i in (0..600).step_by(37) {
            let mut d: Vec<f32> = (0..600)
                .filter(|&j| j != i)
                .map(|j| (0..3).map(|a| (p[j * 3 + a] - p[i * 3 + a]).powi(2)).sum())
                .collect();
            d.sort_by(|a, b| a.total_cmp(b));
            let want = (d[0] + d[1] + d[2]) / 3.0;
            assert!(
                (fast[i] - want).abs() < 1e-6 * want.max(1.0),
                "{i}: {} vs {want}",
                fast[i]
            );
        }
    }

    #[test]
    fn random_init_matches_3dgs() {
        let cfg = InitConfig {
            random_points: 1000,
            ..InitConfig::default()
        };
        let m = random(&cfg, &mut ChaCha8Rng::seed_from_u64(0));
        m.validate().unwrap();
        assert_eq!(m.len(), 1000);
        assert!(m.means.iter().all(|v| v.abs() <= 1.3));
        assert!(m.sh.chunks(SH_FLOATS).all(|s| s[..3]
            .iter()
            .all(|&c| (0.0..1.0 / 255.0 + 1e-6).contains(&c))));
        assert!((crate::model::sigmoid(m.opacity_logits[0]) - 0.1).abs() < 1e-6);
    }
}
