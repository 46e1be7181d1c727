//! Typed errors of the SemDynReg regularizer.

use thiserror::Error;

use super::rigid_fit::FitError;

/// Everything that can go wrong when grouping Gaussians or evaluating the regularizer.
/// Each variant names the buffer and the sizes involved so the caller's message is actionable.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RegError {
    #[error("top-k buffer has {len} entries, not a multiple of k={k}")]
    TopKLength { len: usize, k: usize },
    #[error("top-k stride k must be ≥ 1 (got 0)")]
    ZeroTopK,
    #[error("top-k weights have {len} entries, the top-k ids {ids}")]
    TopKWeights { len: usize, ids: usize },
    #[error("object-ID map has {len} pixels but the top-k render has {pixels} (size mismatch?)")]
    IdMapLength { len: usize, pixels: usize },
    #[error("top-k entry at pixel {pixel} names Gaussian {id}, but only {n} Gaussians exist")]
    GaussianIndexOutOfRange { pixel: usize, id: u32, n: usize },
    #[error("deformation buffer `{name}` has {len} floats, expected {expected} (N={n})")]
    DeformLength {
        name: &'static str,
        len: usize,
        expected: usize,
        n: usize,
    },
    #[error("groups were built for {groups_n} Gaussians but the deformation has {deform_n}")]
    GaussianCount { groups_n: usize, deform_n: usize },
    #[error("invalid regularizer config: `{field}` {problem}")]
    InvalidConfig {
        field: &'static str,
        problem: String,
    },
    #[error("pose of object {object} is not a rigid transform: {problem}")]
    NotRigid { object: u8, problem: String },
    #[error("position buffer `{name}` has {len} floats, expected {expected}")]
    PositionLength {
        name: &'static str,
        len: usize,
        expected: usize,
    },
    #[error("no vehicle Gaussians were evaluated: deformation consistency is undefined")]
    NoConsistencySamples,
    #[error("no vehicle Gaussians were evaluated: the rigidity residual is undefined")]
    NoRigiditySamples,
    #[error("object {object}: {source}")]
    RigidFit { object: u8, source: FitError },
}
