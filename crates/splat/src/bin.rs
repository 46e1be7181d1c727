//! Tile binning: every visible Gaussian goes to the list of each 16×16 tile its per-axis
//! box touches (gsplat `_isect_tiles`: `floor(m/16 − r/16) .. ceil(m/16 + r/16)`, clamped
//! to the tile grid), and each list is in increasing depth (ties: lower index first, as
//! gsplat's sort of `tile | depth` keys over index-ordered intersections).
//!
//! Instead of sorting all (tile, depth) keys, the visible Gaussians are sorted once by depth
//! and then distributed into the tiles by a counting sort, which keeps each list in depth
//! order: O(N log N + intersections).

use crate::project::Projected;
use crate::TILE_SIZE;
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
    /// Tile rectangle `[x0, x1, y0, y1)` of each Gaussian (by global index).
    pub rects: Vec<[u32; 4]>,
    cursor: Vec<usize>,
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

impl Bins {
    pub fn n_isects(&self) -> usize {
        self.ids.len()
    }

    pub fn tile_list(&self, tile: usize) -> &[u32] {
        &self.ids[self.offsets[tile]..self.offsets[tile + 1]]
    }

    /// Gradient slot of the Gaussian of depth rank `rank` in tile `(tx, ty)`, which must
    /// be inside its rectangle.
    #[inline]
    pub fn slot(&self, rank: usize, tx: usize, ty: usize) -> usize {
        let g = self.slot_geom[rank];
        g.start + (ty - g.y0 as usize) * g.width as usize + (tx - g.x0 as usize)
    }

    pub fn build(&mut self, proj: &[Projected], width: u32, height: u32) {
        let ts = TILE_SIZE as usize;
        self.tiles_x = (width as usize).div_ceil(ts);
        self.tiles_y = (height as usize).div_ceil(ts);
        let n_tiles = self.tiles_x * self.tiles_y;
        let (tx, ty) = (self.tiles_x, self.tiles_y);
        self.rects.clear();
        self.rects
            .par_extend(proj.par_iter().map(|p| tile_rect(p, tx, ty)));
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
        self.slot_start.clear();
        self.slot_start.push(0);
        self.slot_geom.clear();
        let mut slots = 0;
        for (rank, &gid) in self.order.iter().enumerate() {
            self.rank_of[gid as usize] = rank as u32;
            let [x0, x1, y0, y1] = self.rects[gid as usize];
            self.slot_geom.push(SlotGeom {
                start: slots,
                x0,
                width: x1 - x0,
                y0,
            });
            slots += (x1 - x0) as usize * (y1 - y0) as usize;
            self.slot_start.push(slots);
        }

        self.offsets.clear();
        self.offsets.resize(n_tiles + 1, 0);
        let bands = ty.min(4 * rayon::current_num_threads()).max(1);
        count_bands(rects, tx, (0, ty), bands, &mut self.offsets[1..]);
        for t in 0..n_tiles {
            self.offsets[t + 1] += self.offsets[t];
        }
        self.ids.clear();
        self.ids.resize(self.offsets[n_tiles], 0);
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.offsets[..n_tiles]);
        fill_bands(
            &self.keys,
            rects,
            tx,
            (0, ty),
            bands,
            &mut self.cursor,
            &mut self.ids,
            0,
        );
    }
}

/// Counts the intersections of each tile in tile rows `rows` into `counts` (one slot per
/// tile of those rows), splitting the rows into `bands` parallel jobs.
fn count_bands(
    rects: &[[u32; 4]],
    tx: usize,
    rows: (usize, usize),
    bands: usize,
    counts: &mut [usize],
) {
    if bands > 1 && rows.1 - rows.0 > 1 {
        let mid = rows.0 + (rows.1 - rows.0) / 2;
        let (lo, hi) = counts.split_at_mut((mid - rows.0) * tx);
        rayon::join(
            || count_bands(rects, tx, (rows.0, mid), bands / 2, lo),
            || count_bands(rects, tx, (mid, rows.1), bands - bands / 2, hi),
        );
        return;
    }
    for &[x0, x1, y0, y1] in rects {
        let (ya, yb) = ((y0 as usize).max(rows.0), (y1 as usize).min(rows.1));
        for y in ya..yb {
            let row = (y - rows.0) * tx;
            for x in x0..x1 {
                counts[row + x as usize] += 1;
            }
        }
    }
}

/// Writes each Gaussian (in depth order) into the lists of the tiles of rows `rows`.
/// `cursor` holds those tiles' next write positions (absolute), `ids` is the part of the
/// id buffer that starts at absolute position `base`.
#[allow(clippy::too_many_arguments)]
fn fill_bands(
    keys: &[u64],
    rects: &[[u32; 4]],
    tx: usize,
    rows: (usize, usize),
    bands: usize,
    cursor: &mut [usize],
    ids: &mut [u32],
    base: usize,
) {
    if bands > 1 && rows.1 - rows.0 > 1 {
        let mid = rows.0 + (rows.1 - rows.0) / 2;
        let (clo, chi) = cursor.split_at_mut((mid - rows.0) * tx);
        let split = chi.first().map_or(base + ids.len(), |&c| c);
        let (ilo, ihi) = ids.split_at_mut(split - base);
        rayon::join(
            || fill_bands(keys, rects, tx, (rows.0, mid), bands / 2, clo, ilo, base),
            || {
                fill_bands(
                    keys,
                    rects,
                    tx,
                    (mid, rows.1),
                    bands - bands / 2,
                    chi,
                    ihi,
                    split,
                )
            },
        );
        return;
    }
    // Lists hold depth ranks: the kernels then read the rank-ordered splats forwards.
    for (rank, &key) in keys.iter().enumerate() {
        let [x0, x1, y0, y1] = rects[key as u32 as usize];
        let (ya, yb) = ((y0 as usize).max(rows.0), (y1 as usize).min(rows.1));
        for y in ya..yb {
            let row = (y - rows.0) * tx;
            for x in x0..x1 {
                let c = &mut cursor[row + x as usize];
                ids[*c - base] = rank as u32;
                *c += 1;
            }
        }
    }
}
