//! A `--route` as motion: a centripetal Catmull-Rom curve through the waypoints (no
//! cusps or self-loops inside a segment, unlike the uniform kind), travelled at constant
//! speed over t ∈ [0, 1] (arc length inverted from a table, like the preset's `path`).
//! Heading follows the tangent unless waypoints give angles, which are then interpolated
//! by arc length the shortest way round.

use super::geometry::{sub, V3};
use super::motion::Pose;
use super::spec::Waypoint;
use std::f32::consts::{PI, TAU};

/// Arc-length table samples per segment.
const SAMPLES: usize = 128;
/// Waypoints closer than this cannot be parametrized by arc length.
pub const MIN_GAP: f32 = 1e-3;

pub struct Route {
    /// Waypoints with a reflected phantom point at each end (`2·P0 − P1`), so the curve
    /// passes through every given waypoint and leaves the ends straight.
    pts: Vec<V3>,
    /// Cumulative arc length at curve parameter `u = k / SAMPLES` (`u ∈ [0, segments]`).
    cum: Vec<f32>,
    /// Tangent heading at each table sample, carried over where the path is vertical.
    heading: Vec<f32>,
    /// `(arc length, [yaw, pitch, roll] in radians)` of waypoints that give angles.
    keys: Vec<(f32, V3)>,
}

fn dist(a: V3, b: V3) -> f32 {
    let d = sub(a, b);
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

fn lerp(a: V3, b: V3, wa: f32, wb: f32) -> V3 {
    [0, 1, 2].map(|k| wa * a[k] + wb * b[k])
}

/// Barry–Goldman evaluation of the centripetal (α = ½) segment from `p[1]` to `p[2]`
/// at `f ∈ [0, 1]`.
fn catmull_rom(p: &[V3], f: f32) -> V3 {
    let t1 = dist(p[0], p[1]).sqrt();
    let t2 = t1 + dist(p[1], p[2]).sqrt();
    let t3 = t2 + dist(p[2], p[3]).sqrt();
    let t = t1 + f * (t2 - t1);
    let a1 = lerp(p[0], p[1], (t1 - t) / t1, t / t1);
    let a2 = lerp(p[1], p[2], (t2 - t) / (t2 - t1), (t - t1) / (t2 - t1));
    let a3 = lerp(p[2], p[3], (t3 - t) / (t3 - t2), (t - t2) / (t3 - t2));
    let b1 = lerp(a1, a2, (t2 - t) / t2, t / t2);
    let b2 = lerp(a2, a3, (t3 - t) / (t3 - t1), (t - t1) / (t3 - t1));
    lerp(b1, b2, (t2 - t) / (t2 - t1), (t - t1) / (t2 - t1))
}

/// `a + f·(b − a)` for angles, the shortest way round.
fn lerp_angle(a: f32, b: f32, f: f32) -> f32 {
    let d = (b - a + PI).rem_euclid(TAU) - PI;
    a + f * d
}

impl Route {
    /// The route through `waypoints` (at least 2, consecutive ones ≥ [`MIN_GAP`] apart;
    /// checked by the caller, which can name the option).
    pub fn new(waypoints: &[Waypoint]) -> Self {
        let w: Vec<V3> = waypoints.iter().map(|p| p.pos).collect();
        let n = w.len();
        let mut pts = vec![sub([0, 1, 2].map(|k| 2.0 * w[0][k]), w[1])];
        pts.extend_from_slice(&w);
        pts.push(sub([0, 1, 2].map(|k| 2.0 * w[n - 1][k]), w[n - 2]));
        let mut route = Self {
            pts,
            cum: Vec::new(),
            heading: Vec::new(),
            keys: Vec::new(),
        };
        route.cum = route.arc_table();
        route.heading = route.heading_table();
        route.keys = waypoints
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let a = p.angles_deg?;
                Some((route.cum[i * SAMPLES], a.map(f32::to_radians)))
            })
            .collect();
        route
    }

    fn segments(&self) -> usize {
        self.pts.len() - 3
    }

    /// Point at curve parameter `u ∈ [0, segments]` (segment `⌊u⌋`).
    fn at(&self, u: f32) -> V3 {
        let seg = (u.floor() as usize).min(self.segments() - 1);
        catmull_rom(&self.pts[seg..seg + 4], u - seg as f32)
    }

    fn arc_table(&self) -> Vec<f32> {
        let n = self.segments() * SAMPLES;
        let mut cum = vec![0.0f32; n + 1];
        let mut prev = self.at(0.0);
        for k in 1..=n {
            let p = self.at(k as f32 / SAMPLES as f32);
            cum[k] = cum[k - 1] + dist(p, prev);
            prev = p;
        }
        cum
    }

    /// Heading of the horizontal tangent at `u`, if the path is not (near) vertical there.
    fn tangent_heading(&self, u: f32) -> Option<f32> {
        const H: f32 = 1e-3;
        let end = self.segments() as f32;
        let d = sub(self.at((u + H).min(end)), self.at((u - H).max(0.0)));
        let horizontal = d[0].hypot(d[1]);
        (horizontal > 1e-4 * d[2].abs().max(1e-6)).then(|| d[1].atan2(d[0]))
    }

    fn heading_table(&self) -> Vec<f32> {
        let raw: Vec<Option<f32>> = (0..self.cum.len())
            .map(|k| self.tangent_heading(k as f32 / SAMPLES as f32))
            .collect();
        // A vertical stretch keeps the heading it had before (or, at the start, the one
        // it will have): a lift does not spin the object.
        let first = raw.iter().flatten().next().copied().unwrap_or(0.0);
        let mut last = first;
        raw.iter()
            .map(|h| {
                last = h.unwrap_or(last);
                last
            })
            .collect()
    }

    /// Total length in world units.
    pub fn length(&self) -> f32 {
        self.cum[self.cum.len() - 1]
    }

    /// Curve parameter and table index at fraction `t` of the length (constant speed).
    fn param(&self, t: f32) -> (f32, usize) {
        let n = self.cum.len() - 1;
        let target = t.clamp(0.0, 1.0) * self.length();
        let i = self.cum.partition_point(|&c| c < target).clamp(1, n);
        let f = (target - self.cum[i - 1]) / (self.cum[i] - self.cum[i - 1]).max(1e-12);
        (
            (i as f32 - 1.0 + f) / SAMPLES as f32,
            if f < 0.5 { i - 1 } else { i },
        )
    }

    /// Yaw, pitch, roll at arc length `s` from the waypoints' angles.
    fn angles_at(&self, s: f32) -> V3 {
        let (first, last) = (self.keys[0], self.keys[self.keys.len() - 1]);
        if s <= first.0 {
            return first.1;
        }
        if s >= last.0 {
            return last.1;
        }
        let j = self.keys.partition_point(|k| k.0 <= s);
        let ((s0, a), (s1, b)) = (self.keys[j - 1], self.keys[j]);
        let f = (s - s0) / (s1 - s0).max(1e-12);
        [0, 1, 2].map(|k| lerp_angle(a[k], b[k], f))
    }

    /// Pose at fraction `t ∈ [0, 1]` of the route. z is clamped at the ground where the
    /// curve would swing below it (e.g. just after landing from a jump).
    pub fn pose(&self, t: f32) -> Pose {
        let (u, k) = self.param(t);
        let mut pos = self.at(u);
        pos[2] = pos[2].max(0.0);
        let [yaw, pitch, roll] = if self.keys.is_empty() {
            let yaw = self.tangent_heading(u).unwrap_or(self.heading[k]);
            [yaw, 0.0, 0.0]
        } else {
            self.angles_at(t.clamp(0.0, 1.0) * self.length())
        };
        Pose {
            pos,
            yaw,
            pitch,
            roll,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wp(x: f32, y: f32, z: f32, a: Option<f32>) -> Waypoint {
        Waypoint {
            pos: [x, y, z],
            angles_deg: a.map(|y| [y, 0.0, 0.0]),
        }
    }

    #[test]
    fn passes_waypoints_at_constant_speed() {
        let w = [
            wp(-0.8, -0.5, 0.0, None),
            wp(0.0, 0.3, 0.0, None),
            wp(0.6, -0.4, 0.0, None),
        ];
        let r = Route::new(&w);
        let n = 60;
        let p: Vec<V3> = (0..=n).map(|i| r.pose(i as f32 / n as f32).pos).collect();
        let steps: Vec<f32> = p.windows(2).map(|s| dist(s[0], s[1])).collect();
        let (lo, hi) = steps
            .iter()
            .fold((f32::MAX, 0.0f32), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(hi / lo < 1.02, "speed varies {lo}..{hi}");
        assert!(dist(p[0], w[0].pos) < 1e-5 && dist(p[n], w[2].pos) < 1e-4);
        // The middle waypoint lies on the curve.
        let near = p
            .iter()
            .map(|q| dist(*q, w[1].pos))
            .fold(f32::MAX, f32::min);
        assert!(near < 0.5 * hi, "middle waypoint missed by {near}");
    }

    #[test]
    fn heading_follows_the_tangent() {
        let r = Route::new(&[wp(-0.5, -0.5, 0.0, None), wp(0.5, 0.5, 0.0, None)]);
        for i in 0..=10 {
            let yaw = r.pose(i as f32 / 10.0).yaw;
            assert!((yaw - PI / 4.0).abs() < 1e-3, "{yaw}");
        }
        let r = Route::new(&[wp(0.5, 0.0, 0.0, None), wp(-0.5, 0.0, 0.0, None)]);
        assert!((r.pose(0.5).yaw.abs() - PI).abs() < 1e-3);
    }

    #[test]
    fn given_angles_are_interpolated_the_short_way() {
        let r = Route::new(&[
            wp(-0.5, 0.0, 0.0, Some(170.0)),
            wp(0.0, 0.0, 0.0, None),
            wp(0.5, 0.0, 0.0, Some(-170.0)),
        ]);
        assert!((r.pose(0.0).yaw - 170f32.to_radians()).abs() < 1e-5);
        // Half way: 180°, through the back, not through 0.
        assert!((r.pose(0.5).yaw.rem_euclid(TAU) - PI).abs() < 1e-3);
        assert!((r.pose(1.0).yaw - (-170f32).to_radians()).rem_euclid(TAU) < 1e-4);
        assert_eq!((r.pose(0.3).pitch, r.pose(0.3).roll), (0.0, 0.0));
    }

    #[test]
    fn a_jump_rises_and_lands_heading_straight() {
        let r = Route::new(&[
            wp(-0.6, 0.0, 0.0, None),
            wp(0.0, 0.0, 0.3, None),
            wp(0.6, 0.0, 0.0, None),
        ]);
        let z: Vec<f32> = (0..=20).map(|i| r.pose(i as f32 / 20.0).pos[2]).collect();
        assert!(z.iter().all(|&z| (0.0..=0.31).contains(&z)), "{z:?}");
        assert!((z[10] - 0.3).abs() < 0.01 && z[0] == 0.0, "{z:?}");
        assert!((0..=20).all(|i| r.pose(i as f32 / 20.0).yaw.abs() < 1e-4));
    }

    /// A straight lift has no horizontal tangent: the heading stays put instead of
    /// spinning with rounding noise.
    #[test]
    fn a_vertical_lift_keeps_a_fixed_heading() {
        let r = Route::new(&[wp(0.2, 0.1, 0.0, None), wp(0.2, 0.1, 0.25, None)]);
        for i in 0..=10 {
            let p = r.pose(i as f32 / 10.0);
            assert_eq!(p.yaw, 0.0);
            assert!((p.pos[2] - 0.025 * i as f32).abs() < 1e-4, "{:?}", p.pos);
        }
    }
}
