//! A residual deformation on top of each object's rigid or articulated motion
//! (`[objects] residual = true`). The poses carry what moves as a body or as parts; what
//! they cannot carry (a hand's fingers bending, a field's motion that is not piecewise
//! rigid) is left to a small Deformable-3DGS field per object, evaluated in the object's
//! own frame: at time t a Gaussian of object o with stored mean `x`, quaternion `q` and
//! log-scale `l` is placed as
//!
//! `x' = x + δx`, `q' = q/|q| + δr`, `s = exp(l) + δs`, with `δ = F_o(γ(x), γ(t))`,
//!
//! and then by its poses exactly as without the residual (`x_w = R·x' + p`,
//! `q_w = r ⊗ q'/|q'|`). drivestudio's deformable nodes compose an instance pose with a
//! per-instance deformation network the same way. The parts of one articulated object
//! share their object's field (they are stored in one frame). Each field's head starts at
//! zero, so the objects' start is unchanged and the residual grows only where the
//! photometric loss asks for it.

use super::place::Shape;
use super::RigidObject;
use crate::adam::{expon_lr, Adam, AdamHyper};
use crate::deform::{CanonicalGrads, Deformed};
use crate::error::Result;
use crate::field::{DeformField, DeformOutput, FieldConfig};
use crate::finite::first_nonfinite;
use crate::model::GaussianModel;
use crate::node::{SectionReader, SectionWriter};
use crate::quat;
use rand::SeedableRng;

/// One object's field, its optimizer and this step's evaluation.
pub struct ObjectField {
    /// The object's ID in the ID maps (its parts' `mask`).
    pub mask: u8,
    pub field: DeformField,
    pub adam: Adam,
    rows: Vec<u32>,
    delta: DeformOutput,
    grad: DeformOutput,
    weight_grad: Vec<f32>,
}

/// The residual fields of a run's objects (empty until the objects start).
pub struct Residual {
    pub cfg: FieldConfig,
    lr: (f32, f32, u32),
    pub fields: Vec<ObjectField>,
    /// This step's shape: the store's means and quaternions, with δ on object rows.
    means: Vec<f32>,
    quats: Vec<f32>,
    /// Seconds of the last [`Residual::place`] and [`Residual::backward`], so the node
    /// can count them as the field's phases rather than as placement.
    pub seconds: (f64, f64),
}

/// The field of one object: `depth × width`, Deformable-3DGS's encodings, no time network,
/// evaluated on every row of the object, head at zero (δ = 0 at the start).
pub fn field_config(depth: usize, width: usize) -> FieldConfig {
    FieldConfig {
        depth,
        width,
        skip: depth / 2,
        warm_up: 0,
        visible_only: false,
        time_net_width: 0,
        head_init_scale: 0.0,
        ..FieldConfig::default()
    }
}

impl Residual {
    /// `lr`: the main field's schedule (`[lr] field_init`, `field_final`,
    /// `field_max_steps`), which [`Residual::step`] restarts at the objects' start.
    pub fn new(cfg: FieldConfig, lr: (f32, f32, u32)) -> Self {
        Self {
            cfg,
            lr,
            fields: Vec::new(),
            means: Vec::new(),
            quats: Vec::new(),
            seconds: (0.0, 0.0),
        }
    }

    /// One field per object of `objects` that has none yet; each from its own seeded
    /// stream (`seed` and the object's ID), so a run's other random draws do not move.
    pub fn ensure(&mut self, objects: &[RigidObject], seed: u64) {
        for o in objects {
            if self.fields.iter().all(|f| f.mask != o.mask) {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ u64::from(o.mask));
                let field = DeformField::new(&self.cfg, &mut rng);
                self.fields.push(ObjectField::new(o.mask, field));
            }
        }
    }

    /// Evaluates every object's field at `t` on its rows (`rows` per `objects` slot, as
    /// `place::rows_by_object` gives them; an object's parts share its field), writes δs
    /// into `out`'s scales (which hold the rest scales there) and returns the shape the
    /// poses place.
    pub fn place(
        &mut self,
        objects: &[RigidObject],
        rows: &[Vec<u32>],
        model: &GaussianModel,
        t: f32,
        out: &mut Deformed,
    ) -> Shape<'_> {
        let t0 = std::time::Instant::now();
        self.means.clone_from(&model.means);
        self.quats.clone_from(&model.quats);
        for f in &mut self.fields {
            f.rows.clear();
            for (o, r) in objects.iter().zip(rows) {
                if o.mask == f.mask {
                    f.rows.extend_from_slice(r);
                }
            }
            f.rows.sort_unstable();
            f.field.forward(&model.means, t, &f.rows, &mut f.delta);
            for &i in &f.rows {
                let i = i as usize;
                for c in 0..3 {
                    self.means[i * 3 + c] += f.delta.dx[i * 3 + c];
                    out.scales[i * 3 + c] += f.delta.ds[i * 3 + c];
                }
                let u = quat::normalize(&model.quats[i * 4..i * 4 + 4]).0;
                let dr = &f.delta.dr[i * 4..i * 4 + 4];
                let q = &mut self.quats[i * 4..i * 4 + 4];
                q.iter_mut()
                    .zip(u)
                    .zip(dr)
                    .for_each(|((q, u), d)| *q = u + d);
            }
        }
        self.seconds.0 = t0.elapsed().as_secs_f64();
        Shape {
            means: &self.means,
            quats: &self.quats,
        }
    }

    /// The shape of the last [`Residual::place`], when some object has a field.
    pub fn shape(&self) -> Option<Shape<'_>> {
        (!self.fields.is_empty()).then_some(Shape {
            means: &self.means,
            quats: &self.quats,
        })
    }

    /// `canon` holds, on object rows, the gradients of the shape the poses placed
    /// (`dL/dx'`, `dL/dq'`): they are `dL/dδx` and `dL/dδr`, `g_scales` (world = object
    /// frame) is `dL/dδs`. Collects each field's weight gradient and leaves in `canon` the
    /// gradients of the store's means (`dL/dx = dL/dx'`) and quaternions (through
    /// `q/|q|`).
    pub fn backward(
        &mut self,
        model: &GaussianModel,
        g_scales: &[f32],
        canon: &mut CanonicalGrads,
    ) {
        let t0 = std::time::Instant::now();
        let n = model.len();
        for f in &mut self.fields {
            f.grad.reset(n);
            for &i in &f.rows {
                let i = i as usize;
                f.grad.dx[i * 3..i * 3 + 3].copy_from_slice(&canon.means[i * 3..i * 3 + 3]);
                f.grad.ds[i * 3..i * 3 + 3].copy_from_slice(&g_scales[i * 3..i * 3 + 3]);
                let g: [f32; 4] = std::array::from_fn(|c| canon.quats[i * 4 + c]);
                f.grad.dr[i * 4..i * 4 + 4].copy_from_slice(&g);
                let (u, norm) = quat::normalize(&model.quats[i * 4..i * 4 + 4]);
                canon.quats[i * 4..i * 4 + 4].copy_from_slice(&quat::normalize_vjp(u, norm, g));
            }
            f.field.backward(&f.grad, &mut f.weight_grad);
        }
        self.seconds.1 = t0.elapsed().as_secs_f64();
    }

    /// Adam on every field at `iteration`; whether every weight is finite after it. The
    /// rate is the `[lr] field_*` schedule started afresh at the objects' `start` and
    /// compressed into what is left of it: a field that begins at δ = 0 half-way through
    /// a run would otherwise learn at the main field's late, decayed rate.
    pub fn step(&mut self, iteration: u32, start: u32, hp: AdamHyper) -> bool {
        let (init, last, max_steps) = self.lr;
        let left = max_steps.saturating_sub(start).max(1);
        let lr = expon_lr(init, last, left, iteration.saturating_sub(start));
        let mut ok = true;
        for f in &mut self.fields {
            if f.rows.is_empty() {
                continue;
            }
            ok &= f.adam.step(&mut f.field.mlp.params, &f.weight_grad, hp, lr);
        }
        ok
    }

    /// The first non-finite weight or moment, named.
    pub fn nonfinite(&self) -> Option<String> {
        self.fields.iter().find_map(|f| {
            let p = &f.field.mlp.params;
            let bad = [
                ("weight", p),
                ("Adam moment", &f.adam.m),
                ("Adam moment", &f.adam.v),
            ];
            bad.into_iter().find_map(|(what, v)| {
                first_nonfinite(v)
                    .map(|i| format!("residual field of object {}: {what} {i}", f.mask))
            })
        })
    }

    /// Each field's weights and Adam state, named by object ID.
    pub fn save(&self, out: &mut dyn SectionWriter) {
        let masks: Vec<String> = self.fields.iter().map(|f| f.mask.to_string()).collect();
        out.meta("objects.residual", masks.join(","));
        for f in &self.fields {
            let key = |what: &str| format!("objects.residual.{}.{what}", f.mask);
            let p = &f.field.mlp.params;
            out.tensor(key("params"), vec![p.len()], p);
            out.tensor(key("adam.m"), vec![f.adam.m.len()], &f.adam.m);
            out.tensor(key("adam.v"), vec![f.adam.v.len()], &f.adam.v);
            out.meta(&key("adam.step"), f.adam.step.to_string());
        }
    }

    /// The fields' weights (rendering); `optimizer` adds their Adam state (resuming).
    pub fn load(&mut self, sec: &dyn SectionReader, optimizer: bool) -> Result<()> {
        let Some(list) = sec.meta("objects.residual").filter(|l| !l.is_empty()) else {
            self.fields.clear();
            return Ok(());
        };
        let mut fields = Vec::new();
        for m in list.split(',') {
            let mask: u8 = m.parse().map_err(|_| {
                sec.problem(format!("`objects.residual` lists `{m}`, not an object ID"))
            })?;
            let key = |what: &str| format!("objects.residual.{mask}.{what}");
            let mut field =
                DeformField::new(&self.cfg, &mut rand_chacha::ChaCha8Rng::seed_from_u64(0));
            let want = field.mlp.num_params();
            if let Some(got) = sec.len_of(&key("params")).filter(|&g| g != want) {
                return Err(sec.problem(format!(
                    "tensor `{}` holds {got} values, but the {}×{} residual field of {} has {want}",
                    key("params"),
                    self.cfg.depth,
                    self.cfg.width,
                    sec.config_file().display()
                )));
            }
            field.mlp.params = sec.f32s(&key("params"), want)?;
            let mut f = ObjectField::new(mask, field);
            if optimizer {
                f.adam = read_adam(sec, &key("adam.m"), &key("adam.v"), &key("adam.step"), want)?;
            }
            fields.push(f);
        }
        self.fields = fields;
        Ok(())
    }
}

fn read_adam(sec: &dyn SectionReader, m: &str, v: &str, step: &str, len: usize) -> Result<Adam> {
    let s = sec
        .meta(step)
        .ok_or_else(|| sec.problem(format!("metadata `{step}` missing")))?;
    Ok(Adam {
        m: sec.f32s(m, len)?,
        v: sec.f32s(v, len)?,
        step: s
            .parse()
            .map_err(|_| sec.problem(format!("metadata `{step}` = `{s}` is not valid")))?,
    })
}

impl ObjectField {
    fn new(mask: u8, field: DeformField) -> Self {
        let adam = Adam::zeros(field.mlp.num_params());
        Self {
            mask,
            field,
            adam,
            rows: Vec::new(),
            delta: DeformOutput::default(),
            grad: DeformOutput::default(),
            weight_grad: Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deform;
    use crate::objects::place::{self, WorldGrads};
    use crate::objects::trajectory::{Trajectory, TrajectoryGrad};

    const COLUMN: [u8; 3] = [4, crate::state::NO_OBJECT, 4];

    fn model() -> GaussianModel {
        GaussianModel {
            means: vec![0.3, -0.2, 0.5, 1.0, 1.0, 1.0, -0.4, 0.1, 0.2],
            quats: vec![0.9, 0.1, -0.2, 0.3, 1.0, 0.0, 0.0, 0.0, 0.5, -0.5, 0.3, 0.1],
            log_scales: vec![-2.0, -1.5, -1.0, -2.0, -2.0, -2.0, -1.2, -1.8, -2.2],
            opacity_logits: vec![0.0; 3],
            sh: vec![0.0; 3 * 48],
            sh_degree: 0,
        }
    }

    fn objects() -> Vec<RigidObject> {
        let tr = Trajectory {
            times: vec![0.0, 1.0],
            translations: vec![[0.1, 0.2, 0.0], [0.8, -0.3, 0.4]],
            rotations: vec![[1.0, 0.0, 0.0, 0.1], [0.7, 0.2, -0.3, 0.5]],
        };
        vec![RigidObject::new(4, "arm".into(), tr, false)]
    }

    /// A residual whose head is not zero, so δ and every layer's gradient are.
    fn residual() -> Residual {
        let cfg = FieldConfig {
            head_init_scale: 1.0,
            ..field_config(2, 8)
        };
        let mut r = Residual::new(cfg, (8e-4, 1.6e-6, 1000));
        r.ensure(&objects(), 7);
        r
    }

    /// Σ w·x_w + Σ v·q_w + Σ z·s over the placed scene at `t`.
    fn loss(m: &GaussianModel, r: &mut Residual, (w, v, z): (&[f32], &[f32], &[f32])) -> f64 {
        let objs = objects();
        let mut rows = Vec::new();
        place::rows_by_object(&objs, &COLUMN, &mut rows);
        let mut d = Deformed::default();
        deform::apply(m, None, &mut d);
        let shape = r.place(&objs, &rows, m, 0.3, &mut d);
        place::place(&objs, &rows, shape, 0.3, &mut d, &mut Vec::new());
        let dot =
            |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| f64::from(x * y)).sum::<f64>();
        dot(&d.means, w) + dot(&d.quats, v) + dot(&d.scales, z)
    }

    /// The store's gradients and the field's weight gradients through the residual and the
    /// poses match finite differences; rows of no object are left to the rest chain.
    #[test]
    fn chain_through_the_residual_matches_finite_differences() {
        let w: Vec<f32> = (0..9).map(|k| ((k * 7 % 5) as f32 - 2.0) * 0.3).collect();
        let v: Vec<f32> = (0..12).map(|k| ((k * 3 % 7) as f32 - 3.0) * 0.2).collect();
        let z: Vec<f32> = (0..9).map(|k| ((k * 5 % 4) as f32 - 1.5) * 0.4).collect();
        let (m, objs) = (model(), objects());
        let mut r = residual();
        let mut rows = Vec::new();
        place::rows_by_object(&objs, &COLUMN, &mut rows);
        let mut d = Deformed::default();
        deform::apply(&m, None, &mut d);
        let mut poses = Vec::new();
        let shape = r.place(&objs, &rows, &m, 0.3, &mut d);
        place::place(&objs, &rows, shape, 0.3, &mut d, &mut poses);
        assert!(r.fields[0].delta.dx.iter().any(|&x| x.abs() > 1e-3));
        let mut canon = CanonicalGrads::default();
        deform::backward(&m, &w, &v, &z, &mut canon);
        let mut tg = vec![TrajectoryGrad::zeros(2)];
        let world = WorldGrads {
            means: &w,
            quats: &v,
        };
        let shape = r.shape().unwrap();
        place::backward(&objs, &rows, shape, &poses, world, &mut canon, &mut tg);
        r.backward(&m, &z, &mut canon);
        let f = (&w[..], &v[..], &z[..]);
        let h = 1e-3;
        let fd_model = |edit: &dyn Fn(&mut GaussianModel, f32)| {
            let (mut mp, mut mm) = (m.clone(), m.clone());
            edit(&mut mp, h);
            edit(&mut mm, -h);
            let (mut r1, mut r2) = (residual(), residual());
            (loss(&mp, &mut r1, f) - loss(&mm, &mut r2, f)) / (2.0 * f64::from(h))
        };
        let close = |fd: f64, got: f32, what: String| {
            assert!(
                (fd - f64::from(got)).abs() < 3e-3 * (1.0 + fd.abs()),
                "{what}: {fd} vs {got}"
            );
        };
        for k in 0..9 {
            // The field reads the mean (γ(x)); its input gradient is not chained, as in
            // Deformable-3DGS (the mean goes in detached), so only rows of no object match
            // a finite difference of the mean.
            if COLUMN[k / 3] == crate::state::NO_OBJECT {
                close(
                    fd_model(&|m, e| m.means[k] += e),
                    canon.means[k],
                    format!("mean {k}"),
                );
            }
            close(
                fd_model(&|m, e| m.log_scales[k] += e),
                canon.log_scales[k],
                format!("log-scale {k}"),
            );
        }
        for k in 0..12 {
            close(
                fd_model(&|m, e| m.quats[k] += e),
                canon.quats[k],
                format!("quat {k}"),
            );
        }
        let grad = r.fields[0].weight_grad.clone();
        let n = grad.len();
        for k in (0..n).step_by(n / 23 + 1) {
            let fd = {
                let (mut r1, mut r2) = (residual(), residual());
                r1.fields[0].field.mlp.params[k] += h;
                r2.fields[0].field.mlp.params[k] -= h;
                (loss(&m, &mut r1, f) - loss(&m, &mut r2, f)) / (2.0 * f64::from(h))
            };
            close(fd, grad[k], format!("field weight {k}"));
        }
    }

    /// Rows of the object get δ from their object's field and no other; the rest of the
    /// store is copied as it is.
    #[test]
    fn shape_moves_only_the_objects_rows() {
        let (m, objs) = (model(), objects());
        let mut r = residual();
        let mut d = Deformed::default();
        deform::apply(&m, None, &mut d);
        let rest_scales = d.scales.clone();
        let mut rows = Vec::new();
        place::rows_by_object(&objs, &COLUMN, &mut rows);
        let shape = r.place(&objs, &rows, &m, 0.5, &mut d);
        assert_eq!(shape.means[3..6], m.means[3..6]);
        assert_eq!(shape.quats[4..8], m.quats[4..8]);
        assert_eq!(d.scales[3..6], rest_scales[3..6]);
        assert_ne!(shape.means[0..3], m.means[0..3]);
        assert_ne!(d.scales[6..9], rest_scales[6..9]);
    }
}
