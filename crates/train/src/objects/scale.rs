//! The cues to a moving object's scale. One camera fixes a moving object's path only up to
//! a common factor of its size and its distance (`gauge.rs`); the images of the object
//! cannot fix it, the static scene around it can. Per view, with the object's and the
//! background's depth rendered in that view, four readings (each as `ln` of the factor
//! that would satisfy it, relative to the current gauge):
//!
//! - **ring**: the median background depth in a ring around the silhouette over the
//!   object's centroid depth: the object stands where the scene around it is;
//! - **surface**: the median, over the background pixels next to the silhouette, of their
//!   depth over the object's surface depth at the nearest pixel of its mask: the scene
//!   beside an object meets it at its sides and its base;
//! - **contact**: the low quantile of the same ratios (`contact.rs`): where the object
//!   rests on the scene, the two meet;
//! - **behind** (an upper bound): the low quantile of background over object depth across
//!   the object's own pixels: the object is seen, so it is in front of what it covers;
//! - **occluded** (a lower bound): the high quantile of background over object depth where
//!   the object renders but the mask shows the scene, and that scene is nearer: the object
//!   is hidden there, so it is behind what hides it.
//!
//! [`ScaleCues::gather`] reduces them over the views (medians, a Theil–Sen line in time for
//! the contact, robust extremes for the bounds); [`choose`] combines them with the lift's
//! own reading (the first view's ring) into the gauge and its confidence.

use super::contact;
use super::lift::{self, DepthMap};
use super::NO_OBJECT;

/// Pixels a reading needs in one view.
const MIN_PIXELS: usize = 10;

/// What one view says about the gauge, as `ln` factors relative to the current gauge.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewCues {
    pub time: f32,
    pub ring: Option<f32>,
    pub contact: Option<f32>,
    pub behind: Option<f32>,
    pub occluded: Option<f32>,
    pub surface: Option<f32>,
}

/// The inputs of one view: the object's depth rendered alone, the background's depth,
/// the ID map, and the camera depth of the object's centroid.
pub struct ViewDepths<'a> {
    pub time: f32,
    pub object: &'a DepthMap,
    pub background: &'a DepthMap,
    pub id_map: &'a [u8],
    pub centroid_depth: f32,
}

/// The `q`-quantile of `v` (reordered), None when it has fewer than [`MIN_PIXELS`].
fn quantile(v: &mut [f32], q: f32) -> Option<f32> {
    if v.len() < MIN_PIXELS {
        return None;
    }
    let k = ((v.len() - 1) as f32 * q).round() as usize;
    v.select_nth_unstable_by(k, f32::total_cmp);
    Some(v[k])
}

/// Whether pixel `k` has a pixel of object `id` within `r` pixels.
fn near_mask(id_map: &[u8], w: usize, k: usize, id: u8, r: usize) -> bool {
    let h = id_map.len() / w;
    let (x, y) = (k % w, k / w);
    (y.saturating_sub(r)..=(y + r).min(h - 1))
        .any(|v| (x.saturating_sub(r)..=(x + r).min(w - 1)).any(|u| id_map[v * w + u] == id))
}

/// The four readings of one view (`q` the low quantile, `ring` the ring's width, pixels).
pub fn view_cues(v: &ViewDepths, id: u8, q: f32, ring: u32) -> ViewCues {
    let ln = |x: f32| (x > 0.0 && x.is_finite()).then(|| x.ln());
    let ring_read = lift::ring_depth(v.background, v.id_map, id, ring)
        .filter(|_| v.centroid_depth > 0.0)
        .and_then(|d| ln(d / v.centroid_depth));
    let mut next_to = contact::ring_ratios(v.object, v.background, v.id_map, id, ring);
    let w = v.object.width as usize;
    let (mut own, mut hidden) = (Vec::new(), Vec::new());
    for (k, &m) in v.id_map.iter().enumerate() {
        let (zo, zb) = (v.object.depth[k], v.background.depth[k]);
        if !(zo.is_finite() && zb.is_finite() && zo > 0.0) {
            continue;
        }
        if m == id {
            own.push(zb / zo);
        } else if m == NO_OBJECT && zb < zo && !near_mask(v.id_map, w, k, id, ring as usize) {
            // Away from the silhouette's edge, where a slightly wrong shape spills.
            hidden.push(zb / zo);
        }
    }
    ViewCues {
        time: v.time,
        ring: ring_read,
        surface: quantile(&mut next_to, 0.5).and_then(ln),
        contact: quantile(&mut next_to, q).and_then(ln),
        behind: quantile(&mut own, q).and_then(ln),
        occluded: quantile(&mut hidden, 1.0 - q).and_then(ln),
    }
}

/// An estimate of the gauge from one kind of reading: `ln` of its factor, the spread of
/// the views about it (median absolute deviation, `ln` units) and how many views read it.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Estimate {
    #[serde(with = "super::json_f32")]
    pub ln_factor: f32,
    #[serde(with = "super::json_f32")]
    pub spread: f32,
    pub views: usize,
}

impl Estimate {
    /// The median of the views' readings `v` and their spread about it.
    fn of(v: Vec<f32>) -> Option<Self> {
        let m = median(&mut v.clone())?;
        Some(Estimate {
            ln_factor: m,
            spread: mad(&v, m),
            views: v.len(),
        })
    }
}

/// Every cue of one object reduced over its views.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScaleCues {
    pub ring: Option<Estimate>,
    /// The level of a Theil–Sen line through the contact readings in time (a jump off the
    /// ground for a stretch of views does not bend it), its spread about that line.
    pub contact: Option<Estimate>,
    /// The gauge may not exceed this (`ln`; a low quantile over the views' readings).
    #[serde(with = "super::json_f32::option")]
    pub upper: Option<f32>,
    /// The gauge may not go below this (`ln`; a high quantile over the views' readings).
    #[serde(with = "super::json_f32::option")]
    pub lower: Option<f32>,
    /// The median over the views of their surface readings.
    pub surface: Option<Estimate>,
    pub views: usize,
}

fn median(v: &mut [f32]) -> Option<f32> {
    contact::median(v)
}

fn mad(v: &[f32], centre: f32) -> f32 {
    let mut d: Vec<f32> = v.iter().map(|x| (x - centre).abs()).collect();
    median(&mut d).unwrap_or(0.0)
}

/// A robust extreme over views: the `q`-quantile with at least 3 views reading it.
fn extreme(mut v: Vec<f32>, q: f32) -> Option<f32> {
    if v.len() < 3 {
        return None;
    }
    let k = ((v.len() - 1) as f32 * q).round() as usize;
    v.select_nth_unstable_by(k, f32::total_cmp);
    Some(v[k])
}

impl ScaleCues {
    pub fn gather(views: &[ViewCues]) -> Self {
        let ring = Estimate::of(views.iter().filter_map(|v| v.ring).collect());
        let surface = Estimate::of(views.iter().filter_map(|v| v.surface).collect());
        let pts: Vec<(f32, f32)> = views
            .iter()
            .filter_map(|v| v.contact.map(|c| (v.time, c)))
            .collect();
        let contact = contact::robust_line(&pts).map(|(level, slope, t_mean)| {
            let res: Vec<f32> = pts
                .iter()
                .map(|p| p.1 - level - slope * (p.0 - t_mean))
                .collect();
            Estimate {
                ln_factor: level,
                spread: mad(&res, 0.0),
                views: pts.len(),
            }
        });
        ScaleCues {
            ring,
            surface,
            contact,
            upper: extreme(views.iter().filter_map(|v| v.behind).collect(), 0.1),
            lower: extreme(views.iter().filter_map(|v| v.occluded).collect(), 0.9),
            views: views.len(),
        }
    }
}

/// How a mover's gauge is set (`[objects] gauge`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GaugeRule {
    /// Where the lift put it: the first view's ring depth.
    #[default]
    Lift,
    /// The median of the lift's reading, the ring over all views and the surface contact
    /// over all views.
    Cues,
}

/// The gauge chosen for a mover and how far the cues back it.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GaugeChoice {
    /// `ln` of the factor applied to the lifted guess of size and distance.
    #[serde(with = "super::json_f32")]
    pub ln_factor: f32,
    /// The share of the three readings (the lift's, the ring's and the surface contact's
    /// over all views) within the tolerance of the chosen factor: 1 when all agree, 1/3
    /// when only the chosen one reads it; a missing reading does not agree.
    #[serde(with = "super::json_f32")]
    pub confidence: f32,
}

/// The readings the gauge is chosen among: the lift's (0, its own factor), then the ring's
/// and the surface contact's over all views where they exist.
fn readings(cues: &ScaleCues) -> Vec<f32> {
    let mut r = vec![0.0];
    r.extend(cues.ring.map(|e| e.ln_factor));
    r.extend(cues.surface.map(|e| e.ln_factor));
    r
}

/// The gauge under `rule` and its confidence (`tolerance`: `ln` factor within which two
/// readings agree).
pub fn choose(cues: &ScaleCues, rule: GaugeRule, tolerance: f32) -> GaugeChoice {
    let mut r = readings(cues);
    let ln_factor = match rule {
        GaugeRule::Lift => 0.0,
        // With two readings the median is their upper one: prefer the lift's instead.
        GaugeRule::Cues if r.len() < 3 => 0.0,
        GaugeRule::Cues => median(&mut r).unwrap_or(0.0),
    };
    let agree = r
        .iter()
        .filter(|x| (*x - ln_factor).abs() <= tolerance)
        .count();
    GaugeChoice {
        ln_factor,
        confidence: agree as f32 / 3.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(w: u32, h: u32, z: f32) -> DepthMap {
        DepthMap {
            width: w,
            height: h,
            depth: vec![z; (w * h) as usize],
        }
    }

    /// A 6×6 object at depth 2 on a background at depth 3 (placed too near by 1.5×): the
    /// ring and the upper bound both read ln 1.5; nothing hides it, so no lower bound.
    #[test]
    fn an_object_in_front_of_its_background_reads_its_distance() {
        let (w, h) = (32u32, 24u32);
        let mut id_map = vec![NO_OBJECT; (w * h) as usize];
        let mut obj = map(w, h, f32::NAN);
        for y in 9..15 {
            for x in 13..19 {
                id_map[(y * w + x) as usize] = 4;
                obj.depth[(y * w + x) as usize] = 2.0;
            }
        }
        let bg = map(w, h, 3.0);
        let v = ViewDepths {
            time: 0.0,
            object: &obj,
            background: &bg,
            id_map: &id_map,
            centroid_depth: 2.0,
        };
        let c = view_cues(&v, 4, 0.03, 3);
        let l = 1.5f32.ln();
        assert!((c.ring.unwrap() - l).abs() < 1e-5);
        assert!((c.contact.unwrap() - l).abs() < 1e-5);
        assert!((c.behind.unwrap() - l).abs() < 1e-5);
        assert_eq!(c.occluded, None);
    }

    /// Where the object renders but the mask shows a nearer scene, the object is hidden
    /// there: a lower bound.
    #[test]
    fn a_hidden_part_gives_a_lower_bound() {
        let (w, h) = (32u32, 24u32);
        let mut id_map = vec![NO_OBJECT; (w * h) as usize];
        let mut obj = map(w, h, f32::NAN);
        let mut bg = map(w, h, 5.0);
        for y in 4..20 {
            for x in 4..28 {
                obj.depth[(y * w + x) as usize] = 4.0;
                if x < 16 {
                    id_map[(y * w + x) as usize] = 1;
                } else {
                    bg.depth[(y * w + x) as usize] = 2.0; // a wall in front of its right half
                }
            }
        }
        let v = ViewDepths {
            time: 0.0,
            object: &obj,
            background: &bg,
            id_map: &id_map,
            centroid_depth: 4.0,
        };
        let c = view_cues(&v, 1, 0.03, 3);
        assert!((c.occluded.unwrap() - 0.5f32.ln()).abs() < 1e-5);
    }

    #[test]
    fn gather_takes_medians_and_robust_extremes() {
        let views: Vec<ViewCues> = (0..9)
            .map(|k| ViewCues {
                time: k as f32 / 8.0,
                ring: Some(0.1 + if k == 4 { 2.0 } else { 0.0 }),
                contact: Some(0.05 * k as f32),
                behind: Some(0.3 + 0.01 * k as f32),
                occluded: None,
                surface: Some(-0.2),
            })
            .collect();
        let c = ScaleCues::gather(&views);
        let ring = c.ring.unwrap();
        assert!((ring.ln_factor - 0.1).abs() < 1e-6 && ring.spread < 1e-6);
        let con = c.contact.unwrap();
        assert!(
            (con.ln_factor - 0.2).abs() < 1e-5 && con.spread < 1e-5,
            "{con:?}"
        );
        assert!((c.upper.unwrap() - 0.31).abs() < 1e-5);
        assert_eq!(c.lower, None);
    }

    fn estimate(ln_factor: f32) -> Option<Estimate> {
        Some(Estimate {
            ln_factor,
            spread: 0.0,
            views: 5,
        })
    }

    /// `lift` keeps the lifted factor and says how many readings back it; `cues` takes the
    /// median of three, so one reading far off does not move it.
    #[test]
    fn choose_keeps_or_takes_the_median_and_counts_agreement() {
        let cues = ScaleCues {
            ring: estimate(0.05),
            surface: estimate(0.6),
            ..Default::default()
        };
        let lift = choose(&cues, GaugeRule::Lift, 0.1);
        assert_eq!(lift.ln_factor, 0.0);
        assert!((lift.confidence - 2.0 / 3.0).abs() < 1e-6);
        let med = choose(&cues, GaugeRule::Cues, 0.1);
        assert!((med.ln_factor - 0.05).abs() < 1e-6);
        assert!((med.confidence - 2.0 / 3.0).abs() < 1e-6);
        // Readings far apart: only the chosen one backs it.
        let apart = ScaleCues {
            ring: estimate(-0.5),
            surface: estimate(0.5),
            ..Default::default()
        };
        assert!((choose(&apart, GaugeRule::Cues, 0.1).confidence - 1.0 / 3.0).abs() < 1e-6);
        // Without the views' readings, the lift's alone: a third.
        let none = ScaleCues::default();
        let c = choose(&none, GaugeRule::Cues, 0.1);
        assert_eq!(c.ln_factor, 0.0);
        assert!((c.confidence - 1.0 / 3.0).abs() < 1e-6);
    }
}
