//! The training loop of Deformable-3DGS (`train.py`) over the scene model's nodes: one
//! random training view per iteration; the nodes place every Gaussian at the view's time,
//! one rasterizer call renders them, the photometric loss's gradient goes back through the
//! rasterizer and each node's placement; Adam on the Gaussians and on each node's own
//! parameters; then 3DGS density control on the Gaussian store. The order of the calls is
//! listed in `crate::node`.

use crate::adam::{expon_lr, AdamHyper};
use crate::config::TrainConfig;
use crate::deform::{self, CanonicalGrads, Deformed};
use crate::densify::{self, DensifyReport};
use crate::error::{Result, TrainError};
use crate::hook::{DeformHook, HookContext};
use crate::loss::{LossValue, PhotoLoss};
use crate::model::{GaussianModel, SH_COEFFS};
use crate::node::{At, Milestone, Placed, Refining, Rendered, Rows};
use crate::nodes::{NodeInit, Nodes};
use crate::state::GaussianState;
use crate::timing::{Phase, StepTimings};
use rand::seq::SliceRandom;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scene::Dataset;
use splat::{Gradients, Rasterizer, RenderOptions};

/// What one iteration did.
#[derive(Clone, Copy, Debug)]
pub struct StepStats {
    pub iteration: u32,
    pub loss: LossValue,
    /// Extra loss: the hook's, the nodes' own terms (the rigid objects' mask term) and the
    /// `mcmc` strategy's opacity and scale penalties (0 without them).
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
    /// Every Gaussian, row-aligned with its optimizer state; the object column says which
    /// node owns a row.
    pub state: GaussianState,
    /// The scene model's nodes, in placement order (`crate::nodes`).
    pub nodes: Nodes,
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
    ws: Workspace,
}

/// Buffers reused every iteration (docs/architecture.md, "Performance principles": no
/// allocation per iteration once warm).
#[derive(Default)]
struct Workspace {
    raster: Rasterizer,
    deformed: Deformed,
    grads: Gradients,
    canon: CanonicalGrads,
    gt: Vec<f32>,
    dl_dimage: Vec<f32>,
    radii: Vec<[i32; 2]>,
    /// Width and height of the last render.
    size: (u32, u32),
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
        let model = initial_gaussians(&cfg, &dataset, &mut rng);
        let nodes = Nodes::build(NodeInit {
            cfg: &cfg,
            dataset: Some(&dataset),
            rng: &mut rng,
        })?;
        let extent = dataset.scene_extent();
        Ok(Self::assemble(cfg, dataset, model, nodes, rng, extent))
    }

    pub(crate) fn assemble(
        cfg: TrainConfig,
        dataset: Dataset,
        model: GaussianModel,
        nodes: Nodes,
        rng: ChaCha8Rng,
        extent: f32,
    ) -> Self {
        Self {
            cfg,
            dataset,
            state: GaussianState::new(model),
            nodes,
            iteration: 0,
            rng,
            order: Vec::new(),
            cursor: 0,
            extent,
            timings: StepTimings::default(),
            train_seconds: 0.0,
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
    /// placed as a checkpoint of this iteration would be (the field past its warm-up).
    pub fn evaluate_test(&mut self, max_frames: usize) -> Result<crate::render::EvalReport> {
        let frames = self.cfg.log.eval_split.frames(&self.dataset);
        let k = if max_frames == 0 {
            frames.len()
        } else {
            max_frames.min(frames.len())
        };
        let scene = crate::render::Scene {
            model: &self.state.model,
            column: &self.state.object,
            aux: &self.state.aux,
            nodes: &mut self.nodes,
            iteration: self.iteration,
        };
        let mut r = crate::render::Renderer::default();
        r.evaluate(scene, &frames[..k], self.dataset.background, None)
    }

    /// The first non-finite value of the Gaussians, their optimizer state or any node's
    /// own parameters, named; `None` when everything is finite.
    pub fn nonfinite(&self) -> Option<String> {
        crate::finite::locate_store(&self.state).or_else(|| self.nodes.nonfinite())
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
        self.begin_nodes(it)?;
        let fi = self.next_frame();
        let hook_k = hook.as_ref().map_or(0, |h| h.topk(it));
        let topk = self.nodes.iter().map(|n| n.topk()).fold(hook_k, usize::max);
        let at = At {
            time: self.dataset.train[fi].time,
            camera: Some(&self.dataset.train[fi].camera),
            iteration: it,
        };
        let rows = Rows {
            model: &self.state.model,
            column: &self.state.object,
            aux: &self.state.aux,
        };
        self.nodes.place(rows, &at, &mut self.ws.deformed, &mut tm);
        let (loss, psnr, extra_loss) = self.render_and_loss(fi, it, topk, &mut hook, &mut tm)?;
        if !loss.total.is_finite() {
            let culprit = self
                .nonfinite()
                .map_or("every parameter is finite".into(), |c| {
                    format!("first non-finite: {c}")
                });
            return Err(TrainError::NonFinite {
                iteration: it,
                what: format!("the loss ({culprit})"),
            });
        }
        let nodes_loss = self.backward(fi, it, &mut tm)?;
        let (densify, finite, penalty) = self.optimize_and_densify(it, fi, &mut tm);
        if let Some(what) = (!finite).then(|| self.nonfinite()).flatten() {
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
            extra_loss: extra_loss + nodes_loss + penalty,
            psnr,
            num_gaussians: self.state.len(),
            field_active: self.field_active_at(it),
            densify,
        })
    }

    /// Each node's work at the start of iteration `it` (milestones), in order; a node may
    /// place the nodes before it.
    fn begin_nodes(&mut self, it: u32) -> Result<()> {
        for i in 0..self.nodes.len() {
            let (earlier, rest) = self.nodes.split_at_mut(i);
            rest[0].begin_step(Milestone {
                iteration: it,
                state: &mut self.state,
                dataset: &self.dataset,
                rng: &mut self.rng,
                earlier,
            })?;
        }
        Ok(())
    }

    fn render_options(&self, topk: usize) -> RenderOptions {
        RenderOptions {
            background: self.dataset.background,
            topk,
            ..RenderOptions::default()
        }
    }

    /// The one rasterizer call, the photometric loss, then each node's look at the render
    /// and the hook on the deformation; returns the loss, the PSNR and the hook's loss.
    fn render_and_loss(
        &mut self,
        fi: usize,
        it: u32,
        topk: usize,
        hook: &mut Option<&mut dyn DeformHook>,
        tm: &mut StepTimings,
    ) -> Result<(LossValue, f64, f32)> {
        let opts = self.render_options(topk);
        let ws = &mut self.ws;
        let model = &self.state.model;
        let frame = &self.dataset.train[fi];
        let g = deform::gaussians(model, &ws.deformed);
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
        let mut aux = crate::state::AuxStore::new(&mut self.state.aux, model.len());
        for node in self.nodes.iter_mut() {
            let r = Rendered {
                iteration: it,
                frame: fi,
                topk,
                topk_ids: out.topk_ids,
                topk_weights: out.topk_weights,
                dl_dimage: &mut ws.dl_dimage,
            };
            node.after_render(r, &mut aux)?;
        }
        let psnr = metrics::psnr(out.image, &ws.gt);
        ws.radii.clear();
        ws.radii.extend_from_slice(out.radii);
        ws.size = (out.width, out.height);
        tm.record(Phase::Loss, t0);
        let mut extra_loss = 0.0;
        let deformation = self.nodes.iter_mut().find_map(|n| n.deformation());
        if let (Some(h), Some(d)) = (hook.as_mut(), deformation) {
            let t0 = std::time::Instant::now();
            let ctx = HookContext {
                iteration: it,
                frame_index: fi,
                frame,
                field_active: d.active,
                width: out.width,
                height: out.height,
                topk,
                topk_ids: out.topk_ids,
                topk_weights: out.topk_weights,
                delta: d.delta,
                means: &model.means,
                field_rows: d.rows,
            };
            extra_loss = h
                .apply(&ctx, &mut aux, d.grad)
                .map_err(|e| TrainError::Hook(e.to_string()))?;
            tm.record(Phase::Hook, t0);
        }
        let projection = ws.raster.timings().project;
        tm.move_seconds(Phase::RasterForward, Phase::Projection, projection);
        Ok((loss, psnr, extra_loss))
    }

    /// Rasterizer backward, the nodes' own loss terms, the chain through the rest
    /// placement, then each node's chain through its own placement; returns the nodes'
    /// loss.
    fn backward(&mut self, fi: usize, it: u32, tm: &mut StepTimings) -> Result<f32> {
        let opts = self.render_options(0);
        let ws = &mut self.ws;
        let model = &self.state.model;
        let frame = &self.dataset.train[fi];
        let g = deform::gaussians(model, &ws.deformed);
        let t0 = std::time::Instant::now();
        ws.raster
            .backward(&g, &frame.camera, &opts, &ws.dl_dimage, None, &mut ws.grads)?;
        tm.record(Phase::RasterBackward, t0);
        let projection = ws.raster.timings().project;
        tm.move_seconds(Phase::RasterBackward, Phase::ProjectionBackward, projection);
        let placed = Placed {
            iteration: it,
            frame: fi,
            camera: &frame.camera,
            time: frame.time,
            model,
            deformed: &ws.deformed,
        };
        let mut nodes_loss = 0.0;
        for node in self.nodes.iter_mut() {
            nodes_loss += node.add_loss(&placed, &mut ws.grads, tm)?;
        }
        let t0 = std::time::Instant::now();
        let (gr, canon) = (&ws.grads, &mut ws.canon);
        deform::backward(model, &gr.means, &gr.quats, &gr.scales, canon);
        tm.record(Phase::Deform, t0);
        let rows = Rows {
            model,
            column: &self.state.object,
            aux: &self.state.aux,
        };
        for node in self.nodes.iter_mut() {
            node.backward(rows, &ws.grads, &mut ws.canon, tm);
        }
        Ok(nodes_loss)
    }

    /// Adam on the Gaussians and on each node's parameters, then density control (3DGS
    /// `train.py` order; what the strategy does when: `densify::Schedule`). Returns the
    /// refinement's report, whether every value the optimizer wrote is finite, and the
    /// `mcmc` penalties' loss.
    fn optimize_and_densify(
        &mut self,
        it: u32,
        frame: usize,
        tm: &mut StepTimings,
    ) -> (Option<DensifyReport>, bool, f32) {
        let t0 = std::time::Instant::now();
        let c = &self.cfg;
        let hp = AdamHyper {
            beta1: c.lr.adam_beta1,
            beta2: c.lr.adam_beta2,
            eps: c.lr.adam_eps,
        };
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
        let mut finite = true;
        if plan.step_gaussians {
            finite &= self.adam_gaussians(lr_means, hp, plan.step_opacity);
        }
        let mut aux = crate::state::AuxStore::new(&mut self.state.aux, self.state.model.len());
        for node in self.nodes.iter_mut() {
            finite &= node.step(it, hp, &mut aux);
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
            self.before_refine(it, frame);
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

    /// Each node's rule before a refinement, seeing where this step placed every row.
    fn before_refine(&mut self, it: u32, frame: usize) {
        let mut placed = vec![true; self.state.len()];
        for node in self.nodes.iter() {
            node.mark_unplaced(&self.state.object, &mut placed);
        }
        let step = Refining {
            iteration: it,
            time: self.dataset.train[frame].time,
            deformed: &self.ws.deformed,
            placed: &placed,
        };
        for node in self.nodes.iter() {
            node.before_refine(&mut self.state, &step);
        }
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

/// The first Gaussians: the scene's point cloud (if any and enabled) or random points
/// from `rng`, prepared for the density-control strategy.
fn initial_gaussians(cfg: &TrainConfig, dataset: &Dataset, rng: &mut ChaCha8Rng) -> GaussianModel {
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
        _ => crate::init::random(&cfg.init, rng),
    };
    let mut model = model;
    if cfg.densify.strategy == crate::densify::Strategy::Mcmc {
        crate::densify::mcmc::prepare_init(&mut model, &cfg.densify.mcmc);
    }
    if cfg.densify.strategy == crate::densify::Strategy::Mcmc && model.len() > cfg.densify.mcmc.cap
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
    model
}
