//! Where things are at time t ∈ [0, 1] (6 s): the objects' poses (in the presets two
//! parked, one driving a curve with a left turn; `--route` adds others, see `route`) and
//! the camera sliding along an arc.
//!
//! Scale: everything stays inside [−1.3, 1.3]³ (the ground mat is [−1.25, 1.25]² at z = 0),
//! where the trainer seeds its random initial points as Deformable-3DGS does for
//! synthetic scenes. The moving vehicle covers ~2.6 units while the camera's centre moves
//! ~1.05 units along a 30° arc, and the camera keeps looking at the same spot: the
//! monocular setting in which deformable 3DGS struggles (paper, Sec. 1 and 4).

use super::geometry::{normalize, sub, V3};
use super::joints::link_matrices;
use super::model::Model;
use super::route::Route;
use super::vehicles::{green_suv, white_suv, yellow_sedan};
use super::Preset;
use crate::objects::apply;

/// Half side of the square ground mat.
pub const GROUND_HALF: f32 = 1.25;

/// Where an object is at one instant: its origin (z = height above the ground) and its
/// orientation as right-handed rotations about its own axes, applied yaw (z), then pitch
/// (y, positive lowers the nose), then roll (x, positive raises the left side).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub pos: V3,
    pub yaw: f32,
    pub pitch: f32,
    pub roll: f32,
}

impl Pose {
    /// On the ground at `(x, y)`, heading `yaw`.
    pub fn flat(x: f32, y: f32, yaw: f32) -> Self {
        Self {
            pos: [x, y, 0.0],
            yaw,
            pitch: 0.0,
            roll: 0.0,
        }
    }

    /// Row-major local→world matrix `[Rz(yaw)·Ry(pitch)·Rx(roll) | pos]`: what the ray
    /// caster renders with and `objects.json` records.
    pub fn matrix(&self) -> [[f32; 4]; 4] {
        let [x, y, z] = self.pos;
        let (sy, cy) = self.yaw.sin_cos();
        if self.pitch == 0.0 && self.roll == 0.0 {
            // Yaw only: exactly the matrix the presets have always written (the general
            // product would turn some zeros into −0).
            return [
                [cy, -sy, 0.0, x],
                [sy, cy, 0.0, y],
                [0.0, 0.0, 1.0, z],
                [0.0, 0.0, 0.0, 1.0],
            ];
        }
        let (sp, cp) = self.pitch.sin_cos();
        let (sr, cr) = self.roll.sin_cos();
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr, x],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr, y],
            [-sp, cp * sr, cp * cr, z],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }
}

/// How one object moves.
pub enum Motion {
    Parked(Pose),
    /// The preset's drive: the first `drive` of [`path`].
    Drive,
    /// A `--route`, also travelled to its `drive` fraction.
    Route(Route),
}

/// The objects in mask-ID order (0 white SUV, 1 yellow sedan, 2 green SUV, then any
/// `--add`ed props) and how each moves.
pub struct Layout {
    pub models: Vec<Model>,
    pub motions: Vec<Motion>,
    /// The preset's moving vehicle (what an unnamed `--route` moves).
    pub driver: usize,
    /// Fraction of its route each moving object covers between t = 0 and t = 1.
    pub drive: f32,
}

impl Layout {
    /// A preset as the paper has it: the moving vehicle drives [`path`], the others take
    /// the two parking spots in ID order.
    pub fn new(preset: Preset, drive: f32) -> Self {
        let moving = match preset {
            Preset::Scene1 => 0,
            Preset::Scene2 => 1,
        };
        const SPOTS: [(f32, f32, f32); 2] = [(-0.15, 0.12, 0.35), (-0.62, 0.62, -1.05)];
        let mut spots = SPOTS.iter();
        let motions = (0..3)
            .map(|i| match i == moving {
                true => Motion::Drive,
                false => {
                    let &(x, y, yaw) = spots.next().expect("two parked vehicles");
                    Motion::Parked(Pose::flat(x, y, yaw))
                }
            })
            .collect();
        Self {
            models: vec![white_suv(), yellow_sedan(), green_suv()],
            motions,
            driver: moving,
            drive,
        }
    }

    /// Pose of object `i` at time `t`.
    pub fn pose(&self, i: usize, t: f32) -> Pose {
        match &self.motions[i] {
            Motion::Parked(p) => *p,
            Motion::Drive => {
                let (x, y, yaw) = path(t * self.drive);
                Pose::flat(x, y, yaw)
            }
            Motion::Route(r) => r.pose(t * self.drive),
        }
    }

    /// Whether object `i` moves: along a route or the drive, or any of its joints.
    pub fn is_moving(&self, i: usize) -> bool {
        !matches!(self.motions[i], Motion::Parked(_))
            || self.models[i].links.iter().any(|l| l.moves())
    }

    /// Link→world matrices of object `i`'s links at `t` (empty for a rigid object).
    pub fn link_poses(&self, i: usize, t: f32) -> Vec<[[f32; 4]; 4]> {
        link_matrices(&self.models[i].links, &self.pose(i, t).matrix(), t)
    }

    /// World corners of object `i`'s boxes at `t`: the body's eight, then each link's.
    pub fn corners(&self, i: usize, t: f32) -> Vec<V3> {
        let model = &self.models[i];
        let m = self.pose(i, t).matrix();
        let mut out: Vec<V3> = (0..8).map(|c| apply(&m, model.corner(c))).collect();
        for (link, lm) in model.links.iter().zip(self.link_poses(i, t)) {
            out.extend((0..8).map(|c| apply(&lm, link.model.corner(c))));
        }
        out
    }
}

/// Cubic Bézier control points of the drive: along the near side heading +x, then a left
/// turn of ~95° up the right side.
const CONTROL: [[f32; 2]; 4] = [[-0.9, -0.55], [0.25, -0.8], [0.8, -0.45], [0.72, 0.72]];

fn bezier(s: f32) -> ([f32; 2], [f32; 2]) {
    let u = 1.0 - s;
    let w = [u * u * u, 3.0 * u * u * s, 3.0 * u * s * s, s * s * s];
    let dw = [
        -3.0 * u * u,
        3.0 * u * u - 6.0 * u * s,
        6.0 * u * s - 3.0 * s * s,
        3.0 * s * s,
    ];
    let mut p = [0.0; 2];
    let mut d = [0.0; 2];
    for k in 0..4 {
        for c in 0..2 {
            p[c] += w[k] * CONTROL[k][c];
            d[c] += dw[k] * CONTROL[k][c];
        }
    }
    (p, d)
}

/// Pose on the drive at time `t`: constant speed along the curve (arc length inverted
/// from a 512-segment table), heading along the tangent.
pub fn path(t: f32) -> (f32, f32, f32) {
    const N: usize = 512;
    let mut cum = [0.0f32; N + 1];
    let mut prev = bezier(0.0).0;
    for (i, c) in cum.iter_mut().enumerate().skip(1) {
        let p = bezier(i as f32 / N as f32).0;
        *c = (p[0] - prev[0]).hypot(p[1] - prev[1]);
        prev = p;
    }
    for i in 1..=N {
        cum[i] += cum[i - 1];
    }
    let target = t.clamp(0.0, 1.0) * cum[N];
    let i = cum.partition_point(|&c| c < target).clamp(1, N);
    let f = (target - cum[i - 1]) / (cum[i] - cum[i - 1]).max(1e-12);
    let s = (i as f32 - 1.0 + f) / N as f32;
    let (p, d) = bezier(s);
    (p[0], p[1], d[1].atan2(d[0]))
}

/// Horizontal field of view written as `camera_angle_x`.
pub const CAMERA_ANGLE_X: f32 = 0.95;

/// Camera centre and the world→camera rotation rows (right, down, forward; OpenCV) at `t`:
/// 2.7 units from a target above the mat's centre, 42° above the horizon, azimuth
/// sweeping 30° from the near-left.
pub fn camera_pose(t: f32) -> (V3, [V3; 3]) {
    let target = [-0.02, -0.05, 0.08];
    let (r, elev) = (2.7f32, 42f32.to_radians());
    let az = (-112.0 + 30.0 * t).to_radians();
    let c = [
        target[0] + r * elev.cos() * az.cos(),
        target[1] + r * elev.cos() * az.sin(),
        target[2] + r * elev.sin(),
    ];
    let f = normalize(sub(target, c));
    let right = normalize([f[1], -f[0], 0.0]); // f × z
    let down = [
        f[1] * right[2] - f[2] * right[1],
        f[2] * right[0] - f[0] * right[2],
        f[0] * right[1] - f[1] * right[0],
    ];
    (c, [right, down, f])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_has_constant_speed_and_turns_left() {
        let steps: Vec<(f32, f32, f32)> = (0..=20).map(|i| path(i as f32 / 20.0)).collect();
        let d: Vec<f32> = steps
            .windows(2)
            .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
            .collect();
        let (lo, hi) = d
            .iter()
            .fold((f32::MAX, 0.0f32), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(hi / lo < 1.05, "{d:?}");
        assert!(d.iter().sum::<f32>() > 1.8);
        let turn = steps[20].2 - steps[0].2;
        assert!(turn > 1.2, "turn {turn}");
    }

    /// A partial drive is the start of the full route at a proportionally lower speed;
    /// parked vehicles do not depend on it.
    #[test]
    fn partial_drive_follows_the_start_of_the_route() {
        let (full, quarter) = (
            Layout::new(Preset::Scene1, 1.0),
            Layout::new(Preset::Scene1, 0.25),
        );
        for i in 0..=8 {
            let t = i as f32 / 8.0;
            assert_eq!(quarter.pose(0, t), full.pose(0, t * 0.25));
            assert_eq!(quarter.pose(1, t), full.pose(1, t));
            assert_eq!(quarter.pose(2, t), full.pose(2, t));
        }
        let ([x0, y0, _], [x1, y1, _]) = (quarter.pose(0, 0.0).pos, quarter.pose(0, 1.0).pos);
        let covered = (x1 - x0).hypot(y1 - y0);
        assert!(
            covered > 0.5 && covered < 0.8,
            "quarter drive covers {covered}"
        );
    }

    /// Yaw-only poses give the presets' matrix exactly; tilted ones a proper rotation
    /// with the documented signs.
    #[test]
    fn pose_matrices() {
        let (s, c) = 0.7f32.sin_cos();
        let old = [
            [c, -s, 0.0, 0.3],
            [s, c, 0.0, -0.2],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        assert_eq!(Pose::flat(0.3, -0.2, 0.7).matrix(), old);
        let p = Pose {
            pos: [0.1, 0.2, 0.3],
            yaw: 0.4,
            pitch: 0.25,
            roll: -0.6,
        };
        let m = p.matrix();
        for a in 0..3 {
            for b in 0..3 {
                let d: f32 = (0..3).map(|k| m[k][a] * m[k][b]).sum();
                assert!((d - f32::from(a == b)).abs() < 1e-6);
            }
        }
        assert_eq!([m[0][3], m[1][3], m[2][3]], p.pos);
        let nose = Pose {
            yaw: 0.0,
            roll: 0.0,
            ..p
        }
        .matrix();
        assert!(nose[2][0] < 0.0, "positive pitch lowers the nose");
        let side = Pose {
            yaw: 0.0,
            pitch: 0.0,
            roll: 0.3,
            ..p
        }
        .matrix();
        assert!(side[2][1] > 0.0, "positive roll raises the left side");
    }

    #[test]
    fn camera_rotation_is_orthonormal_and_right_handed() {
        let (_, r) = camera_pose(0.3);
        let cross = [
            r[0][1] * r[1][2] - r[0][2] * r[1][1],
            r[0][2] * r[1][0] - r[0][0] * r[1][2],
            r[0][0] * r[1][1] - r[0][1] * r[1][0],
        ];
        for k in 0..3 {
            assert!((cross[k] - r[2][k]).abs() < 1e-5);
        }
        assert!(r[1][2] < 0.0, "image down must point to world −z");
    }
}
