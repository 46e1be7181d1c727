//! Grouping `G_o` (paper Sec. 3.3) against a naive set-based reference. Its speed at the
//! full-size case is `cargo bench -p train --bench regularizer_grouping`.

use std::collections::{BTreeMap, BTreeSet};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use train::regularizer::{ObjectGroups, TopKView, BACKGROUND_ID, NO_GAUSSIAN};

/// `G_o = { K(p) | ID(p) = o }` written literally with ordered sets.
fn naive(ids: &[u32], stride: usize, use_k: usize, map: &[u8]) -> BTreeMap<u8, BTreeSet<u32>> {
    let mut out: BTreeMap<u8, BTreeSet<u32>> = BTreeMap::new();
    for (p, &o) in map.iter().enumerate() {
        if o == BACKGROUND_ID {
            continue;
        }
        let set = out.entry(o).or_default();
        for &id in &ids[p * stride..p * stride + use_k.min(stride)] {
            if id != NO_GAUSSIAN {
                set.insert(id);
            }
        }
    }
    out
}

/// A random top-k map whose per-pixel entries are distinct and padded with NO_GAUSSIAN, as the
/// rasterizer returns them, with object regions of a few IDs (including 0 and 254).
fn random_case(rng: &mut ChaCha8Rng, pixels: usize, k: usize, n: u32) -> (Vec<u32>, Vec<u8>) {
    let mut ids = Vec::with_capacity(pixels * k);
    for _ in 0..pixels {
        let filled = rng.gen_range(0..=k);
        let mut seen = BTreeSet::new();
        while seen.len() < filled.min(n as usize) {
            seen.insert(rng.gen_range(0..n));
        }
        ids.extend(seen.iter().copied());
        ids.extend(std::iter::repeat_n(NO_GAUSSIAN, k - seen.len()));
    }
    let palette = [0u8, 3, 254, BACKGROUND_ID];
    let map = (0..pixels).map(|_| palette[rng.gen_range(0..4)]).collect();
    (ids, map)
}

#[test]
fn matches_naive_reference_across_reused_builds() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut groups = ObjectGroups::new();
    // Varying N (as densification does) and k; the same struct is reused throughout.
    for (round, &(n, k, use_k)) in [(50, 4, 2), (500, 8, 8), (20, 1, 1), (300, 8, 3), (60, 3, 5)]
        .iter()
        .enumerate()
    {
        let pixels = 400;
        let (ids, map) = random_case(&mut rng, pixels, k, n);
        groups
            .build(
                TopKView {
                    ids: &ids,
                    stride: k,
                },
                use_k,
                &map,
                n as usize,
            )
            .unwrap();
        let want = naive(&ids, k, use_k, &map);
        let got: BTreeMap<u8, BTreeSet<u32>> = groups
            .iter()
            .map(|g| {
                let set: BTreeSet<u32> = g.members.iter().copied().collect();
                assert_eq!(
                    set.len(),
                    g.members.len(),
                    "round {round}: duplicate member"
                );
                (g.object, set)
            })
            .collect();
        assert_eq!(got, want, "round {round}");
        for g in groups.iter() {
            let pixels = map.iter().filter(|&&o| o == g.object).count() as u32;
            assert_eq!(g.pixels, pixels);
        }
    }
}
