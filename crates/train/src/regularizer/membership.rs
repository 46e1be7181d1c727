//! Persistent object membership: our extension of the paper's groups (Sec. 3.3), selected with
//! `[reg] membership = "persistent"` (docs/architecture.md, "SemDynReg" item 5).
//!
//! The paper's `G_o` holds the Gaussians in the top-k of the pixels that carry ID `o` *in this
//! view*. A Gaussian that drew the moving object at other times but lags behind it now (a
//! trailing ghost) is in the top-k of background pixels at this time, so the loss never reaches
//! it when it matters (docs/regularizer.md, "Motion regime"). Here every active iteration adds
//! each top-k entry's weight `w = T·α` to a per-Gaussian vote for its pixel's ID (or for the
//! background); a Gaussian whose votes are mostly on `o` joins `G_o` at every later iteration in
//! which the field evaluates it, in view of `o`'s pixels or not.
//!
//! Votes are weighted by `w` so that a faint ghost over the background (small `α`) barely
//! counts against the object it was fitted to. They live in the trainer's per-Gaussian hook rows
//! ([`crate::state::AuxRows`], one column per object and one for the background): densification
//! copies a parent's votes to its clones and split children, and checkpoints keep them.

use super::error::RegError;
use super::grouping::{TopKView, BACKGROUND_ID, NO_GAUSSIAN};

/// Name of the hook rows that hold the votes.
pub const VOTES_NAME: &str = "reg.membership_votes";

/// Object columns of the votes and this iteration's persistent members per object.
#[derive(Clone, Debug)]
pub struct MembershipVotes {
    /// Object IDs (ascending) with a column each; the background's column is the last.
    ids: Vec<u8>,
    /// Column of every ID (background and IDs absent from the maps → the background column).
    column: [u16; 256],
    /// Per object column: ascending Gaussian indices that are members now.
    members: Vec<Vec<u32>>,
}

impl MembershipVotes {
    /// Columns for every object ID that occurs in the training ID maps.
    pub fn new<'a>(id_maps: impl IntoIterator<Item = &'a [u8]>) -> Self {
        let mut seen = [false; 256];
        for map in id_maps {
            for &id in map {
                seen[id as usize] = true;
            }
        }
        let ids: Vec<u8> = (0..BACKGROUND_ID).filter(|&i| seen[i as usize]).collect();
        let mut column = [ids.len() as u16; 256];
        for (c, &id) in ids.iter().enumerate() {
            column[id as usize] = c as u16;
        }
        let members = vec![Vec::new(); ids.len()];
        Self {
            ids,
            column,
            members,
        }
    }

    /// The object ID of each vote column but the last (the background's), ascending.
    pub fn ids(&self) -> &[u8] {
        &self.ids
    }

    /// Values per Gaussian in the votes: one per object plus the background.
    pub fn cols(&self) -> usize {
        self.ids.len() + 1
    }

    /// Adds this view's top-k weights (the first `use_k` entries per pixel) to `votes`
    /// (`n·cols`, row-major per Gaussian).
    pub fn record(
        &self,
        topk: TopKView<'_>,
        weights: &[f32],
        use_k: usize,
        id_map: &[u8],
        votes: &mut [f32],
    ) -> Result<(), RegError> {
        let cols = self.cols();
        let n = votes.len() / cols;
        super::grouping::check_shapes(topk, id_map)?;
        if weights.len() != topk.ids.len() {
            return Err(RegError::TopKWeights {
                len: weights.len(),
                ids: topk.ids.len(),
            });
        }
        let use_k = use_k.min(topk.stride);
        for (p, &id) in id_map.iter().enumerate() {
            let col = self.column[id as usize] as usize;
            let base = p * topk.stride;
            let entries = topk.ids[base..base + use_k].iter();
            for (&g, &w) in entries.zip(&weights[base..base + use_k]) {
                if g == NO_GAUSSIAN {
                    break; // entries are sorted by weight: the rest are empty too
                }
                if g as usize >= n {
                    return Err(RegError::GaussianIndexOutOfRange { pixel: p, id: g, n });
                }
                votes[g as usize * cols + col] += w;
            }
        }
        Ok(())
    }

    /// Recomputes the members among `rows` (ascending): Gaussian `i` belongs to object `o`
    /// when `votes[i][o] ≥ min_weight` and `votes[i][o] ≥ share · Σ_c votes[i][c]`.
    pub fn update_members(&mut self, votes: &[f32], rows: &[u32], share: f32, min_weight: f32) {
        let cols = self.cols();
        for m in &mut self.members {
            m.clear();
        }
        for &r in rows {
            let row = &votes[r as usize * cols..(r as usize + 1) * cols];
            let total: f32 = row.iter().sum();
            for (o, &v) in row[..cols - 1].iter().enumerate() {
                if v >= min_weight && v >= share * total {
                    self.members[o].push(r);
                }
            }
        }
    }

    /// Persistent members of `object` from the last [`MembershipVotes::update_members`]
    /// (empty for an ID without a column).
    pub fn members_of(&self, object: u8) -> &[u32] {
        match self.ids.binary_search(&object) {
            Ok(c) => &self.members[c],
            Err(_) => &[],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_cover_the_ids_in_the_maps() {
        let maps = [vec![255u8, 3, 3], vec![7, 255, 255]];
        let v = MembershipVotes::new(maps.iter().map(|m| m.as_slice()));
        assert_eq!(v.cols(), 3);
        assert_eq!(v.ids, vec![3, 7]);
        assert_eq!(v.column[255], 2);
        assert_eq!(v.column[9], 2, "unknown IDs vote as background");
    }

    #[test]
    fn weighted_votes_decide_membership() {
        let maps = [vec![1u8, 255]];
        let mut v = MembershipVotes::new(maps.iter().map(|m| m.as_slice()));
        let mut votes = vec![0.0f32; 3 * 2];
        // Pixel 0 (object 1): Gaussians 0 (w 0.9) and 2 (w 0.1); pixel 1 (background):
        // Gaussians 2 (w 0.5) and 1 (w 0.4).
        let ids = [0, 2, 2, 1];
        let w = [0.9, 0.1, 0.5, 0.4];
        let topk = TopKView {
            ids: &ids,
            stride: 2,
        };
        for _ in 0..2 {
            v.record(topk, &w, 2, &maps[0], &mut votes).unwrap();
        }
        assert_eq!(votes, [1.8, 0.0, 0.0, 0.8, 0.2, 1.0]);
        v.update_members(&votes, &[0, 1, 2], 0.5, 1.0);
        assert_eq!(v.members_of(1), &[0]);
        // A lower share admits Gaussian 2 only once its object weight reaches min_weight.
        v.update_members(&votes, &[0, 1, 2], 0.1, 0.1);
        assert_eq!(v.members_of(1), &[0, 2]);
        // Rows the field did not evaluate are never members.
        v.update_members(&votes, &[2], 0.1, 0.1);
        assert_eq!(v.members_of(1), &[2]);
        assert!(v.members_of(4).is_empty());
    }

    #[test]
    fn bad_ids_and_shapes_are_errors() {
        let maps = [vec![1u8]];
        let v = MembershipVotes::new(maps.iter().map(|m| m.as_slice()));
        let mut votes = vec![0.0f32; 2];
        let topk = TopKView {
            ids: &[5],
            stride: 1,
        };
        let e = v.record(topk, &[1.0], 1, &maps[0], &mut votes);
        assert!(matches!(e, Err(RegError::GaussianIndexOutOfRange { .. })));
        let topk = TopKView {
            ids: &[0],
            stride: 1,
        };
        assert!(v.record(topk, &[], 1, &maps[0], &mut votes).is_err());
        assert_eq!(votes, [0.0, 0.0]);
    }
}
