//! Tile binning: every visible Gaussian goes to the list of each 16×16 tile its per-axis
//! box touches (gsplat `_isect_tiles`: `floor(m/16 − r/16) .. ceil(m/16 + r/16)`, clamped
//! to the tile grid), and each list is in increasing depth (ties: lower index first, as
//! gsplat's sort of `tile | depth` keys over index-ordered intersections).
//!
//! With [`Cull::Exact`] a Gaussian keeps, in each tile row of that box, only the
//! tiles its opacity-aware ellipse `σ ≤ ln(255·o)` can reach, in the kernels' own row tests
//! ([`Splat::rows`], [`Splat::chord`]): the per-row analogue of the exact ellipse–tile tests
//! of FlashGS, StopThePop (as ported in Brush) and Speedy-Splat's AccuTile, and of gsplat's
//! opacity-aware extent (PR #597). Binning computes each pixel row's chord once per
//! Gaussian and from it, per tile, the 16-bit mask of rows the kernels evaluate
//! ([`Splat::row_mask`], bit-exact: the same compares on the same f32 values); tiles whose
//! mask is zero are dropped, the others carry their mask in the list (`masks`), so the
//! kernels no longer test rows (a square root and a division per row and tile, in both
//! passes). A dropped tile is one in which the kernels would evaluate no row, so dropping
//! it changes no image and no gradient (tests/cull_equivalence.rs).
//!
//! Instead of sorting all (tile, depth) keys, the visible Gaussians are sorted once by depth
//! and then distributed into the tiles by a counting sort, which keeps each list in depth
//! order: O(N log N + intersections).

use crate::forward::{Splat, TileList, TS};
use crate::project::Projected;
use crate::raster::Simd;
use crate::{Cull, TILE_SIZE};
use rayon::prelude::*;

/// Per-tile, depth-sorted Gaussian lists; buffers are reused across builds.
#[derive(Default, Debug)]
pub(crate) struct Bins {
    pub tiles_x: usize,
    pub tiles_y: usize,
    /// `tiles_x·tiles_y + 1` offsets into `ids`.
    pub offsets: Vec<usize>,
    /// Depth ranks (indices into `order`), tile after tile, increasing in each tile.
    pub ids: Vec<u32>,
    /// With [`Cull::Exact`]: the [`Splat::row_mask`] of each entry of `ids` (else empty).
    pub masks: Vec<u16>,
    /// Global index of the visible Gaussian of each depth rank (front to back).
    pub order: Vec<u32>,
    /// Depth rank of each Gaussian (`u32::MAX` when not visible).
    pub rank_of: Vec<u32>,
    /// `order.len() + 1` prefix sums of the ranks' tile-rectangle areas: rank `r` owns
    /// the intersection slots `slot_start[r]..slot_start[r + 1]` (see `grad_slots`).
    pub slot_start: Vec<usize>,
    /// What [`Bins::slot`] needs of each rank, in rank order: one load per (Gaussian,
    /// tile) in the backward instead of a dependent chain through `order` and `rects`.
    slot_geom: Vec<SlotGeom>,
    keys: Vec<u64>,
    /// 3.33σ tile rectangle `[x0, x1, y0, y1)` of each Gaussian (by global index).
    rects: Vec<[u32; 4]>,
    /// Tile rectangle of each rank: the bounding box of its kept tiles (with
    /// [`Cull::Box3Sigma`], its whole 3.33σ box).
    rank_rects: Vec<[u32; 4]>,
    /// Kept tiles `[x0, x1)` of each tile row of each rank's 3.33σ box, rank after rank;
    /// `span_at[rank]` says where its rows start.
    spans: Vec<[u32; 2]>,
    /// With [`Cull::Exact`]: the row mask of every tile of each rank's 3.33σ box
    /// (row-major; 0 = dropped), rank after rank.
    box_masks: Vec<u16>,
    span_at: Vec<SpanAt>,
    cursor: Vec<usize>,
}

/// Where a Gaussian's tile-row spans and box masks start, and its 3.33σ box's corner and
/// width.
#[derive(Clone, Copy, Debug, Default)]
struct SpanAt {
    start: usize,
    mask: usize,
    x0: u32,
    y0: u32,
    w: u32,
}

impl SpanAt {
    /// Span of tile row `y` (inside the Gaussian's rectangle).
    #[inline]
    fn span(self, spans: &[[u32; 2]], y: usize) -> [u32; 2] {
        spans[self.start + y - self.y0 as usize]
    }

    /// Row mask of tile `(x, y)` of the box (`u16::MAX`, "keep", without masks).
    #[inline]
    fn mask(self, masks: &[u16], x: usize, y: usize) -> u16 {
        if masks.is_empty() {
            return u16::MAX;
        }
        let row = (y - self.y0 as usize) * self.w as usize;
        masks[self.mask + row + x - self.x0 as usize]
    }
}

/// A rank's first slot and the corner and width of its tile rectangle.
#[derive(Clone, Copy, Debug, Default)]
struct SlotGeom {
    start: usize,
    x0: u32,
    width: u32,
    y0: u32,
}

/// Tile rectangle `[x0, x1, y0, y1)` of a projected Gaussian (empty when culled).
fn tile_rect(p: &Projected, tiles_x: usize, tiles_y: usize) -> [u32; 4] {
    if p.radii[0] <= 0 || p.radii[1] <= 0 {
        return [0; 4];
    }
    let ts = TILE_SIZE as f32;
    let (mx, my) = (p.mean2d[0] / ts, p.mean2d[1] / ts);
    let (rx, ry) = (p.radii[0] as f32 / ts, p.radii[1] as f32 / ts);
    let clampx = |v: f32| (v.max(0.0) as usize).min(tiles_x) as u32;
    let clampy = |v: f32| (v.max(0.0) as usize).min(tiles_y) as u32;
    [
        clampx((mx - rx).floor()),
        clampx((mx + rx).ceil()),
        clampy((my - ry).floor()),
        clampy((my + ry).ceil()),
    ]
}

/// Row masks of the tiles `[rx0, rx1)` of tile row `ty` into `masks` (one per tile);
/// returns the span `[x0, x1)` from the first to the last non-zero one (empty: `x0 == x1`).
/// Each row's chord `(lo, hi)` is computed once ([`Splat::chord`], as the kernels do); a
/// tile `tx` gets bit `r` iff `hi ≥ 16·tx + 0.5 && lo ≤ 16·tx + 15.5`, the compares of
/// [`Splat::reaches_row`] on the same f32 values, so the mask equals [`Splat::row_mask`]
/// (unit-tested). Every tile of the box is tested, so that no branch waits on the chords
/// (the loop is latency-bound otherwise: square root, reductions, mispredicted exits).
#[inline(always)]
fn row_masks<const AVX512: bool>(
    sp: &Splat,
    ty: u32,
    rx0: u32,
    rx1: u32,
    masks: &mut [u16],
) -> [u32; 2] {
    let y0 = ty * TILE_SIZE;
    let (r0, r1) = sp.rows(y0);
    // All 16 rows branch-free (one vector); rows outside [r0, r1) and NaN chords (which
    // fail the kernels' compares too) get the empty chord (+∞, −∞).
    let (mut lo, mut hi) = ([0.0f32; TS], [0.0f32; TS]);
    for r in 0..TS {
        let (a, b) = sp.chord(sp.row_dy(y0, r));
        let on = (r >= r0) & (r < r1) & (a <= b);
        lo[r] = if on { a } else { f32::INFINITY };
        hi[r] = if on { b } else { f32::NEG_INFINITY };
    }
    let mut span = [u32::MAX, 0];
    for (tx, out) in (rx0..rx1).zip(masks.iter_mut()) {
        let x0 = (tx * TILE_SIZE) as f32;
        let m = if AVX512 {
            // SAFETY: `AVX512` is only set by `CullJob::run_avx512`, which has the feature.
            #[cfg(target_arch = "x86_64")]
            unsafe {
                tile_bits_avx512(&lo, &hi, x0)
            }
            #[cfg(not(target_arch = "x86_64"))]
            tile_bits(&lo, &hi, x0)
        } else {
            tile_bits(&lo, &hi, x0)
        };
        *out = m;
        let on = m != 0;
        span = [
            if on { span[0].min(tx) } else { span[0] },
            if on { tx + 1 } else { span[1] },
        ];
    }
    if span[0] < span[1] {
        span
    } else {
        [rx0, rx0]
    }
}

/// Bit `r` set where row `r`'s chord `[lo, hi]` meets the pixel centres of the tile at
/// `x0`: the compares of [`Splat::reaches_row`] (reference of [`tile_bits_avx512`]).
#[inline(always)]
fn tile_bits(lo: &[f32; TS], hi: &[f32; TS], x0: f32) -> u16 {
    let mut m = 0u16;
    for r in 0..TS {
        m |= (((hi[r] >= x0 + 0.5) & (lo[r] <= x0 + (TS as f32 - 0.5))) as u16) << r;
    }
    m
}

/// [`tile_bits`] as two 16-lane compares into mask registers (ordered compares: false for
/// NaN, as Rust's `>=`/`<=`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn tile_bits_avx512(lo: &[f32; TS], hi: &[f32; TS], x0: f32) -> u16 {
    use std::arch::x86_64::*;
    // SAFETY: 16 f32 per array, unaligned loads.
    let (l, h) = unsafe { (_mm512_loadu_ps(lo.as_ptr()), _mm512_loadu_ps(hi.as_ptr())) };
    let ge = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(h, _mm512_set1_ps(x0 + 0.5));
    let le = _mm512_cmp_ps_mask::<_CMP_LE_OQ>(l, _mm512_set1_ps(x0 + (TS as f32 - 0.5)));
    ge & le
}

/// Fills `spans` (one per tile row of `rect`, the 3.33σ box) and, with [`Cull::Exact`],
/// `masks` (one per tile of `rect`); returns the bounding rectangle of the kept
/// tiles (all zero when none).
#[inline(always)]
fn cull_spans<const AVX512: bool>(
    sp: &Splat,
    rect: [u32; 4],
    cull: Cull,
    spans: &mut [[u32; 2]],
    masks: &mut [u16],
) -> [u32; 4] {
    let [x0, x1, y0, y1] = rect;
    if cull == Cull::Box3Sigma {
        spans.fill([x0, x1]);
        return rect;
    }
    let w = (x1 - x0) as usize;
    let mut bound = [u32::MAX, 0, u32::MAX, 0];
    for (ty, s) in (y0..y1).zip(spans.iter_mut()) {
        let row = (ty - y0) as usize * w;
        *s = row_masks::<AVX512>(sp, ty, x0, x1, &mut masks[row..row + w]);
        if s[0] < s[1] {
            bound = [
                bound[0].min(s[0]),
                bound[1].max(s[1]),
                bound[2].min(ty),
                ty + 1,
            ];
        }
    }
    if bound[0] < bound[1] {
        bound
    } else {
        [0; 4]
    }
}

/// One parallel job of [`Bins::cull`]: a chunk of ranks (`gids`: their Gaussians) with
/// their spans, box masks, rectangles and splats.
struct CullJob<'a> {
    proj: &'a [Projected],
    gids: &'a [u32],
    cull: Cull,
    spans: &'a mut [[u32; 2]],
    masks: &'a mut [u16],
    rects: &'a mut [[u32; 4]],
    splats: &'a mut [Splat],
}

impl CullJob<'_> {
    /// Runs at the widest vector level (the 16 rows' chords are one AVX-512 vector); the
    /// arithmetic is the same at every level (no FMA contraction), so are the masks.
    fn run(self, simd: Simd) {
        #[cfg(target_arch = "x86_64")]
        match simd {
            // SAFETY: `simd_level` checked that the CPU supports these features.
            Simd::Avx512 => return unsafe { self.run_avx512() },
            // SAFETY: as above.
            Simd::Avx2 => return unsafe { self.run_avx2() },
            Simd::Portable => {}
        }
        let _ = simd;
        self.run_impl::<false>()
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,fma")]
    unsafe fn run_avx512(self) {
        self.run_impl::<true>()
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn run_avx2(self) {
        self.run_impl::<false>()
    }

    #[inline(always)]
    fn run_impl<const AVX512: bool>(self) {
        let exact = self.cull == Cull::Exact;
        let (mut so, mut mo) = (0, 0);
        let per_rank = self.gids.iter().zip(self.rects.iter_mut());
        for ((&g, rect), out) in per_rank.zip(self.splats.iter_mut()) {
            let p = &self.proj[g as usize];
            *out = Splat::new(p.mean2d, p.conic, p.opacity, p.rgb);
            let h = (rect[3] - rect[2]) as usize;
            let a = if exact {
                h * (rect[1] - rect[0]) as usize
            } else {
                0
            };
            let (s, m) = (&mut self.spans[so..so + h], &mut self.masks[mo..mo + a]);
            *rect = cull_spans::<AVX512>(out, *rect, self.cull, s, m);
            (so, mo) = (so + h, mo + a);
        }
    }
}

impl Bins {
    pub fn n_isects(&self) -> usize {
        self.ids.len()
    }

    /// Gradient slots: the area of each visible Gaussian's tile rectangle.
    pub fn n_slots(&self) -> usize {
        self.slot_start.last().copied().unwrap_or(0)
    }

    pub fn tile_list(&self, tile: usize) -> TileList<'_> {
        let range = self.offsets[tile]..self.offsets[tile + 1];
        TileList {
            masks: if self.masks.is_empty() {
                &[]
            } else {
                &self.masks[range.clone()]
            },
            ranks: &self.ids[range],
        }
    }

    /// Gradient slot of the Gaussian of depth rank `rank` in tile `(tx, ty)`, which must
    /// be inside its rectangle.
    #[inline]
    pub fn slot(&self, rank: usize, tx: usize, ty: usize) -> usize {
        let g = self.slot_geom[rank];
        g.start + (ty - g.y0 as usize) * g.width as usize + (tx - g.x0 as usize)
    }

    /// Culls the ranks' 3.33σ boxes (`rank_rects` on entry) into the bounding boxes of
    /// their kept tiles, filling `spans`, `box_masks` and `span_at`, and writes each rank's
    /// splat; in rank order (sequential writes, one read of each Gaussian), parallel over
    /// chunks of ranks.
    fn cull(&mut self, proj: &[Projected], cull: Cull, simd: Simd, splats: &mut [Splat]) {
        self.span_at.clear();
        let (mut rows, mut area) = (0, 0);
        for r in &self.rank_rects {
            let (w, h) = ((r[1] - r[0]) as usize, (r[3] - r[2]) as usize);
            self.span_at.push(SpanAt {
                start: rows,
                mask: area,
                x0: r[0],
                y0: r[2],
                w: w as u32,
            });
            (rows, area) = (rows + h, area + w * h);
        }
        resize(&mut self.spans, rows, [0; 2]);
        let exact = cull == Cull::Exact;
        resize(&mut self.box_masks, if exact { area } else { 0 }, 0);
        // Disjoint (ranks, spans, masks, rects, splats) chunks for the parallel jobs.
        const CHUNK: usize = 2048;
        let mut jobs = Vec::with_capacity(self.order.len().div_ceil(CHUNK));
        let (mut spans, mut masks) = (&mut self.spans[..], &mut self.box_masks[..]);
        let (mut rects, mut sps) = (&mut self.rank_rects[..], splats);
        for (c, at) in self.span_at.chunks(CHUNK).enumerate() {
            let next = self.span_at.get((c + 1) * CHUNK);
            let (s_end, m_end) = next.map_or((rows, area), |a| (a.start, a.mask));
            let (s, s_rest) = std::mem::take(&mut spans).split_at_mut(s_end - at[0].start);
            let m_len = if exact { m_end - at[0].mask } else { 0 };
            let (m, m_rest) = std::mem::take(&mut masks).split_at_mut(m_len);
            let (r, r_rest) = std::mem::take(&mut rects).split_at_mut(at.len());
            let (p, p_rest) = std::mem::take(&mut sps).split_at_mut(at.len());
            (spans, masks, rects, sps) = (s_rest, m_rest, r_rest, p_rest);
            let gids = &self.order[c * CHUNK..c * CHUNK + at.len()];
            jobs.push((gids, s, m, r, p));
        }
        jobs.into_par_iter()
            .for_each(|(gids, spans, masks, rects, splats)| {
                let job = CullJob {
                    proj,
                    gids,
                    cull,
                    spans,
                    masks,
                    rects,
                    splats,
                };
                job.run(simd);
            });
    }

    /// Bins `proj` and writes the visible Gaussians' splats in depth order into `splats`.
    pub fn build(
        &mut self,
        proj: &[Projected],
        size: (u32, u32),
        (cull, simd): (Cull, Simd),
        splats: &mut Vec<Splat>,
    ) {
        let (width, height) = size;
        let ts = TILE_SIZE as usize;
        self.tiles_x = (width as usize).div_ceil(ts);
        self.tiles_y = (height as usize).div_ceil(ts);
        let (tx, ty) = (self.tiles_x, self.tiles_y);
        self.rects.clear();
        self.rects
            .par_extend(proj.par_iter().map(|p| tile_rect(p, tx, ty)));
        self.sort_visible(proj);
        // Ranks whose culled rectangle is empty stay in the order with no tiles and no
        // slots: their gradient sums are zero, as a Gaussian outside the order gets.
        let rects = &self.rects;
        self.rank_rects.clear();
        self.rank_rects
            .par_extend(self.order.par_iter().map(|&g| rects[g as usize]));
        splats.clear();
        splats.resize(self.order.len(), Splat::default());
        self.cull(proj, cull, simd, splats);
        self.slots();
        self.fill_lists(tx, ty);
    }

    /// `keys`, `order`, `rank_of`: the Gaussians with a non-empty 3.33σ box, by depth.
    fn sort_visible(&mut self, proj: &[Projected]) {
        self.keys.clear();
        let rects = &self.rects;
        self.keys.par_extend(
            proj.par_iter()
                .enumerate()
                .filter(|(i, _)| rects[*i][0] < rects[*i][1] && rects[*i][2] < rects[*i][3])
                .map(|(i, p)| ((p.depth.to_bits() as u64) << 32) | i as u64),
        );
        // Depths of visible Gaussians are > near plane > 0, so their bit patterns order
        // like the floats.
        self.keys.par_sort_unstable();
        self.order.clear();
        self.order
            .par_extend(self.keys.par_iter().map(|&k| k as u32));
        self.rank_of.clear();
        self.rank_of.resize(proj.len(), u32::MAX);
        for (rank, &gid) in self.order.iter().enumerate() {
            self.rank_of[gid as usize] = rank as u32;
        }
    }

    /// `slot_start` and `slot_geom` from the ranks' (culled) rectangles.
    fn slots(&mut self) {
        self.slot_start.clear();
        self.slot_start.push(0);
        self.slot_geom.clear();
        let mut slots = 0;
        for &[x0, x1, y0, y1] in &self.rank_rects {
            self.slot_geom.push(SlotGeom {
                start: slots,
                x0,
                width: x1 - x0,
                y0,
            });
            slots += (x1 - x0) as usize * (y1 - y0) as usize;
            self.slot_start.push(slots);
        }
    }

    /// The tile lists: a counting pass, prefix sums, a filling pass (banded, parallel).
    fn fill_lists(&mut self, tx: usize, ty: usize) {
        let n_tiles = tx * ty;
        self.offsets.clear();
        self.offsets.resize(n_tiles + 1, 0);
        let bands = ty.min(4 * rayon::current_num_threads()).max(1);
        let sp = Spans {
            rects: &self.rank_rects,
            spans: &self.spans,
            masks: &self.box_masks,
            at: &self.span_at,
        };
        count_bands(&sp, tx, (0, ty), bands, &mut self.offsets[1..]);
        for t in 0..n_tiles {
            self.offsets[t + 1] += self.offsets[t];
        }
        let n = self.offsets[n_tiles];
        resize(&mut self.ids, n, 0);
        resize(&mut self.masks, if sp.masks.is_empty() { 0 } else { n }, 0);
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.offsets[..n_tiles]);
        let out = ListsOut {
            ids: &mut self.ids,
            masks: &mut self.masks,
        };
        let job = (tx, (0, ty), bands);
        fill_bands(&sp, job, &mut self.cursor, out, 0);
    }
}

/// What the band jobs read of each rank (in depth order): its rectangle, its rows' spans
/// and its box masks (empty with [`Cull::Box3Sigma`]).
struct Spans<'a> {
    rects: &'a [[u32; 4]],
    spans: &'a [[u32; 2]],
    masks: &'a [u16],
    at: &'a [SpanAt],
}

/// The part of the tile lists (ids and, if any, masks) a band job writes.
struct ListsOut<'a> {
    ids: &'a mut [u32],
    masks: &'a mut [u16],
}

impl<'a> ListsOut<'a> {
    fn split_at(self, at: usize) -> (ListsOut<'a>, ListsOut<'a>) {
        let (ia, ib) = self.ids.split_at_mut(at);
        let (ma, mb) = if self.masks.is_empty() {
            (self.masks, &mut [][..])
        } else {
            self.masks.split_at_mut(at)
        };
        (
            ListsOut { ids: ia, masks: ma },
            ListsOut { ids: ib, masks: mb },
        )
    }
}

/// Sets `v` to `len` copies of `fill`, reusing its allocation.
fn resize<T: Clone>(v: &mut Vec<T>, len: usize, fill: T) {
    v.clear();
    v.resize(len, fill);
}

/// Counts the intersections of each tile in tile rows `rows` into `counts` (one slot per
/// tile of those rows), splitting the rows into `bands` parallel jobs.
fn count_bands(sp: &Spans, tx: usize, rows: (usize, usize), bands: usize, counts: &mut [usize]) {
    if bands > 1 && rows.1 - rows.0 > 1 {
        let mid = rows.0 + (rows.1 - rows.0) / 2;
        let (lo, hi) = counts.split_at_mut((mid - rows.0) * tx);
        rayon::join(
            || count_bands(sp, tx, (rows.0, mid), bands / 2, lo),
            || count_bands(sp, tx, (mid, rows.1), bands - bands / 2, hi),
        );
        return;
    }
    for (&[_, _, y0, y1], &at) in sp.rects.iter().zip(sp.at) {
        let (ya, yb) = ((y0 as usize).max(rows.0), (y1 as usize).min(rows.1));
        for y in ya..yb {
            let row = (y - rows.0) * tx;
            let [x0, x1] = at.span(sp.spans, y);
            for x in x0..x1 {
                counts[row + x as usize] += (at.mask(sp.masks, x as usize, y) != 0) as usize;
            }
        }
    }
}

/// Writes each rank (in depth order) into the lists of the tiles of tile rows `rows`,
/// `job = (tiles_x, rows, bands)`. `cursor` holds those tiles' next write positions
/// (absolute), `out` is the part of the lists that starts at absolute position `base`.
fn fill_bands(
    sp: &Spans,
    job: (usize, (usize, usize), usize),
    cursor: &mut [usize],
    out: ListsOut,
    base: usize,
) {
    let (tx, rows, bands) = job;
    if bands > 1 && rows.1 - rows.0 > 1 {
        let mid = rows.0 + (rows.1 - rows.0) / 2;
        let (clo, chi) = cursor.split_at_mut((mid - rows.0) * tx);
        let split = chi.first().map_or(base + out.ids.len(), |&c| c);
        let (olo, ohi) = out.split_at(split - base);
        let (jlo, jhi) = (
            (tx, (rows.0, mid), bands / 2),
            (tx, (mid, rows.1), bands - bands / 2),
        );
        rayon::join(
            || fill_bands(sp, jlo, clo, olo, base),
            || fill_bands(sp, jhi, chi, ohi, split),
        );
        return;
    }
    // Lists hold depth ranks: the kernels then read the rank-ordered splats forwards.
    for (rank, (&[_, _, y0, y1], &at)) in sp.rects.iter().zip(sp.at).enumerate() {
        let (ya, yb) = ((y0 as usize).max(rows.0), (y1 as usize).min(rows.1));
        for y in ya..yb {
            let row = (y - rows.0) * tx;
            let [x0, x1] = at.span(sp.spans, y);
            for x in x0..x1 {
                let m = at.mask(sp.masks, x as usize, y);
                if m == 0 {
                    continue;
                }
                let c = &mut cursor[row + x as usize];
                out.ids[*c - base] = rank as u32;
                if !out.masks.is_empty() {
                    out.masks[*c - base] = m;
                }
                *c += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fastexp;
    use crate::forward::{ALPHA_MAX, ALPHA_MIN};
    use rand::{Rng, SeedableRng};

    /// A random projected Gaussian around a 6×6-tile grid: rotated, elongated up to 1:100,
    /// opacity from just under 1/255 to 1, mean anywhere including off the grid.
    fn random_projected(rng: &mut impl Rng) -> Projected {
        let (s1, s2) = (rng.gen_range(0.3f32..40.0), rng.gen_range(0.3f32..40.0));
        let th = rng.gen_range(0.0f32..std::f32::consts::PI);
        let (c, s) = (th.cos(), th.sin());
        let xx = c * c * s1 * s1 + s * s * s2 * s2 + 0.3;
        let yy = s * s * s1 * s1 + c * c * s2 * s2 + 0.3;
        let xy = c * s * (s1 * s1 - s2 * s2);
        let det = xx * yy - xy * xy;
        let o = if rng.gen_bool(0.3) {
            rng.gen_range(0.97f32..1.5) / 255.0
        } else {
            rng.gen_range(0.004f32..1.0)
        };
        // Per-axis 3.33σ radii, as `project` (the box the exact culling starts from).
        let r = |v: f32| (3.33 * v.sqrt()).ceil() as i32;
        Projected {
            mean2d: [
                rng.gen_range(-40.0f32..136.0),
                rng.gen_range(-40.0f32..136.0),
            ],
            depth: 1.0,
            conic: [yy / det, -xy / det, xx / det],
            radii: [r(xx), r(yy)],
            opacity: o,
            rgb: [1.0; 3],
        }
    }

    /// Binning's row masks equal the kernels' own [`Splat::row_mask`] on every tile of the
    /// 3.33σ box, and every tile that `Cull::Exact` drops is one in which (1) no pixel row
    /// passes the kernels' row tests and (2) no pixel reaches α ≥ 1/255 in the kernels' own
    /// arithmetic (σ in f32, the polynomial exp). (1) is what makes images and gradients
    /// bit-identical; (2) holds through the row tests' margins (without them it fails, as
    /// `chord_cull_is_conservative` shows for the rows). The counts make sure the test
    /// reaches the boundary: many dropped tiles, some within 10 % of the threshold.
    #[test]
    fn exact_cull_drops_only_tiles_the_kernels_skip() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let (tiles, ts) = (6usize, TS as f32);
        let (mut dropped, mut near_miss, mut kept) = (0u64, 0u64, 0u64);
        for _ in 0..20_000 {
            let p = random_projected(&mut rng);
            let rect = tile_rect(&p, tiles, tiles);
            let (w, h) = ((rect[1] - rect[0]) as usize, (rect[3] - rect[2]) as usize);
            let mut spans = vec![[0u32; 2]; h];
            let mut masks = vec![0u16; w * h];
            let sp = Splat::new(p.mean2d, p.conic, p.opacity, p.rgb);
            let bound = cull_spans::<false>(&sp, rect, Cull::Exact, &mut spans, &mut masks);
            for ty in rect[2]..rect[3] {
                let [sx0, sx1] = spans[(ty - rect[2]) as usize];
                for tx in rect[0]..rect[1] {
                    let m = masks[(ty - rect[2]) as usize * w + (tx - rect[0]) as usize];
                    let want = sp.row_mask(tx * TILE_SIZE, ty * TILE_SIZE);
                    assert_eq!(m, want, "tile ({tx}, {ty}): {p:?}");
                    assert!(m == 0 || (sx0 <= tx && tx < sx1));
                    if m != 0 {
                        kept += 1;
                        assert!(bound[0] <= tx && tx < bound[1] && bound[2] <= ty && ty < bound[3]);
                        continue;
                    }
                    dropped += 1;
                    let (x0, y0) = (tx as f32 * ts, ty * TILE_SIZE);
                    let (r0, r1) = sp.rows(y0);
                    for r in 0..TS {
                        let dy = sp.row_dy(y0, r);
                        let row_on = (r0..r1).contains(&r) && sp.reaches_row(dy, x0);
                        assert!(!row_on, "tile ({tx}, {ty}) row {r}: {p:?}");
                        for l in 0..TS {
                            let dx = sp.mx - (x0 + l as f32 + 0.5);
                            let sigma = 0.5 * (sp.a * dx * dx + sp.c * dy * dy) + sp.b * dx * dy;
                            let alpha = (sp.o * fastexp::exp(-sigma)).min(ALPHA_MAX);
                            assert!(!(sigma >= 0.0 && alpha >= ALPHA_MIN), "{p:?}");
                            near_miss += (alpha >= 0.9 * ALPHA_MIN) as u64;
                        }
                    }
                }
            }
        }
        assert!(
            dropped > 20_000 && near_miss > 100 && kept > 20_000,
            "{dropped} {near_miss} {kept}"
        );
    }
}
