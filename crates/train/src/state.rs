//! Gaussians with everything that must stay row-aligned with them: Adam moments per
//! parameter group, the densification statistics and the rows a training hook keeps per
//! Gaussian. Every row operation goes through here so no buffer can fall out of step.

use crate::adam::Adam;
use crate::model::{GaussianModel, ROWS};

/// The object column's value for a Gaussian of no object: it belongs to the deformation
/// field's node (the object-ID maps' background value).
pub const NO_OBJECT: u8 = 255;

/// Per-Gaussian statistics of 3DGS `add_densification_stats`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DensifyStats {
    /// Σ over iterations where visible of the view-space gradient norm (NDC units).
    pub grad_accum: Vec<f32>,
    /// Number of iterations where visible.
    pub denom: Vec<f32>,
    /// Largest screen radius seen, pixels.
    pub max_radii: Vec<f32>,
}

impl DensifyStats {
    pub fn zeros(n: usize) -> Self {
        Self {
            grad_accum: vec![0.0; n],
            denom: vec![0.0; n],
            max_radii: vec![0.0; n],
        }
    }

    /// Accumulates one iteration: `radii` and the gradient w.r.t. the projected means in
    /// pixels, converted to 3DGS's NDC units (× W/2, H/2) before taking the norm.
    pub fn add(&mut self, radii: &[[i32; 2]], means2d_grad: &[[f32; 2]], width: u32, height: u32) {
        let (sx, sy) = (width as f32 * 0.5, height as f32 * 0.5);
        for i in 0..self.denom.len() {
            let r = radii[i][0].max(radii[i][1]);
            if r > 0 {
                let g = means2d_grad[i];
                self.grad_accum[i] += ((g[0] * sx).powi(2) + (g[1] * sy).powi(2)).sqrt();
                self.denom[i] += 1.0;
                self.max_radii[i] = self.max_radii[i].max(r as f32);
            }
        }
    }

    fn arrays_mut(&mut self) -> [&mut Vec<f32>; 3] {
        [&mut self.grad_accum, &mut self.denom, &mut self.max_radii]
    }
}

/// Per-Gaussian rows that a [`crate::hook::DeformHook`] keeps across iterations (the
/// regularizer's persistent object membership): `cols` values per Gaussian, kept aligned
/// through densification (a clone or split child inherits its parent's row, pruned rows
/// go) and saved in checkpoints, so a resumed run continues with the same values.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AuxRows {
    pub name: String,
    pub cols: usize,
    pub data: Vec<f32>,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianState {
    pub model: GaussianModel,
    /// Adam per group, in [`ROWS`] order (means, quats, log_scales, opacity, sh).
    pub adam: [Adam; 5],
    pub stats: DensifyStats,
    /// Hook-owned rows, by name (usually none).
    pub aux: Vec<AuxRows>,
    /// The object each Gaussian belongs to, which says the node that owns its row
    /// ([`NO_OBJECT`]: the deformation field's; an object's ID: the node of that object's
    /// kind). Maintained through every row change, never by raw row indices: a clone or
    /// split child belongs to its parent's object.
    pub object: Vec<u8>,
}

/// The hook rows of a state, handed to [`crate::hook::DeformHook::apply`].
#[derive(Debug)]
pub struct AuxStore<'a> {
    rows: &'a mut Vec<AuxRows>,
    n: usize,
}

impl<'a> AuxStore<'a> {
    pub fn new(rows: &'a mut Vec<AuxRows>, n: usize) -> Self {
        Self { rows, n }
    }

    /// The rows called `name` (`n·cols` values), created as zeros on first use. Errors when
    /// rows of that name exist with another width (a checkpoint from another setup).
    pub fn get_or_zeros(&mut self, name: &str, cols: usize) -> Result<&mut [f32], String> {
        let i = match self.rows.iter().position(|r| r.name == name) {
            Some(i) => i,
            None => {
                self.rows.push(AuxRows {
                    name: name.to_string(),
                    cols,
                    data: vec![0.0; self.n * cols],
                });
                self.rows.len() - 1
            }
        };
        let r = &mut self.rows[i];
        if r.cols != cols || r.data.len() != self.n * cols {
            return Err(format!(
                "per-Gaussian rows `{name}` hold {} values per Gaussian, expected {cols}",
                r.cols
            ));
        }
        Ok(&mut r.data)
    }
}

impl GaussianState {
    pub fn new(model: GaussianModel) -> Self {
        let n = model.len();
        let adam = ROWS.map(|r| Adam::zeros(n * r));
        Self {
            model,
            adam,
            stats: DensifyStats::zeros(n),
            aux: Vec::new(),
            object: vec![NO_OBJECT; n],
        }
    }

    pub fn len(&self) -> usize {
        self.model.len()
    }

    pub fn is_empty(&self) -> bool {
        self.model.is_empty()
    }

    /// Keeps the Gaussians where `keep[i]`, with their moments and statistics.
    pub fn retain(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len(), "mask length");
        self.model.retain(keep);
        for (a, r) in self.adam.iter_mut().zip(ROWS) {
            a.retain(r, keep);
        }
        for s in self.stats.arrays_mut() {
            crate::model::retain_rows(s, 1, keep);
        }
        for a in &mut self.aux {
            crate::model::retain_rows(&mut a.data, a.cols, keep);
        }
        crate::model::retain_rows(&mut self.object, 1, keep);
    }

    /// Appends new Gaussians with zero moments and zero statistics; `parents[j]` is the row
    /// that new Gaussian `j` was cloned or split from, whose hook rows it inherits.
    pub fn append(&mut self, new: &GaussianModel, parents: &[usize]) {
        let k = new.len();
        assert_eq!(parents.len(), k, "one parent per new Gaussian");
        for a in &mut self.aux {
            let c = a.cols;
            a.data.reserve(k * c);
            for &p in parents {
                a.data.extend_from_within(p * c..(p + 1) * c);
            }
        }
        let inherited: Vec<u8> = parents.iter().map(|&p| self.object[p]).collect();
        self.object.extend(inherited);
        self.append_rows(new);
    }

    /// Moves Gaussian `src` into row `dst` (MCMC relocation: a dead Gaussian becomes a copy
    /// of a live one): parameters, object and hook rows copied; `dst`'s moments and
    /// statistics zeroed, since those described the Gaussian that was there.
    pub fn copy_row(&mut self, src: usize, dst: usize) {
        for (arr, r) in self.model.arrays_mut().into_iter().zip(ROWS) {
            arr.copy_within(src * r..(src + 1) * r, dst * r);
        }
        for a in &mut self.aux {
            let c = a.cols;
            a.data.copy_within(src * c..(src + 1) * c, dst * c);
        }
        self.object[dst] = self.object[src];
        self.zero_moments(dst);
    }

    /// Zeroes row `i`'s Adam moments (every group) and densification statistics.
    pub fn zero_moments(&mut self, i: usize) {
        for (a, r) in self.adam.iter_mut().zip(ROWS) {
            a.m[i * r..(i + 1) * r].fill(0.0);
            a.v[i * r..(i + 1) * r].fill(0.0);
        }
        for s in self.stats.arrays_mut() {
            s[i] = 0.0;
        }
    }

    /// Appends the Gaussians of a new object (`objects::start`): zero moments, statistics
    /// and hook rows, `object` in the column.
    pub fn append_object(&mut self, new: &GaussianModel, object: u8) {
        let k = new.len();
        for a in &mut self.aux {
            a.data.resize(a.data.len() + k * a.cols, 0.0);
        }
        self.object.resize(self.object.len() + k, object);
        self.append_rows(new);
    }

    fn append_rows(&mut self, new: &GaussianModel) {
        let k = new.len();
        self.model.append(new);
        for (a, r) in self.adam.iter_mut().zip(ROWS) {
            a.append_zeros(k * r);
        }
        for s in self.stats.arrays_mut() {
            s.resize(s.len() + k, 0.0);
        }
    }

    /// Lengths of every buffer agree with N (checked after each densification in debug).
    pub fn is_aligned(&self) -> bool {
        let n = self.len();
        let model_ok = self
            .model
            .arrays()
            .iter()
            .zip(ROWS)
            .all(|(a, r)| a.len() == n * r);
        let adam_ok = self
            .adam
            .iter()
            .zip(ROWS)
            .all(|(a, r)| a.m.len() == n * r && a.v.len() == n * r);
        let stats_ok = [
            &self.stats.grad_accum,
            &self.stats.denom,
            &self.stats.max_radii,
        ]
        .iter()
        .all(|s| s.len() == n);
        let aux_ok = self.aux.iter().all(|a| a.data.len() == n * a.cols);
        model_ok && adam_ok && stats_ok && aux_ok && self.object.len() == n
    }
}
