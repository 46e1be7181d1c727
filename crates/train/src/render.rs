//! Rendering and evaluating a trained model at any time t (no gradients): the nodes place
//! the Gaussians exactly as in training (the field's `visible_only` rule included, so views
//! match what was trained), PSNR and 3DGS-SSIM per frame, and the placed Gaussians as a
//! model for export.

use crate::deform::{self, Deformed};
use crate::error::{Result, TrainError};
use crate::model::GaussianModel;
use crate::node::{At, Rows};
use crate::nodes::Nodes;
use crate::timing::StepTimings;
use serde::{Deserialize, Serialize};
use splat::{Camera, Rasterizer, RenderOptions};

#[derive(Default)]
pub struct Renderer {
    raster: Rasterizer,
    deformed: Deformed,
}

/// A trained scene as render, eval and export see it: the Gaussians, their object column,
/// the nodes that place them, and the iteration reached (schedules such as the field's
/// warm-up read it).
pub struct Scene<'a> {
    pub model: &'a GaussianModel,
    pub column: &'a [u8],
    /// The per-Gaussian rows nodes keep beside the parameters (skinning weights).
    pub aux: &'a [crate::state::AuxRows],
    pub nodes: &'a mut Nodes,
    pub iteration: u32,
}

impl Scene<'_> {
    /// Every Gaussian placed at time `t`, only those that can reach `cam` when given.
    fn place(&mut self, cam: Option<&Camera>, t: f32, out: &mut Deformed) {
        let rows = Rows {
            model: self.model,
            column: self.column,
            aux: self.aux,
        };
        let at = At {
            time: t,
            camera: cam,
            iteration: self.iteration,
        };
        self.nodes
            .place(rows, &at, out, &mut StepTimings::default());
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameMetrics {
    pub file_path: String,
    pub time: f32,
    pub psnr: f64,
    pub ssim: f64,
    /// LPIPS with AlexNet and with VGG, present when the caller supplied a scorer for
    /// them (`semdynreg eval` with weights; Deformable-3DGS's table uses VGG).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips_vgg: Option<f64>,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeanMetrics {
    pub psnr: f64,
    pub ssim: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips_vgg: Option<f64>,
    /// Frames averaged.
    #[serde(default)]
    pub frames: usize,
}

impl MeanMetrics {
    /// The mean of `frames` (an LPIPS only when every frame has it).
    pub fn of<'a>(frames: impl IntoIterator<Item = &'a FrameMetrics>) -> Self {
        let frames: Vec<&FrameMetrics> = frames.into_iter().collect();
        let n = frames.len().max(1) as f64;
        let mean = |f: &dyn Fn(&FrameMetrics) -> f64| frames.iter().map(|m| f(m)).sum::<f64>() / n;
        let opt = |f: &dyn Fn(&FrameMetrics) -> Option<f64>| {
            frames
                .iter()
                .map(|m| f(m))
                .sum::<Option<f64>>()
                .map(|s| s / n)
        };
        Self {
            psnr: mean(&|m| m.psnr),
            ssim: mean(&|m| m.ssim),
            lpips: opt(&|m| m.lpips),
            lpips_vgg: opt(&|m| m.lpips_vgg),
            frames: frames.len(),
        }
    }
}

/// Perceptual scores of one frame, each present when its network was loaded.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PerceptualScores {
    pub alex: Option<f64>,
    pub vgg: Option<f64>,
}

/// Extra per-frame image metrics (LPIPS), given the render and the ground truth as
/// `H·W·3` RGB in [0, 1] and the size `(w, h)`. Lives outside this crate because its
/// weights are found and loaded by the caller.
pub type FrameScorer<'a> =
    &'a mut dyn FnMut(&[f32], &[f32], usize, usize) -> Result<PerceptualScores>;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub mean: MeanMetrics,
    /// The mean over the frames whose time lies inside the training frames' time range
    /// (`[min, max]` of the times trained on): what a deformation field interpolates, as
    /// opposed to extrapolating before the first or after the last training time. Absent
    /// when the caller did not give the training times.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covered: Option<CoveredTimes>,
    pub frames: Vec<FrameMetrics>,
}

/// [`EvalReport::covered`]: the training time range and the mean inside it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CoveredTimes {
    pub train_time_min: f32,
    pub train_time_max: f32,
    pub mean: MeanMetrics,
}

impl EvalReport {
    /// Adds [`EvalReport::covered`] for the training times `train_times` (nothing when
    /// there are none).
    pub fn with_covered_times(mut self, train_times: impl IntoIterator<Item = f32>) -> Self {
        let (lo, hi) = train_times
            .into_iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), t| {
                (a.min(t), b.max(t))
            });
        if lo <= hi {
            let inside = self.frames.iter().filter(|f| (lo..=hi).contains(&f.time));
            self.covered = Some(CoveredTimes {
                train_time_min: lo,
                train_time_max: hi,
                mean: MeanMetrics::of(inside),
            });
        }
        self
    }
}

impl Renderer {
    /// The placed geometry at time `t` exactly as [`Renderer::render`] draws it, for
    /// callers that drive the rasterizer themselves (`examples/cull_probe.rs`).
    pub fn deformed(&mut self, mut scene: Scene<'_>, cam: &Camera, t: f32) -> &Deformed {
        scene.place(Some(cam), t, &mut self.deformed);
        &self.deformed
    }

    /// Renders `H·W·3` RGB at time `t` from `cam`.
    pub fn render(
        &mut self,
        mut scene: Scene<'_>,
        cam: &Camera,
        t: f32,
        background: [f32; 3],
    ) -> Result<Vec<f32>> {
        scene.place(Some(cam), t, &mut self.deformed);
        let g = deform::gaussians(scene.model, &self.deformed);
        let opts = RenderOptions {
            background,
            ..RenderOptions::default()
        };
        Ok(self.raster.forward(&g, cam, &opts)?.image.to_vec())
    }

    /// PSNR and SSIM (and `lpips`, when given) of every frame, rendered at its own time.
    pub fn evaluate(
        &mut self,
        scene: Scene<'_>,
        frames: &[scene::Frame],
        background: [f32; 3],
        mut lpips: Option<FrameScorer>,
    ) -> Result<EvalReport> {
        let mut out = Vec::with_capacity(frames.len());
        let mut ssim_ws = metrics::SsimWorkspace::new();
        let (model, column, aux, nodes, iteration) = (
            scene.model,
            scene.column,
            scene.aux,
            scene.nodes,
            scene.iteration,
        );
        for fr in frames {
            let scene = Scene {
                model,
                column,
                aux,
                nodes: &mut *nodes,
                iteration,
            };
            let mut img = self.render(scene, &fr.camera, fr.time, background)?;
            // Scored as the image a viewer shows: clamped to [0, 1], as Deformable-3DGS's
            // `training_report` (`torch.clamp(render, 0, 1)`) and its saved 8-bit renders
            // do. Unclamped overshoot (likely on a white background) could only lower the
            // score.
            img.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
            let gt = fr.image.to_f32();
            if gt.len() != img.len() {
                return Err(TrainError::Data(format!(
                    "image {} does not match its camera's size",
                    fr.file_path
                )));
            }
            let (w, h) = (fr.camera.width as usize, fr.camera.height as usize);
            let lp = match lpips.as_mut() {
                Some(score) => score(&img, &gt, w, h)?,
                None => PerceptualScores::default(),
            };
            out.push(FrameMetrics {
                file_path: fr.file_path.clone(),
                time: fr.time,
                psnr: metrics::psnr(&img, &gt),
                ssim: ssim_ws.ssim(&img, &gt, w, h) as f64,
                lpips: lp.alex,
                lpips_vgg: lp.vgg,
            });
        }
        Ok(EvalReport {
            mean: MeanMetrics::of(&out),
            covered: None,
            frames: out,
        })
    }
}

/// The Gaussians placed at time `t`, every one (no view), as a standard model: field rows
/// at means + δx, quats normalize(q) + δr, log(exp(log_scale) + δs); object rows by their
/// trajectories. Scales that δs drives to ≤ 0 are clamped to 1e-8 first (the rasterizer
/// would square them; a log cannot).
pub fn deformed_model(mut scene: Scene<'_>, t: f32) -> GaussianModel {
    let mut d = Deformed::default();
    scene.place(None, t, &mut d);
    let model = scene.model;
    GaussianModel {
        means: d.means,
        quats: d.quats,
        log_scales: d.scales.iter().map(|s| s.max(1e-8).ln()).collect(),
        opacity_logits: model.opacity_logits.clone(),
        sh: model.sh.clone(),
        sh_degree: model.sh_degree,
    }
}
