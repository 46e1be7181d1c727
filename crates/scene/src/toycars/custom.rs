//! Scenes beyond the presets: `--add`ed props and `--route` motions applied to a
//! preset's layout, checked so that every object is named once, moves along a route that
//! can be parametrized, and stays inside the volume where training seeds its points.

use super::crane::toy_crane;
use super::model::Model;
use super::motion::{Layout, Motion, Pose};
use super::props::{toy_barrel, toy_crate};
use super::route::{Route, MIN_GAP};
use super::spec::{AddSpec, PropKind, RouteSpec};
use super::write::splat_camera;
use super::ToycarsConfig;
use crate::SceneError;

/// Half side of the cube every object's box must stay in (the trainer seeds its random
/// initial points in [−1.3, 1.3]³ for synthetic scenes).
pub const BOUND: f32 = 1.3;

fn route_error(spec: &RouteSpec, msg: impl std::fmt::Display) -> SceneError {
    SceneError::Argument(format!("--route `{}`: {msg}", spec.text))
}

/// Consecutive waypoints must be apart: a route is parametrized by its length.
fn check_gaps(spec: &RouteSpec) -> Result<(), SceneError> {
    for (k, w) in spec.waypoints.windows(2).enumerate() {
        let d = [0, 1, 2].map(|c| w[1].pos[c] - w[0].pos[c]);
        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() < MIN_GAP {
            let msg = format!(
                "waypoints {} and {} coincide (keep them ≥ {MIN_GAP} apart)",
                k + 1,
                k + 2
            );
            return Err(route_error(spec, msg));
        }
    }
    Ok(())
}

impl Layout {
    /// The preset's layout with `cfg.adds` and `cfg.routes` applied and checked.
    pub fn build(cfg: &ToycarsConfig) -> Result<Self, SceneError> {
        let mut layout = Layout::new(cfg.preset, cfg.drive);
        for add in &cfg.adds {
            layout.add(add)?;
        }
        let mut routed: Vec<Option<&RouteSpec>> = vec![None; layout.models.len()];
        for spec in &cfg.routes {
            let i = layout.route_target(spec)?;
            if let Some(first) = routed[i] {
                let name = &layout.models[i].name;
                let msg = format!("{name} already has --route `{}`", first.text);
                return Err(route_error(spec, msg));
            }
            check_gaps(spec)?;
            layout.motions[i] = Motion::Route(Route::new(&spec.waypoints));
            routed[i] = Some(spec);
        }
        // Name what put each object where it is, for the bounds error.
        let origin: Vec<String> = (0..layout.models.len())
            .map(|i| match (routed[i], i.checked_sub(3)) {
                (Some(r), _) => format!("--route `{}`", r.text),
                (None, Some(k)) => format!("--add `{}`", cfg.adds[k].text),
                (None, None) => "the preset".to_string(),
            })
            .collect();
        layout.check_bounds(cfg.frames, &origin)?;
        Ok(layout)
    }

    /// Parks a new prop with the next mask ID and a name unique among its kind.
    fn add(&mut self, add: &AddSpec) -> Result<(), SceneError> {
        if self.models.len() >= usize::from(crate::MASK_BACKGROUND) {
            return Err(SceneError::Argument(format!(
                "--add `{}`: more than {} objects (mask IDs end at {})",
                add.text,
                crate::MASK_BACKGROUND,
                crate::MASK_BACKGROUND - 1
            )));
        }
        let kind = add.kind.name();
        let same = self
            .models
            .iter()
            .filter(|m| m.name == kind || m.name.starts_with(&format!("{kind}-")))
            .count();
        let name = if same == 0 {
            kind.to_string()
        } else {
            format!("{kind}-{}", same + 1)
        };
        let model: Model = match add.kind {
            PropKind::Crate => toy_crate(name),
            PropKind::Barrel => toy_barrel(name),
            PropKind::Crane => toy_crane(name),
        };
        self.models.push(model);
        self.motions.push(Motion::Parked(Pose::flat(
            add.x,
            add.y,
            add.yaw_deg.to_radians(),
        )));
        Ok(())
    }

    /// The object a route moves: the named one, or without a name the preset's driver.
    pub fn route_target(&self, spec: &RouteSpec) -> Result<usize, SceneError> {
        let Some(name) = &spec.object else {
            return Ok(self.driver);
        };
        self.models
            .iter()
            .position(|m| &m.name == name)
            .ok_or_else(|| {
                let names: Vec<&str> = self.models.iter().map(|m| m.name.as_str()).collect();
                route_error(
                    spec,
                    format!("no object named `{name}` (objects: {})", names.join(", ")),
                )
            })
    }

    /// Every corner of every object's boxes (links included) stays in [−BOUND, BOUND]³ at every frame time.
    fn check_bounds(&self, frames: usize, origin: &[String]) -> Result<(), SceneError> {
        for (i, model) in self.models.iter().enumerate() {
            for f in 0..frames {
                let t = f as f32 / (frames - 1) as f32;
                for w in self.corners(i, t) {
                    if w.iter().any(|v| v.abs() > BOUND) {
                        return Err(SceneError::Argument(format!(
                            "{}: {} leaves [−{BOUND}, {BOUND}]³ at t = {t:.3} (frame {f}): a box corner is at ({:.3}, {:.3}, {:.3})",
                            origin[i], model.name, w[0], w[1], w[2]
                        )));
                    }
                }
            }
        }
        Ok(())
    }

    /// Objects whose box leaves the image at some frame (the first such frame each). Not
    /// an error (a tracker may want that) but usually a mistake: the camera sees less
    /// than the mat on the near side (y < −0.6).
    pub fn out_of_view(&self, width: u32, height: u32, frames: usize) -> Vec<String> {
        let mut out = Vec::new();
        for (i, model) in self.models.iter().enumerate() {
            for f in 0..frames {
                let t = f as f32 / (frames - 1) as f32;
                let cam = splat_camera(width, height, t);
                let seen = self.corners(i, t).into_iter().all(|w| {
                    let p = cam.project(w);
                    p.is_some_and(|([u, v], _)| {
                        (0.0..=width as f32).contains(&u) && (0.0..=height as f32).contains(&v)
                    })
                });
                if !seen {
                    out.push(format!(
                        "{} is partly outside the image at t = {t:.3} (frame {f})",
                        model.name
                    ));
                    break;
                }
            }
        }
        out
    }

    /// Pairs of objects whose boxes intersect at some frame (the first such frame each):
    /// objects passing through each other (or a prop parked inside a vehicle), which no
    /// camera could film.
    pub fn collisions(&self, frames: usize) -> Vec<String> {
        let mut out = Vec::new();
        for i in 0..self.models.len() {
            for j in i + 1..self.models.len() {
                let hit = (0..frames).find_map(|f| {
                    let t = f as f32 / (frames - 1) as f32;
                    self.boxes_meet(i, j, t).then_some((f, t))
                });
                if let Some((f, t)) = hit {
                    let (a, b) = (&self.models[i].name, &self.models[j].name);
                    out.push(format!("{a} and {b} intersect at t = {t:.3} (frame {f})"));
                }
            }
        }
        out
    }

    /// Separating-axis test of two posed boxes on the world z axis and the boxes' own
    /// horizontal axes: exact for upright boxes, an approximation for tilted ones (and for
    /// articulated objects, whose boxes are tested as their hull).
    fn boxes_meet(&self, i: usize, j: usize, t: f32) -> bool {
        let posed = |k: usize| (self.pose(k, t).matrix(), self.corners(k, t));
        let ((mi, ci), (mj, cj)) = (posed(i), posed(j));
        // Each box's local x and y (first two columns) flattened onto the ground.
        let mut axes = vec![[0.0, 0.0, 1.0]];
        for m in [&mi, &mj] {
            axes.push([m[0][0], m[1][0], 0.0]);
            axes.push([m[0][1], m[1][1], 0.0]);
        }
        let span = |c: &[[f32; 3]], a: [f32; 3]| {
            c.iter()
                .map(|p| p[0] * a[0] + p[1] * a[1] + p[2] * a[2])
                .fold((f32::MAX, f32::MIN), |(lo, hi), d| (lo.min(d), hi.max(d)))
        };
        axes.iter().all(|&a| {
            let ((lo_i, hi_i), (lo_j, hi_j)) = (span(&ci, a), span(&cj, a));
            lo_i < hi_j && lo_j < hi_i
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::toycars::Preset;

    fn build(routes: &[&str], adds: &[&str]) -> Layout {
        let cfg = ToycarsConfig {
            routes: routes.iter().map(|s| s.parse().unwrap()).collect(),
            adds: adds.iter().map(|s| s.parse().unwrap()).collect(),
            frames: 24,
            ..Default::default()
        };
        Layout::build(&cfg).unwrap()
    }

    #[test]
    fn presets_raise_no_warnings() {
        for preset in [Preset::Scene1, Preset::Scene2] {
            let layout = Layout::new(preset, 1.0);
            assert!(layout.out_of_view(160, 120, 24).is_empty());
            assert!(
                layout.collisions(24).is_empty(),
                "{:?}",
                layout.collisions(24)
            );
        }
    }

    #[test]
    fn collisions_and_leaving_the_view_are_reported() {
        let layout = build(
            &["-0.9,0.12;0.6,0.12", "green-suv=0.45,0.3;0.45,-0.95"],
            &[],
        );
        let hits = layout.collisions(24);
        assert_eq!(hits.len(), 1, "{hits:?}");
        assert!(hits[0].starts_with("white-suv and yellow-sedan intersect at t = "));
        let gone = layout.out_of_view(160, 120, 24);
        assert_eq!(gone.len(), 1, "{gone:?}");
        assert!(gone[0].starts_with("green-suv is partly outside the image"));
        // A crate lifted over a parked vehicle does not touch it; one parked in it does.
        let over = build(&["crate=-0.15,0.12,0.3;0.05,0.12,0.3"], &["crate@0,0"]);
        assert!(over.collisions(24).is_empty(), "{:?}", over.collisions(24));
        let inside = build(&[], &["barrel@-0.3,0.1"]);
        assert_eq!(inside.collisions(24).len(), 1);
    }
}
