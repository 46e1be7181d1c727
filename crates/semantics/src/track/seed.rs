//! How objects are chosen once: a click (`NAME@x,y`), a box (`NAME@x0,y0,x1,y1`), either on
//! another frame (`…@FRAME`), or a mask (the automatic generator's, `auto.rs`); and the check
//! that a click or box selects an object rather than the background.

use serde::Serialize;

use super::region::Region;
use super::TrackError;
use crate::automask::stability_score;
use crate::sam::{Outputs, Prediction, Predictor, Prompt, Scratch};

/// Least stability score of the mask a click selects (see `Seed::resolve`).
pub(crate) const MIN_SEED_STABILITY: f32 = 0.7;

/// Where the object is shown, in original-image pixels.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SeedShape {
    Point([f32; 2]),
    Box([f32; 4]),
    /// A mask given directly (automatic seeds); not serialized pixel by pixel.
    #[serde(skip)]
    Mask(Region),
}

/// A frame named on the command line: an index into the time-ordered frames, or a
/// `file_path` such as `train/r_005`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum FrameRef {
    Index(usize),
    Path(String),
}

/// One object to track.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Seed {
    pub name: String,
    pub shape: SeedShape,
    /// `None`: the first frame in time order.
    pub frame: Option<FrameRef>,
}

fn bad(spec: &str, why: &str) -> TrackError {
    TrackError::Prompt(format!("`{spec}`: {why}"))
}

fn numbers(spec: &str, text: &str) -> Result<Vec<f32>, TrackError> {
    text.split(',')
        .map(|v| {
            v.trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(spec, &format!("`{v}` is not a number")))
        })
        .collect()
}

fn frame_ref(text: &str) -> FrameRef {
    match text.trim().parse::<usize>() {
        Ok(i) => FrameRef::Index(i),
        Err(_) => FrameRef::Path(text.trim().to_string()),
    }
}

impl Seed {
    /// Parse `NAME@x,y[@FRAME]` (`boxed` false) or `NAME@x0,y0,x1,y1[@FRAME]` (`boxed` true).
    pub fn parse(spec: &str, boxed: bool) -> Result<Self, TrackError> {
        let form = if boxed {
            "NAME@x0,y0,x1,y1[@FRAME]"
        } else {
            "NAME@x,y[@FRAME]"
        };
        let parts: Vec<&str> = spec.split('@').collect();
        if !(2..=3).contains(&parts.len()) {
            return Err(bad(spec, &format!("expected {form}")));
        }
        let name = parts[0].trim();
        if name.is_empty() {
            return Err(bad(spec, &format!("the object needs a name ({form})")));
        }
        let v = numbers(spec, parts[1])?;
        let shape = match (boxed, v.as_slice()) {
            (false, &[x, y]) => SeedShape::Point([x, y]),
            (true, &[x0, y0, x1, y1]) if x1 > x0 && y1 > y0 => SeedShape::Box([x0, y0, x1, y1]),
            (true, &[_, _, _, _]) => return Err(bad(spec, "the box needs x1 > x0 and y1 > y0")),
            _ => return Err(bad(spec, &format!("expected {form}"))),
        };
        Ok(Self {
            name: name.to_string(),
            shape,
            frame: parts.get(2).map(|f| frame_ref(f)),
        })
    }

    /// Where the prompt points (a click, a box's centre); none for a mask.
    pub fn anchor(&self) -> Option<[f32; 2]> {
        match &self.shape {
            SeedShape::Point(p) => Some(*p),
            SeedShape::Box([x0, y0, x1, y1]) => Some([(x0 + x1) / 2.0, (y0 + y1) / 2.0]),
            SeedShape::Mask(_) => None,
        }
    }

    /// The object's mask on its seed frame: the largest stable one of SAM's three nested
    /// masks for a click that holds none of `others` (the other objects' clicks on this
    /// frame), the single mask for a box. Refused when the prompt lies outside the image,
    /// selects nothing, or selects the background (over `max_area` of the image, or
    /// touching three or more of its sides).
    pub fn resolve(
        &self,
        pred: &Predictor,
        frame_name: &str,
        max_area: f32,
        others: &[[f32; 2]],
    ) -> Result<Region, TrackError> {
        let (h, w) = pred.size();
        let inside = |x: f32, y: f32| x >= 0.0 && y >= 0.0 && x < w as f32 && y < h as f32;
        let fail =
            |why: String| TrackError::Prompt(format!("{}: {why}", self.describe(frame_name)));
        let mut sc = Scratch::default();
        let region = match &self.shape {
            SeedShape::Mask(r) => r.clone(),
            SeedShape::Point([x, y]) => {
                if !inside(*x, *y) {
                    return Err(fail(format!("the point is outside the {w}×{h} image")));
                }
                let prompt = Prompt {
                    points: vec![(*x, *y, true)],
                    bbox: None,
                };
                // SAM's three outputs for a click are nested (subpart, part, whole); a click
                // names an object, so take the largest whose boundary is stable (stability
                // score, SAM's logits thresholded at ±1, ≥ MIN_SEED_STABILITY), else the
                // most confident. The most confident alone often names a part (the green
                // SUV's roof on toycars scene1 at 480×360: IoU 0.07, the whole 0.97); the
                // largest alone can merge two cars at 160×120 (stability 0.13–0.24 there,
                // 0.76–0.97 for the single vehicles), and even a stable one can when the
                // cars touch in the image (toycars scene2 at frame 62: the green SUV's
                // click took it and the white SUV in front, stability 0.97), so a mask that
                // holds another object's click is not this object's.
                let preds = pred.predict(&prompt, Outputs::Multimask, &mut sc);
                let stable =
                    |p: &&Prediction| stability_score(&p.logits, 0.0, 1.0) >= MIN_SEED_STABILITY;
                let alone = |p: &&Prediction| {
                    others.iter().all(|&[x, y]| {
                        let (i, j) = (y as usize, x as usize);
                        !(i < h && j < w && p.logits[i * w + j] > 0.0)
                    })
                };
                let chosen = preds
                    .iter()
                    .filter(stable)
                    .filter(alone)
                    .max_by_key(|p| p.logits.iter().filter(|&&v| v > 0.0).count())
                    .or_else(|| {
                        preds
                            .iter()
                            .max_by(|a, b| a.pred_iou.total_cmp(&b.pred_iou))
                    })
                    .expect("three outputs");
                Region::from_logits(w, h, &chosen.logits)
            }
            SeedShape::Box(b) => {
                if !inside(b[0], b[1]) || !inside(b[2], b[3]) {
                    return Err(fail(format!("the box leaves the {w}×{h} image")));
                }
                let prompt = Prompt {
                    points: Vec::new(),
                    bbox: Some(*b),
                };
                let preds = pred.predict(&prompt, Outputs::Single, &mut sc);
                Region::from_logits(w, h, &preds[0].logits)
            }
        };
        let area = region.area();
        if area == 0 {
            return Err(fail("SAM finds no object there".into()));
        }
        let frac = area as f32 / (w * h) as f32;
        let sides = region.borders_touched();
        if is_background(&region, max_area) {
            return Err(fail(format!(
                "this selects the background, not an object (the mask covers {:.0} % of the image \
                 and touches {sides} of its sides): click the object itself, or give a box \
                 around it (--box)",
                100.0 * frac
            )));
        }
        Ok(region)
    }

    /// `"white SUV" (click at 120,80 on train/r_000)`.
    pub fn describe(&self, frame_name: &str) -> String {
        let what = match &self.shape {
            SeedShape::Point([x, y]) => format!("click at {x},{y}"),
            SeedShape::Box([a, b, c, d]) => format!("box {a},{b},{c},{d}"),
            SeedShape::Mask(_) => "automatic mask".into(),
        };
        format!("\"{}\" ({what} on {frame_name})", self.name)
    }
}

/// A mask over `max_area` of the image, or touching three or more of its sides, is
/// background (ground, sky, a wall), not an object.
pub fn is_background(region: &Region, max_area: f32) -> bool {
    let frac = region.area() as f32 / (region.width * region.height) as f32;
    frac > max_area || region.borders_touched() >= 3
}

/// The index in `names` (time-ordered frame names) of a seed's frame.
pub fn frame_index(seed: &Seed, names: &[String]) -> Result<usize, TrackError> {
    match &seed.frame {
        None => Ok(0),
        Some(FrameRef::Index(i)) if *i < names.len() => Ok(*i),
        Some(FrameRef::Index(i)) => Err(TrackError::Prompt(format!(
            "\"{}\": frame {i} does not exist (the scene has {} frames, 0…{})",
            seed.name,
            names.len(),
            names.len().saturating_sub(1)
        ))),
        Some(FrameRef::Path(p)) => names.iter().position(|n| n == p).ok_or_else(|| {
            TrackError::Prompt(format!(
                "\"{}\": no frame is called `{p}` (frames are named like `{}`)",
                seed.name,
                names.first().map_or("", String::as_str)
            ))
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_clicks_boxes_and_frames() {
        let s = Seed::parse("white SUV@120,80.5", false).unwrap();
        assert_eq!(s.name, "white SUV");
        assert_eq!(s.shape, SeedShape::Point([120.0, 80.5]));
        assert_eq!(s.frame, None);
        let s = Seed::parse("car@1,2,30,40@train/r_004", true).unwrap();
        assert_eq!(s.shape, SeedShape::Box([1.0, 2.0, 30.0, 40.0]));
        assert_eq!(s.frame, Some(FrameRef::Path("train/r_004".into())));
        let s = Seed::parse("car@1,2@7", false).unwrap();
        assert_eq!(s.frame, Some(FrameRef::Index(7)));
    }

    #[test]
    fn refuses_malformed_specs_naming_them() {
        for (spec, boxed, needle) in [
            ("car", false, "expected NAME@x,y"),
            ("@1,2", false, "needs a name"),
            ("car@1", false, "expected NAME@x,y"),
            ("car@1,x", false, "`x` is not a number"),
            ("car@1,2,3,4", false, "expected NAME@x,y"),
            ("car@5,5,1,9", true, "x1 > x0"),
            ("car@1,2@3@4", false, "expected"),
            ("car@nan,2", false, "not a number"),
        ] {
            let e = Seed::parse(spec, boxed).unwrap_err().to_string();
            assert!(e.contains(needle) && e.contains(spec), "{spec}: {e}");
        }
    }

    #[test]
    fn frame_index_by_number_or_name() {
        let names: Vec<String> = ["train/a", "val/b", "train/c"].map(String::from).to_vec();
        let mut s = Seed::parse("o@1,1", false).unwrap();
        assert_eq!(frame_index(&s, &names).unwrap(), 0);
        s.frame = Some(FrameRef::Path("val/b".into()));
        assert_eq!(frame_index(&s, &names).unwrap(), 1);
        s.frame = Some(FrameRef::Index(3));
        assert!(frame_index(&s, &names)
            .unwrap_err()
            .to_string()
            .contains("0…2"));
        s.frame = Some(FrameRef::Path("test/x".into()));
        assert!(frame_index(&s, &names)
            .unwrap_err()
            .to_string()
            .contains("train/a"));
    }
}
