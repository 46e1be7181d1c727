//! Object-level grouping of Gaussians (paper Sec. 3.3, Eq. for `G_o`):
//! `G_o = { K(p) | ID(p) = o }`, the SET of global Gaussian indices found in the per-pixel
//! top-k of the pixels whose object ID is `o`.
//!
//! Set semantics, as in the paper: a Gaussian seen in many pixels of one object appears once in
//! that object's group; a Gaussian in the top-k of pixels of two objects (typically at a shared
//! silhouette edge) belongs to BOTH groups and so receives both objects' regularization
//! gradients. The background ID (255) forms no group.
//!
//! Cost: one pass over the `H·W` ID map (counting sort of pixels by object), one pass over the
//! `H·W·k` top-k ids setting bits in an `N`-bit set (62.5 KB for N = 500k, so it stays in L2
//! while the ids stream by), and per object one scan of the set's `N/64` words that extracts
//! the members in ascending index order and zeroes the words behind it, leaving the set clean
//! for the next object without a separate clear. Ascending members make the loss's gathers
//! monotone in memory and its sums independent of pixel order. Every buffer is kept in the
//! struct and reused: no allocation in steady state.

use super::error::RegError;

/// Object ID reserved for background pixels in object-ID maps (docs/architecture.md,
/// "Object IDs").
pub const BACKGROUND_ID: u8 = 255;

/// Marker for "no Gaussian" in a top-k slot (`splat::ForwardOutput::topk_ids`).
pub const NO_GAUSSIAN: u32 = u32::MAX;

/// The top-k contributors of one render, as `splat::ForwardOutput` returns them.
#[derive(Clone, Copy, Debug)]
pub struct TopKView<'a> {
    /// `H·W·stride` global Gaussian indices, largest weight first, [`NO_GAUSSIAN`] where fewer.
    pub ids: &'a [u32],
    /// The k the render was made with (entries per pixel).
    pub stride: usize,
}

/// One object's group, borrowed from [`ObjectGroups`].
#[derive(Clone, Copy, Debug)]
pub struct Group<'a> {
    /// Object ID from the ID map (0..=254).
    pub object: u8,
    /// Number of pixels carrying this ID.
    pub pixels: u32,
    /// Distinct global Gaussian indices in ascending order.
    pub members: &'a [u32],
}

/// Reusable storage for the groups `G_o` of one iteration (CSR layout over objects present).
#[derive(Clone, Debug, Default)]
pub struct ObjectGroups {
    n_gaussians: usize,
    objects: Vec<u8>,
    pixel_counts: Vec<u32>,
    /// `objects.len() + 1` offsets into `members`.
    offsets: Vec<usize>,
    members: Vec<u32>,
    /// Membership bits of the group being built; all zero between objects.
    bits: Vec<u64>,
    /// Foreground pixel indices bucketed by object (counting sort scratch).
    pixel_order: Vec<u32>,
}

impl ObjectGroups {
    pub fn new() -> Self {
        Self::default()
    }

    /// Rebuild the groups from a render's top-k and the matching object-ID map.
    ///
    /// `use_k` (clamped to `topk.stride`) selects how many of the per-pixel contributors count,
    /// so one render with k = 8 serves any k ≤ 8 (entries are sorted by weight). Errors leave
    /// the groups empty.
    pub fn build(
        &mut self,
        topk: TopKView<'_>,
        use_k: usize,
        id_map: &[u8],
        n_gaussians: usize,
    ) -> Result<(), RegError> {
        self.build_with(topk, use_k, id_map, n_gaussians, &|_| &[])
    }

    /// [`ObjectGroups::build`], with `extra(o)` (ascending indices) joined to the group of
    /// every object `o` present in the view: the persistent members of
    /// [`super::MembershipVotes`].
    pub fn build_with<'e>(
        &mut self,
        topk: TopKView<'_>,
        use_k: usize,
        id_map: &[u8],
        n_gaussians: usize,
        extra: &dyn Fn(u8) -> &'e [u32],
    ) -> Result<(), RegError> {
        self.clear(n_gaussians);
        let result = self.build_inner(topk, use_k, id_map, extra);
        if result.is_err() {
            self.clear(n_gaussians);
        }
        result
    }

    fn clear(&mut self, n_gaussians: usize) {
        self.n_gaussians = n_gaussians;
        self.objects.clear();
        self.pixel_counts.clear();
        self.offsets.clear();
        self.offsets.push(0);
        self.members.clear();
    }

    fn build_inner<'e>(
        &mut self,
        topk: TopKView<'_>,
        use_k: usize,
        id_map: &[u8],
        extra: &dyn Fn(u8) -> &'e [u32],
    ) -> Result<(), RegError> {
        check_shapes(topk, id_map)?;
        let n = self.n_gaussians;
        // The set is all-zero between builds (extraction clears it), so a resize needs no fill.
        self.bits.resize(n.div_ceil(64), 0);
        let counts = self.bucket_pixels(id_map);
        let use_k = use_k.min(topk.stride);
        let mut start = 0usize;
        for (object, &count) in counts.iter().enumerate() {
            if count == 0 {
                continue;
            }
            let bucket = start..start + count as usize;
            start += count as usize;
            for &pixel in &self.pixel_order[bucket] {
                let base = pixel as usize * topk.stride;
                for &id in &topk.ids[base..base + use_k] {
                    if id == NO_GAUSSIAN {
                        continue;
                    }
                    if id as usize >= n {
                        // Leave the set clean for the next build before reporting.
                        self.bits.fill(0);
                        return Err(RegError::GaussianIndexOutOfRange {
                            pixel: pixel as usize,
                            id,
                            n,
                        });
                    }
                    self.bits[id as usize >> 6] |= 1u64 << (id & 63);
                }
            }
            for &id in extra(object as u8) {
                if id as usize >= n {
                    self.bits.fill(0);
                    return Err(RegError::GaussianIndexOutOfRange { pixel: 0, id, n });
                }
                self.bits[id as usize >> 6] |= 1u64 << (id & 63);
            }
            self.extract_members();
            self.objects.push(object as u8);
            self.pixel_counts.push(count);
            self.offsets.push(self.members.len());
        }
        Ok(())
    }

    /// Counting sort of foreground pixels by object ID into `pixel_order`; returns the counts.
    fn bucket_pixels(&mut self, id_map: &[u8]) -> [u32; 255] {
        let mut counts = [0u32; 255];
        for &id in id_map {
            if id != BACKGROUND_ID {
                counts[id as usize] += 1;
            }
        }
        let mut next = [0u32; 255];
        let mut total = 0u32;
        for (slot, &c) in next.iter_mut().zip(&counts) {
            *slot = total;
            total += c;
        }
        self.pixel_order.clear();
        self.pixel_order.resize(total as usize, 0);
        for (pixel, &id) in id_map.iter().enumerate() {
            if id != BACKGROUND_ID {
                let at = &mut next[id as usize];
                self.pixel_order[*at as usize] = pixel as u32;
                *at += 1;
            }
        }
        counts
    }

    /// Append the set bits' indices (ascending) to `members`, zeroing the set as it goes.
    fn extract_members(&mut self) {
        for (w, word) in self.bits.iter_mut().enumerate() {
            let mut bits = std::mem::take(word);
            while bits != 0 {
                self.members.push((w as u32) << 6 | bits.trailing_zeros());
                bits &= bits - 1;
            }
        }
    }

    /// Number of Gaussians the groups were built for.
    pub fn n_gaussians(&self) -> usize {
        self.n_gaussians
    }

    /// Number of objects with at least one pixel (groups may still be empty when every top-k
    /// slot of their pixels is empty).
    pub fn len(&self) -> usize {
        self.objects.len()
    }

    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// The `i`-th group, objects in ascending ID order.
    pub fn get(&self, i: usize) -> Group<'_> {
        Group {
            object: self.objects[i],
            pixels: self.pixel_counts[i],
            members: &self.members[self.offsets[i]..self.offsets[i + 1]],
        }
    }

    /// The group of object `object`, if any of its pixels were present.
    pub fn group(&self, object: u8) -> Option<Group<'_>> {
        let i = self.objects.binary_search(&object).ok()?;
        Some(self.get(i))
    }

    pub fn iter(&self) -> impl Iterator<Item = Group<'_>> + '_ {
        (0..self.len()).map(move |i| self.get(i))
    }
}

pub(super) fn check_shapes(topk: TopKView<'_>, id_map: &[u8]) -> Result<(), RegError> {
    if topk.stride == 0 {
        return Err(RegError::ZeroTopK);
    }
    let pixels = topk.ids.len() / topk.stride;
    if topk.ids.len() != pixels * topk.stride {
        return Err(RegError::TopKLength {
            len: topk.ids.len(),
            k: topk.stride,
        });
    }
    if id_map.len() != pixels {
        return Err(RegError::IdMapLength {
            len: id_map.len(),
            pixels,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn build(ids: &[u32], stride: usize, use_k: usize, map: &[u8], n: usize) -> ObjectGroups {
        let mut g = ObjectGroups::new();
        g.build(TopKView { ids, stride }, use_k, map, n).unwrap();
        g
    }

    #[test]
    fn set_semantics_and_shared_gaussian() {
        // 4 pixels, k = 2: object 0 on pixels 0,1; object 1 on pixel 2; background pixel 3.
        let m = NO_GAUSSIAN;
        let ids = [5, 2, 2, 5, 2, 7, 9, m];
        let g = build(&ids, 2, 2, &[0, 0, 1, 255], 10);
        assert_eq!(g.len(), 2);
        assert_eq!(g.group(0).unwrap().members, &[2, 5]);
        assert_eq!(g.group(0).unwrap().pixels, 2);
        // Gaussian 2 is in both groups; background pixel's Gaussian 9 is in none.
        assert_eq!(g.group(1).unwrap().members, &[2, 7]);
        assert!(g.group(255).is_none());
    }

    #[test]
    fn extra_members_join_present_objects_only() {
        // Object 0 on pixel 0 (Gaussian 5), object 1 nowhere in this view.
        let ids = [5, NO_GAUSSIAN];
        let mut g = ObjectGroups::new();
        let extra = |o: u8| -> &'static [u32] {
            match o {
                0 => &[1, 5, 8],
                1 => &[3],
                _ => &[],
            }
        };
        g.build_with(
            TopKView {
                ids: &ids,
                stride: 1,
            },
            1,
            &[0, 255],
            10,
            &extra,
        )
        .unwrap();
        // Union as a set, ascending; object 1 has no pixels, so no group.
        assert_eq!(g.group(0).unwrap().members, &[1, 5, 8]);
        assert!(g.group(1).is_none());
        let bad = |_: u8| -> &'static [u32] { &[10] };
        let e = g.build_with(
            TopKView {
                ids: &ids,
                stride: 1,
            },
            1,
            &[0, 255],
            10,
            &bad,
        );
        assert!(e.is_err() && g.is_empty());
    }

    #[test]
    fn use_k_takes_the_strongest_entries_only() {
        let ids = [1, 2, 3, 4, 5, 6];
        let g = build(&ids, 3, 1, &[3, 3], 7);
        assert_eq!(g.group(3).unwrap().members, &[1, 4]);
        let g = build(&ids, 3, 99, &[3, 3], 7);
        assert_eq!(g.group(3).unwrap().members, &[1, 2, 3, 4, 5, 6]);
    }

    #[test]
    fn all_background_gives_no_groups() {
        let g = build(&[0, 1, 2], 1, 1, &[255, 255, 255], 3);
        assert!(g.is_empty());
    }

    #[test]
    fn reuse_across_builds_does_not_leak_members() {
        let mut g = ObjectGroups::new();
        g.build(
            TopKView {
                ids: &[0, 1],
                stride: 1,
            },
            1,
            &[0, 0],
            2,
        )
        .unwrap();
        g.build(
            TopKView {
                ids: &[1, 1],
                stride: 1,
            },
            1,
            &[0, 0],
            2,
        )
        .unwrap();
        assert_eq!(g.group(0).unwrap().members, &[1]);
        // Shrinking N keeps working.
        g.build(
            TopKView {
                ids: &[0],
                stride: 1,
            },
            1,
            &[4],
            1,
        )
        .unwrap();
        assert_eq!(g.group(4).unwrap().members, &[0]);
    }

    #[test]
    fn bits_beyond_64_and_clean_after_error() {
        let mut g = ObjectGroups::new();
        let e = g.build(
            TopKView {
                ids: &[130, 7],
                stride: 1,
            },
            1,
            &[0, 0],
            100,
        );
        assert!(e.is_err());
        assert!(g.bits.iter().all(|&w| w == 0));
        g.build(
            TopKView {
                ids: &[130, 64, 63],
                stride: 1,
            },
            1,
            &[1, 1, 1],
            200,
        )
        .unwrap();
        assert_eq!(g.group(1).unwrap().members, &[63, 64, 130]);
        assert!(g.bits.iter().all(|&w| w == 0));
    }

    #[test]
    fn bad_inputs_are_errors_and_leave_groups_empty() {
        let mut g = ObjectGroups::new();
        let e = g.build(
            TopKView {
                ids: &[0, 1, 2],
                stride: 2,
            },
            2,
            &[0, 0],
            3,
        );
        assert_eq!(e, Err(RegError::TopKLength { len: 3, k: 2 }));
        let e = g.build(
            TopKView {
                ids: &[0, 1, 2, 0],
                stride: 2,
            },
            2,
            &[0; 3],
            3,
        );
        assert_eq!(e, Err(RegError::IdMapLength { len: 3, pixels: 2 }));
        let e = g.build(
            TopKView {
                ids: &[0, 9],
                stride: 1,
            },
            1,
            &[0, 0],
            3,
        );
        assert_eq!(
            e,
            Err(RegError::GaussianIndexOutOfRange {
                pixel: 1,
                id: 9,
                n: 3
            })
        );
        assert!(g.is_empty());
        let e = g.build(
            TopKView {
                ids: &[],
                stride: 0,
            },
            1,
            &[],
            3,
        );
        assert_eq!(e, Err(RegError::ZeroTopK));
    }
}
