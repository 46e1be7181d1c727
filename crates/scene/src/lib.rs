//! `scene`: cameras, data sets and their files (docs/architecture.md, "On disk").
//!
//! - [`load_dataset`] reads D-NeRF/Blender (`transforms_*.json`) and Nerfies/HyperNeRF
//!   (`dataset.json`) scenes into a [`Dataset`] of [`Frame`]s with [`splat::Camera`]s in the
//!   project's conventions (OpenCV axes, world→camera) and u8 images; also nerfstudio
//!   `transforms.json`, LLFF (`poses_bounds.npy`, `precomputed.json`) and COLMAP sparse
//!   models ([`colmap`]), detected by their marker files ([`LAYOUTS`]).
//! - [`align`]: similarity alignment of two camera sets and their pose errors.
//! - [`ImageU8`] / [`MaskU8`]: 8-bit RGB images and object-ID maps (255 = background),
//!   read and written as PNG (writes are atomic).
//! - [`objects`]: the `objects.json` ground truth of the toycars scenes.
//! - [`toycars`]: the procedural rebuild of the paper's experiment, with custom routes
//!   and rigid props for object-level motion tests.

pub mod align;
pub mod colmap;
mod dataset;
mod dnerf;
mod error;
mod image;
pub mod io;
mod llff;
pub mod math;
mod nerfies;
mod nerfstudio;
pub mod objects;
mod ply;
pub mod toycars;

pub use crate::image::{
    load_alpha_ids, load_mask, save_mask, save_rgba_png, ImageU8, MaskU8, MASK_BACKGROUND,
};
pub use dataset::{
    detect_kind, image_file, load_dataset, mask_path, part_map_path, semantics_path, Dataset,
    DatasetKind, Frame, LoadOptions, LAYOUTS,
};
pub use error::SceneError;
pub use ply::read_points as read_ply_points;
pub use ply::read_points_rgb as read_ply_points_rgb;
pub use ply::write_points_rgb as write_ply_points_rgb;
