//! The rigid objects as a node of the scene model: rows whose column holds an object's ID,
//! stored in that object's frame and placed by its trajectory `T_o(t)` (no δ, no
//! time-varying scale or opacity). The node owns the trajectories and their Adam state,
//! brings the objects in at `start_iter` and re-applies the occlusion gauge at
//! `rescale_at` ([`Node::begin_step`]), masks object pixels out of the background's
//! gradient before the start and records the membership votes ([`Node::after_render`]),
//! adds the alpha-against-mask term ([`Node::add_loss`]) and moves voted Gaussians between
//! objects before each refinement ([`Node::before_refine`]).

use super::membership::StepPlacement;
use super::{adopt, regauge, start, ObjectSource, ObjectsConfig, RigidObjects};
use crate::adam::AdamHyper;
use crate::deform::{CanonicalGrads, Deformed};
use crate::error::{Result, TrainError};
use crate::node::{
    At, Milestone, Node, Placed, Refining, Rendered, Rows, SectionReader, SectionWriter,
};
use crate::state::{AuxStore, GaussianState};
use crate::timing::{Phase, StepTimings};
use splat::Gradients;
use std::any::Any;
use std::time::Instant;

impl RigidObjects {
    /// The node of a run whose `[objects]` enables it: with the training views' ID maps
    /// when `dataset` is given (training an `iterations`-long schedule), without them for
    /// rendering a checkpoint.
    pub fn for_run(
        cfg: &ObjectsConfig,
        dataset: Option<&scene::Dataset>,
        iterations: u32,
    ) -> Result<Option<Self>> {
        if !cfg.enabled {
            return Ok(None);
        }
        Ok(Some(match dataset {
            Some(ds) => Self::for_training(cfg, ds, iterations)?,
            None => Self::new(cfg.clone(), Vec::new(), Vec::new()),
        }))
    }

    /// Brings the objects in: lifted and tracked ([`start`]) or taken over from the field
    /// ([`adopt`]).
    fn start_now(&mut self, m: Milestone<'_>) -> Result<()> {
        let t0 = Instant::now();
        let iteration = m.iteration;
        match self.cfg.source {
            ObjectSource::Lift => {
                start::start(self, m.state, m.dataset, m.rng)?;
            }
            ObjectSource::Field => {
                let at = (&mut *m.state, m.dataset, &mut *m.earlier);
                adopt::adopt(self, at, iteration);
            }
        }
        if self.cfg.skin {
            let (k, radius) = (self.cfg.parts, self.cfg.skin_radius);
            super::parts::skin::init(m.state, &self.objects, k, radius);
        }
        if let Some(r) = &mut self.residual {
            r.ensure(&self.objects, rand::Rng::gen(&mut *m.rng));
        }
        let seconds = t0.elapsed().as_secs_f64();
        tracing::info!(iteration, seconds, "rigid objects started");
        Ok(())
    }

    /// The occlusion gauge again ([`regauge`]), against the rest of the scene placed by the
    /// nodes before this one.
    fn regauge_now(&mut self, m: Milestone<'_>) -> Result<()> {
        let t0 = Instant::now();
        let (earlier, it) = (m.earlier, m.iteration);
        let mut background = |st: &GaussianState, time: f32, out: &mut Deformed| {
            crate::node::place_state(earlier, st, (time, it), out);
        };
        let applied = regauge::regauge(self, m.state, &mut background, m.dataset)?;
        let seconds = t0.elapsed().as_secs_f64();
        tracing::info!(
            iteration = it,
            seconds,
            ?applied,
            "occlusion gauge applied again"
        );
        Ok(())
    }
}

impl Node for RigidObjects {
    fn kind(&self) -> &'static str {
        "rigid objects"
    }

    fn owns(&self, id: u8) -> bool {
        self.objects.iter().any(|o| o.id == id)
    }

    fn begin_step(&mut self, m: Milestone<'_>) -> Result<()> {
        if !self.started && m.iteration >= self.cfg.start_at() {
            self.start_now(m)
        } else if self.started
            && self.cfg.source == ObjectSource::Lift
            && self.cfg.rescale_at.contains(&m.iteration)
        {
            self.regauge_now(m)
        } else {
            Ok(())
        }
    }

    fn topk(&self) -> usize {
        RigidObjects::topk(self)
    }

    fn place(&mut self, rows: Rows<'_>, at: &At<'_>, out: &mut Deformed, tm: &mut StepTimings) {
        let t0 = Instant::now();
        RigidObjects::place(self, rows.model, rows.column, rows.aux, at.time, out);
        tm.record(Phase::Deform, t0);
        if let Some(r) = &self.residual {
            tm.move_seconds(Phase::Deform, Phase::FieldForward, r.seconds.0);
        }
    }

    fn after_render(&mut self, r: Rendered<'_>, aux: &mut AuxStore) -> Result<()> {
        self.mask_background(r.iteration, r.frame, r.dl_dimage);
        self.record_votes(r.frame, r.topk_ids, r.topk_weights, r.topk, aux)
            .map_err(TrainError::Hook)
    }

    fn add_loss(
        &mut self,
        at: &Placed<'_>,
        grads: &mut Gradients,
        tm: &mut StepTimings,
    ) -> Result<f32> {
        if !self.started {
            return Ok(0.0);
        }
        let t0 = Instant::now();
        let cam = at.camera;
        let loss = self.add_mask_loss(at.frame, cam, at.model, at.deformed, grads)?;
        let arap = self.add_arap(at.model, at.deformed, &mut grads.means);
        tm.record(Phase::Objects, t0);
        Ok(loss + arap)
    }

    fn backward(
        &mut self,
        rows: Rows<'_>,
        grads: &Gradients,
        canon: &mut CanonicalGrads,
        tm: &mut StepTimings,
    ) {
        let t0 = Instant::now();
        RigidObjects::backward(self, rows.model, grads, canon);
        tm.record(Phase::Deform, t0);
        if let Some(r) = &self.residual {
            tm.move_seconds(Phase::Deform, Phase::FieldBackward, r.seconds.1);
        }
    }

    /// Adam on the knots and the skinning logits; whether every value is finite after it.
    fn step(&mut self, iteration: u32, hp: AdamHyper, aux: &mut AuxStore<'_>) -> bool {
        RigidObjects::step(self, hp);
        let logits_ok = self.step_skin(iteration, hp, aux);
        let start = self.cfg.start_at();
        let residual_ok = (self.residual.as_mut()).is_none_or(|r| r.step(iteration, start, hp));
        logits_ok && residual_ok && self.nonfinite_knot().is_none()
    }

    fn before_refine(&self, state: &mut GaussianState, step: &Refining<'_>) {
        let at = StepPlacement {
            deformed: step.deformed,
            placed: step.placed,
            time: step.time,
        };
        let skinned = super::parts::skin::rows_of(&state.aux).is_some();
        let before = skinned.then(|| state.object.clone());
        let moved = self.transfer(state, &at);
        if let Some(before) = before {
            super::parts::skin::rehome(state, &self.objects, &before);
        }
        tracing::debug!(
            iteration = step.iteration,
            moved,
            "object membership transfers"
        );
    }

    fn nonfinite(&self) -> Option<String> {
        let residual = self.residual.as_ref().and_then(|r| r.nonfinite());
        self.nonfinite_knot().or(residual)
    }

    fn save(&self, out: &mut dyn SectionWriter) {
        out.meta("objects", super::store::metadata(self));
        super::store::write_tensors(self, &mut |name, shape, v| out.tensor(name, shape, v));
        if let Some(r) = &self.residual {
            r.save(out);
        }
    }

    /// Trajectories and their Adam state together (a few hundred floats).
    fn load(&mut self, sec: &dyn SectionReader) -> Result<()> {
        let tensor = |name: &str, len: usize| sec.f32s(name, len);
        let stored = super::store::read(sec.meta("objects"), tensor, |p| sec.problem(p))?;
        self.started = stored.started;
        self.start_reports = stored.start_reports;
        self.objects = stored.objects;
        self.knot_adam = stored.knot_adam;
        self.joints = stored.joints;
        match &mut self.residual {
            Some(r) => r.load(sec, false),
            None => Ok(()),
        }
    }

    fn load_optimizer(&mut self, sec: &dyn SectionReader) -> Result<()> {
        match &mut self.residual {
            Some(r) => r.load(sec, true),
            None => Ok(()),
        }
    }

    fn as_any(&self) -> &dyn Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}
