//! A run's Gaussians at time t as splat data the page's renderer draws, made on demand
//! from the checkpoint (the same deformation `semdynreg export --time` writes as a PLY)
//! and cached in memory, so a time step already seen comes back at once.
//!
//! The data is the `.splat` layout of antimatter15/splat that gsplat.js reads: 32 bytes a
//! Gaussian, `x y z` (f32), `sx sy sz` (f32, linear scales), `r g b a` (u8; colour from the
//! SH DC term, alpha = sigmoid(opacity)), `qw qx qy qz` (u8, q·128 + 128). It is an eighth
//! of a PLY's size and drops the view-dependent SH terms, which the viewer need not show.

use crate::cmd::render::LoadedRun;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;
use train::objects::{RigidObject, NO_OBJECT};
use train::GaussianModel;

pub const ROW_BYTES: usize = 32;
/// SH band-0 constant: colour = 0.5 + C0 · f_dc.
const SH_C0: f32 = 0.282_094_8;

/// How the Gaussians are coloured: their own colour, or by the object they belong to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Colouring {
    Rgb,
    Objects,
}

/// Times are cached at this resolution (and evaluated at the rounded time), so `t=0.5`
/// and `t=0.50000001` share one entry.
const TIME_STEPS: f32 = 10_000.0;

pub fn time_key(t: f32) -> u32 {
    (t.clamp(0.0, 1.0) * TIME_STEPS).round() as u32
}

/// Serializes a (deformed) model as `.splat` rows.
pub fn splat_bytes(m: &GaussianModel) -> Vec<u8> {
    let sh = train::model::SH_FLOATS;
    let mut out = Vec::with_capacity(m.len() * ROW_BYTES);
    for i in 0..m.len() {
        for v in &m.means[i * 3..i * 3 + 3] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in &m.log_scales[i * 3..i * 3 + 3] {
            out.extend_from_slice(&v.exp().to_le_bytes());
        }
        let dc = &m.sh[i * sh..i * sh + 3];
        out.extend(dc.iter().map(|c| unit_to_u8(0.5 + SH_C0 * c)));
        out.push(unit_to_u8(1.0 / (1.0 + (-m.opacity_logits[i]).exp())));
        let q = &m.quats[i * 4..i * 4 + 4];
        let norm = q.iter().map(|c| c * c).sum::<f32>().sqrt();
        // A zero quaternion (never produced by training) renders as the identity.
        let q = if norm > 0.0 {
            [q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm]
        } else {
            [1.0, 0.0, 0.0, 0.0]
        };
        out.extend(
            q.iter()
                .map(|c| (c * 128.0 + 128.0).round().clamp(0.0, 255.0) as u8),
        );
    }
    out
}

fn unit_to_u8(v: f32) -> u8 {
    (v * 255.0).round().clamp(0.0, 255.0) as u8
}

/// Distinct colours for objects (Tableau 10), by position in the run's object list;
/// the background (Gaussians of no object) is grey.
const PALETTE: [[u8; 3]; 10] = [
    [78, 121, 167],
    [242, 142, 43],
    [225, 87, 89],
    [118, 183, 178],
    [89, 161, 79],
    [237, 201, 72],
    [176, 122, 161],
    [255, 157, 167],
    [156, 117, 95],
    [186, 176, 172],
];
pub const BACKGROUND_COLOUR: [u8; 3] = [90, 90, 90];

/// The colour of each object, in the order of `objects` (the legend the page shows).
pub fn object_colour(index: usize) -> [u8; 3] {
    PALETTE[index % PALETTE.len()]
}

/// One colour per Gaussian: its object's, or [`BACKGROUND_COLOUR`].
pub fn membership_colours(objects: &[RigidObject], column: &[u8]) -> Vec<[u8; 3]> {
    let by_id: HashMap<u8, [u8; 3]> = objects
        .iter()
        .enumerate()
        .map(|(k, o)| (o.id, object_colour(k)))
        .collect();
    column
        .iter()
        .map(|c| match *c {
            NO_OBJECT => BACKGROUND_COLOUR,
            id => by_id.get(&id).copied().unwrap_or(BACKGROUND_COLOUR),
        })
        .collect()
}

/// Replaces the RGB bytes of `.splat` rows (alpha stays).
pub fn recolour(bytes: &mut [u8], colours: &[[u8; 3]]) {
    for (row, c) in bytes.chunks_exact_mut(ROW_BYTES).zip(colours) {
        row[24..27].copy_from_slice(c);
    }
}

/// A frame's cache key: its rounded time ([`time_key`]) and colouring.
pub type Key = (u32, Colouring);

/// Cached frames, evicted least recently used first once they pass a byte budget.
pub struct Cache {
    budget: usize,
    total: usize,
    clock: u64,
    /// Each frame's bytes and the clock of its last use.
    entries: HashMap<Key, (Arc<Vec<u8>>, u64)>,
}

impl Cache {
    pub fn new(budget: usize) -> Self {
        Self {
            budget,
            total: 0,
            clock: 0,
            entries: HashMap::new(),
        }
    }

    pub fn get(&mut self, key: Key) -> Option<Arc<Vec<u8>>> {
        self.clock += 1;
        let clock = self.clock;
        self.entries.get_mut(&key).map(|(b, used)| {
            *used = clock;
            b.clone()
        })
    }

    /// Keeps `bytes`, evicting older entries past the budget (the newest always stays,
    /// so a frame larger than the budget is still served).
    pub fn insert(&mut self, key: Key, bytes: Arc<Vec<u8>>) {
        self.clock += 1;
        self.total += bytes.len();
        if let Some((old, _)) = self.entries.insert(key, (bytes, self.clock)) {
            self.total -= old.len();
        }
        while self.total > self.budget && self.entries.len() > 1 {
            let oldest = self
                .entries
                .iter()
                .min_by_key(|(_, (_, used))| *used)
                .map(|(k, _)| *k);
            let Some(k) = oldest else { break };
            if let Some((b, _)) = self.entries.remove(&k) {
                self.total -= b.len();
            }
        }
    }

    #[cfg(test)]
    fn len(&self) -> usize {
        self.entries.len()
    }
}

/// A frame as served: its bytes, whether they came from the cache, and how long making
/// them took (0 for a cached frame).
pub struct Frame {
    pub bytes: Arc<Vec<u8>>,
    pub cached: bool,
    pub millis: f64,
}

/// One run the viewer shows: its checkpoint (behind a lock: the field's forward pass
/// needs scratch space) and its cache.
pub struct FrameSource {
    run: Mutex<LoadedRun>,
    cache: Mutex<Cache>,
    /// Per-Gaussian membership colours; None for a run without objects.
    membership: Option<Vec<[u8; 3]>>,
}

/// A poisoned lock only means another request panicked mid-way; the data it guards
/// (a checkpoint read-only but for scratch buffers, a cache of whole entries) is intact.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl FrameSource {
    pub fn new(run: LoadedRun, cache_bytes: usize) -> Self {
        let membership =
            (!run.objects.is_empty()).then(|| membership_colours(&run.objects, &run.column));
        Self {
            run: Mutex::new(run),
            cache: Mutex::new(Cache::new(cache_bytes)),
            membership,
        }
    }

    pub fn has_objects(&self) -> bool {
        self.membership.is_some()
    }

    /// The Gaussians at time `t` (in [0, 1]; the caller checks), coloured as asked. A run
    /// without objects has no membership colouring: the caller checks [`Self::has_objects`].
    pub fn frame(&self, t: f32, colouring: Colouring) -> Frame {
        let key = (time_key(t), colouring);
        if let Some(bytes) = lock(&self.cache).get(key) {
            return Frame {
                bytes,
                cached: true,
                millis: 0.0,
            };
        }
        let start = Instant::now();
        // The run lock serializes the making of frames; a request that waited for it may
        // find its frame made meanwhile.
        let mut run = lock(&self.run);
        if let Some(bytes) = lock(&self.cache).get(key) {
            return Frame {
                bytes,
                cached: true,
                millis: 0.0,
            };
        }
        let rgb_key = (key.0, Colouring::Rgb);
        // Bound first: a guard in the match's scrutinee would live through its arms.
        let cached_rgb = lock(&self.cache).get(rgb_key);
        let rgb = match cached_rgb {
            Some(b) => b,
            None => {
                let b = Arc::new(deformed_splats(&mut run, key.0 as f32 / TIME_STEPS));
                lock(&self.cache).insert(rgb_key, b.clone());
                b
            }
        };
        let bytes = match (colouring, &self.membership) {
            (Colouring::Objects, Some(colours)) => {
                let mut b = rgb.as_ref().clone();
                recolour(&mut b, colours);
                let b = Arc::new(b);
                lock(&self.cache).insert(key, b.clone());
                b
            }
            _ => rgb,
        };
        let millis = start.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(t, ?colouring, millis, "frame made");
        Frame {
            bytes,
            cached: false,
            millis,
        }
    }
}

/// The run's Gaussians deformed to `t`, as `semdynreg export --time t` computes them.
fn deformed_splats(r: &mut LoadedRun, t: f32) -> Vec<u8> {
    let m = train::render::deformed_model(r.scene(), t);
    splat_bytes(&m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_gaussian() -> GaussianModel {
        let mut sh = vec![0.0; train::model::SH_FLOATS];
        sh[..3].copy_from_slice(&[1.0, 0.0, -1.0]);
        GaussianModel {
            means: vec![1.0, -2.0, 3.5],
            quats: vec![2.0, 0.0, 0.0, 0.0],
            log_scales: vec![0.0, 1.0_f32.ln() - 1.0, 2.0_f32.ln()],
            opacity_logits: vec![0.0],
            sh,
            sh_degree: 0,
        }
    }

    #[test]
    fn splat_row_layout() {
        let b = splat_bytes(&one_gaussian());
        assert_eq!(b.len(), ROW_BYTES);
        let f = |k: usize| f32::from_le_bytes(b[k * 4..k * 4 + 4].try_into().unwrap());
        assert_eq!([f(0), f(1), f(2)], [1.0, -2.0, 3.5]);
        assert!((f(3) - 1.0).abs() < 1e-6 && (f(4) - (-1.0f32).exp()).abs() < 1e-6);
        assert!((f(5) - 2.0).abs() < 1e-6);
        // (0.5 ± C0)·255 → 199 / 56; sigmoid(0)·255 → 128; normalized q = (1, 0, 0, 0).
        assert_eq!(&b[24..28], &[199, 128, 56, 128]);
        assert_eq!(&b[28..32], &[255, 128, 128, 128]);
    }

    #[test]
    fn recolour_keeps_geometry_and_alpha() {
        let mut b = splat_bytes(&one_gaussian());
        let before = b.clone();
        recolour(&mut b, &[[1, 2, 3]]);
        assert_eq!(&b[24..28], &[1, 2, 3, before[27]]);
        assert_eq!(&b[..24], &before[..24]);
        assert_eq!(&b[28..], &before[28..]);
    }

    #[test]
    fn cache_evicts_least_recently_used() {
        let mut c = Cache::new(25);
        let bytes = |n: usize| Arc::new(vec![0u8; n]);
        c.insert((1, Colouring::Rgb), bytes(10));
        c.insert((2, Colouring::Rgb), bytes(10));
        assert!(c.get((1, Colouring::Rgb)).is_some());
        c.insert((3, Colouring::Rgb), bytes(10));
        assert_eq!(c.len(), 2);
        assert!(
            c.get((2, Colouring::Rgb)).is_none(),
            "2 was the least recent"
        );
        assert!(c.get((1, Colouring::Rgb)).is_some());
        c.insert((4, Colouring::Objects), bytes(100));
        assert_eq!(c.len(), 1, "an entry over the budget stays alone");
    }

    #[test]
    fn times_round_to_the_cache_resolution() {
        assert_eq!(time_key(0.5), time_key(0.500_000_1));
        assert_ne!(time_key(0.5), time_key(0.5001));
        assert_eq!(time_key(1.0), 10_000);
    }
}
