//! Rendering and evaluating a trained model at any time t (no gradients): the same
//! deformation as training (`visible_only` rule included, so views match what was trained),
//! PSNR and 3DGS-SSIM per frame, and the deformed Gaussians as a model for export.

use crate::deform::{self, Deformed};
use crate::error::{Result, TrainError};
use crate::field::{DeformField, DeformOutput};
use crate::model::GaussianModel;
use crate::objects::ObjectsView;
use serde::{Deserialize, Serialize};
use splat::{Camera, Rasterizer, RenderOptions};

#[derive(Default)]
pub struct Renderer {
    raster: Rasterizer,
    rows: Vec<u32>,
    delta: DeformOutput,
    deformed: Deformed,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameMetrics {
    pub file_path: String,
    pub time: f32,
    pub psnr: f64,
    pub ssim: f64,
    /// Present when the caller supplied an LPIPS scorer (`semdynreg eval` with weights).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeanMetrics {
    pub psnr: f64,
    pub ssim: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
}

/// An extra per-frame image metric (LPIPS), given the render and the ground truth as
/// `H·W·3` RGB in [0, 1] and the size `(w, h)`. Lives outside this crate because its
/// weights are found and loaded by the caller.
pub type FrameScorer<'a> = &'a mut dyn FnMut(&[f32], &[f32], usize, usize) -> Result<f64>;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub mean: MeanMetrics,
    pub frames: Vec<FrameMetrics>,
}

impl Renderer {
    /// Fills the deformed geometry at time `t` (δ = 0 when `field` is None), objects placed
    /// by their trajectories.
    fn deform(
        &mut self,
        model: &GaussianModel,
        field: Option<&mut DeformField>,
        objects: ObjectsView,
        cam: &Camera,
        t: f32,
    ) {
        match field {
            Some(f) => {
                crate::visibility::field_rows(
                    &model.means,
                    cam,
                    f.cfg.visible_only,
                    f.cfg.visible_margin,
                    &mut self.rows,
                );
                objects.keep_background_rows(&mut self.rows);
                f.forward(&model.means, t, &self.rows, &mut self.delta);
                deform::apply(model, Some(&self.delta), &mut self.deformed);
            }
            None => deform::apply(model, None, &mut self.deformed),
        }
        objects.place(model, t, &mut self.deformed);
    }

    /// The deformed geometry at time `t` exactly as [`Renderer::render`] draws it, for
    /// callers that drive the rasterizer themselves (`examples/cull_probe.rs`).
    pub fn deformed(
        &mut self,
        model: &GaussianModel,
        field: Option<&mut DeformField>,
        objects: ObjectsView,
        cam: &Camera,
        t: f32,
    ) -> &Deformed {
        self.deform(model, field, objects, cam, t);
        &self.deformed
    }

    /// Renders `H·W·3` RGB at time `t` from `cam`.
    pub fn render(
        &mut self,
        model: &GaussianModel,
        field: Option<&mut DeformField>,
        objects: ObjectsView,
        cam: &Camera,
        t: f32,
        background: [f32; 3],
    ) -> Result<Vec<f32>> {
        self.deform(model, field, objects, cam, t);
        let g = crate::trainer::gaussians(model, &self.deformed);
        let opts = RenderOptions {
            background,
            ..RenderOptions::default()
        };
        Ok(self.raster.forward(&g, cam, &opts)?.image.to_vec())
    }

    /// PSNR and SSIM (and `lpips`, when given) of every frame, rendered at its own time.
    pub fn evaluate(
        &mut self,
        model: &GaussianModel,
        mut field: Option<&mut DeformField>,
        objects: ObjectsView,
        frames: &[scene::Frame],
        background: [f32; 3],
        mut lpips: Option<FrameScorer>,
    ) -> Result<EvalReport> {
        let mut out = Vec::with_capacity(frames.len());
        let mut ssim_ws = metrics::SsimWorkspace::new();
        for fr in frames {
            let f = field.as_deref_mut();
            let img = self.render(model, f, objects, &fr.camera, fr.time, background)?;
            let gt = fr.image.to_f32();
            if gt.len() != img.len() {
                return Err(TrainError::Data(format!(
                    "image {} does not match its camera's size",
                    fr.file_path
                )));
            }
            let (w, h) = (fr.camera.width as usize, fr.camera.height as usize);
            let lp = match lpips.as_mut() {
                Some(score) => Some(score(&img, &gt, w, h)?),
                None => None,
            };
            out.push(FrameMetrics {
                file_path: fr.file_path.clone(),
                time: fr.time,
                psnr: metrics::psnr(&img, &gt),
                ssim: ssim_ws.ssim(&img, &gt, w, h) as f64,
                lpips: lp,
            });
        }
        let n = out.len().max(1) as f64;
        let lpips_mean = out
            .iter()
            .map(|f| f.lpips)
            .sum::<Option<f64>>()
            .map(|s| s / n);
        Ok(EvalReport {
            mean: MeanMetrics {
                psnr: out.iter().map(|f| f.psnr).sum::<f64>() / n,
                ssim: out.iter().map(|f| f.ssim).sum::<f64>() / n,
                lpips: lpips_mean,
            },
            frames: out,
        })
    }
}

/// The Gaussians deformed to time `t`, every one evaluated (no view), as a standard model:
/// means + δx, quats normalize(q) + δr, log(exp(log_scale) + δs), and object Gaussians
/// placed by their trajectories. Scales that δs drives to ≤ 0 are clamped to 1e-8 first
/// (the rasterizer would square them; a log cannot).
pub fn deformed_model(
    model: &GaussianModel,
    field: Option<&mut DeformField>,
    objects: ObjectsView,
    t: f32,
) -> GaussianModel {
    let mut d = Deformed::default();
    let mut delta = DeformOutput::default();
    match field {
        Some(f) => {
            let mut rows: Vec<u32> = (0..model.len() as u32).collect();
            objects.keep_background_rows(&mut rows);
            f.forward(&model.means, t, &rows, &mut delta);
            deform::apply(model, Some(&delta), &mut d);
        }
        None => deform::apply(model, None, &mut d),
    }
    objects.place(model, t, &mut d);
    GaussianModel {
        means: d.means,
        quats: d.quats,
        log_scales: d.scales.iter().map(|s| s.max(1e-8).ln()).collect(),
        opacity_logits: model.opacity_logits.clone(),
        sh: model.sh.clone(),
        sh_degree: model.sh_degree,
    }
}
