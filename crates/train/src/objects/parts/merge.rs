//! From clusters to parts: clusters whose trajectories carry their Gaussians alike are one
//! part (motion clustering of the tracked clusters), and each Gaussian then joins the part
//! whose motion keeps it on its own colour inside its object's mask over the views.

use super::super::trajectory::Trajectory;
use crate::init::SH_C0;
use crate::model::{GaussianModel, SH_FLOATS};
use splat::Camera;

/// RMS over the `times` and the Gaussians of clusters `a` and `b` of the distance between
/// where `ta` and `tb` carry them, over `size`: 0 for two clusters that move as one.
pub fn relative_motion(
    means: &[f32],
    labels: &[u32],
    (a, b): (u32, u32),
    (ta, tb): (&Trajectory, &Trajectory),
    (times, size): (&[f32], f32),
) -> f32 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for &t in times {
        let (pa, pb) = (ta.pose(t), tb.pose(t));
        for (i, &l) in labels.iter().enumerate() {
            if l != a && l != b {
                continue;
            }
            let x = [means[i * 3], means[i * 3 + 1], means[i * 3 + 2]];
            let d = super::cluster::dist2(pa.apply(x), pb.apply(x));
            sum += f64::from(d);
            n += 1;
        }
    }
    ((sum / n.max(1) as f64).sqrt() as f32) / size.max(1e-12)
}

/// Groups `0..k` joined wherever `moves_alike(a, b)` (union–find over every pair); returns
/// each cluster's group, groups numbered by their lowest cluster.
pub fn group(k: usize, moves_alike: impl Fn(usize, usize) -> bool) -> Vec<u32> {
    let mut parent: Vec<usize> = (0..k).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for a in 0..k {
        for b in a + 1..k {
            if moves_alike(a, b) {
                let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
    }
    let roots: Vec<usize> = (0..k).map(|i| root(&mut parent, i)).collect();
    let mut labels: Vec<u32> = roots.iter().map(|&r| r as u32).collect();
    super::cluster::pack(&mut labels);
    labels
}

/// One view of the object for the reassignment: its camera, time, ID map and image (RGB
/// in [0, 1]).
pub struct MaskView<'a> {
    pub cam: &'a Camera,
    pub time: f32,
    pub id_map: &'a [u8],
    pub image: Vec<f32>,
}

/// A reassignment wins only by this much mean error: a Gaussian the parts explain about
/// equally (near a joint, or seen in few views) keeps its cluster's part.
const MARGIN: f32 = 0.02;

/// Each Gaussian's part: the one whose trajectory (`parts[g]`) best explains it in the
/// views, by the mean over views of its colour's distance to the pixel it projects onto
/// (mean absolute difference over RGB, at most 1), counting 1 where it leaves the object's
/// mask. A Gaussian that rides on the base and is carried by the boom's motion lands on
/// wrong colours or off the mask; carried by the base's, it stays on its own colour. Returns
/// how many changed part.
pub fn reassign(
    model: &GaussianModel,
    labels: &mut [u32],
    parts: &[&Trajectory],
    views: &[MaskView],
    id: u8,
) -> usize {
    let poses: Vec<Vec<_>> = parts
        .iter()
        .map(|t| views.iter().map(|v| t.pose(v.time)).collect())
        .collect();
    let mut moved = 0;
    for (i, l) in labels.iter_mut().enumerate() {
        let x = [
            model.means[i * 3],
            model.means[i * 3 + 1],
            model.means[i * 3 + 2],
        ];
        let rgb: [f32; 3] = std::array::from_fn(|c| SH_C0 * model.sh[i * SH_FLOATS + c] + 0.5);
        let error = |g: usize| -> f32 {
            let sum: f32 = poses[g]
                .iter()
                .zip(views)
                .map(|(p, v)| pixel_error(v, p.apply(x), rgb, id))
                .sum();
            sum / views.len().max(1) as f32
        };
        let mine = error(*l as usize);
        let mut best = (*l as usize, mine - MARGIN);
        for g in (0..parts.len()).filter(|&g| g != *l as usize) {
            let e = error(g);
            if e < best.1 {
                best = (g, e);
            }
        }
        if best.0 != *l as usize {
            *l = best.0 as u32;
            moved += 1;
        }
    }
    moved
}

/// How badly a Gaussian of colour `rgb` at `x` fits view `v`: the mean absolute RGB
/// difference to the pixel it projects onto when that pixel is the object's, else 1.
fn pixel_error(v: &MaskView, x: [f32; 3], rgb: [f32; 3], id: u8) -> f32 {
    let Some((px, _)) = v.cam.project(x) else {
        return 1.0;
    };
    let (w, h) = (v.cam.width as f32, v.cam.height as f32);
    if !(px[0] >= 0.0 && px[1] >= 0.0 && px[0] < w && px[1] < h) {
        return 1.0;
    }
    let p = px[1] as usize * v.cam.width as usize + px[0] as usize;
    if v.id_map[p] != id {
        return 1.0;
    }
    let d: f32 = (0..3).map(|c| (v.image[p * 3 + c] - rgb[c]).abs()).sum();
    (d / 3.0).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn traj(ps: &[[f32; 3]]) -> Trajectory {
        Trajectory {
            times: (0..ps.len()).map(|k| k as f32).collect(),
            translations: ps.to_vec(),
            rotations: vec![[1.0, 0.0, 0.0, 0.0]; ps.len()],
        }
    }

    #[test]
    fn clusters_moving_alike_merge_others_stay_apart() {
        let means = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        let labels = [0, 1];
        let still = traj(&[[0.0; 3], [0.0; 3]]);
        let same = traj(&[[0.0; 3], [0.001, 0.0, 0.0]]);
        let away = traj(&[[0.0; 3], [0.5, 0.0, 0.0]]);
        let times = [0.0, 1.0];
        let m =
            |t: &Trajectory| relative_motion(&means, &labels, (0, 1), (&still, t), (&times, 1.0));
        assert!(m(&same) < 0.001);
        // Knot 0 agrees, knot 1 is 0.5 apart: RMS over the two knots is 0.5/√2.
        assert!((m(&away) - 0.5 / 2f32.sqrt()).abs() < 1e-5);
        let g = group(4, |a, b| (a, b) == (0, 2) || (a, b) == (2, 3));
        assert_eq!(g, vec![0, 1, 0, 0]);
    }
}
