//! Per-object numbers for the training log (group sizes, deviations and skips), one record
//! per object present in the ID map.

use serde::Serialize;

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ObjectStats {
    /// Object ID from the ID map.
    pub object: u8,
    /// Pixels carrying this ID in the training view.
    pub pixels: u32,
    /// `|G_o|`, distinct Gaussians in the group.
    pub group_size: u32,
    /// `‖δx̄_o‖`, compared with τ_d for the static skip.
    pub mean_dx_norm: f32,
    /// `(1/|G_o|) Σ ‖δx_i − δx̄_o‖²` (unweighted).
    pub dev_x: f32,
    /// `(1/|G_o|) Σ ‖δr_i − δr̄_o‖²` (unweighted, 4-vector quaternion offsets).
    pub dev_r: f32,
    /// `(1/|G_o|) Σ ‖δs_i − δs̄_o‖²` (unweighted).
    pub dev_s: f32,
    /// `L_reg^(o)`: `λx·dev_x + λr·dev_r + λs·dev_s` with `consistency = "paper"`,
    /// `λx·rigid_residual` with `"rigid"`; 0 when skipped.
    pub loss: f32,
    /// Paper: true when `‖δx̄_o‖ ≤ τ_d` (static) or the group is empty. Rigid: true only
    /// for an empty group (no static skip).
    pub skipped: bool,
    /// With `membership = "persistent"`: the object's persistent members this iteration
    /// (joined to the view's group, so `group_size` counts the union); 0 otherwise.
    pub persistent: u32,
    /// With `consistency = "rigid"`: `min_{R,t} (1/|G_o|) Σ ‖(x_i + δx_i) − (R x_i + t)‖²`
    /// (unweighted; `rigid_fit`). Absent (`None`, not logged) with `"paper"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rigid_residual: Option<f32>,
}
