//! Scores one run's rendered frames against the ground truth: full-frame means over every
//! evaluation frame, and per-object crops at the paper's time steps (see `crops.rs` for
//! which frames and pixels).

use super::crops::{nearest_frames, CropPolicy};
use super::images::{crop, load_rgb};
use super::results::{mean_scores, CropSeries, MethodResults, Scores, TimedScores};
use anyhow::{bail, ensure, Context, Result};
use image::RgbImage;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Computes the three metrics for an image pair (ground truth first).
pub trait Scorer {
    fn score(&mut self, gt: &RgbImage, render: &RgbImage) -> Result<Scores>;
}

/// One ground-truth evaluation frame.
pub struct EvalFrame {
    pub file_path: String,
    pub time: f32,
    pub gt: RgbImage,
    /// Instance mask (`H·W`, 255 = background) for the object crops: the ground truth
    /// when the scene has one, else a tracked object-ID map (see [`EvalSet::masks`]).
    pub mask: Option<Vec<u8>>,
}

/// One object of `objects.json`.
#[derive(Clone, Debug)]
pub struct ObjectSpec {
    pub id: u8,
    pub name: String,
    pub moving: bool,
}

/// The frames, objects and protocol shared by every method.
pub struct EvalSet {
    pub frames: Vec<EvalFrame>,
    pub objects: Vec<ObjectSpec>,
    pub duration_s: f32,
    pub t_seconds: Vec<u32>,
    pub policy: CropPolicy,
    /// Where the frames' masks come from.
    pub masks: MaskSource,
}

/// Where the object crops' masks come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaskSource {
    /// `masks/` and `objects.json` (generated scenes).
    GroundTruth,
    /// The held-out frames' tracked object-ID maps (`segment --track`): a real capture
    /// has no ground truth, so the crops are as good as the tracking.
    Tracked,
    /// Neither: no object crops.
    Absent,
}

impl MaskSource {
    /// The masks' name in the protocol's crop description.
    pub fn label(self) -> &'static str {
        match self {
            Self::GroundTruth => "ground-truth mask",
            Self::Tracked => "tracked object-ID map (segment --track, no ground truth)",
            Self::Absent => "mask (none available)",
        }
    }
}

impl EvalSet {
    /// Index into `frames` of the frame used for each entry of `t_seconds`.
    pub fn picked_frames(&self) -> Result<Vec<usize>> {
        let times: Vec<f32> = self.frames.iter().map(|f| f.time).collect();
        nearest_frames(&times, &self.t_seconds, self.duration_s)
            .context("the evaluation split has no frames")
    }

    /// The first moving object (the one `moving_object_crop` and the figure's zooms show).
    pub fn moving_object(&self) -> Option<&ObjectSpec> {
        self.moving_objects().next()
    }

    /// Every moving object, in `objects.json` order.
    pub fn moving_objects(&self) -> impl Iterator<Item = &ObjectSpec> {
        self.objects.iter().filter(|o| o.moving)
    }
}

/// A folder of rendered PNGs, one per frame of the evaluation split, named after the
/// frame's `file_path` (`DIR/test/r_000.png`), its last component (`DIR/r_000.png`), or
/// its index in the split (`DIR/0000.png`, what `semdynreg render` writes).
pub struct RenderDir(pub PathBuf);

impl RenderDir {
    pub fn path_for(&self, file_path: &str, index: usize) -> Result<PathBuf> {
        let stem = file_path.trim_end_matches(".png");
        let name = Path::new(stem).file_name().unwrap_or_default();
        let candidates = [
            self.0.join(format!("{stem}.png")),
            self.0.join(name).with_extension("png"),
            self.0.join(format!("{index:04}.png")),
        ];
        match candidates.iter().find(|p| p.is_file()) {
            Some(p) => Ok(p.clone()),
            None => bail!(
                "no rendered image for frame {file_path} in {} (looked for {}, {} and {})",
                self.0.display(),
                candidates[0].display(),
                candidates[1].display(),
                candidates[2].display()
            ),
        }
    }

    /// Loads the render of a frame and checks it matches the ground truth's size.
    pub fn load(&self, frame: &EvalFrame, index: usize) -> Result<RgbImage> {
        let path = self.path_for(&frame.file_path, index)?;
        let img = load_rgb(&path)?;
        ensure!(
            img.dimensions() == frame.gt.dimensions(),
            "{} is {}×{} but the ground truth of {} is {}×{}",
            path.display(),
            img.width(),
            img.height(),
            frame.file_path,
            frame.gt.width(),
            frame.gt.height()
        );
        Ok(img)
    }
}

/// The scores of one run plus the renders of the picked frames (for the figures).
pub struct RunEval {
    pub results: MethodResults,
    /// Render of `frames[picked[i]]` for each time step i.
    pub picked_renders: Vec<RgbImage>,
}

/// Scores every frame of `set` against `renders`; `progress(done, total)` after each frame.
pub fn evaluate_run(
    set: &EvalSet,
    renders: &RenderDir,
    scorer: &mut dyn Scorer,
    progress: &dyn Fn(usize, usize),
) -> Result<RunEval> {
    let picked = set.picked_frames()?;
    let mut kept: BTreeMap<usize, RgbImage> = BTreeMap::new();
    let mut full = Vec::with_capacity(set.frames.len());
    for (i, frame) in set.frames.iter().enumerate() {
        let render = renders.load(frame, i)?;
        full.push(
            scorer
                .score(&frame.gt, &render)
                .with_context(|| format!("scoring frame {}", frame.file_path))?,
        );
        if picked.contains(&i) {
            kept.insert(i, render);
        }
        progress(i + 1, set.frames.len());
    }
    let picked_renders: Vec<RgbImage> = picked.iter().map(|i| kept[i].clone()).collect();
    let mut static_object_crops = BTreeMap::new();
    let mut moving_object_crops = BTreeMap::new();
    for object in &set.objects {
        let series = crop_series(set, &picked, &picked_renders, object, scorer)?;
        let crops = if object.moving {
            &mut moving_object_crops
        } else {
            &mut static_object_crops
        };
        crops.insert(object.name.clone(), series);
    }
    let moving_object_crop = set
        .moving_object()
        .map(|o| moving_object_crops[&o.name].clone())
        .unwrap_or_default();
    let results = MethodResults {
        full_frame: mean_scores(&full),
        moving_object_crop,
        moving_object_crops,
        static_object_crops,
        deformation_consistency_rms: None,
        deformation_consistency_per_object: Default::default(),
        deformation_follow_per_object: Default::default(),
        rigidity_rms: None,
        rigidity_rms_per_object: Default::default(),
        node_share_per_object: Default::default(),
        follow_in_node_per_object: Default::default(),
        rigid_decision_per_object: Default::default(),
        scale_confidence_per_object: Default::default(),
        follow_per_part: Default::default(),
        renders: renders.0.display().to_string(),
    };
    Ok(RunEval {
        results,
        picked_renders,
    })
}

/// Crop scores of one object at each picked frame.
fn crop_series(
    set: &EvalSet,
    picked: &[usize],
    renders: &[RgbImage],
    object: &ObjectSpec,
    scorer: &mut dyn Scorer,
) -> Result<CropSeries> {
    let mut per_time = Vec::with_capacity(picked.len());
    for ((&t, &i), render) in set.t_seconds.iter().zip(picked).zip(renders) {
        let frame = &set.frames[i];
        let (w, h) = frame.gt.dimensions();
        let bbox = frame
            .mask
            .as_ref()
            .and_then(|m| set.policy.object_crop(m, w, h, object.id));
        let scores = match bbox {
            Some(b) => scorer
                .score(&crop(&frame.gt, b), &crop(render, b))
                .with_context(|| {
                    format!("scoring the {} crop of {}", object.name, frame.file_path)
                })?,
            None => Scores::default(),
        };
        per_time.push(TimedScores {
            t_seconds: t,
            psnr: scores.psnr,
            ssim: scores.ssim,
            lpips: scores.lpips,
            frame: frame.file_path.clone(),
            time: frame.time,
            crop: bbox.map(|b| b.to_array()),
        });
    }
    let mean = mean_scores(&per_time.iter().map(TimedScores::scores).collect::<Vec<_>>());
    Ok(CropSeries { per_time, mean })
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    /// Scores by mean absolute difference and records every pair's size.
    #[derive(Default)]
    struct RecordingScorer {
        sizes: Vec<(u32, u32)>,
    }

    impl Scorer for RecordingScorer {
        fn score(&mut self, gt: &RgbImage, render: &RgbImage) -> Result<Scores> {
            self.sizes.push(gt.dimensions());
            let diff: f64 = gt
                .as_raw()
                .iter()
                .zip(render.as_raw())
                .map(|(&a, &b)| (a as f64 - b as f64).abs())
                .sum::<f64>()
                / gt.as_raw().len() as f64;
            Ok(Scores {
                psnr: Some(diff),
                ssim: None,
                lpips: None,
            })
        }
    }

    /// 6 frames (t = 0..5 s of 6 s) of 64×48; object 0 moves right 4 px per frame,
    /// object 1 stays. The render differs from the ground truth only on object 0.
    fn synthetic_set(dir: &Path) -> EvalSet {
        let (w, h) = (64u32, 48u32);
        let mut frames = Vec::new();
        std::fs::create_dir_all(dir.join("test")).unwrap();
        for f in 0..6u32 {
            let mut mask = vec![255u8; (w * h) as usize];
            let mut gt = RgbImage::from_pixel(w, h, Rgb([10, 10, 10]));
            let mut render = gt.clone();
            for y in 10..18 {
                for x in 4 + 4 * f..12 + 4 * f {
                    mask[(y * w + x) as usize] = 0;
                    gt.put_pixel(x, y, Rgb([200, 200, 200]));
                    render.put_pixel(x, y, Rgb([100, 200, 200]));
                }
            }
            for y in 30..40 {
                for x in 40..50 {
                    mask[(y * w + x) as usize] = 1;
                }
            }
            let name = format!("test/r_{f:03}");
            super::super::images::save_png(&render, &dir.join(format!("{name}.png"))).unwrap();
            frames.push(EvalFrame {
                file_path: name,
                time: f as f32 / 6.0,
                gt,
                mask: Some(mask),
            });
        }
        EvalSet {
            frames,
            objects: vec![
                ObjectSpec {
                    id: 0,
                    name: "mover".into(),
                    moving: true,
                },
                ObjectSpec {
                    id: 1,
                    name: "sitter".into(),
                    moving: false,
                },
            ],
            duration_s: 6.0,
            t_seconds: (0..6).collect(),
            policy: CropPolicy {
                pad_fraction: 0.0,
                min_pad_px: 2,
                min_pixels: 4,
                min_side: 1,
            },
            masks: MaskSource::GroundTruth,
        }
    }

    #[test]
    fn crops_follow_the_moving_object_and_static_crops_are_clean() {
        let dir = tempfile::tempdir().unwrap();
        let set = synthetic_set(dir.path());
        let mut scorer = RecordingScorer::default();
        let eval =
            evaluate_run(&set, &RenderDir(dir.path().into()), &mut scorer, &|_, _| {}).unwrap();
        let r = &eval.results;
        assert_eq!(r.moving_object_crop.per_time.len(), 6);
        for (f, ts) in r.moving_object_crop.per_time.iter().enumerate() {
            let f = f as u32;
            assert_eq!(ts.frame, format!("test/r_{f:03}"));
            // Tight box x 4+4f..12+4f, y 10..18, padded by 2 px.
            assert_eq!(ts.crop, Some([2 + 4 * f, 8, 12, 12]));
            // 64 of 144 crop pixels differ by 100 in one channel of three.
            let expected = 64.0 * 100.0 / (144.0 * 3.0);
            assert!((ts.psnr.unwrap() - expected).abs() < 1e-9);
        }
        assert_eq!(r.moving_object_crops["mover"], r.moving_object_crop);
        assert_eq!(r.static_object_crops.len(), 1, "the mover is not static");
        let sitter = &r.static_object_crops["sitter"];
        assert_eq!(sitter.mean.psnr, Some(0.0));
        assert_eq!(sitter.per_time[3].crop, Some([38, 28, 14, 14]));
        // 6 full frames, then 6 moving and 6 static crops.
        assert_eq!(scorer.sizes.len(), 18);
        assert_eq!(eval.picked_renders.len(), 6);
        assert!(r.full_frame.psnr.unwrap() > 0.0);
    }

    #[test]
    fn every_moving_object_has_its_crop_and_the_first_stays_the_main_one() {
        let dir = tempfile::tempdir().unwrap();
        let mut set = synthetic_set(dir.path());
        set.objects[1].moving = true;
        let mut scorer = RecordingScorer::default();
        let eval =
            evaluate_run(&set, &RenderDir(dir.path().into()), &mut scorer, &|_, _| {}).unwrap();
        let r = &eval.results;
        let names: Vec<&String> = r.moving_object_crops.keys().collect();
        assert_eq!(names, ["mover", "sitter"]);
        assert_eq!(r.moving_object_crop, r.moving_object_crops["mover"]);
        assert!(r.static_object_crops.is_empty());
    }

    #[test]
    fn missing_or_mis_sized_render_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let set = synthetic_set(dir.path());
        std::fs::remove_file(dir.path().join("test/r_002.png")).unwrap();
        let mut scorer = RecordingScorer::default();
        let renders = RenderDir(dir.path().into());
        let err = format!(
            "{:#}",
            evaluate_run(&set, &renders, &mut scorer, &|_, _| {})
                .err()
                .unwrap()
        );
        assert!(err.contains("test/r_002"), "{err}");
        super::super::images::save_png(&RgbImage::new(8, 8), &dir.path().join("test/r_002.png"))
            .unwrap();
        let err = format!(
            "{:#}",
            evaluate_run(&set, &renders, &mut scorer, &|_, _| {})
                .err()
                .unwrap()
        );
        assert!(err.contains("8×8"), "{err}");
        // Index-named renders (as `semdynreg render` writes them) are found too.
        let flat = dir.path().join("flat");
        for (i, f) in set.frames.iter().enumerate() {
            std::fs::create_dir_all(&flat).unwrap();
            super::super::images::save_png(&f.gt, &flat.join(format!("{i:04}.png"))).unwrap();
        }
        let eval = evaluate_run(&set, &RenderDir(flat), &mut scorer, &|_, _| {}).unwrap();
        assert_eq!(eval.results.moving_object_crop.mean.psnr, Some(0.0));
    }

    #[test]
    fn invisible_object_gives_null_scores() {
        let dir = tempfile::tempdir().unwrap();
        let mut set = synthetic_set(dir.path());
        set.objects.push(ObjectSpec {
            id: 7,
            name: "ghost".into(),
            moving: false,
        });
        let mut scorer = RecordingScorer::default();
        let eval =
            evaluate_run(&set, &RenderDir(dir.path().into()), &mut scorer, &|_, _| {}).unwrap();
        let ghost = &eval.results.static_object_crops["ghost"];
        assert!(ghost
            .per_time
            .iter()
            .all(|t| t.crop.is_none() && t.psnr.is_none()));
        assert_eq!(ghost.mean.psnr, None);
    }
}
