//! `toycars`: the paper's private experiment (Sec. 4.1: three toy vehicles on a plane, one
//! moving, one moving camera) rebuilt procedurally with ground truth, written in the
//! D-NeRF layout plus `masks/<file_path>.png` and `objects.json`. Beyond the two
//! presets, `routes` move any object along waypoints and `adds` place rigid props, so that
//! object-level rigid motion (turns, jumps, two movers, a non-vehicle) can be tested, and
//! an articulated crane (`joints`) whose boom and bucket turn with known angles.

mod crane;
mod custom;
mod geometry;
mod joints;
mod model;
mod motion;
mod props;
mod render;
mod route;
mod spec;
mod texture;
mod variety;
mod vehicles;
mod write;

pub use custom::BOUND;
pub use spec::{AddSpec, PropKind, RouteSpec, Waypoint};
pub use variety::{ground_truth_id_maps, varied, VariedScene};

use crate::SceneError;
use rand::{Rng, SeedableRng};
use std::path::Path;

/// Which of the paper's two scenes: which vehicle moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// The white SUV drives; the yellow sedan and the green SUV are parked.
    Scene1,
    /// The yellow sedan drives; the white SUV and the green SUV are parked.
    Scene2,
}

impl Preset {
    pub fn name(self) -> &'static str {
        match self {
            Preset::Scene1 => "scene1",
            Preset::Scene2 => "scene2",
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = SceneError;
    fn from_str(s: &str) -> Result<Self, SceneError> {
        match s.to_ascii_lowercase().as_str() {
            "scene1" => Ok(Preset::Scene1),
            "scene2" => Ok(Preset::Scene2),
            other => Err(SceneError::Argument(format!(
                "unknown toycars preset `{other}` (scene1 or scene2)"
            ))),
        }
    }
}

/// Generator settings. Time `t ∈ [0, 1]` spans 6 s; frame `i` is at `t = i / (frames − 1)`.
#[derive(Clone, Debug, PartialEq)]
pub struct ToycarsConfig {
    pub preset: Preset,
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    /// Seeds the printed textures (ground grain and blotches, camouflage); the layout and
    /// motion are the same for every seed.
    pub seed: u64,
    /// 4 rotated-grid samples per pixel (true) or one at the centre.
    pub supersample: bool,
    /// Hard shadows from the sun.
    pub shadows: bool,
    /// Fraction of its route (~2.6 units, a left turn at the end) the moving vehicle
    /// covers over the sequence, in (0, 1]: 1 is the paper-like full drive, smaller values
    /// give the slower motion that deformable 3DGS can follow (docs/regularizer.md).
    /// Applies to every moving object (the fraction of its route).
    pub drive: f32,
    /// Routes replacing the preset's drive or moving other objects (at most one per
    /// object); empty keeps the preset.
    pub routes: Vec<RouteSpec>,
    /// Parked props added after the three vehicles (mask IDs 3, 4, …).
    pub adds: Vec<AddSpec>,
}

impl Default for ToycarsConfig {
    fn default() -> Self {
        Self {
            preset: Preset::Scene1,
            width: 480,
            height: 360,
            frames: 120,
            seed: 0,
            supersample: true,
            shadows: true,
            drive: 1.0,
            routes: Vec::new(),
            adds: Vec::new(),
        }
    }
}

/// Split and key of frame `i`: test = every 8th frame, val = the frame after each test
/// frame, train = the rest (D-NeRF layout).
pub fn frame_key(i: usize) -> (&'static str, String) {
    let split = match i % 8 {
        0 => "test",
        1 => "val",
        _ => "train",
    };
    (split, format!("{split}/r_{i:03}"))
}

/// Renders the scene into `out_dir` (created if needed); `progress(done, total)` is
/// called after each frame.
pub fn generate(
    cfg: &ToycarsConfig,
    out_dir: &Path,
    progress: &dyn Fn(usize, usize),
) -> Result<(), SceneError> {
    if cfg.width < 8 || cfg.height < 8 || cfg.width > 8192 || cfg.height > 8192 {
        return Err(SceneError::Argument(format!(
            "image size {}×{} outside 8..=8192",
            cfg.width, cfg.height
        )));
    }
    if cfg.frames < 2 || cfg.frames > 100_000 {
        return Err(SceneError::Argument(format!(
            "frame count {} outside 2..=100000",
            cfg.frames
        )));
    }
    if !(cfg.drive > 0.0 && cfg.drive <= 1.0) {
        return Err(SceneError::Argument(format!(
            "drive fraction {} outside (0, 1]",
            cfg.drive
        )));
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
    let keys = (rng.gen::<u64>(), rng.gen::<u64>());
    let layout = motion::Layout::build(cfg)?;
    if !(cfg.routes.is_empty() && cfg.adds.is_empty()) {
        let mut warnings = layout.out_of_view(cfg.width, cfg.height, cfg.frames);
        warnings.extend(layout.collisions(cfg.frames));
        for msg in warnings {
            tracing::warn!("toycars: {msg}");
        }
    }
    tracing::info!(
        "toycars {}: {} objects ({} moving), {} frames of {}×{} into {}",
        cfg.preset.name(),
        layout.models.len(),
        (0..layout.models.len())
            .filter(|&i| layout.is_moving(i))
            .count(),
        cfg.frames,
        cfg.width,
        cfg.height,
        out_dir.display()
    );
    let mut frames = Vec::with_capacity(cfg.frames);
    for i in 0..cfg.frames {
        let t = i as f32 / (cfg.frames - 1) as f32;
        let frame = write::render_frame(cfg, &layout, keys, t, out_dir, i)?;
        frames.push(frame);
        progress(i + 1, cfg.frames);
    }
    write::write_metadata(cfg, &layout, &frames, out_dir)
}

/// Camera of a toycars frame at time `t` for a `width`×`height` image (what the written
/// `transforms_*.json` describe).
pub fn camera(width: u32, height: u32, t: f32) -> splat::Camera {
    write::splat_camera(width, height, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every corner of every vehicle's box stays inside the image at all times, so no
    /// object leaves the view (the paper's videos keep all three vehicles in frame).
    #[test]
    fn all_vehicles_stay_in_view() {
        for preset in [Preset::Scene1, Preset::Scene2] {
            let layout = motion::Layout::new(preset, 1.0);
            for i in 0..=40 {
                let t = i as f32 / 40.0;
                let cam = camera(480, 360, t);
                for (k, v) in layout.models.iter().enumerate() {
                    let m = layout.pose(k, t).matrix();
                    for c in 0..8 {
                        let w = crate::objects::apply(&m, v.corner(c));
                        assert!(
                            w.iter().all(|a| a.abs() < 1.3),
                            "{preset:?} vehicle {k} leaves [-1.3,1.3]³ at t={t}: {w:?}"
                        );
                        let (px, _) = cam.project(w).expect("in front of the camera");
                        let inside = px[0] > 4.0 && px[0] < 476.0 && px[1] > 4.0 && px[1] < 356.0;
                        assert!(
                            inside,
                            "{preset:?} vehicle {k} corner at {px:?} out of view at t={t}"
                        );
                    }
                }
            }
        }
    }
}
