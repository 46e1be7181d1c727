//! The regularizer as one training-step hook: config + reused group/stat buffers.
//!
//! Intended use in the training loop (paper Sec. 3.4, docs/architecture.md item 6):
//! ```text
//! let k = if reg.active_at(iter) { reg.render_topk() } else { 0 };  // RenderOptions::topk
//! let out = rasterizer.forward(&deformed, &camera, &opts)?;
//! ... dL_rgb/dδ from the rasterizer backward and the field chain ...
//! if reg.active_at(iter) {
//!     let loss = reg.apply(TopKView { ids: out.topk_ids, stride: k }, id_map, deform, &mut grad)?;
//!     // log loss.weighted and reg.stats(); then run the field backward with grad
//! }
//! ```

use super::config::{ConsistencyMode, Membership, RegConfig};
use super::error::RegError;
use super::grouping::{ObjectGroups, TopKView};
use super::loss::{evaluate, DeformGradMut, DeformView, RegLoss};
use super::membership::MembershipVotes;
use super::rigid_loss::evaluate_rigid;
use super::stats::ObjectStats;

#[derive(Clone, Debug)]
pub struct Regularizer {
    cfg: RegConfig,
    groups: ObjectGroups,
    stats: Vec<ObjectStats>,
    /// Present with `membership = "persistent"` once [`Regularizer::set_objects`] ran.
    membership: Option<MembershipVotes>,
}

/// What persistent membership needs from the training step besides the top-k ids.
#[derive(Debug)]
pub struct Persist<'a> {
    /// Top-k weights `T·α`, laid out like the ids.
    pub weights: &'a [f32],
    /// Ascending indices of the Gaussians the field evaluated (the others have δ = 0).
    pub rows: &'a [u32],
    /// The votes (`N × votes_cols()`), kept by the trainer across iterations.
    pub votes: &'a mut [f32],
}

impl Regularizer {
    /// Validates `cfg` (already rescaled to the run's length with [`RegConfig::rescaled`]).
    pub fn new(cfg: RegConfig) -> Result<Self, RegError> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            groups: ObjectGroups::new(),
            stats: Vec::new(),
            membership: None,
        })
    }

    /// Declares the object IDs of the training ID maps; with `membership = "persistent"` this
    /// sets up one vote column per object (and one for the background).
    pub fn set_objects<'a>(&mut self, id_maps: impl IntoIterator<Item = &'a [u8]>) {
        if self.cfg.membership == Membership::Persistent {
            self.membership = Some(MembershipVotes::new(id_maps));
        }
    }

    /// Columns of the per-Gaussian votes persistent membership keeps (None: not persistent).
    pub fn votes_cols(&self) -> Option<usize> {
        self.membership.as_ref().map(MembershipVotes::cols)
    }

    pub fn config(&self) -> &RegConfig {
        &self.cfg
    }

    /// Whether the loss applies at 1-based iteration `iter`.
    pub fn active_at(&self, iter: u64) -> bool {
        self.cfg.active_at(iter)
    }

    /// The `RenderOptions::topk` the training render needs while active.
    pub fn render_topk(&self) -> usize {
        self.cfg.k
    }

    /// Group the view's Gaussians by object, evaluate `λ·L_reg` and add its gradient into
    /// `grad` (the trainer's dL/dδ, before the field backward). With persistent membership
    /// and `persist` given, this view's top-k first votes, then the groups take in the
    /// persistent members. `means` are the canonical means (`N·3`), read only with
    /// `consistency = "rigid"`.
    pub fn apply(
        &mut self,
        topk: TopKView<'_>,
        id_map: &[u8],
        means: &[f32],
        deform: DeformView<'_>,
        grad: &mut DeformGradMut<'_>,
        persist: Option<Persist<'_>>,
    ) -> Result<RegLoss, RegError> {
        let n = deform.dx.len() / 3;
        let k = self.cfg.k;
        match (&mut self.membership, persist) {
            (Some(mv), Some(p)) => {
                mv.record(topk, p.weights, k, id_map, p.votes)?;
                let (share, min_w) = (self.cfg.persist_share, self.cfg.persist_min_weight);
                mv.update_members(p.votes, p.rows, share, min_w);
                let mv = &*mv;
                self.groups
                    .build_with(topk, k, id_map, n, &|o| mv.members_of(o))?;
            }
            _ => self.groups.build(topk, k, id_map, n)?,
        }
        let (groups, cfg, stats) = (&self.groups, &self.cfg, &mut self.stats);
        let loss = match cfg.consistency {
            ConsistencyMode::Paper => evaluate(groups, deform, cfg, Some(grad), stats)?,
            ConsistencyMode::Rigid => {
                evaluate_rigid(groups, means, deform, cfg, Some(grad), stats)?
            }
        };
        if let Some(mv) = &self.membership {
            for s in &mut self.stats {
                s.persistent = mv.members_of(s.object).len() as u32;
            }
        }
        tracing::debug!(
            l_reg = loss.l_reg,
            active = loss.active,
            skipped = loss.skipped,
            mode = ?self.cfg.consistency,
            "SemDynReg"
        );
        Ok(loss)
    }

    /// Per-object stats of the last [`Regularizer::apply`], for the training log.
    pub fn stats(&self) -> &[ObjectStats] {
        &self.stats
    }

    /// Groups of the last [`Regularizer::apply`].
    pub fn groups(&self) -> &ObjectGroups {
        &self.groups
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn apply_groups_evaluates_and_keeps_stats() {
        let cfg = RegConfig {
            k: 1,
            lambda: 1.0,
            ..RegConfig::default()
        };
        let mut reg = Regularizer::new(cfg).unwrap();
        assert!(!reg.active_at(1) && reg.active_at(10_000));
        // Render with k = 2; only the strongest entry per pixel is used (cfg.k = 1).
        let ids = [0, 2, 1, 2];
        let dx = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 100.0, 0.0, 0.0];
        let (dr, ds) = ([0.0; 12], [0.0; 9]);
        let (mut gx, mut gr, mut gs) = ([0.0; 9], [0.0; 12], [0.0; 9]);
        let mut grad = DeformGradMut {
            dx: &mut gx,
            dr: &mut gr,
            ds: &mut gs,
        };
        let deform = DeformView {
            dx: &dx,
            dr: &dr,
            ds: &ds,
        };
        let loss = reg
            .apply(
                TopKView {
                    ids: &ids,
                    stride: 2,
                },
                &[5, 5],
                &[0.0; 9],
                deform,
                &mut grad,
                None,
            )
            .unwrap();
        // G_5 = {0, 1}: mean δx 1, deviation 1; Gaussian 2 (rank 2) is not grouped.
        assert!((loss.weighted - 1.0).abs() < 1e-6, "{loss:?}");
        assert_eq!(reg.stats().len(), 1);
        assert_eq!(reg.stats()[0].group_size, 2);
        assert_eq!(gx, [-1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert!(Regularizer::new(RegConfig {
            lambda: -1.0,
            ..RegConfig::default()
        })
        .is_err());
    }
}
