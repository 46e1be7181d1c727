//! SemDynReg: object-level deformation regularization (paper Sec. 3.3–3.4,
//! docs/architecture.md items 5–6).
//!
//! Pure functions on flat `f32` buffers, independent of the rest of the trainer, so that they
//! are tested alone and wired into the training step:
//!
//! 1. [`ObjectGroups::build`] turns the training render's per-pixel top-k ids and the view's
//!    object-ID map into the groups `G_o` (sets of Gaussian indices);
//! 2. [`evaluate`] computes `L_reg` over the groups for the field's `δx, δr, δs`, adds
//!    `d(λ·L_reg)/dδ` into the trainer's gradient buffers before the field backward, and fills
//!    per-object [`ObjectStats`] for the log;
//! 3. [`RegConfig`] holds every constant and the activation schedule; [`Regularizer`] bundles
//!    config and reused buffers into one call per training step;
//! 4. [`membership`] (opt-in, our extension) keeps per-Gaussian object votes across views so
//!    that `G_o` also holds the object's Gaussians that left its mask in this view;
//! 5. [`consistency`] measures how far vehicle Gaussians stray from the ground-truth rigid
//!    motion (the `compare` metric);
//! 6. beyond the paper, `consistency = "rigid"` ([`rigid_loss`]) replaces the per-object loss
//!    by the residual of the best rigid fit ([`rigid_fit`], Horn 1987), which a turning car
//!    does not pay; [`rigidity`] measures the same residual on a trained run (a metric).

pub mod config;
pub mod consistency;
pub mod eigen4;
pub mod error;
pub mod grouping;
pub mod hook;
pub mod loss;
pub mod membership;
pub mod rigid_fit;
pub mod rigid_loss;
pub mod rigidity;
pub mod stats;
pub mod step;

pub use config::{ConsistencyMode, Membership, RegConfig, REFERENCE_ITERS};
pub use consistency::{ConsistencyAccumulator, ConsistencyReport, ObjectTrack};
pub use error::RegError;
pub use grouping::{Group, ObjectGroups, TopKView, BACKGROUND_ID, NO_GAUSSIAN};
pub use hook::SemanticHook;
pub use loss::{evaluate, DeformGradMut, DeformView, RegLoss};
pub use membership::{MembershipVotes, VOTES_NAME};
pub use rigid_fit::{fit_rigid, FitError, FitKind, RigidFit, RigidTransform};
pub use rigid_loss::evaluate_rigid;
pub use rigidity::{RigidityAccumulator, RigidityReport};
pub use stats::ObjectStats;
pub use step::{Persist, Regularizer};
