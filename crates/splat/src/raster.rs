//! The [`Rasterizer`]: owns every buffer of the forward and backward passes and runs them,
//! in parallel over Gaussians (projection) and over tiles (rasterization).

use crate::backward::{backward_tile, GradAcc, TileGradIn};
use crate::bin::Bins;
use crate::forward::{render_tile, PairCounts, Splat, TileCtx, TileOut, TP, TS};
use crate::grad_slots::{GradSlots, SlotWriter};
use crate::project::{project, project_vjp, CamInfo, GaussGradMut, ProjGrad, Projected};
use crate::project_batch::{project_all, project_vjp_all};
use crate::validate::{validate_backward, validate_forward};
use crate::{
    Camera, Colors, ForwardOutput, Gaussians, Gradients, RasterStats, RenderOptions, SplatError,
};
use rayon::prelude::*;
pub use simd::Simd;
use std::time::Instant;

/// Wall-clock seconds of the phases of the last [`Rasterizer::forward`] or
/// [`Rasterizer::backward`] call (for performance breakdowns).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    /// Forward: projection + SH. Backward: projection and SH backward.
    pub project: f64,
    /// Forward: tile binning and depth sort. Backward: fixed-order sum of the tile slots.
    pub bin: f64,
    /// Tile rasterization (forward or backward kernels).
    pub raster: f64,
    /// Forward: copy to row-major outputs. Backward: zeroing the gradient slots.
    pub finish: f64,
}

/// Owns every buffer the forward and backward passes reuse across calls.
#[derive(Default)]
pub struct Rasterizer {
    proj: Vec<Projected>,
    splats: Vec<Splat>,
    radii: Vec<[i32; 2]>,
    means2d: Vec<[f32; 2]>,
    depths: Vec<f32>,
    bins: Bins,
    tile_color: Vec<f32>,
    tile_tfin: Vec<f32>,
    tile_last: Vec<u32>,
    tile_topk_ids: Vec<u32>,
    tile_topk_w: Vec<f32>,
    image: Vec<f32>,
    alpha: Vec<f32>,
    topk_ids: Vec<u32>,
    topk_weights: Vec<f32>,
    slots: GradSlots,
    proj_grads: Vec<GradAcc>,
    stats: RasterStats,
    count_alpha: bool,
    timings: Timings,
    /// (N, width, height) of the last forward pass.
    shape: Option<(usize, u32, u32)>,
    /// Upper bound on the vector level (None: the widest the CPU has).
    simd_cap: Option<Simd>,
    /// Project one Gaussian at a time with the scalar reference instead of 16 at a time.
    scalar_projection: bool,
}

/// The level the tile kernels use by default: the CPU's, capped by `SEMDYNREG_SIMD`
/// (the `simd` crate).
pub fn simd_level() -> Simd {
    simd::level()
}

impl Rasterizer {
    pub fn new() -> Self {
        Self::default()
    }

    /// (pixel, Gaussian) pairs the last forward pass evaluated (rows of 16 pixels that a
    /// Gaussian's alpha can reach, in tiles where pixels were still unfinished).
    pub fn evaluated_pairs(&self) -> u64 {
        self.stats.evaluated_pairs
    }

    /// Work counts of the last forward pass.
    pub fn stats(&self) -> RasterStats {
        self.stats
    }

    /// Whether forward passes also count the pairs with `α ≥ 1/255`
    /// ([`RasterStats::alpha_pairs`]). Diagnostic: the tiles then run a portable kernel
    /// with the counter (same results, slower).
    pub fn set_count_alpha_pairs(&mut self, on: bool) {
        self.count_alpha = on;
    }

    /// Sets the tile kernels' vector level (for A/B timings and the test that all levels
    /// give bit-identical results), in place of `SEMDYNREG_SIMD`; the CPU's own limit still
    /// applies.
    pub fn set_simd_cap(&mut self, cap: Simd) {
        self.simd_cap = Some(cap);
    }

    /// Runs the projection and its backward one Gaussian at a time with the scalar
    /// reference (`project.rs`) instead of sixteen at a time (`project_batch.rs`). Results
    /// are bit-identical; for A/B timings and the tests that say so.
    pub fn set_scalar_projection(&mut self, on: bool) {
        self.scalar_projection = on;
    }

    /// The vector level the tile kernels use.
    pub fn simd(&self) -> Simd {
        match self.simd_cap {
            Some(cap) => simd::capped(simd::cpu_level(), Some(cap)),
            None => simd_level(),
        }
    }

    /// Phase timings of the last forward or backward call.
    pub fn timings(&self) -> Timings {
        self.timings
    }

    /// Renders `g` from `cam`; keeps what the backward pass needs.
    pub fn forward(
        &mut self,
        g: &Gaussians,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> Result<ForwardOutput<'_>, SplatError> {
        validate_forward(g, cam)?;
        let ci = CamInfo::new(cam, opts);
        let n = g.len();
        let t0 = Instant::now();
        if self.scalar_projection {
            self.proj.clear();
            self.proj
                .par_extend((0..n).into_par_iter().map(|i| project(g, i, &ci)));
        } else {
            project_all(self.simd(), g, &ci, &mut self.proj);
        }
        self.split_projections();
        let t1 = Instant::now();
        let size = (cam.width, cam.height);
        let mode = (opts.cull, self.simd());
        // Binning also writes the splats in depth order (tile lists hold depth ranks, so
        // the kernels read memory forwards).
        self.bins.build(&self.proj, size, mode, &mut self.splats);
        let t2 = Instant::now();
        self.rasterize(cam, opts);
        let t3 = Instant::now();
        self.scatter(cam, opts.topk);
        self.timings = Timings {
            project: (t1 - t0).as_secs_f64(),
            bin: (t2 - t1).as_secs_f64(),
            raster: (t3 - t2).as_secs_f64(),
            finish: t3.elapsed().as_secs_f64(),
        };
        self.shape = Some((n, cam.width, cam.height));
        Ok(ForwardOutput {
            width: cam.width,
            height: cam.height,
            image: &self.image,
            alpha: &self.alpha,
            topk_ids: &self.topk_ids,
            topk_weights: &self.topk_weights,
            radii: &self.radii,
            means2d: &self.means2d,
            depths: &self.depths,
            n_isects: self.bins.n_isects(),
            stats: self.stats,
        })
    }

    /// Copies the radii, 2D means and depths out of the projections (the forward output's
    /// per-Gaussian arrays), in parallel: a serial pass over 100k projections cost ~1 ms.
    fn split_projections(&mut self) {
        let n = self.proj.len();
        set_len(&mut self.radii, n, [0; 2]);
        set_len(&mut self.means2d, n, [0.0; 2]);
        set_len(&mut self.depths, n, 0.0);
        const CH: usize = 4096;
        self.proj
            .par_chunks(CH)
            .zip(self.radii.par_chunks_mut(CH))
            .zip(self.means2d.par_chunks_mut(CH))
            .zip(self.depths.par_chunks_mut(CH))
            .for_each(|(((p, r), m), d)| {
                for (k, p) in p.iter().enumerate() {
                    (r[k], m[k], d[k]) = (p.radii, p.mean2d, p.depth);
                }
            });
    }

    fn rasterize(&mut self, cam: &Camera, opts: &RenderOptions) {
        let n_tiles = self.bins.tiles_x * self.bins.tiles_y;
        let k = opts.topk;
        resize(&mut self.tile_color, n_tiles * 3 * TP, 0.0);
        resize(&mut self.tile_tfin, n_tiles * TP, 0.0);
        resize(&mut self.tile_last, n_tiles * TP, 0);
        resize(&mut self.tile_topk_ids, n_tiles * TP * k, u32::MAX);
        resize(&mut self.tile_topk_w, n_tiles * TP * k, 0.0);
        let simd = self.simd();
        let (bins, splats, count) = (&self.bins, &self.splats, self.count_alpha);
        let run = |tile: usize, out: TileOut| {
            let ctx = tile_ctx(tile, bins.tiles_x, cam, opts, count);
            render_tile(simd, &ctx, bins.tile_list(tile), splats, &bins.order, out)
        };
        let main = self
            .tile_color
            .par_chunks_mut(3 * TP)
            .zip(self.tile_tfin.par_chunks_mut(TP))
            .zip(self.tile_last.par_chunks_mut(TP))
            .enumerate();
        let add = |a: PairCounts, b: PairCounts| a + b;
        let n = if k == 0 {
            main.map(|(t, ((color, tfin), last))| {
                let (topk_ids, topk_w) = (&mut [][..], &mut [][..]);
                run(
                    t,
                    TileOut {
                        color,
                        tfin,
                        last,
                        topk_ids,
                        topk_w,
                    },
                )
            })
            .reduce(PairCounts::default, add)
        } else {
            main.zip(self.tile_topk_ids.par_chunks_mut(TP * k))
                .zip(self.tile_topk_w.par_chunks_mut(TP * k))
                .map(|(((t, ((color, tfin), last)), topk_ids), topk_w)| {
                    run(
                        t,
                        TileOut {
                            color,
                            tfin,
                            last,
                            topk_ids,
                            topk_w,
                        },
                    )
                })
                .reduce(PairCounts::default, add)
        };
        self.stats = RasterStats {
            tile_intersections: self.bins.n_isects() as u64,
            gradient_slots: self.bins.n_slots() as u64,
            evaluated_pairs: n.pairs,
            alpha_pairs: self.count_alpha.then_some(n.alpha),
            pairs_4x4: self.count_alpha.then_some(n.block_4x4),
            pairs_8x2: self.count_alpha.then_some(n.block_8x2),
        };
    }

    /// Copies the tile-major results into the row-major outputs.
    fn scatter(&mut self, cam: &Camera, k: usize) {
        let w = cam.width as usize;
        let h = cam.height as usize;
        resize(&mut self.image, w * h * 3, 0.0);
        resize(&mut self.alpha, w * h, 0.0);
        let tiles_x = self.bins.tiles_x;
        // (tile, pixel-in-tile) of image pixel (x, y).
        let at = move |x: usize, y: usize| ((y / TS) * tiles_x + x / TS, (y % TS) * TS + x % TS);
        let (tc, tt) = (&self.tile_color, &self.tile_tfin);
        self.image
            .par_chunks_mut(w * 3)
            .zip(self.alpha.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (img, alp))| {
                for x in 0..w {
                    let (tile, p) = at(x, y);
                    for c in 0..3 {
                        img[3 * x + c] = tc[tile * 3 * TP + c * TP + p];
                    }
                    alp[x] = 1.0 - tt[tile * TP + p];
                }
            });
        resize(&mut self.topk_ids, w * h * k, u32::MAX);
        resize(&mut self.topk_weights, w * h * k, 0.0);
        if k == 0 {
            return;
        }
        let (tki, tkw) = (&self.tile_topk_ids, &self.tile_topk_w);
        self.topk_ids
            .par_chunks_mut(w * k)
            .zip(self.topk_weights.par_chunks_mut(w * k))
            .enumerate()
            .for_each(|(y, (ids, ws))| {
                for x in 0..w {
                    let (tile, p) = at(x, y);
                    let src = (tile * TP + p) * k;
                    ids[x * k..(x + 1) * k].copy_from_slice(&tki[src..src + k]);
                    ws[x * k..(x + 1) * k].copy_from_slice(&tkw[src..src + k]);
                }
            });
    }

    /// Gradients of a loss given `dL/dimage` (H·W·3) and optionally `dL/dalpha` (H·W), for the
    /// same `g`, `cam`, `opts` as the last `forward`.
    pub fn backward(
        &mut self,
        g: &Gaussians,
        cam: &Camera,
        opts: &RenderOptions,
        dl_dimage: &[f32],
        dl_dalpha: Option<&[f32]>,
        grads: &mut Gradients,
    ) -> Result<(), SplatError> {
        validate_backward(g, cam, self.shape, dl_dimage, dl_dalpha)?;
        let t0 = Instant::now();
        let mut slots = std::mem::take(&mut self.slots);
        let writer = slots.reset(self.bins.n_slots());
        let t1 = Instant::now();
        self.accumulate_tiles(&writer, cam, opts, dl_dimage, dl_dalpha);
        self.slots = slots;
        let t2 = Instant::now();
        self.reduce_slots(g.len());
        let t3 = Instant::now();
        self.project_backward(g, cam, opts, grads);
        self.timings = Timings {
            finish: (t1 - t0).as_secs_f64(),
            raster: (t2 - t1).as_secs_f64(),
            bin: (t3 - t2).as_secs_f64(),
            project: t3.elapsed().as_secs_f64(),
        };
        Ok(())
    }

    fn accumulate_tiles(
        &self,
        slots: &SlotWriter,
        cam: &Camera,
        opts: &RenderOptions,
        dl_dimage: &[f32],
        dl_dalpha: Option<&[f32]>,
    ) {
        let n_tiles = self.bins.tiles_x * self.bins.tiles_y;
        let simd = self.simd();
        let (bins, splats) = (&self.bins, &self.splats);
        let (tfin, last) = (&self.tile_tfin, &self.tile_last);
        let w = cam.width as usize;
        // Tiles in parallel; each stores its per-Gaussian sums in that (Gaussian, tile)'s
        // own slot, so no two jobs write the same memory and the reduction order is fixed.
        (0..n_tiles).into_par_iter().for_each(|tile| {
            let list = bins.tile_list(tile);
            if list.ranks.is_empty() {
                return;
            }
            let (tx, ty) = (tile % bins.tiles_x, tile / bins.tiles_x);
            let (x0, y0) = (tx * TS, ty * TS);
            let mut v_color = [0.0f32; 3 * TP];
            let mut v_alpha_eff = [0.0f32; TP];
            let (cols, rows) = ((w - x0).min(TS), (cam.height as usize - y0).min(TS));
            for r in 0..rows {
                for l in 0..cols {
                    let (p, pix) = (r * TS + l, (y0 + r) * w + x0 + l);
                    let mut bgdot = 0.0;
                    for c in 0..3 {
                        let v = dl_dimage[3 * pix + c];
                        v_color[c * TP + p] = v;
                        bgdot += opts.background[c] * v;
                    }
                    let va = dl_dalpha.map_or(0.0, |a| a[pix]);
                    // alpha = 1 − T_final and C += T_final·bg both scale with T_final.
                    v_alpha_eff[p] = tfin[tile * TP + p] * (va - bgdot);
                }
            }
            let tin = TileGradIn {
                x0: x0 as u32,
                y0: y0 as u32,
                tfin: &tfin[tile * TP..(tile + 1) * TP],
                last: &last[tile * TP..(tile + 1) * TP],
                v_color: &v_color,
                v_alpha_eff: &v_alpha_eff,
            };
            // SAFETY: the slot of (rank, this tile) is written by this tile's job only.
            let mut emit =
                |rank: usize, sums: &GradAcc| unsafe { slots.store(bins.slot(rank, tx, ty), sums) };
            backward_tile(simd, &tin, list, splats, &mut emit);
        });
    }

    /// Per-Gaussian sums: each Gaussian adds its tile slots in row-major tile order.
    fn reduce_slots(&mut self, n: usize) {
        set_len(&mut self.proj_grads, n, [0.0; 9]);
        let (slots, rank_of, start) = (&self.slots, &self.bins.rank_of, &self.bins.slot_start);
        self.proj_grads
            .par_chunks_mut(4096)
            .enumerate()
            .for_each(|(ci, out)| {
                for (j, o) in out.iter_mut().enumerate() {
                    let rank = rank_of[ci * 4096 + j];
                    *o = if rank == u32::MAX {
                        [0.0; 9]
                    } else {
                        let r = rank as usize;
                        slots.sum(start[r]..start[r + 1])
                    };
                }
            });
    }

    fn project_backward(
        &self,
        g: &Gaussians,
        cam: &Camera,
        opts: &RenderOptions,
        grads: &mut Gradients,
    ) {
        let n = g.len();
        let cstride = match g.colors {
            Colors::Sh { num_coeffs, .. } => num_coeffs * 3,
            Colors::Rgb(_) => 3,
        };
        set_len(&mut grads.means, n * 3, 0.0);
        set_len(&mut grads.quats, n * 4, 0.0);
        set_len(&mut grads.scales, n * 3, 0.0);
        set_len(&mut grads.opacity_logits, n, 0.0);
        set_len(&mut grads.colors, n * cstride, 0.0);
        set_len(&mut grads.means2d, n, [0.0; 2]);
        let ci = CamInfo::new(cam, opts);
        let (proj, pgs) = (&self.proj, &self.proj_grads);
        if !self.scalar_projection {
            project_vjp_all(self.simd(), g, &ci, (proj, pgs), grads);
            return;
        }
        grads
            .means
            .par_chunks_mut(3)
            .zip(grads.quats.par_chunks_mut(4))
            .zip(grads.scales.par_chunks_mut(3))
            .zip(grads.opacity_logits.par_iter_mut())
            .zip(grads.colors.par_chunks_mut(cstride))
            .zip(grads.means2d.par_iter_mut())
            .enumerate()
            .for_each(|(i, (((((mean, quat), scale), logit), color), m2))| {
                let s = &pgs[i];
                *m2 = [s[0], s[1]];
                if proj[i].radii[0] <= 0 {
                    mean.fill(0.0);
                    quat.fill(0.0);
                    scale.fill(0.0);
                    *logit = 0.0;
                    color.fill(0.0);
                    return;
                }
                let pg = ProjGrad::from_acc(s);
                let out = GaussGradMut {
                    mean,
                    quat,
                    scale,
                    logit,
                    color,
                };
                project_vjp(g, i, &ci, &pg, out);
            });
    }
}

fn tile_ctx(
    tile: usize,
    tiles_x: usize,
    cam: &Camera,
    opts: &RenderOptions,
    count_alpha: bool,
) -> TileCtx {
    let (tx, ty) = (tile % tiles_x, tile / tiles_x);
    let (x0, y0) = ((tx * TS) as u32, (ty * TS) as u32);
    TileCtx {
        x0,
        y0,
        cols: (cam.width - x0).min(TS as u32) as usize,
        rows: (cam.height - y0).min(TS as u32) as usize,
        k: opts.topk,
        bg: opts.background,
        count_alpha,
    }
}

/// Sets `v` to `len` copies of `fill`, reusing its allocation.
fn resize<T: Clone>(v: &mut Vec<T>, len: usize, fill: T) {
    v.clear();
    v.resize(len, fill);
}

/// Sets the length of a buffer whose every entry the caller overwrites: unlike [`resize`]
/// it does not first zero what is already there (for the gradients of 100k SH-3 Gaussians
/// that would be 24 MB of writes per backward pass).
pub(crate) fn set_len<T: Clone>(v: &mut Vec<T>, len: usize, fill: T) {
    v.truncate(len);
    v.resize(len, fill);
}
