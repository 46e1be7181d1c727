//! The mask term of training: each moving object is rendered alone and its alpha compared
//! with its mask in the view, balanced inside and outside,
//! `λ·(Σ_M (1 − α) + Σ_out α) / |M|` (`out` = background pixels; other objects' pixels are
//! skipped since they may hide this one). It keeps the trajectory on the object where the
//! photometric gradient is weak (flat colours, motion blur of a poor early model), and keeps
//! the object's Gaussians inside its silhouette. Only alpha is rendered (colour 0). The
//! parts of an articulated object share its mask, so they are rendered together.

use super::place::NO_OBJECT;
use super::RigidObject;
use crate::deform::Deformed;
use crate::model::GaussianModel;
use splat::{Camera, Colors, Gaussians, Gradients, Rasterizer, RenderOptions};

pub struct MaskInput<'a> {
    pub objects: &'a [RigidObject],
    /// Rows of each object (as `place::rows_by_object`).
    pub rows: &'a [Vec<u32>],
    pub id_map: &'a [u8],
    pub cam: &'a Camera,
    pub model: &'a GaussianModel,
    /// World placement of every Gaussian this step.
    pub deformed: &'a Deformed,
    pub lambda: f32,
}

/// Reused buffers of the objects-only renders.
#[derive(Default)]
pub struct MaskLoss {
    raster: Rasterizer,
    means: Vec<f32>,
    quats: Vec<f32>,
    scales: Vec<f32>,
    opacity: Vec<f32>,
    colors: Vec<f32>,
    grads: Gradients,
    dl_dimage: Vec<f32>,
    dl_dalpha: Vec<f32>,
    /// The rows of the object being rendered (all its parts).
    rows: Vec<u32>,
}

impl MaskLoss {
    /// Adds every moving object's mask term into `grads` (rows of the full set); returns
    /// the summed loss.
    pub fn add(
        &mut self,
        inp: &MaskInput,
        grads: &mut Gradients,
    ) -> Result<f32, splat::SplatError> {
        let mut total = 0.0;
        let mut rows = std::mem::take(&mut self.rows);
        for mask in moving_masks(inp.objects) {
            rows.clear();
            let bodies = inp.objects.iter().zip(inp.rows);
            rows.extend(bodies.filter(|(o, _)| o.mask == mask).flat_map(|(_, r)| r));
            let area = inp.id_map.iter().filter(|&&v| v == mask).count();
            if rows.is_empty() || area == 0 {
                continue;
            }
            self.gather(inp, &rows);
            let g = Gaussians {
                means: &self.means,
                quats: &self.quats,
                scales: &self.scales,
                opacity_logits: &self.opacity,
                colors: Colors::Rgb(&self.colors),
            };
            let opts = RenderOptions::default();
            let out = self.raster.forward(&g, inp.cam, &opts)?;
            let w = inp.lambda / area as f32;
            self.dl_dalpha.clear();
            let mut loss = 0.0;
            for (&id, &a) in inp.id_map.iter().zip(out.alpha) {
                let d = if id == mask {
                    loss += w * (1.0 - a);
                    -w
                } else if id == NO_OBJECT {
                    loss += w * a;
                    w
                } else {
                    0.0
                };
                self.dl_dalpha.push(d);
            }
            self.dl_dimage.clear();
            self.dl_dimage.resize(out.image.len(), 0.0);
            self.raster.backward(
                &g,
                inp.cam,
                &opts,
                &self.dl_dimage,
                Some(&self.dl_dalpha),
                &mut self.grads,
            )?;
            self.scatter(&rows, grads);
            total += loss;
        }
        self.rows = rows;
        Ok(total)
    }
}

/// The mask IDs of the objects with a moving body, in first-seen order.
fn moving_masks(objects: &[RigidObject]) -> Vec<u8> {
    let mut out: Vec<u8> = Vec::new();
    for o in objects.iter().filter(|o| !o.is_static) {
        if !out.contains(&o.mask) {
            out.push(o.mask);
        }
    }
    out
}

impl MaskLoss {
    fn gather(&mut self, inp: &MaskInput, rows: &[u32]) {
        let d = inp.deformed;
        self.means.clear();
        self.quats.clear();
        self.scales.clear();
        self.opacity.clear();
        for &r in rows {
            let i = r as usize;
            self.means.extend_from_slice(&d.means[i * 3..i * 3 + 3]);
            self.quats.extend_from_slice(&d.quats[i * 4..i * 4 + 4]);
            self.scales.extend_from_slice(&d.scales[i * 3..i * 3 + 3]);
            self.opacity.push(inp.model.opacity_logits[i]);
        }
        self.colors.clear();
        self.colors.resize(rows.len() * 3, 0.0);
    }

    fn scatter(&self, rows: &[u32], grads: &mut Gradients) {
        let g = &self.grads;
        for (j, &r) in rows.iter().enumerate() {
            let i = r as usize;
            for c in 0..3 {
                grads.means[i * 3 + c] += g.means[j * 3 + c];
                grads.scales[i * 3 + c] += g.scales[j * 3 + c];
            }
            for k in 0..4 {
                grads.quats[i * 4 + k] += g.quats[j * 4 + k];
            }
            grads.opacity_logits[i] += g.opacity_logits[j];
        }
    }
}
