//! Which object a Gaussian belongs to, from the paper's grouping made persistent (Sec. 3.3:
//! the top-k contributors of an object's pixels): every step, each of the training view's
//! per-pixel top-k entries votes with its weight `T·α` for its pixel's ID, or for the
//! background (`regularizer::MembershipVotes`, the votes kept as per-Gaussian hook rows, so
//! densified children inherit them and checkpoints keep them). At each densification a
//! Gaussian whose votes put at least `transfer_share` of their weight (and `transfer_min_weight`
//! in all) on one object joins that object: a background Gaussian that keeps drawing a car
//! (a flip-book copy) becomes part of the car where it drew it; one voted into two objects
//! joins the one holding the larger share, and none when no object holds the share (a
//! silhouette edge shared by two objects). It is converted into the new object's frame at
//! the step's time, with fresh optimizer moments and cleared votes. A Gaussian is never
//! released from an object to the background: the mask term pushes object Gaussians that
//! spill outside the silhouette back in, or makes them transparent.

use super::RigidObject;
use crate::deform::Deformed;
use crate::quat;
use crate::regularizer::{MembershipVotes, TopKView};
use crate::state::GaussianState;

/// Name of the per-Gaussian hook rows that hold the votes.
pub const VOTES_NAME: &str = "objects.membership_votes";

/// The vote columns and the transfer rule's constants.
pub struct Membership {
    votes: MembershipVotes,
    pub k: usize,
    pub share: f32,
    pub min_weight: f32,
}

/// Where a step's Gaussians are in the world, for converting the ones that move.
pub struct StepPlacement<'a> {
    pub deformed: &'a Deformed,
    /// Whether each row's placement is valid this step: false for rows their node left at
    /// rest (the field's rows culled from the view, `Node::mark_unplaced`).
    pub placed: &'a [bool],
    pub time: f32,
}

impl Membership {
    pub fn new<'a>(
        id_maps: impl IntoIterator<Item = &'a [u8]>,
        k: usize,
        share: f32,
        min_weight: f32,
    ) -> Self {
        Self {
            votes: MembershipVotes::new(id_maps),
            k,
            share,
            min_weight,
        }
    }

    pub fn cols(&self) -> usize {
        self.votes.cols()
    }

    /// Adds this view's top-k votes.
    pub fn record(
        &self,
        ids: &[u32],
        weights: &[f32],
        stride: usize,
        id_map: &[u8],
        votes: &mut [f32],
    ) -> Result<(), String> {
        let topk = TopKView { ids, stride };
        self.votes
            .record(topk, weights, self.k, id_map, votes)
            .map_err(|e| e.to_string())
    }

    /// The object (vote column's ID) that Gaussian `i`'s votes elect, if any.
    fn elected(&self, row: &[f32]) -> Option<u8> {
        let total: f32 = row.iter().sum();
        if total < self.min_weight {
            return None;
        }
        let objects = &row[..row.len() - 1];
        let (c, &best) = objects
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))?;
        (best >= self.share * total && best >= self.min_weight).then(|| self.votes.ids()[c])
    }

    /// Moves every Gaussian its votes elect into another object (see the module docs);
    /// returns how many moved.
    pub fn transfer(
        &self,
        state: &mut GaussianState,
        objects: &[RigidObject],
        at: &StepPlacement,
    ) -> usize {
        let Some(vi) = state.aux.iter().position(|a| a.name == VOTES_NAME) else {
            return 0;
        };
        let cols = state.aux[vi].cols;
        // Votes name objects of the ID maps; a part counts as its object.
        let mask_of = |id: u8| objects.iter().find(|o| o.id == id).map_or(id, |o| o.mask);
        let mut moved = Vec::new();
        for (i, &ok) in at.placed.iter().enumerate() {
            let from = mask_of(state.object[i]);
            if !ok {
                continue;
            }
            let row = &state.aux[vi].data[i * cols..(i + 1) * cols];
            let Some(to) = self.elected(row).filter(|&to| to != from) else {
                continue;
            };
            if objects.iter().any(|o| o.mask == to) {
                moved.push((i, to));
            }
        }
        for &(i, to) in &moved {
            let o = nearest_body(state, objects, to, i, at);
            convert(state, i, o, at);
            state.object[i] = o.id;
            state.aux[vi].data[i * cols..(i + 1) * cols].fill(0.0);
        }
        moved.len()
    }
}

/// The body of object `mask` that Gaussian `i` joins: the object itself, or for an
/// articulated one the part whose placed Gaussian is nearest to it at `at.time`.
fn nearest_body<'a>(
    state: &GaussianState,
    objects: &'a [RigidObject],
    mask: u8,
    i: usize,
    at: &StepPlacement,
) -> &'a RigidObject {
    let bodies: Vec<&RigidObject> = objects.iter().filter(|o| o.mask == mask).collect();
    let whole = bodies.iter().find(|o| !o.is_part()).unwrap_or(&bodies[0]);
    if bodies.len() == 1 {
        return whole;
    }
    let d = &at.deformed.means;
    let x = [d[i * 3], d[i * 3 + 1], d[i * 3 + 2]];
    let mut best = (f32::INFINITY, *whole);
    for (j, &id) in state.object.iter().enumerate() {
        let Some(b) = bodies
            .iter()
            .find(|b| b.id == id)
            .filter(|_| at.placed[j] && j != i)
        else {
            continue;
        };
        let y = [d[j * 3], d[j * 3 + 1], d[j * 3 + 2]];
        let dist = (0..3).map(|c| (x[c] - y[c]).powi(2)).sum::<f32>();
        if dist < best.0 {
            best = (dist, *b);
        }
    }
    best.1
}

/// Puts Gaussian `i` (placed in the world by `at`) into object `o`'s frame at `at.time`.
fn convert(state: &mut GaussianState, i: usize, o: &RigidObject, at: &StepPlacement) {
    let d = at.deformed;
    let pose = o.trajectory.pose(at.time);
    let x = [0, 1, 2].map(|c| d.means[i * 3 + c]);
    let q = quat::normalize(&d.quats[i * 4..i * 4 + 4]).0;
    let m = &mut state.model;
    m.means[i * 3..i * 3 + 3].copy_from_slice(&pose.invert(x));
    m.quats[i * 4..i * 4 + 4].copy_from_slice(&quat::mul(quat::conj(pose.q), q));
    for c in 0..3 {
        m.log_scales[i * 3 + c] = d.scales[i * 3 + c].max(1e-8).ln();
    }
    for (a, w) in state.adam.iter_mut().zip(crate::model::ROWS) {
        a.m[i * w..(i + 1) * w].fill(0.0);
        a.v[i * w..(i + 1) * w].fill(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The resolution rule of the module docs: the largest share wins if it holds
    /// `share` of all votes (background included) and `min_weight`; otherwise no one.
    #[test]
    fn votes_elect_the_majority_object_or_none() {
        let map: &[u8] = &[2, 7, 255];
        let m = Membership::new([map], 3, 0.6, 1.0);
        assert_eq!(m.cols(), 3, "objects 2 and 7, then the background");
        assert_eq!(m.elected(&[3.0, 0.5, 0.5]), Some(2));
        assert_eq!(m.elected(&[0.5, 2.0, 0.5]), Some(7));
        // Voted into two objects with no majority (a shared silhouette edge): neither.
        assert_eq!(m.elected(&[1.5, 1.4, 0.1]), None);
        // Mostly background: stays where it is.
        assert_eq!(m.elected(&[1.0, 0.0, 2.0]), None);
        // Too few votes in all to decide.
        assert_eq!(m.elected(&[0.5, 0.0, 0.1]), None);
    }
}
