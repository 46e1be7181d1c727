//! 3DGS adaptive density control (`densify_and_prune`, `densify_and_clone`,
//! `densify_and_split`, `reset_opacity`), applied to [`GaussianState`] so that parameters,
//! Adam moments and statistics move together. Deformable-3DGS trains with exactly this.

use super::DensifyConfig;
use super::{max_scale, rotation, DensifyReport};
use crate::model::{inverse_sigmoid, sigmoid};
use crate::state::{DensifyStats, GaussianState};
use rand::Rng;

/// Standard normal sample (Box–Muller), so the split draws come from the run's ChaCha RNG.
fn normal(rng: &mut impl Rng) -> f32 {
    let u1: f32 = rng.gen_range(f32::EPSILON..1.0);
    let u2: f32 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// Clone small Gaussians and split large ones whose mean view-space gradient reaches the
/// threshold, then prune transparent (and, when `prune_screen`, huge) ones. Statistics are
/// reset afterwards, as 3DGS's `densification_postfix` does.
pub fn densify_and_prune(
    st: &mut GaussianState,
    cfg: &DensifyConfig,
    extent: f32,
    prune_screen: bool,
    rng: &mut impl Rng,
) -> DensifyReport {
    let n0 = st.len();
    let grads: Vec<f32> = (0..n0)
        .map(|i| {
            let d = st.stats.denom[i];
            if d > 0.0 {
                st.stats.grad_accum[i] / d
            } else {
                0.0
            }
        })
        .collect();
    let dense = cfg.percent_dense * extent;
    let hot = |i: usize| grads[i] >= cfg.grad_threshold;
    let clone_idx: Vec<usize> = (0..n0)
        .filter(|&i| hot(i) && max_scale(&st.model.log_scales, i) <= dense)
        .collect();
    let split_idx: Vec<usize> = (0..n0)
        .filter(|&i| hot(i) && max_scale(&st.model.log_scales, i) > dense)
        .collect();
    let clones = st.model.gather(&clone_idx);
    st.append(&clones, &clone_idx);
    let children = split_children(st, &split_idx, cfg.split_children, rng);
    let parents: Vec<usize> = split_idx
        .iter()
        .flat_map(|&i| std::iter::repeat_n(i, cfg.split_children))
        .collect();
    st.append(&children, &parents);
    let mut keep = vec![true; st.len()];
    for &i in &split_idx {
        keep[i] = false;
    }
    let pruned = prune_mask(st, cfg, extent, prune_screen, &mut keep);
    st.retain(&keep);
    st.stats = DensifyStats::zeros(st.len());
    debug_assert!(st.is_aligned());
    DensifyReport {
        cloned: clone_idx.len(),
        split: split_idx.len(),
        pruned,
        ..Default::default()
    }
}

/// `children` samples per Gaussian at N(mean, R·diag(s)) with scales s/(0.8·children).
fn split_children(
    st: &GaussianState,
    idx: &[usize],
    children: usize,
    rng: &mut impl Rng,
) -> crate::model::GaussianModel {
    let rep: Vec<usize> = idx
        .iter()
        .flat_map(|&i| std::iter::repeat_n(i, children))
        .collect();
    let mut out = st.model.gather(&rep);
    let shrink = (0.8 * children as f32).ln();
    for (k, &i) in rep.iter().enumerate() {
        let r = rotation(&st.model.quats[i * 4..i * 4 + 4]);
        let ls = &st.model.log_scales[i * 3..i * 3 + 3];
        let z: [f32; 3] = std::array::from_fn(|a| normal(rng) * ls[a].exp());
        for (a, row) in r.iter().enumerate() {
            out.means[k * 3 + a] += row[0] * z[0] + row[1] * z[1] + row[2] * z[2];
            out.log_scales[k * 3 + a] -= shrink;
        }
    }
    out
}

/// Marks for removal: opacity below the minimum; with `prune_screen`, screen radius above
/// `screen_size` px or largest scale above `world_size_factor·extent`. Returns the count.
fn prune_mask(
    st: &GaussianState,
    cfg: &DensifyConfig,
    extent: f32,
    prune_screen: bool,
    keep: &mut [bool],
) -> usize {
    let mut pruned = 0;
    for (i, k) in keep.iter_mut().enumerate() {
        let transparent = sigmoid(st.model.opacity_logits[i]) < cfg.min_opacity;
        let huge = prune_screen
            && (st.stats.max_radii[i] > cfg.screen_size
                || max_scale(&st.model.log_scales, i) > cfg.world_size_factor * extent);
        if *k && (transparent || huge) {
            *k = false;
        }
        if !*k {
            pruned += 1;
        }
    }
    pruned
}

/// 3DGS `reset_opacity`: opacity = min(opacity, reset), with the group's moments zeroed.
pub fn reset_opacity(st: &mut GaussianState, reset: f32) {
    let cap = inverse_sigmoid(reset);
    for o in &mut st.model.opacity_logits {
        *o = o.min(cap);
    }
    st.adam[3].reset();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{GaussianModel, SH_FLOATS};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Gaussian i gets value i (+ a per-group offset) in every parameter and moment, so
    /// after densification each row must still carry one consistent id.
    fn tagged(n: usize) -> GaussianState {
        let model = GaussianModel {
            means: (0..n * 3).map(|k| (k / 3) as f32).collect(),
            quats: (0..n * 4)
                .map(|k| if k % 4 == 0 { 1.0 } else { 0.0 })
                .collect(),
            log_scales: (0..n)
                .flat_map(|i| [if i % 2 == 0 { -6.0 } else { -1.0 }; 3])
                .collect(),
            opacity_logits: (0..n).map(|i| if i == 5 { -8.0 } else { 0.0 }).collect(),
            sh: (0..n * SH_FLOATS).map(|k| (k / SH_FLOATS) as f32).collect(),
            sh_degree: 0,
        };
        let mut st = GaussianState::new(model);
        for (g, a) in st.adam.iter_mut().enumerate() {
            let row = a.m.len() / n;
            for k in 0..a.m.len() {
                a.m[k] = (k / row) as f32 + 1000.0 * g as f32;
                a.v[k] = (k / row) as f32;
            }
        }
        st
    }

    #[test]
    fn densify_keeps_parameters_and_moments_aligned() {
        let n = 10;
        let mut st = tagged(n);
        st.aux.push(crate::state::AuxRows {
            name: "tag".into(),
            cols: 2,
            data: (0..n).flat_map(|i| [i as f32, -(i as f32)]).collect(),
        });
        // Rigid-object membership (`objects`): Gaussians 0..3 belong to object i % 3 (255 =
        // the field's, i.e. none), the rest to the field.
        let owner = |i: usize| if i < 3 { (i % 3) as u8 } else { 255 };
        st.object = (0..n).map(owner).collect();
        // Gaussians 0..4 hot (0, 2, 4 small → clone; 1, 3 large → split); 5 transparent.
        for i in 0..5 {
            st.stats.grad_accum[i] = 1.0;
            st.stats.denom[i] = 2.0;
        }
        let cfg = DensifyConfig::default();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let rep = densify_and_prune(&mut st, &cfg, 1.0, false, &mut rng);
        assert_eq!(
            rep,
            DensifyReport {
                cloned: 3,
                split: 2,
                pruned: 3,
                ..Default::default()
            }
        );
        assert!(st.is_aligned());
        assert_eq!(st.len(), 10 + 3 + 4 - 2 - 1);
        // Survivors of the original set keep their own moments.
        let survivors: Vec<usize> = (0..st.len() - 7)
            .map(|r| st.model.sh[r * SH_FLOATS] as usize)
            .collect();
        assert_eq!(survivors, vec![0, 2, 4, 6, 7, 8, 9]);
        for (r, &id) in survivors.iter().enumerate() {
            assert_eq!(st.model.opacity_logits[r], 0.0);
            assert_eq!(st.adam[0].m[r * 3], id as f32);
            assert_eq!(st.adam[4].m[r * SH_FLOATS + 7], id as f32 + 4000.0);
            assert_eq!(st.adam[3].v[r], id as f32);
        }
        // New rows: clones are exact copies, children are shrunk; all have zero moments.
        for r in st.len() - 7..st.len() {
            assert_eq!(st.adam[0].m[r * 3], 0.0);
            assert_eq!(st.adam[4].v[r * SH_FLOATS], 0.0);
        }
        let child = st.len() - 1;
        assert!((st.model.log_scales[child * 3] - (-1.0 - 1.6f32.ln())).abs() < 1e-6);
        assert!(st.stats.denom.iter().all(|&d| d == 0.0));
        // Hook rows: every row, new ones included, carries its parent's (the SH tag's) id.
        for r in 0..st.len() {
            let id = st.model.sh[r * SH_FLOATS];
            assert_eq!(st.aux[0].data[r * 2..r * 2 + 2], [id, -id], "row {r}");
            // Membership survives: a clone or split child belongs to its parent's object.
            assert_eq!(st.object[r], owner(id as usize), "row {r}");
        }
        assert!(
            st.object.contains(&1),
            "split object Gaussian 1 lives on in its children"
        );
    }

    #[test]
    fn screen_and_world_prune_only_when_enabled() {
        let mut st = tagged(4);
        st.stats.max_radii[0] = 50.0;
        let cfg = DensifyConfig::default();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut a = st.clone();
        densify_and_prune(&mut a, &cfg, 1.0, false, &mut rng);
        assert_eq!(a.len(), 4);
        // With screen pruning: 0 (50 px) and the large ones (scale e^-1 > 0.1) go.
        densify_and_prune(&mut st, &cfg, 1.0, true, &mut rng);
        assert_eq!(st.len(), 1);
        assert_eq!(st.model.means[0], 2.0);
    }

    #[test]
    fn reset_opacity_caps_and_clears_moments() {
        let mut st = tagged(3);
        st.model.opacity_logits = vec![3.0, -6.0, 0.0];
        reset_opacity(&mut st, 0.01);
        assert!((sigmoid(st.model.opacity_logits[0]) - 0.01).abs() < 1e-6);
        assert_eq!(st.model.opacity_logits[1], -6.0);
        assert!(st.adam[3].m.iter().all(|&m| m == 0.0));
    }
}
