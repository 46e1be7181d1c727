//! Articulated objects: a model's links, each a rigid set of parts hinged to the body or
//! to an earlier link, turning about its joint by known angles over time. The ground truth
//! of every link's pose is written beside the object's (`objects.json`, `parts` and
//! `part_to_world`), so per-part motion can be checked, as the lego bulldozer's arm and
//! shovel cannot be.

use super::model::Model;
use super::motion::Pose;
use crate::objects::apply;
use std::f32::consts::TAU;

/// One joint angle over time: `rest + amp · sin(2π · cycles · t)` radians, `t ∈ [0, 1]`.
/// A back-and-forth motion visits most angles twice, at different times.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Swing {
    pub rest: f32,
    pub amp: f32,
    pub cycles: f32,
}

impl Swing {
    pub const STILL: Swing = Swing {
        rest: 0.0,
        amp: 0.0,
        cycles: 0.0,
    };

    pub fn at(&self, t: f32) -> f32 {
        self.rest + self.amp * (TAU * self.cycles * t).sin()
    }
}

/// A rigid link of an articulated model.
#[derive(Clone, Debug)]
pub struct Link {
    /// The part's name in `objects.json` (`parts[k].name`).
    pub name: String,
    /// Its parts, in the link's own frame (origin at the joint).
    pub model: Model,
    /// The link it hangs from: `None` the body, `Some(k)` an earlier link.
    pub parent: Option<usize>,
    /// Where the joint sits in the parent's frame.
    pub joint: [f32; 3],
    /// Turn about the parent's z axis (yaw), then about the turned y axis (pitch; positive
    /// lowers the link's +x end, as [`Pose`]).
    pub yaw: Swing,
    pub pitch: Swing,
}

impl Link {
    /// Link→parent matrix at time `t`.
    pub fn local(&self, t: f32) -> [[f32; 4]; 4] {
        Pose {
            pos: self.joint,
            yaw: self.yaw.at(t),
            pitch: self.pitch.at(t),
            roll: 0.0,
        }
        .matrix()
    }

    /// Whether the joint moves at all.
    pub fn moves(&self) -> bool {
        self.yaw.amp != 0.0 || self.pitch.amp != 0.0
    }
}

/// Row-major 4×4 product `a · b` (affine matrices).
pub fn compose(a: &[[f32; 4]; 4], b: &[[f32; 4]; 4]) -> [[f32; 4]; 4] {
    let mut out = [[0.0f32; 4]; 4];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[r][k] * b[k][c]).sum();
        }
    }
    out
}

/// Link→world matrices of `links` at `t`, given the body's local→world matrix.
pub fn link_matrices(links: &[Link], body: &[[f32; 4]; 4], t: f32) -> Vec<[[f32; 4]; 4]> {
    let mut out: Vec<[[f32; 4]; 4]> = Vec::with_capacity(links.len());
    for link in links {
        let parent = match link.parent {
            None => *body,
            Some(k) => out[k],
        };
        out.push(compose(&parent, &link.local(t)));
    }
    out
}

/// The box a model's body and links cover in the body's frame over `frames` frame times
/// (`objects.json`'s `bbox_local`); the body's own box for a rigid model.
pub fn swept_box(model: &Model, frames: usize) -> [[f32; 3]; 2] {
    let (mut lo, mut hi) = (model.bbox_lo, model.bbox_hi);
    if model.links.is_empty() {
        return [lo, hi];
    }
    let identity = Pose::flat(0.0, 0.0, 0.0).matrix();
    for f in 0..frames {
        let t = f as f32 / (frames - 1).max(1) as f32;
        for (link, m) in model
            .links
            .iter()
            .zip(link_matrices(&model.links, &identity, t))
        {
            for c in 0..8 {
                let p = apply(&m, link.model.corner(c));
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
    }
    [lo, hi]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn link(parent: Option<usize>, joint: [f32; 3], yaw: Swing, pitch: Swing) -> Link {
        Link {
            name: "l".into(),
            model: Model::new("l", "l", Vec::new()),
            parent,
            joint,
            yaw,
            pitch,
        }
    }

    /// A chain turns its child with it: the tip of a boom yawed by 90° on a body moved to
    /// (1, 0, 0) lies on the body's +y side; the hook hanging from the tip follows.
    #[test]
    fn chains_compose_from_the_body_out() {
        let quarter = Swing {
            rest: std::f32::consts::FRAC_PI_2,
            amp: 0.0,
            cycles: 0.0,
        };
        let links = [
            link(None, [0.0, 0.0, 0.2], quarter, Swing::STILL),
            link(Some(0), [0.5, 0.0, 0.0], Swing::STILL, Swing::STILL),
        ];
        let body = Pose::flat(1.0, 0.0, 0.0).matrix();
        let m = link_matrices(&links, &body, 0.3);
        let tip = apply(&m[0], [0.5, 0.0, 0.0]);
        let hook = apply(&m[1], [0.0, 0.0, 0.0]);
        for (got, want) in [(tip, [1.0, 0.5, 0.2]), (hook, [1.0, 0.5, 0.2])] {
            for k in 0..3 {
                assert!((got[k] - want[k]).abs() < 1e-6, "{got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn swings_go_back_and_forth() {
        let s = Swing {
            rest: 0.1,
            amp: 0.5,
            cycles: 1.0,
        };
        assert!((s.at(0.0) - 0.1).abs() < 1e-6);
        assert!((s.at(0.25) - 0.6).abs() < 1e-6);
        assert!((s.at(0.75) + 0.4).abs() < 1e-6);
        let still = link(None, [0.0; 3], Swing::STILL, Swing::STILL);
        assert!(!still.moves());
    }
}
