//! Forward rasterization of one 16×16 tile (gsplat `rasterize_to_pixels_fwd`, classic):
//! front to back, `σ = ½(a dx² + c dy²) + b dx dy`, `α = min(0.999, o·e^{−σ})`, skip
//! `σ < 0` or `α < 1/255`, stop a pixel before the Gaussian that would make
//! `T(1−α) ≤ 1e-4`.
//!
//! Layout for vectorization: per-pixel state is kept as 16 rows of 16 lanes; each Gaussian
//! updates the rows its alpha can reach (see [`Splat::hy`]) with a branch-free loop over
//! 16 pixels that LLVM turns into SIMD. A finished pixel has `T = 0` (so every later test
//! fails) and keeps its final transmittance in `tfin`.

use crate::fastexp;
use crate::raster::Simd;

pub(crate) const ALPHA_MIN: f32 = 1.0 / 255.0;
pub(crate) const ALPHA_MAX: f32 = 0.999;
pub(crate) const T_MIN: f32 = 1e-4;
pub(crate) const TS: usize = crate::TILE_SIZE as usize;
pub(crate) const TP: usize = TS * TS;

/// One projected Gaussian as the tile kernels read it.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Splat {
    pub mx: f32,
    pub my: f32,
    pub a: f32,
    pub b: f32,
    pub c: f32,
    pub o: f32,
    pub rgb: [f32; 3],
    /// Rows with |y − my| > hy cannot reach α ≥ 1/255: there min over x of σ is
    /// ½·dy²·(c − b²/a) > ln(255·o). Negative when o < 1/255 (never visible).
    pub hy: f32,
    /// 2·ln(255·o) plus a small margin: the row chord test of [`Splat::reaches_row`].
    pub thr2: f32,
}

impl Splat {
    pub fn new(mean2d: [f32; 2], conic: [f32; 3], o: f32, rgb: [f32; 3]) -> Self {
        let [a, b, c] = conic;
        let thr = (255.0 * o).ln();
        // The margin keeps the chord test conservative against f32 rounding of σ and the
        // polynomial exp (tested in `chord_cull_is_conservative`).
        let thr2 = 2.0 * thr + 2e-3;
        let hy = if thr < 0.0 {
            -1.0
        } else {
            let rowk = (c - b * b / a).max(1e-20);
            // Margin so f32 rounding never drops a row that the exact test would keep.
            (2.0 * thr / rowk).sqrt() * 1.001 + 0.01
        };
        Splat {
            mx: mean2d[0],
            my: mean2d[1],
            a,
            b,
            c,
            o,
            rgb,
            hy,
            thr2,
        }
    }

    /// Whether the row at `dy = my − y` can reach α ≥ 1/255 at a pixel centre of the tile
    /// columns `[x0 + 0.5, x0 + 15.5]`. In that row σ ≤ thr ⇔ the quadratic
    /// ½a·dx² + b·dy·dx + ½c·dy² − thr ≤ 0, i.e. pixel x within
    /// `mx + b·dy/a ± √(2a·thr − dy²(ac − b²))/a`. Rows that fail are skipped whole: for
    /// them the kernels would composite nothing, so the result is unchanged.
    #[inline(always)]
    pub fn reaches_row(&self, dy: f32, x0: f32) -> bool {
        let (lo, hi) = self.chord(dy);
        hi >= x0 + 0.5 && lo <= x0 + (TS as f32 - 0.5)
    }

    /// The row's chord `[centre − half, centre + half]` of [`Splat::reaches_row`], with its
    /// margins. Binning (`bin.rs`, [`crate::Cull::Exact`]) calls this same function, so it
    /// keeps exactly the tiles in which some row passes this test.
    #[inline(always)]
    pub fn chord(&self, dy: f32) -> (f32, f32) {
        let disc = self.thr2 * self.a - dy * dy * (self.a * self.c - self.b * self.b);
        let inv_a = 1.0 / self.a;
        let half = disc.max(0.0).sqrt() * inv_a * 1.001 + 0.01;
        let centre = self.mx + self.b * dy * inv_a;
        (centre - half, centre + half)
    }

    /// `my − y` at the centre of row `r` of the tile starting at pixel row `y0`, in the
    /// kernels' own f32 order of operations.
    #[inline(always)]
    pub fn row_dy(&self, y0: u32, r: usize) -> f32 {
        self.my - (y0 as f32 + r as f32 + 0.5)
    }

    /// Bit `r` set for each row `r` of the tile at pixel `(x0, y0)` that the kernels
    /// evaluate: inside [`Splat::rows`] and passing [`Splat::reaches_row`]. Binning computes
    /// the same bits from the rows' chords once per Gaussian (`bin.rs`, [`crate::Cull::Exact`]);
    /// this is the reference and the path of [`crate::Cull::Box3Sigma`].
    #[inline(always)]
    pub fn row_mask(&self, x0: u32, y0: u32) -> u16 {
        let (r0, r1) = self.rows(y0);
        let mut m = 0u16;
        for r in r0..r1 {
            m |= (self.reaches_row(self.row_dy(y0, r), x0 as f32) as u16) << r;
        }
        m
    }

    /// Rows `[r0, r1)` of the tile starting at pixel row `y0` that the Gaussian may reach.
    #[inline(always)]
    pub fn rows(&self, y0: u32) -> (usize, usize) {
        if self.hy < 0.0 {
            return (0, 0);
        }
        let lo = (self.my - self.hy - y0 as f32 - 0.5).ceil();
        let hi = (self.my + self.hy - y0 as f32 - 0.5).floor();
        let r0 = lo.max(0.0).min(TS as f32) as usize;
        let r1 = (hi + 1.0).max(0.0).min(TS as f32) as usize;
        (r0, r1.max(r0))
    }
}

/// Where a tile lies and what to render.
pub(crate) struct TileCtx {
    pub x0: u32,
    pub y0: u32,
    /// Pixels of the tile inside the image.
    pub cols: usize,
    pub rows: usize,
    pub k: usize,
    pub bg: [f32; 3],
    /// Also count the pairs with `α ≥ 1/255` (diagnostic, portable kernel).
    pub count_alpha: bool,
}

/// One tile's slices of the tile-major output buffers.
pub(crate) struct TileOut<'a> {
    /// `3·256` planar colour (R plane, G plane, B plane), background included.
    pub color: &'a mut [f32],
    /// `256` final transmittance.
    pub tfin: &'a mut [f32],
    /// `256` one past the list position of the last composited Gaussian.
    pub last: &'a mut [u32],
    /// `256·k` top-k ids and weights, largest first.
    pub topk_ids: &'a mut [u32],
    pub topk_w: &'a mut [f32],
}

/// (pixel, Gaussian) pairs a tile job evaluated and, only with [`TileCtx::count_alpha`]
/// (else 0), the diagnostics of [`crate::RasterStats`]: the evaluated pairs with
/// `α ≥ 1/255` at an unfinished pixel, and the pairs kernels over 4×4 and 8×2 pixel blocks
/// would evaluate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct PairCounts {
    pub pairs: u64,
    pub alpha: u64,
    pub block_4x4: u64,
    pub block_8x2: u64,
}

impl std::ops::Add for PairCounts {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            pairs: self.pairs + o.pairs,
            alpha: self.alpha + o.alpha,
            block_4x4: self.block_4x4 + o.block_4x4,
            block_8x2: self.block_8x2 + o.block_8x2,
        }
    }
}

/// Which pixel blocks of a tile one Gaussian reaches, for the block-layout estimate of
/// [`crate::RasterStats::pairs_4x4`]: a row the kernels evaluate marks the blocks whose
/// columns its chord ([`Splat::chord`]) meets, as [`Splat::reaches_row`] does for a whole
/// row. `b4` has bit `4·(r/4) + q` for columns `4q..4q+3`; `b8` bit `2·(r/2) + h` for
/// columns `8h..8h+7`.
#[derive(Default)]
struct BlockMarks {
    b4: u16,
    b8: u16,
}

impl BlockMarks {
    fn mark(&mut self, sp: &Splat, dy: f32, r: usize, x0: f32) {
        let (lo, hi) = sp.chord(dy);
        let meets = |c0: usize, c1: usize| hi >= x0 + c0 as f32 + 0.5 && lo <= x0 + c1 as f32 + 0.5;
        for q in 0..4 {
            self.b4 |= (meets(4 * q, 4 * q + 3) as u16) << (4 * (r / 4) + q);
        }
        for h in 0..2 {
            self.b8 |= (meets(8 * h, 8 * h + 7) as u16) << (2 * (r / 2) + h);
        }
    }
}

/// A tile's list: depth ranks indexing the splats and, when binning computed them
/// ([`crate::Cull::Exact`]), each entry's [`Splat::row_mask`] (else empty: the kernels
/// compute it).
#[derive(Clone, Copy)]
pub(crate) struct TileList<'a> {
    pub ranks: &'a [u32],
    pub masks: &'a [u16],
}

impl TileList<'_> {
    /// Rows of entry `pos` (splat `sp`) the kernels evaluate in the tile at `(x0, y0)`.
    #[inline(always)]
    pub fn rows(&self, pos: usize, sp: &Splat, x0: u32, y0: u32) -> u16 {
        if self.masks.is_empty() {
            sp.row_mask(x0, y0)
        } else {
            self.masks[pos]
        }
    }
}

/// Renders one tile; returns its [`PairCounts`]. `gids` maps a rank to its global index.
pub(crate) fn render_tile(
    simd: Simd,
    ctx: &TileCtx,
    list: TileList,
    splats: &[Splat],
    gids: &[u32],
    out: TileOut,
) -> PairCounts {
    if ctx.count_alpha {
        // Diagnostic path: same arithmetic (the levels are bit-identical), not vectorized
        // for AVX, and the hot kernels below stay free of the counter.
        return if ctx.k > 0 {
            tile_impl::<true, true>(ctx, list, splats, gids, out)
        } else {
            tile_impl::<false, true>(ctx, list, splats, gids, out)
        };
    }
    #[cfg(target_arch = "x86_64")]
    match simd {
        // SAFETY: `simd_level` checked that the CPU supports these features.
        Simd::Avx512 => unsafe {
            return if ctx.k > 0 {
                tile_avx512::<true>(ctx, list, splats, gids, out)
            } else {
                tile_avx512::<false>(ctx, list, splats, gids, out)
            };
        },
        // SAFETY: as above.
        Simd::Avx2 => unsafe {
            return if ctx.k > 0 {
                tile_avx2::<true>(ctx, list, splats, gids, out)
            } else {
                tile_avx2::<false>(ctx, list, splats, gids, out)
            };
        },
        Simd::Portable => {}
    }
    let _ = simd;
    if ctx.k > 0 {
        tile_impl::<true, false>(ctx, list, splats, gids, out)
    } else {
        tile_impl::<false, false>(ctx, list, splats, gids, out)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn tile_avx2<const TOPK: bool>(
    ctx: &TileCtx,
    list: TileList,
    splats: &[Splat],
    gids: &[u32],
    out: TileOut,
) -> PairCounts {
    tile_impl::<TOPK, false>(ctx, list, splats, gids, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn tile_avx512<const TOPK: bool>(
    ctx: &TileCtx,
    list: TileList,
    splats: &[Splat],
    gids: &[u32],
    out: TileOut,
) -> PairCounts {
    tile_impl::<TOPK, false>(ctx, list, splats, gids, out)
}

/// Per-pixel compositing state of a tile, row-major 16×16.
struct State {
    t: [f32; TP],
    tfin: [f32; TP],
    col: [[f32; TP]; 3],
    last: [u32; TP],
    /// Bit `r`: row `r` has unfinished pixels.
    live: u16,
    /// Smallest weight in each pixel's top-k list (0 while not full), so that the common
    /// "no insertion" case is one vector compare per row.
    kmin: [f32; TP],
}

impl State {
    fn new(ctx: &TileCtx) -> Self {
        let mut s = State {
            t: [0.0; TP],
            tfin: [1.0; TP],
            col: [[0.0; TP]; 3],
            last: [0; TP],
            live: 0,
            kmin: [0.0; TP],
        };
        for r in 0..ctx.rows {
            s.t[r * TS..r * TS + ctx.cols].fill(1.0);
            s.live |= 1 << r;
        }
        s
    }
}

#[inline(always)]
fn tile_impl<const TOPK: bool, const COUNT: bool>(
    ctx: &TileCtx,
    list: TileList,
    splats: &[Splat],
    gids: &[u32],
    out: TileOut,
) -> PairCounts {
    let mut s = State::new(ctx);
    let px: [f32; TS] = std::array::from_fn(|l| ctx.x0 as f32 + l as f32 + 0.5);
    let mut wrow = [0.0f32; TS];
    let mut n = PairCounts::default();
    for (pos, &rank) in list.ranks.iter().enumerate() {
        let sp = &splats[rank as usize];
        // Rows in increasing order, as a loop over [r0, r1) testing each would visit them.
        let mut todo = list.rows(pos, sp, ctx.x0, ctx.y0) & s.live;
        let mut blocks = BlockMarks::default();
        while todo != 0 {
            let r = todo.trailing_zeros() as usize;
            todo &= todo - 1;
            let dy = sp.row_dy(ctx.y0, r);
            n.pairs += TS as u64;
            let span = r * TS..(r + 1) * TS;
            let row = Row {
                t: (&mut s.t[span.clone()]).try_into().expect("16"),
                tfin: (&mut s.tfin[span.clone()]).try_into().expect("16"),
                last: (&mut s.last[span.clone()]).try_into().expect("16"),
            };
            let [cr, cg, cb] = &mut s.col;
            let cols = [
                (&mut cr[span.clone()]).try_into().expect("16"),
                (&mut cg[span.clone()]).try_into().expect("16"),
                (&mut cb[span.clone()]).try_into().expect("16"),
            ];
            if COUNT {
                n.alpha += count_alpha_row(sp, &px, dy, row.t);
                blocks.mark(sp, dy, r, ctx.x0 as f32);
            }
            let live = composite_row(sp, &px, dy, pos as u32 + 1, row, cols, &mut wrow);
            if !live {
                s.live &= !(1 << r);
            }
            if TOPK {
                let kmin: &mut [f32; TS] = (&mut s.kmin[span]).try_into().expect("16");
                if wrow
                    .iter()
                    .zip(kmin.iter())
                    .fold(false, |a, (w, m)| a | (w > m))
                {
                    let (ids, ws) = (&mut out.topk_ids[..], &mut out.topk_w[..]);
                    insert_topk(ctx.k, r, &wrow, gids[rank as usize], ids, ws, kmin);
                }
            }
        }
        if COUNT {
            n.block_4x4 += TS as u64 * u64::from(blocks.b4.count_ones());
            n.block_8x2 += TS as u64 * u64::from(blocks.b8.count_ones());
        }
        if (pos & 7) == 7 && s.live == 0 {
            break;
        }
    }
    finish(ctx, &s, out);
    n
}

/// Pixels of one row where [`composite_row`] would find `σ ≥ 0`, `α ≥ 1/255` and the pixel
/// unfinished (its `ok`), in its arithmetic.
fn count_alpha_row(sp: &Splat, px: &[f32; TS], dy: f32, t: &[f32; TS]) -> u64 {
    let mut n = 0;
    for l in 0..TS {
        let dx = sp.mx - px[l];
        let sigma = 0.5 * (sp.a * dx * dx + sp.c * dy * dy) + sp.b * dx * dy;
        let alpha = (sp.o * fastexp::exp(-sigma)).min(ALPHA_MAX);
        n += ((sigma >= 0.0) & (alpha >= ALPHA_MIN) & (t[l] > 0.0)) as u64;
    }
    n
}

struct Row<'a> {
    t: &'a mut [f32; TS],
    tfin: &'a mut [f32; TS],
    last: &'a mut [u32; TS],
}

/// Composites one Gaussian over one row of 16 pixels; returns whether any pixel of the
/// row is still unfinished. `wrow` receives each pixel's weight T·α (0 if not composited).
#[inline(always)]
fn composite_row(
    sp: &Splat,
    px: &[f32; TS],
    dy: f32,
    pos1: u32,
    row: Row,
    cols: [&mut [f32; TS]; 3],
    wrow: &mut [f32; TS],
) -> bool {
    let [cr, cg, cb] = cols;
    let mut live = 0u32;
    for l in 0..TS {
        let dx = sp.mx - px[l];
        let sigma = 0.5 * (sp.a * dx * dx + sp.c * dy * dy) + sp.b * dx * dy;
        let alpha = (sp.o * fastexp::exp(-sigma)).min(ALPHA_MAX);
        let t = row.t[l];
        let ok = (sigma >= 0.0) & (alpha >= ALPHA_MIN) & (t > 0.0);
        let next = t * (1.0 - alpha);
        let contrib = ok & (next > T_MIN);
        let term = ok & (next <= T_MIN);
        let w = if contrib { alpha * t } else { 0.0 };
        cr[l] += w * sp.rgb[0];
        cg[l] += w * sp.rgb[1];
        cb[l] += w * sp.rgb[2];
        row.tfin[l] = if term { t } else { row.tfin[l] };
        let tn = if contrib { next } else { t };
        let tn = if term { 0.0 } else { tn };
        row.t[l] = tn;
        row.last[l] = if contrib { pos1 } else { row.last[l] };
        wrow[l] = w;
        live |= (tn > 0.0) as u32;
    }
    live != 0
}

/// Inserts this row's positive weights into the pixels' sorted top-k lists.
#[inline(always)]
fn insert_topk(
    k: usize,
    r: usize,
    wrow: &[f32; TS],
    gid: u32,
    ids: &mut [u32],
    ws: &mut [f32],
    kmin: &mut [f32; TS],
) {
    for (l, &w) in wrow.iter().enumerate() {
        let base = (r * TS + l) * k;
        if w <= kmin[l] {
            continue;
        }
        let mut j = k - 1;
        while j > 0 && ws[base + j - 1] < w {
            ws[base + j] = ws[base + j - 1];
            ids[base + j] = ids[base + j - 1];
            j -= 1;
        }
        ws[base + j] = w;
        ids[base + j] = gid;
        kmin[l] = ws[base + k - 1];
    }
}

fn finish(ctx: &TileCtx, s: &State, out: TileOut) {
    for p in 0..TP {
        let t = if s.t[p] > 0.0 { s.t[p] } else { s.tfin[p] };
        out.tfin[p] = t;
        out.last[p] = s.last[p];
        for c in 0..3 {
            out.color[c * TP + p] = s.col[c][p] + t * ctx.bg[c];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Every row that [`Splat::reaches_row`] rejects composites nothing in the kernel's own
    /// arithmetic (σ and the polynomial exp in f32), for elongated, rotated, faint and
    /// opaque Gaussians placed around a tile: skipping such rows cannot change an image.
    #[test]
    fn chord_cull_is_conservative() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (mut rejected, mut near_miss) = (0u64, 0u64);
        for _ in 0..200_000 {
            let (s1, s2) = (rng.gen_range(0.3f32..40.0), rng.gen_range(0.3f32..40.0));
            let th = rng.gen_range(0.0f32..std::f32::consts::PI);
            let (c, s) = (th.cos(), th.sin());
            // Covariance R diag(s1², s2²) Rᵀ, conic = its inverse.
            let (xx, yy) = (
                c * c * s1 * s1 + s * s * s2 * s2,
                s * s * s1 * s1 + c * c * s2 * s2,
            );
            let xy = c * s * (s1 * s1 - s2 * s2);
            let det = xx * yy - xy * xy;
            let conic = [yy / det, -xy / det, xx / det];
            let o = rng.gen_range(0.003f32..1.0);
            let mean = [rng.gen_range(-60.0f32..76.0), rng.gen_range(-60.0f32..76.0)];
            let sp = Splat::new(mean, conic, o, [1.0; 3]);
            let (r0, r1) = sp.rows(0);
            for r in r0..r1 {
                let dy = sp.my - (r as f32 + 0.5);
                if sp.reaches_row(dy, 0.0) {
                    continue;
                }
                rejected += 1;
                for l in 0..TS {
                    let dx = sp.mx - (l as f32 + 0.5);
                    let sigma = 0.5 * (sp.a * dx * dx + sp.c * dy * dy) + sp.b * dx * dy;
                    let alpha = (sp.o * fastexp::exp(-sigma)).min(ALPHA_MAX);
                    assert!(
                        !(sigma >= 0.0 && alpha >= ALPHA_MIN),
                        "row {r} lane {l} rejected but α = {alpha} for {sp:?}"
                    );
                    near_miss += (alpha >= 0.9 * ALPHA_MIN) as u64;
                }
            }
        }
        // The test must exercise the boundary, not only far-away rows.
        assert!(
            rejected > 10_000 && near_miss > 100,
            "{rejected} {near_miss}"
        );
    }
}
