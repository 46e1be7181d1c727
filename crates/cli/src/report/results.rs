//! The `DIR/results.json` model of `semdynreg compare`.
//!
//! The keys are a fixed contract (what a reader of the file may rely on); every one of them
//! is always present (a number, or `null` where it cannot be measured, with the reason in
//! `notes`). `Option` fields are
//! therefore never skipped during serialization. A method that was not compared (no
//! `--rigid-renders` when scoring renders only) has no key at all, and is not in `methods`.

use super::methods::MethodName;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// PSNR (dB), SSIM and LPIPS of one comparison. `None` is written as `null`: LPIPS when
/// its weights are absent; PSNR when it is not finite (identical crops); any metric when
/// no frame could be scored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub lpips: Option<f64>,
}

/// Scores of one crop at one of the paper's time steps (t = 0, 1, …, 5 s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimedScores {
    pub t_seconds: u32,
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    pub lpips: Option<f64>,
    /// The evaluation frame nearest to `t_seconds` (its `file_path`) and its time in [0, 1].
    pub frame: String,
    pub time: f32,
    /// The padded crop box `[x, y, width, height]` in pixels; `None` when the object is not
    /// visible in that frame's ground-truth mask (the scores are then `null`).
    pub crop: Option<[u32; 4]>,
}

impl TimedScores {
    pub fn scores(&self) -> Scores {
        Scores {
            psnr: self.psnr,
            ssim: self.ssim,
            lpips: self.lpips,
        }
    }
}

/// Crop scores of one object across the time steps, and their mean.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CropSeries {
    pub per_time: Vec<TimedScores>,
    pub mean: Scores,
}

/// Everything measured for one method's run. New fields take `#[serde(default)]`, so
/// that older files still read.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MethodResults {
    /// Mean over all evaluation frames of the per-frame scores.
    pub full_frame: Scores,
    /// The first moving object's crop (the paper's Tables 1 and 2), kept for the readers
    /// of scenes with one moving object; the same series is in `moving_object_crops`.
    pub moving_object_crop: CropSeries,
    /// One entry per moving object, keyed by its name in `objects.json`.
    #[serde(default)]
    pub moving_object_crops: BTreeMap<String, CropSeries>,
    /// One entry per static object, keyed by its name in `objects.json`.
    pub static_object_crops: BTreeMap<String, CropSeries>,
    /// RMS distance (world units) between the object Gaussians' deformed positions and their
    /// positions under the ground-truth rigid motion, averaged over test times; lower is
    /// better. `null` when not computed (see `notes`).
    pub deformation_consistency_rms: Option<f64>,
    /// The same per vehicle (keyed by its name in `objects.json`): the moving vehicle's
    /// value is the one the regularizer is meant to lower. Empty when not computed.
    #[serde(default)]
    pub deformation_consistency_per_object: BTreeMap<String, f64>,
    /// Per moving vehicle, `1 − rms / rms_if_still`: how much of the vehicle's true motion
    /// its Gaussians follow (1 = rigidly with it; 0 = no better than not moving at all;
    /// `train::regularizer::consistency`). Vehicles that do not move have no entry.
    #[serde(default)]
    pub deformation_follow_per_object: BTreeMap<String, f64>,
    /// Rigidity residual (world units, lower is better; `train::regularizer::rigidity`): per
    /// test time, the RMS residual of the best rigid fit from the vehicle Gaussians'
    /// positions at the reference time to their positions then, pooled over the vehicles,
    /// averaged over test times. Whether they move *together* (a flip-book that stands
    /// still scores 0 too; `deformation_follow_per_object` says whether they move *with*
    /// the vehicle). `null` when not computed (see `notes`).
    #[serde(default)]
    pub rigidity_rms: Option<f64>,
    /// The same per vehicle (keyed by its name in `objects.json`). Empty when not computed.
    #[serde(default)]
    pub rigidity_rms_per_object: BTreeMap<String, f64>,
    /// Runs with rigid objects (docs/objects.md, "What follows and what does not"): per
    /// vehicle, the share of its group (the Gaussians drawn inside its mask) that belongs
    /// to its own node, and how much of its motion those follow. Empty for other runs.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub node_share_per_object: BTreeMap<String, f64>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub follow_in_node_per_object: BTreeMap<String, f64>,
    /// Runs with rigid objects: what the objects' start decided for each object, `static`
    /// (one pose), `moving`, or `field` (left to the deformation field).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub rigid_decision_per_object: BTreeMap<String, String>,
    /// Runs with rigid objects: per mover, the confidence of the gauge its start chose
    /// (`objects::scale`, 0–1).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub scale_confidence_per_object: BTreeMap<String, f64>,
    /// Scenes with articulated objects: the motion each moving part's Gaussians follow,
    /// keyed `object/part` (`report::parts`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub follow_per_part: BTreeMap<String, f64>,
    /// Where the rendered frames came from.
    pub renders: String,
}

/// How the numbers were produced, so that a reader can reproduce them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Protocol {
    /// The data split whose frames are scored (`test`).
    pub split: String,
    /// Seconds spanned by time 0 → 1 (toycars: 6 s).
    pub duration_s: f32,
    /// The time steps of the crop tables, in seconds.
    pub t_seconds: Vec<u32>,
    /// Human-readable crop policy (padding, clamping).
    pub crop_policy: String,
    /// Which SSIM variant and which LPIPS network (or why LPIPS is absent).
    pub ssim_variant: String,
    pub lpips: String,
    /// Name of the first moving object, from `objects.json` (empty when none moves).
    pub moving_object: String,
    /// Names of every moving object, in `objects.json` order.
    #[serde(default)]
    pub moving_objects: Vec<String>,
}

/// The whole `results.json`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Results {
    /// The methods compared, in display order.
    pub methods: Vec<MethodName>,
    /// Each method's results as a top-level key (`baseline`, `semdynreg`, `rigid`), where
    /// the readers of the two-method files find them.
    #[serde(flatten)]
    pub by_method: BTreeMap<String, MethodResults>,
    pub scene: String,
    /// The command lines that produced the runs and this evaluation.
    pub commands: Vec<String>,
    /// The resolved configuration of each run (as read from the run), or `null`.
    pub config: BTreeMap<String, serde_json::Value>,
    pub protocol: Protocol,
    /// Caveats (missing LPIPS weights, missing consistency metric, …).
    pub notes: Vec<String>,
}

impl Results {
    /// Each compared method's display name and results, in display order.
    pub fn ordered(&self) -> impl Iterator<Item = (&str, &MethodResults)> {
        self.methods
            .iter()
            .filter_map(|m| Some((m.name.as_str(), self.by_method.get(&m.key)?)))
    }
}

/// Mean of the present values of one metric; `None` when none is present.
pub fn mean_of(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let (sum, n) = values
        .flatten()
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// Element-wise mean of a set of scores (each metric over the entries where it is present).
pub fn mean_scores(items: &[Scores]) -> Scores {
    Scores {
        psnr: mean_of(items.iter().map(|s| s.psnr)),
        ssim: mean_of(items.iter().map(|s| s.ssim)),
        lpips: mean_of(items.iter().map(|s| s.lpips)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_skips_missing_values() {
        let s = [
            Scores {
                psnr: Some(20.0),
                ssim: Some(0.5),
                lpips: None,
            },
            Scores {
                psnr: Some(30.0),
                ssim: None,
                lpips: None,
            },
        ];
        let m = mean_scores(&s);
        assert_eq!(m.psnr, Some(25.0));
        assert_eq!(m.ssim, Some(0.5));
        assert_eq!(m.lpips, None);
    }

    #[test]
    fn null_fields_are_written_not_skipped() {
        let json = serde_json::to_value(MethodResults::default()).unwrap();
        assert!(json["full_frame"].get("lpips").unwrap().is_null());
        assert!(json.get("deformation_consistency_rms").unwrap().is_null());
        assert!(json["moving_object_crop"]["per_time"].is_array());
    }

    #[test]
    fn methods_are_top_level_keys_and_round_trip() {
        let mut r = Results::default();
        for key in ["baseline", "semdynreg"] {
            r.methods.push(MethodName {
                key: key.into(),
                name: key.to_uppercase(),
            });
            r.by_method.insert(key.into(), MethodResults::default());
        }
        let json = serde_json::to_value(&r).unwrap();
        assert!(json["baseline"]["full_frame"].is_object());
        assert!(json["semdynreg"]["moving_object_crops"].is_object());
        assert!(json.get("rigid").is_none(), "not compared: no key");
        assert_eq!(json["methods"][1]["name"], "SEMDYNREG");
        let back: Results = serde_json::from_value(json).unwrap();
        assert_eq!(back, r);
        let names: Vec<&str> = back.ordered().map(|(n, _)| n).collect();
        assert_eq!(names, ["BASELINE", "SEMDYNREG"]);
    }
}
