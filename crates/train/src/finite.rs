//! Divergence: a loss or parameter that turns NaN/Inf stops the run with the iteration and
//! the parameter group named, before anything non-finite reaches a checkpoint. The
//! optimizer reports for free whether every value it wrote is finite
//! ([`crate::adam::Adam::step_rows`]); the scans here then find where (they run only when
//! something is already wrong, and before each checkpoint is written). Each node scans its
//! own parameters ([`crate::node::Node::nonfinite`]); [`locate_store`] scans the Gaussians
//! and the per-Gaussian rows beside them.

use crate::model::ROWS;
use crate::state::GaussianState;

const GROUPS: [&str; 5] = ["means", "quats", "log_scales", "opacity_logits", "sh"];

/// Index of the first non-finite value of `v`. Chunks are tested with a branch-free
/// reduction (vectorized) and only a failing chunk is searched.
pub fn first_nonfinite(v: &[f32]) -> Option<usize> {
    const CHUNK: usize = 1024;
    v.chunks(CHUNK).enumerate().find_map(|(c, chunk)| {
        let bad = chunk.iter().fold(false, |acc, x| acc | !x.is_finite());
        bad.then(|| c * CHUNK + chunk.iter().position(|x| !x.is_finite()).expect("found"))
    })
}

/// The first non-finite Gaussian parameter or Adam moment of the store, named (group, and
/// the Gaussian's row); `None` when everything is finite.
pub fn locate_store(st: &GaussianState) -> Option<String> {
    let m = &st.model;
    let n = st.len();
    let params = [&m.means, &m.quats, &m.log_scales, &m.opacity_logits, &m.sh];
    for ((g, v), r) in GROUPS.iter().zip(params).zip(ROWS) {
        if let Some(i) = first_nonfinite(v) {
            return Some(format!(
                "Gaussian parameter `{g}` (Gaussian {} of {n})",
                i / r
            ));
        }
    }
    for ((g, a), r) in GROUPS.iter().zip(&st.adam).zip(ROWS) {
        for (which, v) in [("first", &a.m), ("second", &a.v)] {
            if let Some(i) = first_nonfinite(v) {
                return Some(format!(
                    "Adam {which} moment of `{g}` (Gaussian {} of {n})",
                    i / r
                ));
            }
        }
    }
    st.aux.iter().find_map(|a| {
        first_nonfinite(&a.data).map(|i| {
            format!(
                "per-Gaussian rows `{}` (Gaussian {} of {n})",
                a.name,
                i / a.cols.max(1)
            )
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_nonfinite_finds_nan_and_inf_in_any_chunk() {
        let mut v = vec![1.0f32; 5000];
        assert_eq!(first_nonfinite(&v), None);
        v[4099] = f32::INFINITY;
        assert_eq!(first_nonfinite(&v), Some(4099));
        v[3] = f32::NAN;
        assert_eq!(first_nonfinite(&v), Some(3));
        assert_eq!(first_nonfinite(&[]), None);
    }

    /// Rows that nodes keep beside the parameters (skinning logits, votes) are scanned too.
    #[test]
    fn the_store_scan_names_per_gaussian_rows() {
        let m = crate::init::from_points(&[0.0; 6], &[0.5; 6], 0.5);
        let mut st = GaussianState::new(m);
        assert_eq!(locate_store(&st), None);
        st.aux.push(crate::state::AuxRows {
            name: "objects.skin".into(),
            cols: 3,
            data: vec![0.0, 0.0, 0.0, 0.0, f32::NAN, 0.0],
        });
        let got = locate_store(&st).expect("found");
        assert!(got.contains("`objects.skin` (Gaussian 1 of 2)"), "{got}");
    }
}
