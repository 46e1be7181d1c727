//! Deterministic accumulation of the backward pass's per-Gaussian sums.
//!
//! Each (Gaussian, tile) intersection owns one slot. A tile job stores the sums of each of
//! its Gaussians into that Gaussian's slot for the tile; afterwards every Gaussian adds its
//! slots in a fixed order (its tiles in row-major order). No sum depends on which thread
//! ran which tile, so gradients are bit-identical from run to run and for any thread
//! count, which per-thread accumulators (the previous design) could not give.
//!
//! Slot layout: Gaussian of depth rank `r` with tile rectangle `[x0, x1) × [y0, y1)` owns
//! `start[r] .. start[r + 1]`, the tile `(tx, ty)` at `start[r] + (ty − y0)·(x1 − x0) +
//! (tx − x0)`.

use crate::backward::GradAcc;
use rayon::prelude::*;
use std::marker::PhantomData;

/// One `[f32; 9]` slot per intersection, reused across calls.
#[derive(Default)]
pub(crate) struct GradSlots {
    slots: Vec<GradAcc>,
}

impl GradSlots {
    /// Sizes the buffer to `n` slots, all zero (intersections the backward pass never
    /// reaches, behind the last composited Gaussian of a tile, keep 0), and returns the
    /// handle the tile jobs store through.
    pub fn reset(&mut self, n: usize) -> SlotWriter<'_> {
        if self.slots.len() < n {
            self.slots.resize(n, [0.0; 9]);
        }
        self.slots[..n]
            .par_chunks_mut(8192)
            .for_each(|c| c.fill([0.0; 9]));
        SlotWriter {
            ptr: self.slots.as_mut_ptr(),
            len: n,
            _borrow: PhantomData,
        }
    }

    /// Sum of the slots `range`, in order.
    #[inline]
    pub fn sum(&self, range: std::ops::Range<usize>) -> GradAcc {
        let mut s = [0.0f32; 9];
        for slot in &self.slots[range] {
            for (sk, a) in s.iter_mut().zip(slot) {
                *sk += a;
            }
        }
        s
    }
}

/// Shared write access to the slots during the backward pass. Tile jobs on different
/// threads store into one buffer; each slot belongs to one (Gaussian, tile) pair and so
/// to one tile job, which is what makes the unsynchronized stores sound.
pub(crate) struct SlotWriter<'a> {
    ptr: *mut GradAcc,
    len: usize,
    _borrow: PhantomData<&'a mut [GradAcc]>,
}

// SAFETY: the writer only hands out stores to distinct slots (see `store`), and the
// buffer is mutably borrowed for the writer's lifetime, so nothing reads it meanwhile.
unsafe impl Sync for SlotWriter<'_> {}

impl SlotWriter<'_> {
    /// Stores `v` in `slot`.
    ///
    /// # Safety
    /// No other thread may store to the same `slot` during this writer's lifetime: callers
    /// pass `Bins::slot(rank, tx, ty)` from the job of tile `(tx, ty)` only.
    #[inline]
    pub unsafe fn store(&self, slot: usize, v: &GradAcc) {
        assert!(slot < self.len, "gradient slot {slot} out of {}", self.len);
        // SAFETY: in bounds (checked above); exclusive per the caller's contract.
        unsafe { self.ptr.add(slot).write(*v) };
    }
}
