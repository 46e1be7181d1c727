//! Scoring trained methods' renders on a scene's evaluation split (full frame, object
//! crops at t = 0…5 s, and the deformation-consistency and rigidity metrics of the trained
//! model): what `compare` reports for its three runs and `sweep` for each of its runs.

use super::consistency::{run_consistency, NodeSplit, RigidStart, VehicleMetrics};
use super::crops::CropPolicy;
use super::evaluate::{evaluate_run, EvalSet, RenderDir, RunEval};
use super::inputs;
use super::methods::Method;
use super::results::{MethodResults, Protocol};
use super::scorer::{load_lpips, MetricsScorer};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How the scene is loaded and its time axis read (must match the runs).
#[derive(Clone, Debug)]
pub struct SceneEval {
    pub scene: PathBuf,
    pub downscale: u32,
    pub white_background: bool,
    /// Seconds spanned by time 0 → 1 (toycars: 6 s), to place t = 0…5 s.
    pub duration_s: f32,
}

/// One scored method: where its renders are and, when trained here, its run folder (for
/// the consistency metric).
pub struct MethodRun {
    pub method: &'static Method,
    pub renders: PathBuf,
    pub run_dir: Option<PathBuf>,
}

/// The scene's evaluation split with the metric state, loaded once for every method.
pub struct Scoring {
    pub ds: scene::Dataset,
    pub set: EvalSet,
    pub policy: CropPolicy,
    lpips_text: String,
    scorer: MetricsScorer,
}

impl Scoring {
    /// Loads the scene and LPIPS (absent weights: LPIPS `null`; fetching is the caller's).
    pub fn load(opts: &SceneEval) -> Result<Self> {
        let ds = load_dataset(opts)?;
        let policy = CropPolicy::default();
        let set = inputs::eval_set(&ds, opts.duration_s, policy)?;
        let (lpips, lpips_text) = load_lpips()?;
        Ok(Self {
            ds,
            set,
            policy,
            lpips_text,
            scorer: MetricsScorer::new(lpips),
        })
    }

    /// Scores the renders in `dir` (labelled `label` in the progress bar and errors).
    pub fn score(&mut self, label: &str, dir: &Path) -> Result<RunEval> {
        let bar = progress_bar(label, self.set.frames.len());
        let eval = evaluate_run(
            &self.set,
            &RenderDir(dir.to_path_buf()),
            &mut self.scorer,
            &|done, _| bar.set_position(done as u64),
        )
        .with_context(|| format!("evaluating the {label} renders in {}", dir.display()))?;
        bar.finish();
        Ok(eval)
    }

    /// How the numbers were produced (results.json's `protocol`).
    pub fn protocol(&self, duration_s: f32) -> Protocol {
        let set = &self.set;
        Protocol {
            split: if self.ds.test.is_empty() {
                "val"
            } else {
                "test"
            }
            .into(),
            duration_s,
            t_seconds: set.t_seconds.clone(),
            crop_policy: self.policy.describe(set.masks.label()),
            ssim_variant: MetricsScorer::ssim_description().into(),
            lpips: self.lpips_text.clone(),
            moving_object: set
                .moving_object()
                .map(|o| o.name.clone())
                .unwrap_or_default(),
            moving_objects: set.moving_objects().map(|o| o.name.clone()).collect(),
        }
    }
}

fn progress_bar(label: &str, total: usize) -> ProgressBar {
    let bar = ProgressBar::new(total as u64);
    let style = ProgressStyle::with_template("{msg:>17} [{bar:30}] {pos}/{len} frames {elapsed}")
        .expect("static template")
        .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(label.to_string());
    bar
}

/// The scene's evaluation split, loaded as the runs were trained.
fn load_dataset(opts: &SceneEval) -> Result<scene::Dataset> {
    let load = scene::LoadOptions {
        background: if opts.white_background {
            [1.0; 3]
        } else {
            [0.0; 3]
        },
        downscale: opts.downscale,
    };
    scene::load_dataset(&opts.scene, &load)
        .with_context(|| format!("loading scene {}", opts.scene.display()))
}

/// Each method's scores with its consistency metric (when its run was trained here),
/// keyed by method; what could not be measured goes to `notes`.
pub fn method_results(
    methods: &[MethodRun],
    evals: Vec<RunEval>,
    set: &EvalSet,
    notes: &mut Vec<String>,
) -> BTreeMap<String, MethodResults> {
    if set.moving_object().is_none() {
        notes.push(
            "no moving object in objects.json (or no objects.json): crop tables are empty".into(),
        );
    }
    if methods.iter().any(|m| m.run_dir.is_none()) {
        notes.push(
            "deformation_consistency_rms is null: it needs the trained models, not only their renders".into(),
        );
    }
    let mut by_method = BTreeMap::new();
    for (m, eval) in methods.iter().zip(evals) {
        let mut res = eval.results;
        if let Some(run) = &m.run_dir {
            add_consistency(&mut res, run, set, notes);
        }
        by_method.insert(m.method.key.to_string(), res);
    }
    by_method
}

/// Fills the consistency fields of `res` from the trained run, or says in `notes` why not.
fn add_consistency(res: &mut MethodResults, run: &Path, set: &EvalSet, notes: &mut Vec<String>) {
    let Some(VehicleMetrics {
        consistency: r,
        rigidity,
        node_split,
        rigid,
        parts,
    }) = consistency(run, notes)
    else {
        return;
    };
    res.follow_per_part = parts
        .iter()
        .filter_map(|p| {
            Some((
                format!("{}/{}", object_name(set, p.object), p.name),
                p.follow?,
            ))
        })
        .collect();
    add_rigid_objects(res, set, node_split.as_ref(), &rigid);
    res.deformation_consistency_rms = Some(r.rms);
    res.deformation_consistency_per_object = r
        .per_object
        .iter()
        .map(|x| (object_name(set, x.object), x.rms))
        .collect();
    res.deformation_follow_per_object = r
        .per_object
        .iter()
        .filter_map(|x| Some((object_name(set, x.object), x.follow()?)))
        .collect();
    res.rigidity_rms = Some(rigidity.rms);
    res.rigidity_rms_per_object = rigidity
        .per_object
        .iter()
        .map(|x| (object_name(set, x.object), x.rms))
        .collect();
}

/// The node-level split and the start's decisions of a run with rigid objects.
fn add_rigid_objects(
    res: &mut MethodResults,
    set: &EvalSet,
    split: Option<&NodeSplit>,
    rigid: &[RigidStart],
) {
    res.rigid_decision_per_object = rigid
        .iter()
        .map(|r| (object_name(set, r.id), r.decision.into()))
        .collect();
    res.scale_confidence_per_object = rigid
        .iter()
        .filter_map(|r| Some((object_name(set, r.id), f64::from(r.scale_confidence?))))
        .collect();
    let Some(split) = split else { return };
    res.node_share_per_object = split
        .share
        .iter()
        .map(|&(id, share)| (object_name(set, id), share))
        .collect();
    res.follow_in_node_per_object = split
        .in_node
        .iter()
        .flat_map(|r| &r.per_object)
        .filter_map(|x| Some((object_name(set, x.object), x.follow()?)))
        .collect();
}

/// The name `objects.json` gives object `id` (its number when it has none).
fn object_name(set: &EvalSet, id: u8) -> String {
    set.objects
        .iter()
        .find(|o| o.id == id)
        .map_or_else(|| id.to_string(), |o| o.name.clone())
}

/// The run's consistency and rigidity reports, or `None` with the reason added to `notes`.
fn consistency(run: &Path, notes: &mut Vec<String>) -> Option<VehicleMetrics> {
    match run_consistency(run, None) {
        Ok(r) => Some(r),
        Err(e) => {
            notes.push(format!(
                "deformation consistency of {} not computed: {e:#}",
                run.display()
            ));
            None
        }
    }
}
