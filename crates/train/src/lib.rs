//! `train`: the deformable 3D Gaussian Splatting trainer (Yang et al., CVPR 2024), the
//! SemDynReg paper's baseline, on the CPU rasterizer of `splat` (docs/architecture.md).
//!
//! Pieces, in data-flow order: [`model`] (raw canonical Gaussians) and [`state`] (the one
//! Gaussian store, with their Adam moments, densification statistics and object column,
//! kept row-aligned), [`init`]; the scene model's [`node`] interface and its kinds,
//! registered in [`nodes`]: [`field_node`] ([`encoding`] + [`mlp`] = [`field`], the
//! deformation field, applied by [`deform`]) and [`objects`] (rigid objects); [`adam`],
//! [`densify`], the training loop in [`trainer`], [`render`], and [`checkpoint`]/[`ply`] on
//! disk; [`fork`] starts a run from another's checkpoint at the regularizer's start.

pub mod adam;
pub mod checkpoint;
pub mod config;
pub mod deform;
pub mod densify;
pub mod encoding;
mod error;
#[cfg(test)]
mod fd_check;
pub mod field;
pub mod field_node;
pub mod finite;
pub mod fork;
mod gemm_util;
pub mod hook;
pub mod id_maps;
pub mod init;
pub mod integrity;
mod io;
pub mod loss;
pub mod mlp;
pub mod model;
pub mod node;
pub mod nodes;
pub mod objects;
pub mod objects_bench;
pub mod ply;
pub mod quat;
pub mod regularizer;
pub mod render;
pub mod run;
pub mod state;
pub mod time_net;
pub mod timing;
pub mod trainer;
mod visibility;

pub use config::TrainConfig;
pub use error::{Result, TrainError};
pub use field::{DeformField, DeformOutput};
pub use hook::{DeformHook, HookContext};
pub use model::GaussianModel;
pub use trainer::{StepStats, Trainer};
