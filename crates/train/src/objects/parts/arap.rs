//! The as-rigid-as-possible term between nearby Gaussians of an articulated object in
//! training (SC-GS's ARAP between control points; Luiten et al.'s local rigidity between
//! neighbouring Gaussians). Blended placement ([`super::skin`]) can stretch and shear a
//! part where weights change quickly; this term asks each skinned Gaussian `a` and its
//! nearest neighbours `b` on the same home part to keep their offset, turned by `a`'s
//! blended rotation `R_a(t)`. Pairs across two parts are left out: their offset must
//! change as the parts turn about their joint (the joint term holds the parts together),
//! and penalizing it drags a swinging part back towards the rest pose. Off by default
//! (`arap_weight = 0`): even within parts it lowered the crane's and the hand's crops
//! (docs/objects.md).
//!
//! `L = arap_weight · mean over pairs |(x_b(t) − x_a(t)) − R_a(t)(x_b − x_a)|² / ℓ²`,
//!
//! `x(t)` placed, `x` in the object's frame, `ℓ` the object's median neighbour spacing (so
//! the term reads as a squared local strain, whatever the object's size). Its gradient
//! goes to the placed means only: the rest offsets and `R_a(t)` are held fixed for the
//! step (as Luiten et al. hold the previous frame's), and the skinning's backward carries
//! it on to the weights, the parts' knots and the object-frame means. Neighbours are found
//! again whenever the object's rows change (after a densification).

use super::skin::Skinning;
use crate::deform::Deformed;
use crate::model::GaussianModel;
use crate::quat;

/// Neighbours per Gaussian.
pub const NEIGHBOURS: usize = 4;

/// The pairs of this run's skinned rows, found when the rows last changed.
#[derive(Default)]
pub struct Arap {
    /// The skinned rows the pairs were found for, and their home parts.
    key: Vec<u32>,
    homes: Vec<u16>,
    /// Pairs as positions in the skinning's row list, with `1/ℓ²` of their object.
    pairs: Vec<(u32, u32, f32)>,
}

impl Arap {
    /// Adds the term's gradient into `g_means` (world space) for this step's placement;
    /// returns the loss.
    pub fn add(
        &mut self,
        skin: &Skinning,
        model: &GaussianModel,
        placed: &Deformed,
        weight: f32,
        g_means: &mut [f32],
    ) -> f32 {
        if weight == 0.0 || !skin.active() {
            return 0.0;
        }
        if self.key != skin.rows || self.homes != skin.home {
            self.pairs = pairs(skin, model);
            self.key.clone_from(&skin.rows);
            self.homes.clone_from(&skin.home);
        }
        if self.pairs.is_empty() {
            return 0.0;
        }
        let c = weight / self.pairs.len() as f32;
        let at = |v: &[f32], i: u32| {
            let i = i as usize;
            [v[i * 3], v[i * 3 + 1], v[i * 3 + 2]]
        };
        let mut loss = 0.0f64;
        for &(a, b, inv_l2) in &self.pairs {
            let (ia, ib) = (skin.rows[a as usize], skin.rows[b as usize]);
            let r = quat::to_matrix(skin.blend[a as usize]);
            let (xa, xb) = (at(&model.means, ia), at(&model.means, ib));
            let rest = quat::rotate(&r, [0, 1, 2].map(|k| xb[k] - xa[k]));
            let (pa, pb) = (at(&placed.means, ia), at(&placed.means, ib));
            let d: [f32; 3] = std::array::from_fn(|k| pb[k] - pa[k] - rest[k]);
            loss += f64::from(c * inv_l2 * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
            for k in 0..3 {
                let g = 2.0 * c * inv_l2 * d[k];
                g_means[ib as usize * 3 + k] += g;
                g_means[ia as usize * 3 + k] -= g;
            }
        }
        loss as f32
    }
}

/// Each skinned row's [`NEIGHBOURS`] nearest rows on its own home part (object frame), by
/// brute force per part (O(n²) per part, run once per densification); `ℓ` is the spacing
/// over the whole object.
fn pairs(skin: &Skinning, model: &GaussianModel) -> Vec<(u32, u32, f32)> {
    let pt = |j: usize| {
        let i = skin.rows[j] as usize;
        [
            model.means[i * 3],
            model.means[i * 3 + 1],
            model.means[i * 3 + 2],
        ]
    };
    let mut out = Vec::new();
    for g in 0..skin.groups.len() {
        let members: Vec<usize> = (0..skin.rows.len())
            .filter(|&j| skin.group[j] as usize == g)
            .collect();
        let flat: Vec<f32> = members.iter().flat_map(|&j| pt(j)).collect();
        let spacing = super::joints::spacing(&flat);
        if spacing <= 0.0 {
            continue;
        }
        let inv_l2 = 1.0 / (spacing * spacing);
        for &a in &members {
            let mut near: Vec<(f32, usize)> = members
                .iter()
                .filter(|&&b| b != a && skin.home[b] == skin.home[a])
                .map(|&b| (super::cluster::dist2(pt(a), pt(b)), b))
                .collect();
            let k = NEIGHBOURS.min(near.len());
            if k == 0 {
                continue;
            }
            near.select_nth_unstable_by(k - 1, |x, y| x.0.total_cmp(&y.0));
            for &(_, b) in &near[..k] {
                out.push((a as u32, b as u32, inv_l2));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::state::{AuxRows, NO_OBJECT};

    /// A row of eight Gaussians on two parts (IDs 4 and 9, mask 4) and one field Gaussian.
    fn scene() -> (
        GaussianModel,
        Vec<u8>,
        Vec<crate::objects::RigidObject>,
        AuxRows,
    ) {
        use crate::objects::{trajectory::Trajectory, RigidObject};
        let n = 9;
        let means: Vec<f32> = (0..n)
            .flat_map(|i| [i as f32 * 0.1, 0.02 * i as f32, 0.0])
            .collect();
        let column: Vec<u8> = (0..n)
            .map(|i| match i {
                0..=3 => 4,
                4..=7 => 9,
                _ => NO_OBJECT,
            })
            .collect();
        let model = crate::init::from_points(&means, &vec![0.5; 3 * n], 0.5);
        let still = Trajectory {
            times: vec![0.0, 1.0],
            translations: vec![[0.0; 3]; 2],
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; 2],
        };
        let mut turn = still.clone();
        turn.rotations[1] = [0.8, 0.0, 0.0, 0.6];
        let mut arm = RigidObject::new(9, "c/part-1".into(), turn, false);
        arm.mask = 4;
        let objects = vec![RigidObject::new(4, "c".into(), still, true), arm];
        let mut data = vec![0.0; n * 6];
        for i in 0..8 {
            data[i * 6] = -0.3 * i as f32;
        }
        let aux = AuxRows {
            name: super::super::skin::SKIN_NAME.into(),
            cols: 6,
            data,
        };
        (model, column, objects, aux)
    }

    fn placed(
        m: &GaussianModel,
        c: &[u8],
        o: &[crate::objects::RigidObject],
        a: &AuxRows,
    ) -> (Skinning, Deformed) {
        let mut rows = Vec::new();
        crate::objects::place::rows_by_object(o, c, &mut rows);
        let mut d = Deformed::default();
        crate::deform::apply(m, None, &mut d);
        let mut poses = Vec::new();
        let shape = crate::objects::place::Shape::of(m);
        crate::objects::place::place(o, &rows, shape, 0.7, &mut d, &mut poses);
        let mut s = Skinning::default();
        s.place(o, &poses, shape, c, std::slice::from_ref(a), &mut d);
        (s, d)
    }

    /// The gradient it adds is that of its loss in the placed means (rotations held), the
    /// pairs stay inside the object, and a rigidly placed object costs nothing.
    #[test]
    fn gradient_matches_finite_differences_and_rigid_is_free() {
        let (m, c, o, a) = scene();
        let (s, d) = placed(&m, &c, &o, &a);
        let mut arap = Arap::default();
        let mut g = vec![0.0; d.means.len()];
        let loss = arap.add(&s, &m, &d, 0.5, &mut g);
        assert!(loss > 0.0, "blended parts turning apart strain");
        // Four Gaussians per part: three neighbours each on its own part.
        assert_eq!(arap.pairs.len(), 8 * 3);
        let part = |x: u32| x / 4;
        assert!(arap
            .pairs
            .iter()
            .all(|&(x, y, _)| x < 8 && y < 8 && x != y && part(x) == part(y)));
        assert_eq!(&g[24..27], &[0.0; 3], "the field's Gaussian has no term");
        let h = 1e-3;
        for (k, &gk) in g.iter().enumerate().take(24) {
            let mut e = |sign: f32| {
                let mut dd = d.clone();
                dd.means[k] += sign * h;
                arap.add(&s, &m, &dd, 0.5, &mut vec![0.0; d.means.len()])
            };
            let fd = (e(1.0) - e(-1.0)) / (2.0 * h);
            assert!(
                (fd - gk).abs() < 2e-3 * (1.0 + gk.abs()),
                "mean {k}: {fd} vs {gk}"
            );
        }
        // The same object with every part still: placed rigidly, no strain.
        let mut o2 = o.clone();
        o2[1].trajectory.rotations[1] = [1.0, 0.0, 0.0, 0.0];
        let (s2, d2) = placed(&m, &c, &o2, &a);
        let l2 = Arap::default().add(&s2, &m, &d2, 0.5, &mut vec![0.0; d.means.len()]);
        assert!(l2 < 1e-10, "{l2}");
    }
}
