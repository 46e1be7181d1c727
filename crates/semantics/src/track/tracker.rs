//! One object followed from frame to frame (prompts from the previous mask, a plausibility
//! check, re-detection when lost). The prompts follow box propagation with SAM: the previous
//! mask's box, moved by the object's last displacement and grown by a margin, plus the point
//! deepest inside the previous mask; the resulting mask is then refined once with its own
//! tight box, points spread inside it and background points just outside its box.

use serde::Serialize;

use super::region::{grow_box, shift_box, Histogram, PixelBox, Region};
use crate::sam::{Outputs, Prediction, Predictor, Prompt, Scratch};

/// The tracker's constants (docs/semantics.md "Tracking"). None depends on a scene: sizes are
/// fractions of the object's box or of the image.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TrackConfig {
    /// The propagated box grows by this fraction of its size on every side (room for motion
    /// the displacement did not predict).
    pub box_margin: f32,
    /// Points spread inside the first mask for the refining prompt.
    pub positive_points: usize,
    /// Background points just outside the first mask's box for the refining prompt.
    pub negative_points: usize,
    /// A mask whose area changed by more than this factor from the last frame's (either
    /// way) is not the object.
    pub max_area_change: f32,
    /// Least colour-histogram similarity (Bhattacharyya) to the object's look on its seed
    /// frame or its last frame.
    pub min_appearance: f32,
    /// Least predicted IoU of an accepted mask.
    pub min_pred_iou: f32,
    /// A mask over this fraction of the image is background, not an object.
    pub max_area: f32,
    /// Re-detection searches the last box grown by this factor per frame lost (capped at the
    /// whole image), with a grid of point prompts.
    pub search_growth: f32,
}

impl Default for TrackConfig {
    fn default() -> Self {
        Self {
            box_margin: 0.15,
            positive_points: 3,
            negative_points: 4,
            max_area_change: 2.5,
            min_appearance: 0.6,
            min_pred_iou: 0.5,
            max_area: 0.5,
            search_growth: 1.0,
        }
    }
}

/// Mask components under this fraction of the largest are dropped (`Region::without_islands`).
const ISLAND_FRACTION: f32 = 0.2;

/// The object as last seen.
#[derive(Debug, Clone)]
struct Sighting {
    region: Region,
    bbox: PixelBox,
    area: usize,
    centroid: (f32, f32),
    hist: Histogram,
    frame: usize,
}

impl Sighting {
    fn new(region: Region, rgb: &[u8], frame: usize) -> Option<Self> {
        Some(Self {
            bbox: region.bbox()?,
            area: region.area(),
            centroid: region.centroid()?,
            hist: region.histogram(rgb),
            region,
            frame,
        })
    }
}

/// A mask the object may be in this frame.
struct Candidate {
    logits: Vec<f32>,
    region: Region,
    pred_iou: f32,
    appearance: f32,
}

/// What a frame gave for one object.
pub struct Found {
    pub logits: Vec<f32>,
    pub region: Region,
}

/// One tracked object.
pub struct ObjectTrack {
    pub name: String,
    template: Histogram,
    last: Sighting,
    /// Centroid displacement per frame between the last two sightings.
    velocity: (f32, f32),
    /// Frames in a row the object has not been found (0 while it is tracked).
    streak: usize,
    /// Frames (indices in processing order's numbering) where the object was not found.
    pub lost_frames: Vec<usize>,
    /// Frames where the propagated prompt failed and re-detection found the object.
    pub recovered_frames: Vec<usize>,
}

impl ObjectTrack {
    /// Start from the object's mask on its seed frame; `None` for an empty mask.
    pub fn start(name: &str, region: Region, rgb: &[u8], frame: usize) -> Option<Self> {
        let last = Sighting::new(region, rgb, frame)?;
        Some(Self {
            name: name.to_string(),
            template: last.hist,
            last,
            velocity: (0.0, 0.0),
            streak: 0,
            lost_frames: Vec::new(),
            recovered_frames: Vec::new(),
        })
    }

    /// Find the object in `frame` (embedded in `pred`, pixels `rgb`).
    pub fn step(
        &mut self,
        pred: &Predictor,
        rgb: &[u8],
        frame: usize,
        cfg: &TrackConfig,
        sc: &mut Scratch,
    ) -> Option<Found> {
        let gap = frame.abs_diff(self.last.frame).max(1) as f32;
        let motion = (self.velocity.0 * gap, self.velocity.1 * gap);
        let found = if self.streak > 0 {
            None
        } else {
            self.propagate(pred, rgb, motion, cfg, sc)
        };
        let found = match found {
            Some(c) => Some(c),
            None => {
                let c = self.redetect(pred, rgb, motion, cfg, sc);
                if c.is_some() {
                    self.recovered_frames.push(frame);
                }
                c
            }
        };
        let Some(c) = found else {
            self.streak += 1;
            self.lost_frames.push(frame);
            return None;
        };
        let seen =
            Sighting::new(c.region.clone(), rgb, frame).expect("plausible masks are non-empty");
        self.velocity = (
            (seen.centroid.0 - self.last.centroid.0) / gap,
            (seen.centroid.1 - self.last.centroid.1) / gap,
        );
        // After a loss the displacement spans the gap and says little: start from rest.
        if self.streak > 0 {
            self.velocity = (0.0, 0.0);
        }
        self.last = seen;
        self.streak = 0;
        Some(Found {
            logits: c.logits,
            region: c.region,
        })
    }

    fn candidate(&self, p: Prediction, rgb: &[u8], (h, w): (usize, usize)) -> Candidate {
        let region = Region::from_logits(w, h, &p.logits).without_islands(ISLAND_FRACTION);
        let hist = region.histogram(rgb);
        let appearance = hist
            .similarity(&self.template)
            .max(hist.similarity(&self.last.hist));
        Candidate {
            logits: p.logits,
            region,
            pred_iou: p.pred_iou,
            appearance,
        }
    }

    /// Whether a mask can be the object: its size close to the last sighting's, its colours
    /// like the object's, SAM confident in it, and not the background.
    fn plausible(&self, c: &Candidate, cfg: &TrackConfig) -> bool {
        let area = c.region.area();
        if area == 0 {
            return false;
        }
        let change = area as f32 / self.last.area as f32;
        change <= cfg.max_area_change
            && change >= 1.0 / cfg.max_area_change
            && c.appearance >= cfg.min_appearance
            && c.pred_iou >= cfg.min_pred_iou
            && !super::seed::is_background(&c.region, cfg.max_area)
    }

    fn predict_one(
        &self,
        pred: &Predictor,
        rgb: &[u8],
        prompt: &Prompt,
        sc: &mut Scratch,
    ) -> Candidate {
        let p = pred.predict(prompt, Outputs::Single, sc).remove(0);
        self.candidate(p, rgb, pred.size())
    }

    /// The previous mask's box and deepest point, moved by the expected motion.
    fn propagate(
        &self,
        pred: &Predictor,
        rgb: &[u8],
        motion: (f32, f32),
        cfg: &TrackConfig,
        sc: &mut Scratch,
    ) -> Option<Candidate> {
        let (h, w) = pred.size();
        let moved = shift_box(self.last.bbox, motion, w, h);
        let bbox = grow_box(moved, cfg.box_margin, 2.0, w, h);
        let inside = |x: f32, y: f32| x >= bbox[0] && x <= bbox[2] && y >= bbox[1] && y <= bbox[3];
        let points = self
            .last
            .region
            .interior_points(1, 2)
            .into_iter()
            .map(|(x, y)| (x + motion.0, y + motion.1, true))
            .filter(|&(x, y, _)| inside(x, y))
            .collect();
        let first = self.predict_one(
            pred,
            rgb,
            &Prompt {
                points,
                bbox: Some(bbox),
            },
            sc,
        );
        self.plausible(&first, cfg).then_some(())?;
        let reference = self.last.region.shifted(motion);
        Some(self.refine(pred, rgb, first, Some(&reference), cfg, sc))
    }

    /// A second prompt from the mask just found: its tight box, points inside, background
    /// points around. Its single mask and its three multimask outputs join the first mask
    /// as candidates; with a `reference` (the previous mask moved by the expected motion)
    /// the plausible one most like it wins, else the single refined mask when plausible.
    /// Why: a box that takes in the object's shadow yields a confident mask of object and
    /// shadow (predicted IoU 0.98 for IoU 0.78 against the ground truth, toycars scene2's
    /// moving sedan), which would then widen every later box; one of the multimask outputs
    /// is the object alone, and it is the one most like the previous frame's mask.
    fn refine(
        &self,
        pred: &Predictor,
        rgb: &[u8],
        c: Candidate,
        reference: Option<&Region>,
        cfg: &TrackConfig,
        sc: &mut Scratch,
    ) -> Candidate {
        let (h, w) = pred.size();
        let Some(b) = c.region.bbox() else {
            return c;
        };
        let size = (b[2] - b[0] + 1).max(b[3] - b[1] + 1) as f32;
        let mut points: Vec<(f32, f32, bool)> = c
            .region
            .interior_points(cfg.positive_points, 2)
            .into_iter()
            .map(|(x, y)| (x, y, true))
            .collect();
        points.extend(
            c.region
                .points_around(b, (0.1 * size).max(3.0), cfg.negative_points)
                .into_iter()
                .map(|(x, y)| (x, y, false)),
        );
        let prompt = Prompt {
            points,
            bbox: Some(grow_box(b, 0.0, 1.0, w, h)),
        };
        let second = self.predict_one(pred, rgb, &prompt, sc);
        let Some(reference) = reference else {
            return if self.plausible(&second, cfg) {
                second
            } else {
                c
            };
        };
        let mut cands = vec![c, second];
        cands.extend(
            pred.predict(&prompt, Outputs::Multimask, sc)
                .into_iter()
                .map(|p| self.candidate(p, rgb, (h, w))),
        );
        let score = |c: &Candidate| c.region.iou(reference);
        // The first mask is plausible (the caller checked), so something always qualifies.
        let best = cands
            .iter()
            .enumerate()
            .filter(|(_, c)| self.plausible(c, cfg))
            .max_by(|a, b| score(a.1).total_cmp(&score(b.1)))
            .map_or(0, |(i, _)| i);
        cands.swap_remove(best)
    }

    /// Search around where the object was last seen (wider for every frame it has been lost)
    /// with a grid of point prompts; the most confident plausible mask wins.
    fn redetect(
        &self,
        pred: &Predictor,
        rgb: &[u8],
        motion: (f32, f32),
        cfg: &TrackConfig,
        sc: &mut Scratch,
    ) -> Option<Candidate> {
        let (h, w) = pred.size();
        let lost_for = self.streak.min(64) as f32 + 1.0;
        let moved = shift_box(self.last.bbox, motion, w, h);
        let window = grow_box(moved, cfg.search_growth * lost_for, 2.0, w, h);
        // Grid spacing at most half the object's smaller side, 4…12 points per axis.
        let obj = (self.last.bbox[2] - self.last.bbox[0] + 1)
            .min(self.last.bbox[3] - self.last.bbox[1] + 1) as f32;
        let n_axis = |len: f32| ((len / (0.5 * obj).max(1.0)).ceil() as usize).clamp(4, 12);
        let (nx, ny) = (n_axis(window[2] - window[0]), n_axis(window[3] - window[1]));
        let mut best: Option<Candidate> = None;
        for j in 0..ny {
            for i in 0..nx {
                let x = window[0] + (i as f32 + 0.5) / nx as f32 * (window[2] - window[0]);
                let y = window[1] + (j as f32 + 0.5) / ny as f32 * (window[3] - window[1]);
                let prompt = Prompt {
                    points: vec![(x, y, true)],
                    bbox: None,
                };
                for p in pred.predict_above(&prompt, Outputs::Multimask, cfg.min_pred_iou, sc) {
                    let c = self.candidate(p, rgb, (h, w));
                    let score = c.appearance * c.pred_iou;
                    let better = best
                        .as_ref()
                        .is_none_or(|b| score > b.appearance * b.pred_iou);
                    if better && self.plausible(&c, cfg) {
                        best = Some(c);
                    }
                }
            }
        }
        let best = best?;
        Some(self.refine(pred, rgb, best, None, cfg, sc))
    }
}
