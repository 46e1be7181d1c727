//! The deformation field's node: the rows of no object (the column's
//! [`crate::state::NO_OBJECT`]), moved by Deformable-3DGS's field (Yang et al., CVPR 2024):
//! δ = F(γ(x), γ(t)) added to the rest placement, mean + δx, normalize(q) + δr,
//! exp(log_scale) + δs, with δ = 0 during the warm-up. The node owns the field's weights,
//! their Adam state and the field's learning-rate schedule; the Gaussians' own parameters
//! stay in the store and step with it.

use crate::adam::{expon_lr, Adam, AdamHyper};
use crate::config::LrConfig;
use crate::deform::{CanonicalGrads, Deformed};
use crate::error::Result;
use crate::field::{DeformField, DeformOutput, FieldConfig};
use crate::finite::first_nonfinite;
use crate::node::{At, Deformation, Node, Rows, SectionReader, SectionWriter};
use crate::state::{AuxStore, NO_OBJECT};
use crate::timing::{Phase, StepTimings};
use splat::Gradients;
use std::any::Any;

/// The field's learning rate: `init → final` exponentially over `max_steps` (`[lr]`).
#[derive(Clone, Copy, Debug)]
struct Schedule {
    init: f32,
    last: f32,
    max_steps: u32,
}

pub struct FieldNode {
    pub field: DeformField,
    pub adam: Adam,
    lr: Schedule,
    /// Whether the last placement applied δ (past the warm-up).
    active: bool,
    /// The rows the field was evaluated on in the last placement (ascending).
    rows: Vec<u32>,
    delta: DeformOutput,
    /// `dL/dδ` from a hook, then with the rasterizer's gradient added.
    grad: DeformOutput,
    weight_grad: Vec<f32>,
}

impl FieldNode {
    /// A fresh field from the run's random stream; `lr` gives its learning-rate schedule.
    pub fn new(cfg: &FieldConfig, lr: &LrConfig, rng: &mut impl rand::Rng) -> Self {
        let field = DeformField::new(cfg, rng);
        let adam = Adam::zeros(field.mlp.num_params());
        Self {
            field,
            adam,
            lr: Schedule {
                init: lr.field_init,
                last: lr.field_final,
                max_steps: lr.field_max_steps,
            },
            active: false,
            rows: Vec::new(),
            delta: DeformOutput::default(),
            grad: DeformOutput::default(),
            weight_grad: Vec::new(),
        }
    }

    /// Whether δ applies at `iteration` (Deformable-3DGS: from `warm_up`).
    pub fn active_at(&self, iteration: u32) -> bool {
        iteration >= self.field.cfg.warm_up
    }

    /// The rows the field evaluates at `at`: those of no object, and with a view and
    /// `visible_only`, only those whose canonical mean can reach it.
    fn select_rows(&mut self, rows: Rows<'_>, at: &At<'_>) {
        let n = rows.model.len() as u32;
        match at.camera {
            Some(cam) => {
                let fc = &self.field.cfg;
                crate::visibility::field_rows(
                    &rows.model.means,
                    cam,
                    fc.visible_only,
                    fc.visible_margin,
                    &mut self.rows,
                );
            }
            None => {
                self.rows.clear();
                self.rows.extend(0..n);
            }
        }
        self.rows.retain(|&r| rows.column[r as usize] == NO_OBJECT);
    }
}

impl Node for FieldNode {
    fn kind(&self) -> &'static str {
        "deformation field"
    }

    fn owns(&self, id: u8) -> bool {
        id == NO_OBJECT
    }

    fn place(&mut self, rows: Rows<'_>, at: &At<'_>, out: &mut Deformed, tm: &mut StepTimings) {
        self.grad.reset(rows.model.len());
        self.active = self.active_at(at.iteration);
        if !self.active {
            return;
        }
        let t0 = std::time::Instant::now();
        self.select_rows(rows, at);
        let means = &rows.model.means;
        self.field
            .forward(means, at.time, &self.rows, &mut self.delta);
        tm.record(Phase::FieldForward, t0);
        let t0 = std::time::Instant::now();
        crate::deform::add_delta(&self.delta, out);
        tm.record(Phase::Deform, t0);
    }

    fn deformation(&mut self) -> Option<Deformation<'_>> {
        Some(Deformation {
            active: self.active,
            delta: &self.delta,
            rows: &self.rows,
            grad: &mut self.grad,
        })
    }

    /// The rest chain ([`crate::deform::backward`]) is already this node's: δ enters
    /// additively, so `dL/dδ` = the placed rows' gradient plus the hook's term.
    fn backward(
        &mut self,
        _rows: Rows<'_>,
        grads: &Gradients,
        _canon: &mut CanonicalGrads,
        tm: &mut StepTimings,
    ) {
        if !self.active {
            return;
        }
        let t0 = std::time::Instant::now();
        for (e, g) in [
            (&mut self.grad.dx, &grads.means),
            (&mut self.grad.dr, &grads.quats),
            (&mut self.grad.ds, &grads.scales),
        ] {
            e.iter_mut().zip(g).for_each(|(a, b)| *a += b);
        }
        self.field.backward(&self.grad, &mut self.weight_grad);
        tm.record(Phase::FieldBackward, t0);
    }

    fn step(&mut self, iteration: u32, hp: AdamHyper, _aux: &mut AuxStore<'_>) -> bool {
        if !self.active_at(iteration) {
            return true;
        }
        let s = self.lr;
        let lr = expon_lr(s.init, s.last, s.max_steps, iteration);
        self.adam
            .step(&mut self.field.mlp.params, &self.weight_grad, hp, lr)
    }

    fn mark_unplaced(&self, column: &[u8], placed: &mut [bool]) {
        if !self.active {
            return;
        }
        let mut evaluated = vec![false; column.len()];
        self.rows.iter().for_each(|&r| evaluated[r as usize] = true);
        for ((p, &id), e) in placed.iter_mut().zip(column).zip(evaluated) {
            if id == NO_OBJECT && !e {
                *p = false;
            }
        }
    }

    fn nonfinite(&self) -> Option<String> {
        if let Some(i) = first_nonfinite(&self.field.mlp.params) {
            return Some(format!("deformation-field weight {i}"));
        }
        for (which, v) in [("first", &self.adam.m), ("second", &self.adam.v)] {
            if let Some(i) = first_nonfinite(v) {
                return Some(format!(
                    "Adam {which} moment of deformation-field weight {i}"
                ));
            }
        }
        None
    }

    fn save(&self, out: &mut dyn SectionWriter) {
        let p = &self.field.mlp.params;
        out.tensor("field.params".into(), vec![p.len()], p);
        out.tensor("field.adam.m".into(), vec![self.adam.m.len()], &self.adam.m);
        out.tensor("field.adam.v".into(), vec![self.adam.v.len()], &self.adam.v);
        out.meta("field.adam.step", self.adam.step.to_string());
    }

    fn load(&mut self, sec: &dyn SectionReader) -> Result<()> {
        let want = self.field.mlp.num_params();
        if let Some(got) = sec.len_of("field.params").filter(|&g| g != want) {
            // Either file may be the wrong one: name both.
            let c = &self.field.cfg;
            return Err(sec.problem(format!(
                "tensor `field.params` holds {got} values, but the {}×{} field of {} has {want}",
                c.depth,
                c.width,
                sec.config_file().display()
            )));
        }
        self.field.mlp.params = sec.f32s("field.params", want)?;
        Ok(())
    }

    fn load_optimizer(&mut self, sec: &dyn SectionReader) -> Result<()> {
        let p = self.field.mlp.num_params();
        let step = sec
            .meta("field.adam.step")
            .ok_or_else(|| sec.problem("metadata `field.adam.step` missing".into()))?;
        self.adam = Adam {
            m: sec.f32s("field.adam.m", p)?,
            v: sec.f32s("field.adam.v", p)?,
            step: step.parse().map_err(|_| {
                sec.problem(format!(
                    "metadata `field.adam.step` = `{step}` is not valid"
                ))
            })?,
        };
        Ok(())
    }

    fn as_any(&self) -> &dyn Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}
