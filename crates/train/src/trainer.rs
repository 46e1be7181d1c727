//! The training loop of Deformable-3DGS (`train.py`): one random training view per
//! iteration, field off during warm-up, loss → rasterizer backward → deformation chain →
//! field backward, Adam on Gaussians and field, then 3DGS density control.

use crate::adam::{expon_lr, Adam, AdamHyper};
use crate::config::TrainConfig;
use crate::deform::{self, CanonicalGrads, Deformed};
use crate::densify::{self, DensifyReport};
use crate::error::{Result, TrainError};
use crate::field::{DeformField, DeformOutput};
use crate::hook::{DeformHook, HookContext};
use crate::loss::{LossValue, PhotoLoss};
use crate::model::{GaussianModel, SH_COEFFS};
use crate::state::GaussianState;
use crate::timing::{Phase, StepTimings};
use rand::seq::SliceRandom;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scene::Dataset;
use splat::{Colors, Gaussians, Gradients, Rasterizer, RenderOptions};

/// What one iteration did.
#[derive(Clone, Copy, Debug)]
pub struct StepStats {
    pub iteration: u32,
    pub loss: LossValue,
    /// Extra loss: the hook's, the rigid objects' mask term and the `mcmc` strategy's
    /// opacity and scale penalties (0 without them).
    pub extra_loss: f32,
    pub psnr: f64,
    pub num_gaussians: usize,
    pub field_active: bool,
    pub densify: Option<DensifyReport>,
}

/// Everything that evolves during training; saved whole by a checkpoint.
pub struct Trainer {
    pub cfg: TrainConfig,
    pub dataset: Dataset,
    pub state: GaussianState,
    pub field: DeformField,
    pub field_adam: Adam,
    /// Completed iterations.
    pub iteration: u32,
    pub(crate) rng: ChaCha8Rng,
    /// Current epoch's permutation of training frames and the position in it.
    pub(crate) order: Vec<u32>,
    pub(crate) cursor: usize,
    pub extent: f32,
    pub timings: StepTimings,
    /// Wall-clock seconds spent training so far, over all resumed segments (the driver
    /// updates it; checkpoints keep it).
    pub train_seconds: f64,
    /// The rigid objects (`[objects] enabled`): None for the baseline and the paper's runs.
    pub objects: Option<crate::objects::RigidObjects>,
    ws: Workspace,
}

/// Buffers reused every iteration (docs/architecture.md, "Performance principles": no
/// allocation per iteration once warm).
#[derive(Default)]
struct Workspace {
    raster: Rasterizer,
    rows: Vec<u32>,
    delta: DeformOutput,
    extra: DeformOutput,
    deformed: Deformed,
    grads: Gradients,
    canon: CanonicalGrads,
    gt: Vec<f32>,
    dl_dimage: Vec<f32>,
    radii: Vec<[i32; 2]>,
    /// Width and height of the last render.
    size: (u32, u32),
    field_grad: Vec<f32>,
    loss: PhotoLoss,
}

impl Trainer {
    /// Fresh run: Gaussians from the scene's point cloud (if any and enabled) or random,
    /// field initialized, all from `seed`.
    pub fn new(cfg: TrainConfig, dataset: Dataset, seed: u64) -> Result<Self> {
        cfg.validate()?;
        if dataset.train.is_empty() {
            return Err(TrainError::Data(format!(
                "{} has no training frames",
                dataset.root.display()
            )));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let model = match (&dataset.point_cloud, cfg.init.use_point_cloud) {
            (Some(pc), true) if !pc.is_empty() => {
                let pos: Vec<f32> = pc.iter().flatten().copied().collect();
                // The file's colours as 3DGS does; grey, a neutral start, without them.
                let rgb: Vec<f32> = match &dataset.point_colors {
                    Some(c) if c.len() == pc.len() => c.iter().flatten().copied().collect(),
                    _ => vec![0.5; pos.len()],
                };
                crate::init::from_points(&pos, &rgb, cfg.init.opacity)
            }
            _ => crate::init::random(&cfg.init, &mut rng),
        };
        let mut model = model;
        if cfg.densify.strategy == crate::densify::Strategy::Mcmc {
            crate::densify::mcmc::prepare_init(&mut model, &cfg.densify.mcmc);
        }
        if cfg.densify.strategy == crate::densify::Strategy::Mcmc
            && model.len() > cfg.densify.mcmc.cap
        {
            // gsplat's MCMC never prunes below the initialization either: the cap then only
            // stops growth, and relocation keeps the initial count.
            tracing::warn!(
                "the initialization holds {} Gaussians, more than [densify.mcmc] cap = {}: \
                 the run keeps {} and never grows",
                model.len(),
                cfg.densify.mcmc.cap,
                model.len()
            );
        }
        let field = DeformField::new(&cfg.field, &mut rng);
        let extent = dataset.scene_extent();
        let mut tr = Self::assemble(cfg, dataset, model, field, rng, extent);
        tr.objects = crate::objects::RigidObjects::for_run(&tr.cfg, &tr.dataset)?;
        Ok(tr)
    }

    pub(crate) fn assemble(
        cfg: TrainConfig,
        dataset: Dataset,
        model: GaussianModel,
        field: DeformField,
        rng: ChaCha8Rng,
        extent: f32,
    ) -> Self {
        let field_adam = Adam::zeros(field.mlp.num_params());
        Self {
            cfg,
            dataset,
            state: GaussianState::new(model),
            field,
            field_adam,
            iteration: 0,
            rng,
            order: Vec::new(),
            cursor: 0,
            extent,
            timings: StepTimings::default(),
            train_seconds: 0.0,
            objects: None,
            ws: Workspace::default(),
        }
    }

    pub fn model(&self) -> &GaussianModel {
        &self.state.model
    }

    /// (pixel, Gaussian) pairs the rasterizer evaluated in the last forward pass.
    pub fn evaluated_pairs(&self) -> u64 {
        self.ws.raster.evaluated_pairs()
    }

    /// The training steps' rasterizer, for the A/B switches of benchmarks
    /// (`set_scalar_projection`, `set_simd_cap`; results are bit-identical either way).
    pub fn rasterizer_mut(&mut self) -> &mut Rasterizer {
        &mut self.ws.raster
    }

    /// Whether the field is applied at 1-based iteration `it` (Deformable-3DGS: from `warm_up`).
    pub fn field_active_at(&self, it: u32) -> bool {
        it >= self.cfg.field.warm_up
    }

    /// Metrics on the first `max_frames` frames (0 = all) of the split `log.eval_split`,
    /// with the field applied once training has passed the warm-up (before that it is
    /// untrained).
    pub fn evaluate_test(&mut self, max_frames: usize) -> Result<crate::render::EvalReport> {
        let active = self.iteration >= self.cfg.field.warm_up;
        let frames = self.cfg.log.eval_split.frames(&self.dataset);
        let k = if max_frames == 0 {
            frames.len()
        } else {
            max_frames.min(frames.len())
        };
        let objects = match &self.objects {
            Some(o) => o.view(&self.state.object),
            None => crate::objects::ObjectsView::none(),
        };
        let mut r = crate::render::Renderer::default();
        r.evaluate(
            &self.state.model,
            active.then_some(&mut self.field),
            objects,
            &frames[..k],
            self.dataset.background,
            None,
        )
    }

    /// The objects and the object column, for rendering (none for baseline runs).
    pub fn objects_view(&self) -> crate::objects::ObjectsView<'_> {
        match &self.objects {
            Some(o) => o.view(&self.state.object),
            None => crate::objects::ObjectsView::none(),
        }
    }

    /// Next training frame: a fresh random permutation each epoch (3DGS `viewpoint_stack`).
    fn next_frame(&mut self) -> usize {
        if self.cursor >= self.order.len() {
            self.order = (0..self.dataset.train.len() as u32).collect();
            self.order.shuffle(&mut self.rng);
            self.cursor = 0;
        }
        self.cursor += 1;
        self.order[self.cursor - 1] as usize
    }

    /// One iteration without a hook.
    pub fn step(&mut self) -> Result<StepStats> {
        self.step_with(None)
    }

    /// One iteration; `hook` may add `dL/dδ` (and report a loss) before the field backward.
    pub fn step_with(&mut self, mut hook: Option<&mut dyn DeformHook>) -> Result<StepStats> {
        let it = self.iteration + 1;
        let mut tm = StepTimings::default();
        if it.is_multiple_of(self.cfg.sh.degree_interval)
            && self.state.model.sh_degree < self.cfg.sh.max_degree
        {
            self.state.model.sh_degree += 1;
        }
        self.start_objects(it)?;
        let fi = self.next_frame();
        let active = self.field_active_at(it);
        let hook_k = hook.as_ref().map_or(0, |h| h.topk(it));
        let topk = hook_k.max(self.objects.as_ref().map_or(0, |o| o.topk()));
        self.forward_deform(fi, active, &mut tm);
        let (loss, psnr, extra_loss) =
            self.render_and_loss(fi, it, active, topk, &mut hook, &mut tm)?;
        if !loss.total.is_finite() {
            let culprit = crate::finite::locate(self)
                .map_or("every parameter is finite".into(), |c| {
                    format!("first non-finite: {c}")
                });
            return Err(TrainError::NonFinite {
                iteration: it,
                what: format!("the loss ({culprit})"),
            });
        }
        let objects_loss = self.backward(fi, active, &mut tm)?;
        let (densify, finite, penalty) = self.optimize_and_densify(it, fi, active, &mut tm);
        let culprit = if finite {
            crate::finite::locate_objects(self)
        } else {
            crate::finite::locate(self)
        };
        if let Some(what) = culprit {
            return Err(TrainError::NonFinite {
                iteration: it,
                what,
            });
        }
        self.iteration = it;
        self.timings.add(&tm);
        Ok(StepStats {
            iteration: it,
            loss,
            extra_loss: extra_loss + objects_loss + penalty,
            psnr,
            num_gaussians: self.state.len(),
            field_active: active,
            densify,
        })
    }

    /// The rigid objects' milestones: brought in at their start iteration
    /// (`objects::start`), their occlusion gauge applied again at `rescale_at`.
    fn start_objects(&mut self, it: u32) -> Result<()> {
        let Some(node) = self.objects.as_mut() else {
            return Ok(());
        };
        let t0 = std::time::Instant::now();
        if !node.started && it >= node.cfg.start_iter {
            crate::objects::start::start(node, &mut self.state, &self.dataset, &mut self.rng)?;
            let seconds = t0.elapsed().as_secs_f64();
            tracing::info!(iteration = it, seconds, "rigid objects started");
        } else if node.started && node.cfg.rescale_at.contains(&it) {
            let field = (it >= self.cfg.field.warm_up).then_some(&mut self.field);
            let applied =
                crate::objects::regauge::regauge(node, &mut self.state, field, &self.dataset)?;
            let seconds = t0.elapsed().as_secs_f64();
            tracing::info!(
                iteration = it,
                seconds,
                ?applied,
                "occlusion gauge applied again"
            );
        }
        Ok(())
    }

    fn forward_deform(&mut self, fi: usize, active: bool, tm: &mut StepTimings) {
        let ws = &mut self.ws;
        let model = &self.state.model;
        let objects = match &self.objects {
            Some(o) => o.view(&self.state.object),
            None => crate::objects::ObjectsView::none(),
        };
        if active {
            let t0 = std::time::Instant::now();
            let frame = &self.dataset.train[fi];
            let fc = &self.cfg.field;
            crate::visibility::field_rows(
                &model.means,
                &frame.camera,
                fc.visible_only,
                fc.visible_margin,
                &mut ws.rows,
            );
            objects.keep_background_rows(&mut ws.rows);
            self.field
                .forward(&model.means, frame.time, &ws.rows, &mut ws.delta);
            tm.record(Phase::FieldForward, t0);
        }
        let t0 = std::time::Instant::now();
        deform::apply(model, active.then_some(&ws.delta), &mut ws.deformed);
        if let Some(node) = self.objects.as_mut() {
            let t = self.dataset.train[fi].time;
            node.place(model, &self.state.object, t, &mut ws.deformed);
        }
        tm.record(Phase::Deform, t0);
    }

    fn render_options(&self, topk: usize) -> RenderOptions {
        RenderOptions {
            background: self.dataset.background,
            topk,
            ..RenderOptions::default()
        }
    }

    fn render_and_loss(
        &mut self,
        fi: usize,
        it: u32,
        active: bool,
        topk: usize,
        hook: &mut Option<&mut dyn DeformHook>,
        tm: &mut StepTimings,
    ) -> Result<(LossValue, f64, f32)> {
        let opts = self.render_options(topk);
        let ws = &mut self.ws;
        let model = &self.state.model;
        let frame = &self.dataset.train[fi];
        let g = gaussians(model, &ws.deformed);
        let t0 = std::time::Instant::now();
        let out = ws.raster.forward(&g, &frame.camera, &opts)?;
        tm.record(Phase::RasterForward, t0);
        let t0 = std::time::Instant::now();
        frame.image.to_f32_into(&mut ws.gt);
        if ws.gt.len() != out.image.len() {
            return Err(TrainError::Data(format!(
                "image {} is {}×{} but its camera is {}×{}",
                frame.file_path, frame.image.width, frame.image.height, out.width, out.height
            )));
        }
        let loss = ws.loss.eval(
            out.image,
            &ws.gt,
            out.width,
            out.height,
            self.cfg.loss.lambda_dssim,
            &mut ws.dl_dimage,
        );
        if let Some(node) = &self.objects {
            node.mask_background(it, fi, &mut ws.dl_dimage);
        }
        let psnr = metrics::psnr(out.image, &ws.gt);
        ws.radii.clear();
        ws.radii.extend_from_slice(out.radii);
        ws.size = (out.width, out.height);
        tm.record(Phase::Loss, t0);
        ws.extra.reset(model.len());
        let mut aux = crate::state::AuxStore::new(&mut self.state.aux, model.len());
        if let Some(node) = &self.objects {
            node.record_votes(fi, out.topk_ids, out.topk_weights, topk, &mut aux)
                .map_err(TrainError::Hook)?;
        }
        let mut extra_loss = 0.0;
        if let Some(h) = hook.as_mut() {
            let t0 = std::time::Instant::now();
            let ctx = HookContext {
                iteration: it,
                frame_index: fi,
                frame,
                field_active: active,
                width: out.width,
                height: out.height,
                topk,
                topk_ids: out.topk_ids,
                topk_weights: out.topk_weights,
                delta: &ws.delta,
                means: &model.means,
                field_rows: &ws.rows,
            };
            extra_loss = h
                .apply(&ctx, &mut aux, &mut ws.extra)
                .map_err(|e| TrainError::Hook(e.to_string()))?;
            tm.record(Phase::Hook, t0);
        }
        let projection = ws.raster.timings().project;
        tm.move_seconds(Phase::RasterForward, Phase::Projection, projection);
        Ok((loss, psnr, extra_loss))
    }

    /// Rasterizer backward, the objects' mask term and chain, the field backward; returns
    /// the objects' mask loss.
    fn backward(&mut self, fi: usize, active: bool, tm: &mut StepTimings) -> Result<f32> {
        let opts = self.render_options(0);
        let ws = &mut self.ws;
        let model = &self.state.model;
        let frame = &self.dataset.train[fi];
        let g = gaussians(model, &ws.deformed);
        let t0 = std::time::Instant::now();
        ws.raster
            .backward(&g, &frame.camera, &opts, &ws.dl_dimage, None, &mut ws.grads)?;
        tm.record(Phase::RasterBackward, t0);
        let projection = ws.raster.timings().project;
        tm.move_seconds(Phase::RasterBackward, Phase::ProjectionBackward, projection);
        let mut objects_loss = 0.0;
        if let Some(node) = self.objects.as_mut().filter(|n| n.started) {
            let t0 = std::time::Instant::now();
            let cam = &frame.camera;
            objects_loss = node.add_mask_loss(fi, cam, model, &ws.deformed, &mut ws.grads)?;
            tm.record(Phase::Objects, t0);
        }
        let t0 = std::time::Instant::now();
        deform::backward(
            model,
            &ws.grads.means,
            &ws.grads.quats,
            &ws.grads.scales,
            &mut ws.canon,
        );
        if let Some(node) = self.objects.as_mut() {
            node.backward(model, &ws.grads.means, &ws.grads.quats, &mut ws.canon);
        }
        tm.record(Phase::Deform, t0);
        if active {
            let t0 = std::time::Instant::now();
            // δ enters additively: dL/dδ = dL/d(deformed) + the hook's extra term.
            for (e, g) in [
                (&mut ws.extra.dx, &ws.grads.means),
                (&mut ws.extra.dr, &ws.grads.quats),
                (&mut ws.extra.ds, &ws.grads.scales),
            ] {
                e.iter_mut().zip(g).for_each(|(a, b)| *a += b);
            }
            self.field.backward(&ws.extra, &mut ws.field_grad);
            tm.record(Phase::FieldBackward, t0);
        }
        Ok(objects_loss)
    }

    /// Adam on the field and Gaussians, then density control (3DGS `train.py` order; what
    /// the strategy does when: `densify::Schedule`). The field always steps. Returns the
    /// refinement's report, whether every value the optimizer wrote is finite, and the
    /// `mcmc` penalties' loss.
    fn optimize_and_densify(
        &mut self,
        it: u32,
        frame: usize,
        active: bool,
        tm: &mut StepTimings,
    ) -> (Option<DensifyReport>, bool, f32) {
        let t0 = std::time::Instant::now();
        let c = &self.cfg;
        let hp = AdamHyper {
            beta1: c.lr.adam_beta1,
            beta2: c.lr.adam_beta2,
            eps: c.lr.adam_eps,
        };
        let mut finite = true;
        if active {
            let lr = expon_lr(c.lr.field_init, c.lr.field_final, c.lr.field_max_steps, it);
            finite &= self
                .field_adam
                .step(&mut self.field.mlp.params, &self.ws.field_grad, hp, lr);
        }
        let d = c.densify.clone();
        let white = self.dataset.background == [1.0; 3];
        let plan = densify::Schedule::at(&d, it, white);
        let lr_means = self.means_lr(it);
        let mut penalty = 0.0;
        if plan.mcmc_terms {
            let g = &mut self.ws;
            penalty = densify::mcmc::add_penalty_grads(
                &self.state.model,
                &d.mcmc,
                &mut g.grads.opacity_logits,
                &mut g.canon.log_scales,
            );
        }
        if plan.step_gaussians {
            finite &= self.adam_gaussians(lr_means, hp, plan.step_opacity);
        }
        if let Some(node) = self.objects.as_mut() {
            node.step(hp);
        }
        tm.record(Phase::Optimizer, t0);
        let t0 = std::time::Instant::now();
        let mut report = None;
        if plan.collect_stats {
            let (w, h) = self.ws.size;
            self.state
                .stats
                .add(&self.ws.radii, &self.ws.grads.means2d, w, h);
        }
        if plan.refine {
            if let Some(node) = &self.objects {
                let at = crate::objects::membership::StepPlacement {
                    deformed: &self.ws.deformed,
                    background_rows: active.then_some(self.ws.rows.as_slice()),
                    time: self.dataset.train[frame].time,
                };
                let moved = node.transfer(&mut self.state, &at);
                tracing::debug!(iteration = it, moved, "object membership transfers");
            }
            let prune_screen = it > d.screen_size_after;
            report = Some(densify::refine(
                &mut self.state,
                &d,
                self.extent,
                prune_screen,
                &mut self.rng,
            ));
        }
        if plan.reset_opacity {
            densify::reset_opacity(&mut self.state, d.reset_opacity);
        }
        if plan.mcmc_terms {
            let key = self.rng.next_u64();
            densify::mcmc::inject_noise(&mut self.state.model, lr_means * d.mcmc.noise_lr, key);
        }
        tm.record(Phase::Densify, t0);
        (report, finite, penalty)
    }

    /// The means' learning rate at iteration `it` (3DGS's exponential decay, × the spatial
    /// scale Deformable-3DGS applies).
    fn means_lr(&self, it: u32) -> f32 {
        let c = &self.cfg.lr;
        expon_lr(
            c.position_init * c.spatial_scale,
            c.position_final * c.spatial_scale,
            c.position_max_steps,
            it,
        )
    }

    /// Adam on the five Gaussian groups; whether every value written is finite.
    fn adam_gaussians(&mut self, lr_means: f32, hp: AdamHyper, step_opacity: bool) -> bool {
        let c = &self.cfg.lr;
        let s = &mut self.state;
        let g = &self.ws;
        let [a_means, a_quats, a_scales, a_opacity, a_sh] = &mut s.adam;
        let mut ok = a_means.step(&mut s.model.means, &g.canon.means, hp, lr_means);
        ok &= a_quats.step(&mut s.model.quats, &g.canon.quats, hp, c.rotation);
        ok &= a_scales.step(&mut s.model.log_scales, &g.canon.log_scales, hp, c.scaling);
        if step_opacity {
            ok &= a_opacity.step(
                &mut s.model.opacity_logits,
                &g.grads.opacity_logits,
                hp,
                c.opacity,
            );
        }
        let (dc, rest) = (c.sh_dc, c.sh_rest);
        ok & a_sh.step_rows(
            &mut s.model.sh,
            &g.grads.colors,
            hp,
            SH_COEFFS * 3,
            move |k| if k < 3 { dc } else { rest },
        )
    }
}

/// The rasterizer's view of canonical colours/opacities with deformed geometry.
pub fn gaussians<'a>(model: &'a GaussianModel, d: &'a Deformed) -> Gaussians<'a> {
    Gaussians {
        means: &d.means,
        quats: &d.quats,
        scales: &d.scales,
        opacity_logits: &model.opacity_logits,
        colors: Colors::Sh {
            coeffs: &model.sh,
            num_coeffs: SH_COEFFS,
            degree: model.sh_degree,
        },
    }
}
