//! Learned skinning of articulated objects in training (SC-GS binds Gaussians to control
//! points the same way; here the "control points" are the object's parts, which the ID
//! maps let us find per object). Every Gaussian of an object with two or more parts keeps
//! one logit per part in the store's per-Gaussian rows ([`SKIN_NAME`]: `k` logits, then
//! their Adam moments m and v), and is placed at time t by a blend of its object's part
//! poses `(R_k, p_k)`, unit quaternions `r_k`, with `w = softmax(z)` (linear blend
//! skinning):
//!
//! `x_w = Σ_k w_k (R_k x + p_k)`, `q_w = n ⊗ q/|q|`, `n = S/|S|`, `S = Σ_k w_k s_k r_k`,
//!
//! `s_k = ±1` putting `r_k` in the hemisphere of the Gaussian's home part (the part its
//! column names), since `r` and `−r` are one rotation. Backward, for `g_x`, `g_q`:
//! `dL/dx = Σ w_k R_kᵀ g_x`; `dL/dn = g_q ⊗ u*`, `dL/du = n* ⊗ g_q` (u = q/|q|);
//! `dL/dS = (I − n nᵀ) dL/dn / |S|`; per part `dL/dp_k = w_k g_x`, `dL/dR_k = w_k g_x xᵀ`,
//! `dL/dr_k = w_k s_k dL/dS`, `dL/dw_k = g_x·(R_k x + p_k) + s_k r_k·dL/dS`; and the
//! softmax `dL/dz_k = w_k (dL/dw_k − Σ_j w_j dL/dw_j)`.
//!
//! The logits start from the split's parts: `z_k = −d_k² / 2σ²`, `d_k` the distance from
//! the Gaussian to part k's nearest Gaussian (0 for its own part), `σ = skin_radius` times
//! their median spacing, so a Gaussian inside a part starts on it and one at a joint
//! blends its neighbours. At each densification the column follows the largest weight
//! (so per-part scores and the mask term see where a Gaussian went), and a Gaussian the
//! votes bring into the object starts on the part it joined.

use super::super::place::{Shape, WorldGrads};
use super::super::trajectory::{Pose, PoseGrad, TrajectoryGrad};
use super::super::RigidObject;
use super::cluster::dist2;
use crate::adam::AdamHyper;
use crate::deform::{CanonicalGrads, Deformed};
use crate::quat;
use crate::state::{AuxRows, AuxStore, GaussianState, NO_OBJECT};

/// Name of the per-Gaussian rows holding the logits and their Adam moments.
pub const SKIN_NAME: &str = "objects.skin";

/// Logit gap that puts a Gaussian on one part: the others weigh < e⁻¹² together.
const HARD: f32 = 12.0;

/// The articulated objects: per object (of the ID maps) with two or more bodies, the
/// indices into `objects` of its bodies, in `objects` order (the order of the logits).
pub fn groups(objects: &[RigidObject]) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    let mut seen = [false; 256];
    for o in objects {
        if std::mem::replace(&mut seen[o.mask as usize], true) {
            continue;
        }
        let g: Vec<usize> = (0..objects.len())
            .filter(|&s| objects[s].mask == o.mask)
            .collect();
        if g.len() >= 2 {
            out.push(g);
        }
    }
    out
}

/// For each column ID: its group and its index in the group (None: not skinned).
fn lookup(groups: &[Vec<usize>], objects: &[RigidObject]) -> Vec<Option<(u16, u16)>> {
    let mut t = vec![None; 256];
    for (g, slots) in groups.iter().enumerate() {
        for (k, &s) in slots.iter().enumerate() {
            t[objects[s].id as usize] = Some((g as u16, k as u16));
        }
    }
    t
}

/// The skinning rows of a store, when there are any (logits per row = `cols / 3`).
pub fn rows_of(aux: &[AuxRows]) -> Option<&AuxRows> {
    aux.iter().find(|a| a.name == SKIN_NAME)
}

/// This step's skinned rows and what their placement computed, for the backward pass, the
/// logits' Adam step and the as-rigid-as-possible term.
#[derive(Default)]
pub struct Skinning {
    pub groups: Vec<Vec<usize>>,
    /// Logits per row in the store (the rows hold `3k` values).
    pub k: usize,
    /// Skinned rows, their group and home part.
    pub rows: Vec<u32>,
    pub group: Vec<u16>,
    pub home: Vec<u16>,
    /// Per row, `k` each: weights and hemisphere signs.
    w: Vec<f32>,
    sign: Vec<f32>,
    /// Per row: the blended unit quaternion `n` and `|S|`.
    pub blend: Vec<[f32; 4]>,
    s_norm: Vec<f32>,
    /// `dL/dz` of this step, `k` per row.
    grad: Vec<f32>,
}

impl Skinning {
    /// Whether this step placed any row by blending.
    pub fn active(&self) -> bool {
        !self.rows.is_empty()
    }

    /// Overwrites the rows of articulated objects in `out` with their blended placement
    /// (the rigid placement has put them on their home part); `poses` per `objects` slot.
    pub fn place(
        &mut self,
        objects: &[RigidObject],
        poses: &[Pose],
        shape: Shape<'_>,
        column: &[u8],
        aux: &[AuxRows],
        out: &mut Deformed,
    ) {
        self.rows.clear();
        self.group.clear();
        self.home.clear();
        let Some(a) = rows_of(aux) else { return };
        self.groups = groups(objects);
        self.k = a.cols / 3;
        let table = lookup(&self.groups, objects);
        for (i, &c) in column.iter().enumerate() {
            if let Some((g, h)) = table[c as usize] {
                self.rows.push(i as u32);
                self.group.push(g);
                self.home.push(h);
            }
        }
        let (n, k) = (self.rows.len(), self.k);
        self.w.resize(n * k, 0.0);
        self.sign.resize(n * k, 0.0);
        self.blend.resize(n, [0.0; 4]);
        self.s_norm.resize(n, 0.0);
        for j in 0..n {
            let i = self.rows[j] as usize;
            let slots = &self.groups[self.group[j] as usize];
            let z = &a.data[i * a.cols..i * a.cols + slots.len()];
            let w = &mut self.w[j * k..j * k + slots.len()];
            softmax(z, w);
            let home = poses[slots[self.home[j] as usize]].q;
            let x = [0, 1, 2].map(|c| shape.means[i * 3 + c]);
            let (mut xw, mut s) = ([0.0f32; 3], [0.0f32; 4]);
            for (p, &slot) in slots.iter().enumerate() {
                let pose = &poses[slot];
                let sg = if dot4(pose.q, home) < 0.0 { -1.0 } else { 1.0 };
                self.sign[j * k + p] = sg;
                let y = pose.apply(x);
                for c in 0..3 {
                    xw[c] += w[p] * y[c];
                }
                for (s, q) in s.iter_mut().zip(pose.q) {
                    *s += w[p] * sg * q;
                }
            }
            let (nq, norm) = quat::normalize(&s);
            self.blend[j] = nq;
            self.s_norm[j] = norm;
            let u = quat::normalize(&shape.quats[i * 4..i * 4 + 4]).0;
            out.means[i * 3..i * 3 + 3].copy_from_slice(&xw);
            out.quats[i * 4..i * 4 + 4].copy_from_slice(&quat::mul(nq, u));
        }
    }

    /// The rows to leave out of the rigid chain rule (they were placed here).
    pub fn placed_rows(&self) -> &[u32] {
        &self.rows
    }

    /// Chains the world gradients of the skinned rows back to their object-frame means and
    /// quaternions (overwriting `canon` there), their logits (kept for [`Self::step`]) and
    /// their parts' knots (added into `traj_grads`, one per `objects` slot).
    pub fn backward(
        &mut self,
        objects: &[RigidObject],
        poses: &[Pose],
        shape: Shape<'_>,
        world: WorldGrads<'_>,
        canon: &mut CanonicalGrads,
        traj_grads: &mut [TrajectoryGrad],
    ) {
        let k = self.k;
        let mut pg = vec![(PoseGrad::default(), [[0.0f64; 3]; 3]); objects.len()];
        self.grad.clear();
        self.grad.resize(self.rows.len() * k, 0.0);
        for j in 0..self.rows.len() {
            let i = self.rows[j] as usize;
            let slots = &self.groups[self.group[j] as usize];
            let gx = [0, 1, 2].map(|c| world.means[i * 3 + c]);
            let gq: [f32; 4] = std::array::from_fn(|c| world.quats[i * 4 + c]);
            let x = [0, 1, 2].map(|c| shape.means[i * 3 + c]);
            let (u, unorm) = quat::normalize(&shape.quats[i * 4..i * 4 + 4]);
            let nq = self.blend[j];
            let dn = quat::mul(gq, quat::conj(u));
            let du = quat::mul(quat::conj(nq), gq);
            canon.quats[i * 4..i * 4 + 4].copy_from_slice(&quat::normalize_vjp(u, unorm, du));
            let nd = dot4(nq, dn);
            let ds: [f32; 4] = std::array::from_fn(|c| (dn[c] - nq[c] * nd) / self.s_norm[j]);
            let (w, sg) = (&self.w[j * k..], &self.sign[j * k..]);
            let mut gmean = [0.0f32; 3];
            let mut dw = [0.0f32; 16];
            for (p, &slot) in slots.iter().enumerate() {
                let pose = &poses[slot];
                let back = quat::rotate_inv(&pose.r, gx);
                let y = pose.apply(x);
                dw[p] = dot3(gx, y) + sg[p] * dot4(pose.q, ds);
                let (g, gr) = &mut pg[slot];
                for a in 0..3 {
                    gmean[a] += w[p] * back[a];
                    g.p[a] += f64::from(w[p] * gx[a]);
                    for b in 0..3 {
                        gr[a][b] += f64::from(w[p] * gx[a]) * f64::from(x[b]);
                    }
                }
                for (q, d) in g.q.iter_mut().zip(ds) {
                    *q += f64::from(w[p] * sg[p] * d);
                }
            }
            canon.means[i * 3..i * 3 + 3].copy_from_slice(&gmean);
            let mean_dw: f32 = (0..slots.len()).map(|p| w[p] * dw[p]).sum();
            for p in 0..slots.len() {
                self.grad[j * k + p] = w[p] * (dw[p] - mean_dw);
            }
        }
        for (((o, pose), (g, gr)), tg) in objects.iter().zip(poses).zip(&mut pg).zip(traj_grads) {
            let from_r = quat::to_matrix_vjp(pose.q, gr);
            for (q, d) in g.q.iter_mut().zip(from_r) {
                *q += d;
            }
            // Slots outside the groups got nothing here (their rows are placed rigidly).
            if !o.is_static {
                o.trajectory.accumulate(pose, g, tg);
            }
        }
    }

    /// Adam on the logits of this step's rows (the moments live beside them in the
    /// rows); `t` counts the logits' steps (from 1). Whether every logit is finite.
    pub fn step(&self, aux: &mut AuxStore<'_>, hp: AdamHyper, lr: f32, t: u32) -> bool {
        if self.rows.is_empty() {
            return true;
        }
        let k = self.k;
        let Ok(data) = aux.get_or_zeros(SKIN_NAME, 3 * k) else {
            return true;
        };
        let bc1 = 1.0 - f64::from(hp.beta1).powi(t as i32);
        let bc2 = 1.0 - f64::from(hp.beta2).powi(t as i32);
        let (step, inv_sqrt_bc2) = ((f64::from(lr) / bc1) as f32, (1.0 / bc2.sqrt()) as f32);
        let mut finite = true;
        for (j, &i) in self.rows.iter().enumerate() {
            let kg = self.groups[self.group[j] as usize].len();
            let row = &mut data[i as usize * 3 * k..(i as usize + 1) * 3 * k];
            for p in 0..kg {
                let g = self.grad[j * k + p];
                let m = hp.beta1 * row[k + p] + (1.0 - hp.beta1) * g;
                let v = hp.beta2 * row[2 * k + p] + (1.0 - hp.beta2) * g * g;
                row[k + p] = m;
                row[2 * k + p] = v;
                row[p] -= step * m / (v.sqrt() * inv_sqrt_bc2 + hp.eps);
                finite &= row[p].is_finite();
            }
        }
        finite
    }
}

/// Creates the skinning rows (`k` logits a row) for the articulated objects of `objects`,
/// starting each Gaussian's logits from its distance to each part (module docs). Nothing
/// when no object has two parts.
pub fn init(state: &mut GaussianState, objects: &[RigidObject], k: usize, radius: f32) {
    let groups = groups(objects);
    if groups.is_empty() {
        return;
    }
    let n = state.len();
    let mut store = AuxStore::new(&mut state.aux, n);
    let Ok(data) = store.get_or_zeros(SKIN_NAME, 3 * k) else {
        tracing::warn!("skinning rows of another width in the state: skinning left off");
        return;
    };
    data.fill(0.0);
    let means = &state.model.means;
    let pt = |i: usize| [means[i * 3], means[i * 3 + 1], means[i * 3 + 2]];
    for slots in &groups {
        let ids: Vec<u8> = slots.iter().map(|&s| objects[s].id).collect();
        let rows: Vec<(usize, usize)> = (0..n)
            .filter_map(|i| {
                ids.iter()
                    .position(|&id| id == state.object[i])
                    .map(|p| (i, p))
            })
            .collect();
        let flat: Vec<f32> = rows.iter().flat_map(|&(i, _)| pt(i)).collect();
        let sigma = radius * super::joints::spacing(&flat).max(1e-6);
        for &(i, home) in &rows {
            let mut d2 = vec![f32::INFINITY; ids.len()];
            d2[home] = 0.0;
            for &(j, p) in &rows {
                if p != home {
                    d2[p] = d2[p].min(dist2(pt(i), pt(j)));
                }
            }
            for (p, d) in d2.iter().enumerate() {
                data[i * 3 * k + p] = (-d / (2.0 * sigma * sigma)).max(-HARD);
            }
        }
    }
}

/// At a densification step, after the votes moved Gaussians (`before` is the column
/// before): a Gaussian that joined an articulated object starts on the part it joined, and
/// every skinned Gaussian's column follows its largest weight.
pub fn rehome(state: &mut GaussianState, objects: &[RigidObject], before: &[u8]) {
    let Some(ai) = state.aux.iter().position(|a| a.name == SKIN_NAME) else {
        return;
    };
    let groups = groups(objects);
    let table = lookup(&groups, objects);
    let (cols, k) = (state.aux[ai].cols, state.aux[ai].cols / 3);
    for i in 0..state.len() {
        let Some((g, home)) = table[state.object[i] as usize] else {
            continue;
        };
        let slots = &groups[g as usize];
        let row = &mut state.aux[ai].data[i * cols..(i + 1) * cols];
        if table[before[i] as usize].map(|(gb, _)| gb) != Some(g) {
            row.fill(0.0);
            for (p, z) in row[..slots.len()].iter_mut().enumerate() {
                *z = if p == home as usize { 0.0 } else { -HARD };
            }
            continue;
        }
        let best = (0..slots.len())
            .max_by(|&a, &b| row[a].total_cmp(&row[b]))
            .unwrap_or(home as usize);
        state.object[i] = objects[slots[best]].id;
        debug_assert!(k >= slots.len() && state.object[i] != NO_OBJECT);
    }
}

/// The skinning weights of body `id`'s Gaussians (its rows of `column`, in row order), with
/// the names of the bodies they weigh (its object's parts, in logit order): what
/// `export --per-object` writes beside a skinned part. None for a body that is not skinned.
pub fn weights_of(
    objects: &[RigidObject],
    column: &[u8],
    aux: &[AuxRows],
    id: u8,
) -> Option<(Vec<String>, Vec<Vec<f32>>)> {
    let a = rows_of(aux)?;
    let groups = groups(objects);
    let slots = groups
        .iter()
        .find(|g| g.iter().any(|&s| objects[s].id == id))?;
    let names = slots.iter().map(|&s| objects[s].name.clone()).collect();
    let weights = (0..column.len())
        .filter(|&i| column[i] == id)
        .map(|i| {
            let mut w = vec![0.0; slots.len()];
            softmax(&a.data[i * a.cols..i * a.cols + slots.len()], &mut w);
            w
        })
        .collect();
    Some((names, weights))
}

fn softmax(z: &[f32], w: &mut [f32]) {
    let m = z.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0;
    for (w, &z) in w.iter_mut().zip(z) {
        *w = (z - m).exp();
        sum += *w;
    }
    w.iter_mut().for_each(|w| *w /= sum);
}

fn dot3(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn dot4(a: [f32; 4], b: [f32; 4]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deform;
    use crate::model::GaussianModel;
    use crate::objects::place;
    use crate::objects::trajectory::Trajectory;

    fn model() -> GaussianModel {
        GaussianModel {
            means: vec![
                0.3, -0.2, 0.5, 1.0, 1.0, 1.0, -0.4, 0.1, 0.2, 0.0, 0.2, -0.3,
            ],
            quats: vec![
                0.9, 0.1, -0.2, 0.3, 1.0, 0.0, 0.0, 0.0, 0.5, -0.5, 0.3, 0.1, 0.2, 0.9, 0.1, 0.0,
            ],
            log_scales: vec![-2.0; 12],
            opacity_logits: vec![0.0; 4],
            sh: vec![0.0; 4 * 48],
            sh_degree: 0,
        }
    }

    /// A body (ID 4) and its part (ID 9, seen in mask 4), turning differently.
    fn objects() -> Vec<RigidObject> {
        let body = Trajectory {
            times: vec![0.0, 1.0],
            translations: vec![[0.1, 0.2, 0.0], [0.8, -0.3, 0.4]],
            rotations: vec![[1.0, 0.0, 0.0, 0.1], [0.7, 0.2, -0.3, 0.5]],
        };
        let arm = Trajectory {
            times: vec![0.0, 1.0],
            translations: vec![[-0.2, 0.1, 0.3], [0.4, 0.5, -0.1]],
            // The second knot in the far hemisphere: the blend must flip it.
            rotations: vec![[0.9, -0.3, 0.1, 0.0], [-0.6, 0.1, 0.5, -0.4]],
        };
        let mut part = RigidObject::new(9, "crane/part-1".into(), arm, false);
        part.mask = 4;
        vec![RigidObject::new(4, "crane".into(), body, false), part]
    }

    fn skin_rows(k: usize) -> AuxRows {
        let z = [[0.4, -0.7], [2.0, 1.5], [-0.3, 0.9]];
        let mut data = vec![0.0; 4 * 3 * k];
        for (i, z) in z.iter().enumerate() {
            data[i * 3 * k..i * 3 * k + 2].copy_from_slice(z);
        }
        AuxRows {
            name: SKIN_NAME.into(),
            cols: 3 * k,
            data,
        }
    }

    const COLUMN: [u8; 4] = [4, 9, 4, NO_OBJECT];

    /// Places rows as `RigidObjects::place` does; returns the skinning and the placement.
    fn placed(
        m: &GaussianModel,
        objs: &[RigidObject],
        aux: &AuxRows,
        t: f32,
    ) -> (Skinning, Deformed, Vec<Pose>) {
        let mut rows = Vec::new();
        place::rows_by_object(objs, &COLUMN, &mut rows);
        let mut d = Deformed::default();
        deform::apply(m, None, &mut d);
        let mut poses = Vec::new();
        place::place(objs, &rows, place::Shape::of(m), t, &mut d, &mut poses);
        let mut s = Skinning::default();
        s.place(
            objs,
            &poses,
            Shape::of(m),
            &COLUMN,
            std::slice::from_ref(aux),
            &mut d,
        );
        (s, d, poses)
    }

    /// L = Σ a·x_w + Σ b·q_w; the skinning's gradients of the object-frame means and
    /// quaternions, the logits and both parts' knots match finite differences.
    #[test]
    fn blended_chain_matches_finite_differences() {
        let k = 3;
        let a: Vec<f32> = (0..12).map(|i| ((i * 7 % 5) as f32 - 2.0) * 0.3).collect();
        let b: Vec<f32> = (0..16).map(|i| ((i * 3 % 7) as f32 - 3.0) * 0.2).collect();
        let t = 0.6;
        let loss = |m: &GaussianModel, o: &[RigidObject], x: &AuxRows| -> f64 {
            let d = placed(m, o, x, t).1;
            let s: f64 = d.means.iter().zip(&a).map(|(p, q)| f64::from(p * q)).sum();
            s + d
                .quats
                .iter()
                .zip(&b)
                .map(|(p, q)| f64::from(p * q))
                .sum::<f64>()
        };
        let (m, o, x) = (model(), objects(), skin_rows(k));
        let (mut s, d, poses) = placed(&m, &o, &x, t);
        assert_eq!(s.rows, vec![0, 1, 2]);
        assert!(
            d.means[9..12] == m.means[9..12],
            "the field's row is untouched"
        );
        let mut canon = CanonicalGrads::default();
        deform::backward(&m, &a, &b, &[0.0; 12], &mut canon);
        let mut tg = vec![TrajectoryGrad::zeros(2), TrajectoryGrad::zeros(2)];
        let world = WorldGrads {
            means: &a,
            quats: &b,
        };
        s.backward(&o, &poses, Shape::of(&m), world, &mut canon, &mut tg);
        let h = 1e-3;
        type Edit<'a> = &'a dyn Fn(&mut GaussianModel, &mut Vec<RigidObject>, &mut AuxRows, f32);
        let fd = |f: Edit| {
            let (mut mp, mut op, mut xp) = (m.clone(), o.clone(), x.clone());
            let (mut mm, mut om, mut xm) = (m.clone(), o.clone(), x.clone());
            f(&mut mp, &mut op, &mut xp, h);
            f(&mut mm, &mut om, &mut xm, -h);
            (loss(&mp, &op, &xp) - loss(&mm, &om, &xm)) / (2.0 * f64::from(h))
        };
        let close = |fd: f64, got: f64, what: String| {
            assert!(
                (fd - got).abs() < 3e-3,
                "{what}: finite difference {fd} vs {got}"
            );
        };
        for i in 0..9 {
            let g = fd(&|m, _, _, e| m.means[i] += e);
            close(g, f64::from(canon.means[i]), format!("mean {i}"));
        }
        for i in 0..12 {
            let g = fd(&|m, _, _, e| m.quats[i] += e);
            close(g, f64::from(canon.quats[i]), format!("quat {i}"));
        }
        for (j, row) in [0usize, 1, 2].iter().enumerate() {
            for p in 0..2 {
                let g = fd(&|_, _, x, e| x.data[row * 3 * k + p] += e);
                close(
                    g,
                    f64::from(s.grad[j * k + p]),
                    format!("logit {p} of row {row}"),
                );
            }
        }
        for (slot, tg) in tg.iter().enumerate() {
            for knot in 0..2 {
                for c in 0..3 {
                    let g = fd(&|_, o, _, e| o[slot].trajectory.translations[knot][c] += e);
                    close(
                        g,
                        tg.translations[knot][c],
                        format!("part {slot} knot {knot} p{c}"),
                    );
                }
                for c in 0..4 {
                    let g = fd(&|_, o, _, e| o[slot].trajectory.rotations[knot][c] += e);
                    close(
                        g,
                        tg.rotations[knot][c],
                        format!("part {slot} knot {knot} q{c}"),
                    );
                }
            }
        }
    }

    /// Hard logits place a Gaussian exactly as its part's rigid pose does.
    #[test]
    fn hard_logits_place_rigidly() {
        let (m, o) = (model(), objects());
        let mut x = skin_rows(2);
        x.data.fill(0.0);
        for (i, &c) in COLUMN[..3].iter().enumerate() {
            let home = usize::from(c == 9);
            x.data[i * 6 + 1 - home] = -30.0;
        }
        let (_, d, poses) = placed(&m, &o, &x, 0.3);
        for (i, &c) in COLUMN[..3].iter().enumerate() {
            let pose = &poses[usize::from(c == 9)];
            let want = pose.apply([0, 1, 2].map(|k| m.means[i * 3 + k]));
            for (k, w) in want.iter().enumerate() {
                assert!((d.means[i * 3 + k] - w).abs() < 1e-5);
            }
        }
    }

    /// The start: a Gaussian deep in its part weighs it ~1, one beside the other part
    /// blends; a densification re-homes the column to the heavier part, and a Gaussian
    /// the votes bring in starts hard on the part it joined.
    #[test]
    fn init_blends_at_the_joint_and_rehome_follows_the_weights() {
        let mut means = Vec::new();
        let mut column = Vec::new();
        for i in 0..10 {
            means.extend([i as f32 * 0.1, 0.0, 0.0]);
            column.push(if i < 5 { 4 } else { 9 });
        }
        means.extend([5.0, 5.0, 5.0]);
        column.push(NO_OBJECT);
        let colours = vec![0.5; means.len()];
        let mut st = GaussianState::new(crate::init::from_points(&means, &colours, 0.5));
        st.object = column;
        let o = objects();
        init(&mut st, &o, 4, 1.0);
        let a = rows_of(&st.aux).unwrap();
        assert_eq!(a.cols, 12);
        let w = |i: usize| {
            let mut w = [0.0; 2];
            softmax(&a.data[i * 12..i * 12 + 2], &mut w);
            w
        };
        assert!(w(0)[0] > 0.999, "deep in the body: {:?}", w(0));
        assert!(
            (0.55..0.75).contains(&w(4)[0]),
            "beside the arm: {:?}",
            w(4)
        );
        assert!(w(9)[1] > 0.999, "deep in the arm: {:?}", w(9));
        // Row 4 learned to follow the arm; the field's row 10 was voted into the arm.
        let before = st.object.clone();
        st.aux[0].data[4 * 12 + 1] = 3.0;
        st.object[10] = 9;
        st.aux[0].data[10 * 12..10 * 12 + 2].copy_from_slice(&[5.0, 5.0]);
        rehome(&mut st, &o, &before);
        assert_eq!(st.object[4], 9, "column follows the largest weight");
        assert_eq!(st.object[0], 4);
        assert_eq!(&st.aux[0].data[10 * 12..10 * 12 + 2], &[-HARD, 0.0]);
    }

    /// The exported weights are the softmax of a body's rows' logits, in row order, named
    /// by the object's parts; a body outside any articulated object has none.
    #[test]
    fn exported_weights_follow_the_rows() {
        let (o, x) = (objects(), skin_rows(3));
        let (names, w) = weights_of(&o, &COLUMN, std::slice::from_ref(&x), 4).unwrap();
        assert_eq!(names, ["crane", "crane/part-1"]);
        assert_eq!(w.len(), 2, "rows 0 and 2 are the body's");
        let e = (-0.7f32 - 0.4).exp();
        assert!((w[0][0] - 1.0 / (1.0 + e)).abs() < 1e-6 && (w[0][0] + w[0][1] - 1.0).abs() < 1e-6);
        let lone = RigidObject::new(7, "box".into(), o[0].trajectory.clone(), true);
        assert!(weights_of(&[lone], &[7], std::slice::from_ref(&x), 7).is_none());
    }

    /// A logit Adam step moves against the gradient and keeps the moments in the rows.
    #[test]
    fn logits_step_against_their_gradient() {
        let (m, o, mut x) = (model(), objects(), skin_rows(2));
        let mut s = placed(&m, &o, &x, 0.3).0;
        s.grad = vec![1.0, -2.0, 0.0, 0.5, 0.0, 0.0];
        let before = x.data.clone();
        let mut rows = vec![x.clone()];
        let mut store = AuxStore::new(&mut rows, 4);
        let hp = AdamHyper {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        };
        assert!(s.step(&mut store, hp, 0.01, 1));
        x = rows.remove(0);
        assert!((x.data[0] - (before[0] - 0.01)).abs() < 1e-6);
        assert!((x.data[1] - (before[1] + 0.01)).abs() < 1e-6);
        assert!(
            (x.data[6 + 1] - (before[6 + 1] - 0.01)).abs() < 1e-6,
            "row 1, part 1"
        );
        assert!(x.data[2] != 0.0 && x.data[4] != 0.0, "moments kept");
    }
}
