//! Seeded mutation fuzzing shared by the `fuzz_*` tests of every crate (docs/robustness.md).
//!
//! Each format's test takes a small valid seed file, applies a few random mutations (bytes:
//! truncation, bit flips, byte sets, splices, deletions, duplicated runs, boundary integers;
//! text: a number token replaced by an extreme literal, which is how a PLY or .npy header
//! lies about its counts; JSON/TOML trees: a value replaced by a wrong type or an extreme
//! number, a key deleted, a value nested deeply, an array element repeated) and checks the
//! robustness property (docs/robustness.md): the loader returns (no panic), within
//! [`TIME_LIMIT`] (no hang), without any single allocation above [`ALLOC_LIMIT`] (a lying header is refused before
//! allocating), and an error names the file. The generator is proptest's ChaCha seeded from
//! the format's name (and `FUZZ_SEED` when set), so a CI run is reproducible.
//!
//! Included with `#[path]` by the tests of other crates; it installs the test binary's
//! global allocator, so a binary includes it once.
#![allow(dead_code)]

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};
use std::alloc::{GlobalAlloc, Layout, System};
use std::fmt::Display;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A loader that has not returned after this long counts as hung. The seeds are tiny
/// (milliseconds to load), so only a loop that does not end gets anywhere near it.
pub const TIME_LIMIT: Duration = Duration::from_secs(20);

/// Largest single allocation a case may make. The seeds need a few MB; the `image` crate
/// refuses decodes above its own 512 MiB default, which sets the bound here.
pub const ALLOC_LIMIT: usize = 600 << 20;

/// Requests above this are refused outright (the process then aborts with the size), so
/// a lying header cannot make the shared test machine swap before the check above runs.
const HARD_LIMIT: usize = 4 << 30;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

/// The system allocator, recording the largest request seen.
pub struct TrackingAlloc;

impl TrackingAlloc {
    fn note(size: usize) -> bool {
        LARGEST.fetch_max(size, Ordering::Relaxed);
        size <= HARD_LIMIT
    }
}

// SAFETY: every call forwards to `System` unchanged, or returns null (allowed: an
// allocation failure) for a request above HARD_LIMIT.
unsafe impl GlobalAlloc for TrackingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !Self::note(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if !Self::note(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if !Self::note(new_size) {
            return std::ptr::null_mut();
        }
        // SAFETY: forwarded with the caller's pointer and layouts.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's pointer and layout.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: TrackingAlloc = TrackingAlloc;

/// Cases per format: `FUZZ_CASES` when set (the long run behind `--ignored`), else `ci`.
pub fn cases(ci: u32) -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(ci)
}

/// Cases per format in the long (ignored) run: `FUZZ_CASES` when set, else 20× `ci`.
pub fn long_cases(ci: u32) -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(ci.saturating_mul(20))
}

/// A deterministic runner for `format`: ChaCha seeded from the format's name and
/// `FUZZ_SEED` (default 0), no failure files, shrinking kept short.
pub fn runner(format: &str, cases: u32) -> TestRunner {
    let extra: u64 = std::env::var("FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    // FNV-1a of the name: each format gets its own stream of cases.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325 ^ extra;
    for b in format.bytes() {
        h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
    }
    let mut seed = [0u8; 32];
    for (i, chunk) in seed.chunks_mut(8).enumerate() {
        chunk.copy_from_slice(&(h.rotate_left(17 * i as u32) ^ i as u64).to_le_bytes());
    }
    let config = Config {
        cases,
        failure_persistence: None,
        max_shrink_iters: 64,
        max_global_rejects: cases.saturating_mul(4),
        ..Config::default()
    };
    TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &seed))
}

/// Counts of one format's run, printed at its end (`--nocapture` shows them).
#[derive(Default)]
pub struct Tally {
    pub ok: AtomicUsize,
    pub err: AtomicUsize,
    pub start: std::sync::OnceLock<Instant>,
}

impl Tally {
    pub fn new() -> Arc<Self> {
        let t = Arc::new(Self::default());
        t.start.get_or_init(Instant::now);
        t
    }

    pub fn report(&self, format: &str) -> usize {
        let (ok, err) = (
            self.ok.load(Ordering::Relaxed),
            self.err.load(Ordering::Relaxed),
        );
        let secs = self.start.get().map_or(0.0, |t| t.elapsed().as_secs_f64());
        println!(
            "fuzz {format}: {} cases ({ok} loaded, {err} refused) in {secs:.2} s",
            ok + err
        );
        ok + err
    }
}

/// Runs `load` with the robustness properties: it must return within [`TIME_LIMIT`]
/// without panicking; an error must mention one of `names` (the file); no allocation may
/// exceed [`ALLOC_LIMIT`]. Returns the loaded value, or `None` for a (good) error.
pub fn check_load<T, E>(
    tally: &Tally,
    names: &[&str],
    load: impl FnOnce() -> Result<T, E> + Send + 'static,
) -> Result<Option<T>, TestCaseError>
where
    T: Send + 'static,
    E: Display + Send + 'static,
{
    // One case at a time per test binary, so that the largest allocation is this case's
    // (and proptest can shrink an input that allocates too much).
    static CASE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one_at_a_time = CASE.lock().unwrap_or_else(|e| e.into_inner());
    LARGEST.store(0, Ordering::Relaxed);
    let (tx, rx) = std::sync::mpsc::channel();
    // A thread of its own, so that a hang is a failed case rather than a stuck test (the
    // hung thread is left behind; the test fails anyway).
    std::thread::Builder::new()
        .name("fuzz-case".into())
        .spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(load));
            let _ = tx.send(r.map(|r| r.map_err(|e| e.to_string())));
        })
        .map_err(|e| TestCaseError::fail(format!("cannot spawn: {e}")))?;
    let outcome = match rx.recv_timeout(TIME_LIMIT) {
        Ok(r) => r,
        Err(_) => {
            return Err(TestCaseError::fail(format!(
                "no result after {TIME_LIMIT:?} (a hang)"
            )))
        }
    };
    let largest = LARGEST.load(Ordering::Relaxed);
    if largest > ALLOC_LIMIT {
        return Err(TestCaseError::fail(format!(
            "an allocation of {largest} bytes (limit {ALLOC_LIMIT})"
        )));
    }
    match outcome {
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            Err(TestCaseError::fail(format!("panicked: {msg}")))
        }
        Ok(Err(msg)) => {
            tally.err.fetch_add(1, Ordering::Relaxed);
            if names.iter().any(|n| msg.contains(n)) {
                Ok(None)
            } else {
                Err(TestCaseError::fail(format!(
                    "error names none of {names:?}: {msg}"
                )))
            }
        }
        Ok(Ok(v)) => {
            tally.ok.fetch_add(1, Ordering::Relaxed);
            Ok(Some(v))
        }
    }
}

/// Panics with proptest's report (the minimal failing mutation) when a run failed.
pub fn finish<T: std::fmt::Debug>(
    format: &str,
    result: Result<(), proptest::test_runner::TestError<T>>,
    tally: &Tally,
) {
    let n = tally.report(format);
    if let Err(e) = result {
        panic!("fuzz {format}: {e}");
    }
    assert!(n > 0, "fuzz {format}: no case ran");
}

/// Literals a number token is replaced by: boundaries of the integer types, f32/f64
/// overflow and underflow, non-finite spellings, and wrong types.
pub const EXTREME: &[&str] = &[
    "0",
    "-1",
    "1",
    "2",
    "255",
    "256",
    "65535",
    "65536",
    "2147483647",
    "2147483648",
    "4294967295",
    "4294967296",
    "1000000000000",
    "9223372036854775807",
    "9223372036854775808",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775808",
    "3.4e38",
    "3.5e38",
    "1e39",
    "-1e39",
    "1e308",
    "1e400",
    "-1e400",
    "1e-45",
    "1e-400",
    "0.5",
    "-0.0",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "true",
    "\"x\"",
    "[]",
    "{}",
    "null",
    "",
];

/// Values a JSON/TOML node is replaced by.
#[derive(Clone, Debug)]
pub enum Replacement {
    Null,
    Bool(bool),
    Str(String),
    EmptyArray,
    EmptyObject,
    Int(i64),
    UInt(u64),
    Float(f64),
}

fn replacement() -> impl Strategy<Value = Replacement> {
    prop_oneof![
        Just(Replacement::Null),
        any::<bool>().prop_map(Replacement::Bool),
        prop_oneof![
            Just(String::new()),
            Just("../../../etc/passwd".to_string()),
            Just("x".repeat(5000)),
            "[a-z0-9_./]{0,12}",
        ]
        .prop_map(Replacement::Str),
        Just(Replacement::EmptyArray),
        Just(Replacement::EmptyObject),
        prop_oneof![
            Just(0i64),
            Just(-1),
            Just(1),
            Just(i64::MIN),
            Just(i64::MAX),
            Just(i64::from(i32::MAX) + 1),
            Just(-(1i64 << 40)),
            -1000i64..1000,
        ]
        .prop_map(Replacement::Int),
        prop_oneof![Just(u64::MAX), Just(1u64 << 63), Just(u64::from(u32::MAX))]
            .prop_map(Replacement::UInt),
        prop_oneof![
            Just(1e308f64),
            Just(-1e308),
            Just(1e39),
            Just(-1e39),
            Just(3.4e38),
            Just(5e-324),
            Just(1e-40),
            Just(-0.0),
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            -1e6f64..1e6,
        ]
        .prop_map(Replacement::Float),
    ]
}

/// One mutation of a file.
#[derive(Clone, Debug)]
pub enum Mutation {
    /// Keep only the first bytes (at a random length).
    Truncate(Index),
    /// Flip bits; `bool` picks a position among the first 512 bytes (headers) rather than
    /// anywhere in the file.
    FlipBits(Vec<(bool, Index, u8)>),
    /// Overwrite bytes with random values.
    SetBytes(Vec<(bool, Index, u8)>),
    /// Insert random bytes.
    Splice(Index, Vec<u8>),
    /// Remove a run of bytes.
    Delete(Index, usize),
    /// Repeat a run of bytes in place.
    Duplicate(Index, usize, usize),
    /// Write a boundary integer (little endian, 1/2/4/8 bytes): lengths and counts in
    /// binary headers.
    Boundary(bool, Index, u64, usize),
    /// Replace a number token of the text by one of [`EXTREME`] (text formats).
    Number(Index, Index),
    /// Replace a JSON/TOML node by a wrong type or an extreme value.
    Replace(Index, Replacement),
    /// Delete a JSON/TOML node (a key of an object, an element of an array).
    Remove(Index),
    /// Wrap a JSON/TOML node in this many arrays.
    Nest(Index, usize),
    /// Repeat the first element of an array node this many times.
    Repeat(Index, usize),
}

/// How a seed file may be mutated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Binary,
    /// Text with number tokens (PLY ASCII header, .npy header, ...).
    Text,
    Json,
    Toml,
}

fn pos() -> impl Strategy<Value = (bool, Index, u8)> {
    (any::<bool>(), any::<Index>(), any::<u8>())
}

fn byte_mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<Index>().prop_map(Mutation::Truncate),
        prop::collection::vec(pos(), 1..8).prop_map(Mutation::FlipBits),
        prop::collection::vec(pos(), 1..8).prop_map(Mutation::SetBytes),
        (any::<Index>(), prop::collection::vec(any::<u8>(), 1..64))
            .prop_map(|(i, b)| Mutation::Splice(i, b)),
        (any::<Index>(), 1usize..256).prop_map(|(i, n)| Mutation::Delete(i, n)),
        (any::<Index>(), 1usize..64, 1usize..8).prop_map(|(i, n, k)| Mutation::Duplicate(i, n, k)),
        (
            any::<bool>(),
            any::<Index>(),
            prop_oneof![
                Just(0u64),
                Just(u64::MAX),
                Just(u64::from(u32::MAX)),
                Just(1u64 << 31),
                Just(1u64 << 32),
                Just(1u64 << 40),
                Just(1u64 << 63),
                Just(0x7f80_0000),           // f32 +inf
                Just(0x7fc0_0000),           // f32 NaN
                Just(0x7ff8_0000_0000_0000), // f64 NaN
            ],
            prop_oneof![Just(1usize), Just(2), Just(4), Just(8)],
        )
            .prop_map(|(h, i, v, w)| Mutation::Boundary(h, i, v, w)),
    ]
}

fn text_mutation() -> impl Strategy<Value = Mutation> {
    (any::<Index>(), any::<Index>()).prop_map(|(a, b)| Mutation::Number(a, b))
}

fn tree_mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        3 => (any::<Index>(), replacement()).prop_map(|(i, r)| Mutation::Replace(i, r)),
        2 => any::<Index>().prop_map(Mutation::Remove),
        1 => (any::<Index>(), prop_oneof![1usize..4, 120usize..300]).prop_map(|(i, d)| Mutation::Nest(i, d)),
        1 => (any::<Index>(), prop_oneof![2usize..4, 50usize..200]).prop_map(|(i, n)| Mutation::Repeat(i, n)),
    ]
}

/// One to four mutations suited to `kind`: byte-level ones for every kind, number tokens for
/// text, tree edits for JSON and TOML (weighted so that most cases stay parseable and reach
/// the loader's own checks).
pub fn mutations(kind: Kind) -> BoxedStrategy<Vec<Mutation>> {
    let one: BoxedStrategy<Mutation> = match kind {
        Kind::Binary => byte_mutation().boxed(),
        Kind::Text => prop_oneof![2 => byte_mutation(), 3 => text_mutation()].boxed(),
        Kind::Json | Kind::Toml => {
            prop_oneof![2 => byte_mutation(), 2 => text_mutation(), 6 => tree_mutation()].boxed()
        }
    };
    prop::collection::vec(one, 1..=4).boxed()
}

fn at(head: bool, i: &Index, len: usize) -> usize {
    let span = if head { len.min(512) } else { len };
    i.index(span.max(1))
}

/// Applies `muts` to `seed` in order.
pub fn apply(seed: &[u8], muts: &[Mutation], kind: Kind) -> Vec<u8> {
    let mut b = seed.to_vec();
    for m in muts {
        apply_one(&mut b, m, kind);
    }
    b
}

fn apply_one(b: &mut Vec<u8>, m: &Mutation, kind: Kind) {
    let len = b.len();
    match m {
        Mutation::Truncate(i) => b.truncate(i.index(len.max(1))),
        Mutation::FlipBits(v) if len > 0 => {
            for (h, i, bit) in v {
                let p = at(*h, i, len);
                b[p] ^= 1 << (bit % 8);
            }
        }
        Mutation::SetBytes(v) if len > 0 => {
            for (h, i, x) in v {
                let p = at(*h, i, len);
                b[p] = *x;
            }
        }
        Mutation::Splice(i, bytes) => {
            let p = i.index(len + 1);
            b.splice(p..p, bytes.iter().copied());
        }
        Mutation::Delete(i, n) if len > 0 => {
            let p = i.index(len);
            let end = (p + n).min(len);
            b.drain(p..end);
        }
        Mutation::Duplicate(i, n, k) if len > 0 => {
            let p = i.index(len);
            let end = (p + n).min(len);
            let run = b[p..end].to_vec();
            for _ in 0..*k {
                b.splice(end..end, run.iter().copied());
            }
        }
        Mutation::Boundary(h, i, v, w) if len >= *w => {
            let p = at(*h, i, len - w + 1).min(len - w);
            b[p..p + w].copy_from_slice(&v.to_le_bytes()[..*w]);
        }
        Mutation::Number(which, lit) => replace_number(b, which, EXTREME[lit.index(EXTREME.len())]),
        Mutation::Replace(..) | Mutation::Remove(_) | Mutation::Nest(..) | Mutation::Repeat(..) => {
            match kind {
                Kind::Json => {
                    if let Ok(mut v) = serde_json::from_slice::<serde_json::Value>(b) {
                        edit_tree(&mut v, m);
                        *b = serde_json::to_vec_pretty(&v).unwrap_or_default();
                    }
                }
                Kind::Toml => edit_toml(b, m),
                Kind::Binary | Kind::Text => {}
            }
        }
        _ => {}
    }
}

/// Replaces the `which`-th run of digits (with its sign, fraction and exponent) by `lit`.
fn replace_number(b: &mut Vec<u8>, which: &Index, lit: &str) {
    let mut spans = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() {
            let start = if i > 0 && b[i - 1] == b'-' { i - 1 } else { i };
            let mut j = i;
            while j < b.len()
                && (b[j].is_ascii_digit() || matches!(b[j], b'.' | b'e' | b'E' | b'+' | b'-'))
            {
                j += 1;
            }
            spans.push((start, j));
            i = j;
        } else {
            i += 1;
        }
    }
    if spans.is_empty() {
        return;
    }
    let (s, e) = spans[which.index(spans.len())];
    b.splice(s..e, lit.bytes());
}

/// JSON pointers of every node of `v` (the root first).
fn pointers(v: &serde_json::Value, here: String, out: &mut Vec<String>) {
    out.push(here.clone());
    match v {
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                pointers(x, format!("{here}/{i}"), out);
            }
        }
        serde_json::Value::Object(o) => {
            for (k, x) in o {
                let k = k.replace('~', "~0").replace('/', "~1");
                pointers(x, format!("{here}/{k}"), out);
            }
        }
        _ => {}
    }
}

fn json_of(r: &Replacement) -> serde_json::Value {
    use serde_json::Value;
    match r {
        Replacement::Null => Value::Null,
        Replacement::Bool(x) => Value::Bool(*x),
        Replacement::Str(s) => Value::String(s.clone()),
        Replacement::EmptyArray => Value::Array(Vec::new()),
        Replacement::EmptyObject => Value::Object(Default::default()),
        Replacement::Int(x) => Value::from(*x),
        Replacement::UInt(x) => Value::from(*x),
        // JSON has no NaN or infinity: the largest finite values stand in.
        Replacement::Float(x) if x.is_nan() => Value::from(f64::MAX),
        Replacement::Float(x) if x.is_infinite() => Value::from(f64::MAX.copysign(*x)),
        Replacement::Float(x) => Value::from(*x),
    }
}

/// Applies a tree mutation to a JSON value.
pub fn edit_tree(root: &mut serde_json::Value, m: &Mutation) {
    let mut ptrs = Vec::new();
    pointers(root, String::new(), &mut ptrs);
    let pick = |i: &Index| ptrs[i.index(ptrs.len())].clone();
    match m {
        Mutation::Replace(i, r) => {
            if let Some(node) = root.pointer_mut(&pick(i)) {
                *node = json_of(r);
            }
        }
        Mutation::Remove(i) => {
            let p = pick(i);
            let Some(cut) = p.rfind('/') else { return };
            let (parent, key) = (
                &p[..cut],
                p[cut + 1..].replace("~1", "/").replace("~0", "~"),
            );
            match root.pointer_mut(parent) {
                Some(serde_json::Value::Object(o)) => {
                    o.remove(&key);
                }
                Some(serde_json::Value::Array(a)) => {
                    if let Ok(k) = key.parse::<usize>() {
                        if k < a.len() {
                            a.remove(k);
                        }
                    }
                }
                _ => {}
            }
        }
        Mutation::Nest(i, depth) => {
            if let Some(node) = root.pointer_mut(&pick(i)) {
                let mut v = node.take();
                for _ in 0..*depth {
                    v = serde_json::Value::Array(vec![v]);
                }
                *node = v;
            }
        }
        Mutation::Repeat(i, n) => {
            if let Some(serde_json::Value::Array(a)) = root.pointer_mut(&pick(i)) {
                if let Some(first) = a.first().cloned() {
                    a.splice(0..0, std::iter::repeat_n(first, *n));
                }
            }
        }
        _ => {}
    }
}

/// TOML: edited as JSON (same tree), written back as TOML; a replacement by NaN or an
/// infinity (which TOML can spell) is written directly. A tree TOML cannot hold (a null,
/// a non-table root) leaves the text as it was.
fn edit_toml(b: &mut Vec<u8>, m: &Mutation) {
    let Ok(text) = std::str::from_utf8(b) else {
        return;
    };
    let Ok(table) = text.parse::<toml::Table>() else {
        return;
    };
    let Ok(mut json) = serde_json::to_value(&table) else {
        return;
    };
    let special = match m {
        Mutation::Replace(_, Replacement::Float(x)) if !x.is_finite() => Some(*x),
        _ => None,
    };
    edit_tree(&mut json, m);
    let Ok(mut back) = serde_json::from_value::<toml::Value>(json) else {
        return;
    };
    if let Some(x) = special {
        // The JSON stand-in (f64::MAX) is at the chosen node: put the non-finite back.
        set_nonfinite(&mut back, x);
    }
    if let toml::Value::Table(t) = back {
        if let Ok(s) = toml::to_string(&t) {
            *b = s.into_bytes();
        }
    }
}

fn set_nonfinite(v: &mut toml::Value, x: f64) {
    // The stand-in is unique enough to find by value.
    match v {
        toml::Value::Float(f) if f.abs() == f64::MAX => *f = x,
        toml::Value::Array(a) => a.iter_mut().for_each(|e| set_nonfinite(e, x)),
        toml::Value::Table(t) => t.iter_mut().for_each(|(_, e)| set_nonfinite(e, x)),
        _ => {}
    }
}

/// Mutations of a safetensors file: tree and number edits go to its JSON header (dtypes,
/// shapes, data offsets, metadata), which is then written back with its new length, so
/// that the header lies instead of failing to parse; byte edits go to the whole file.
pub fn safetensors_mutations() -> BoxedStrategy<Vec<Mutation>> {
    mutations(Kind::Json)
}

/// Applies `muts` to a safetensors file (see [`safetensors_mutations`]).
pub fn apply_safetensors(seed: &[u8], muts: &[Mutation]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for m in muts {
        let header_edit = matches!(
            m,
            Mutation::Number(..)
                | Mutation::Replace(..)
                | Mutation::Remove(_)
                | Mutation::Nest(..)
                | Mutation::Repeat(..)
        );
        let split = (b.len() >= 8)
            .then(|| u64::from_le_bytes(b[..8].try_into().unwrap()) as usize)
            .filter(|&n| n <= b.len() - 8);
        match (header_edit, split) {
            (true, Some(n)) => {
                let mut header = b[8..8 + n].to_vec();
                apply_one(&mut header, m, Kind::Json);
                let mut out = (header.len() as u64).to_le_bytes().to_vec();
                out.extend_from_slice(&header);
                out.extend_from_slice(&b[8 + n..]);
                b = out;
            }
            _ => apply_one(&mut b, m, Kind::Binary),
        }
    }
    b
}

/// CRC-32 (IEEE), as PNG chunks and zip entries use it.
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in data {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A zip of stored (uncompressed) entries, as `torch.save` and `numpy.savez` write them.
pub fn stored_zip(files: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in files {
        let offset = out.len() as u32;
        let crc = crc32(data);
        let header = |sig: u32, central: bool| {
            let mut h = sig.to_le_bytes().to_vec();
            if central {
                h.extend(20u16.to_le_bytes()); // made by
            }
            h.extend(20u16.to_le_bytes()); // version needed
            h.extend(0u16.to_le_bytes()); // flags
            h.extend(0u16.to_le_bytes()); // stored
            h.extend(0u32.to_le_bytes()); // time, date
            h.extend(crc.to_le_bytes());
            h.extend((data.len() as u32).to_le_bytes());
            h.extend((data.len() as u32).to_le_bytes());
            h.extend((name.len() as u16).to_le_bytes());
            h.extend(0u16.to_le_bytes()); // extra
            if central {
                h.extend(0u16.to_le_bytes()); // comment
                h.extend(0u16.to_le_bytes()); // disk
                h.extend(0u16.to_le_bytes()); // internal attributes
                h.extend(0u32.to_le_bytes()); // external attributes
                h.extend(offset.to_le_bytes());
            }
            h.extend(name.as_bytes());
            h
        };
        out.extend(header(0x0403_4b50, false));
        out.extend(data);
        central.extend(header(0x0201_4b50, true));
    }
    let cd_offset = out.len() as u32;
    out.extend(&central);
    out.extend(0x0605_4b50u32.to_le_bytes());
    out.extend([0u8; 4]); // disk numbers
    out.extend((files.len() as u16).to_le_bytes());
    out.extend((files.len() as u16).to_le_bytes());
    out.extend((central.len() as u32).to_le_bytes());
    out.extend(cd_offset.to_le_bytes());
    out.extend(0u16.to_le_bytes());
    out
}

/// A `.npy` file of raw little-endian `data` under a header that says `descr` and `shape`
/// (which need not match the data: a header may lie).
pub fn npy(descr: &str, shape: &[u64], data: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    out.extend(data);
    out
}

/// One test per format with its CI case count, and `fuzz_long_run` (ignored) running them
/// all with `FUZZ_CASES` (default 20× the CI count) each: `cargo test -p CRATE --test FILE
/// -- --ignored`. Shared by every fuzz test file (`#[macro_use] mod fuzz_common`).
macro_rules! formats {
    ($($test:ident: $ci:expr => $body:expr;)*) => {
        $(
            #[test]
            fn $test() {
                ($body)(fuzz_common::cases($ci))
            }
        )*

        #[test]
        #[ignore = "long run: cargo test -p CRATE --test FILE -- --ignored (FUZZ_CASES=N per format)"]
        fn fuzz_long_run() {
            $( ($body)(fuzz_common::long_cases($ci)); )*
        }
    };
}
