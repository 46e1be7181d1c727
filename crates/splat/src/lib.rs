//! `splat`: a CPU rasterizer for 3D Gaussians, following gsplat's "classic" mode.
//!
//! Conventions (docs/architecture.md): OpenCV camera axes, world→camera 4×4, pixel centres
//! at +0.5, 2D covariance + `eps2d` (0.3) on the diagonal, near plane z ≤ 0.01 culled,
//! per-axis 3.33σ boxes (binned to the tiles their `σ ≤ ln(255·o)` ellipse reaches: [`Cull`]),
//! 16×16 tiles, depth sort, `alpha = min(0.999, o·exp(-σ))`, skip
//! `alpha < 1/255`, stop before the Gaussian that would make `T·(1−alpha) ≤ 1e-4`, zero
//! gradient where the 0.999 clamp binds, `C = Σ cᵢαᵢTᵢ + T_final·background`.
//!
//! Layouts: every per-Gaussian array is structure-of-arrays `f32`, row-major:
//! `means (N·3)`, `quats (N·4, w x y z, unnormalized)`, `scales (N·3, linear, not log)`,
//! `opacity_logits (N)`, SH `(N·K·3)` coefficient-major then RGB, or RGB `(N·3)`.
//! Images are `H·W·3` interleaved RGB, row-major; alpha and per-pixel maps are `H·W`;
//! top-k maps are `H·W·k`.
//!
//! Scales are linear because deformable 3DGS adds the field's δs to `exp(log_scale)`
//! (docs/architecture.md, "Deformation"); callers that hold log-scales chain
//! `d/dlog s = s · d/ds`.

mod backward;
mod bin;
pub mod camera;
mod error;
mod fastexp;
mod forward;
mod grad_slots;
mod lanes;
mod project;
mod project_batch;
mod raster;
pub mod reference;
pub mod sh;
mod validate;

pub use camera::Camera;
pub use error::SplatError;
pub use raster::{simd_level, Rasterizer, Simd, Timings};
pub use simd::cpu_level as cpu_simd_level;

/// Side of a square tile in pixels.
pub const TILE_SIZE: u32 = 16;

/// Per-Gaussian colour source.
#[derive(Clone, Copy, Debug)]
pub enum Colors<'a> {
    /// Spherical-harmonic coefficients `(N·K·3)`, K = `num_coeffs` per Gaussian (≥ (degree+1)²).
    /// Only the first `(degree+1)²` coefficients are used; colour = max(SH·basis + 0.5, 0),
    /// evaluated along the view direction `mean − camera centre`.
    Sh {
        coeffs: &'a [f32],
        num_coeffs: usize,
        degree: usize,
    },
    /// RGB `(N·3)` used as is (no offset, no clamp).
    Rgb(&'a [f32]),
}

/// A borrowed set of N Gaussians (see the crate docs for layouts).
#[derive(Clone, Copy, Debug)]
pub struct Gaussians<'a> {
    pub means: &'a [f32],
    pub quats: &'a [f32],
    pub scales: &'a [f32],
    pub opacity_logits: &'a [f32],
    pub colors: Colors<'a>,
}

impl Gaussians<'_> {
    pub fn len(&self) -> usize {
        self.opacity_logits.len()
    }
    pub fn is_empty(&self) -> bool {
        self.opacity_logits.is_empty()
    }
}

/// Options of one render.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub background: [f32; 3],
    /// Per-pixel top-k contributors to record (0 = none, at no cost).
    pub topk: usize,
    /// Added to the diagonal of the 2D covariance (gsplat classic: 0.3).
    pub eps2d: f32,
    /// Gaussians with camera z ≤ near_plane are culled (0.01).
    pub near_plane: f32,
    /// Which (tile, Gaussian) pairs binning keeps; images, alphas, top-k and gradients are
    /// bit-identical either way (tests/cull_equivalence.rs), only the work differs.
    pub cull: Cull,
}

/// Tile culling at binning. gsplat 1.5.3 bins every tile of a Gaussian's 3.33σ
/// box; a pair contributes only where `o·e^{−σ} ≥ 1/255`, i.e. `σ ≤ ln(255·o)`, which
/// gsplat's projection exploits since its PR #597 (opacity-aware radius), FlashGS and
/// Speedy-Splat (SnugBox/AccuTile) with an exact ellipse–tile test.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Cull {
    /// Only the tiles of the 3.33σ box in which some pixel row passes the tile kernels' own
    /// opacity-aware row tests (the rows `|dy| ≤ hy` of `σ ≤ ln(255·o)`, then the row's
    /// chord of that ellipse against the tile's pixel centres), so every dropped pair is one
    /// the kernels would have skipped anyway: the image is unchanged.
    #[default]
    Exact,
    /// Every tile of the 3.33σ box (gsplat `_isect_tiles`; the intersection count then
    /// matches gsplat's `n_isects`).
    Box3Sigma,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            background: [0.0; 3],
            topk: 0,
            eps2d: 0.3,
            near_plane: 0.01,
            cull: Cull::Exact,
        }
    }
}

/// What a forward pass produced; borrowed from the [`Rasterizer`]'s reused buffers.
#[derive(Debug)]
pub struct ForwardOutput<'a> {
    pub width: u32,
    pub height: u32,
    /// `H·W·3`, background included.
    pub image: &'a [f32],
    /// `H·W`, = 1 − T_final.
    pub alpha: &'a [f32],
    /// `H·W·k` global Gaussian indices, largest weight first; `u32::MAX` where fewer than k.
    pub topk_ids: &'a [u32],
    /// `H·W·k` weights `w = T·α` matching `topk_ids` (0 where none).
    pub topk_weights: &'a [f32],
    /// `N·2` per-axis screen radii in pixels (0 = culled / not visible).
    pub radii: &'a [[i32; 2]],
    /// `N·2` projected means in pixels.
    pub means2d: &'a [[f32; 2]],
    /// `N` camera depths.
    pub depths: &'a [f32],
    /// Number of (tile, Gaussian) intersections (= `stats.tile_intersections`).
    pub n_isects: usize,
    /// Work counts of this pass.
    pub stats: RasterStats,
}

/// Work counts of one forward pass ([`ForwardOutput::stats`], [`Rasterizer::stats`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RasterStats {
    /// (tile, Gaussian) entries in the tile lists.
    pub tile_intersections: u64,
    /// Gradient slots the backward pass zeroes and reduces: the area of each Gaussian's
    /// tile rectangle (≥ intersections; see `grad_slots`).
    pub gradient_slots: u64,
    /// (pixel, Gaussian) pairs the forward kernels evaluated: 16-pixel rows that passed the
    /// row tests in rows with unfinished pixels, × 16.
    pub evaluated_pairs: u64,
    /// Of the evaluated pairs, those with `σ ≥ 0`, `α ≥ 1/255` at a still-unfinished
    /// pixel (the ones that composite or end the pixel): the floor of any culling. Counted
    /// only when [`Rasterizer::set_count_alpha_pairs`] is on (a slower, portable
    /// diagnostic kernel with the same arithmetic), else `None`.
    pub alpha_pairs: Option<u64>,
    /// What kernels evaluating 16-lane blocks of 4×4 (and 8 columns × 2 rows) pixels
    /// instead of 16-pixel rows would evaluate: 16 × the blocks that an evaluated row's
    /// chord meets. Measures what such a layout could save (docs/performance.md); counted
    /// with [`Self::alpha_pairs`], else `None`.
    pub pairs_4x4: Option<u64>,
    pub pairs_8x2: Option<u64>,
}

/// Gradients of a scalar loss with respect to every input of [`Gaussians`], same layouts.
/// Buffers are resized (not reallocated when large enough) by [`Rasterizer::backward`].
#[derive(Clone, Debug, Default)]
pub struct Gradients {
    pub means: Vec<f32>,
    pub quats: Vec<f32>,
    pub scales: Vec<f32>,
    pub opacity_logits: Vec<f32>,
    /// SH `(N·K·3)` (zero beyond the active degree) or RGB `(N·3)`, matching the input.
    pub colors: Vec<f32>,
    /// `N·2` gradient w.r.t. the projected means in pixels, as 3DGS accumulates for
    /// densification (multiply by (W/2, H/2) for 3DGS's NDC units).
    pub means2d: Vec<[f32; 2]>,
}
