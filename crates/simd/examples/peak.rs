//! The f32 arithmetic peak of each vector level this CPU has, on one thread and on every
//! thread: the denominator of the kernels' floors in docs/performance.md ("Instruction
//! sets"). Twelve independent multiply-add chains per lane group hide the FMA latency
//! (4 cycles × 2–3 pipes); `portable` is what the baseline target auto-vectorizes (SSE2,
//! a multiply and an add), the others one fused multiply-add per lane.
//!
//! `cargo run --release -p simd --example peak [-- SECONDS_PER_LEVEL]`

use simd::Simd;
use std::time::Instant;

/// Twelve chains of a level's vector width: they stay in registers (16 of AVX2's, 32 of
/// AVX-512's; 24 AVX2 chains spill and measure a third less).
const CHAINS: usize = 12;

fn lanes(level: Simd) -> usize {
    match level {
        Simd::Portable => 4,
        Simd::Avx2 => 8,
        Simd::Avx512 => 16,
    }
}

// Intrinsics rather than auto-vectorized loops: the count of vector instructions per
// round is then exactly `CHAINS` (AVX2/AVX-512: one FMA each; SSE2: a multiply and an add).
#[cfg(target_arch = "x86_64")]
mod kernels {
    use super::CHAINS;
    use std::arch::x86_64::*;

    pub fn sse2(reps: usize) -> f32 {
        // SAFETY: SSE2 is part of x86-64.
        unsafe {
            let (m, a) = (_mm_set1_ps(0.999_9), _mm_set1_ps(1e-4));
            let x: [__m128; CHAINS] = std::array::from_fn(|c| _mm_set1_ps(1.0 + c as f32));
            let mut x = std::hint::black_box(x);
            for _ in 0..reps {
                for v in x.iter_mut() {
                    *v = _mm_add_ps(_mm_mul_ps(*v, m), a);
                }
            }
            let mut out = [0.0f32; 4];
            _mm_storeu_ps(
                out.as_mut_ptr(),
                x.iter().fold(_mm_setzero_ps(), |s, v| _mm_add_ps(s, *v)),
            );
            out.iter().sum()
        }
    }

    #[target_feature(enable = "avx2,fma")]
    pub fn avx2(reps: usize) -> f32 {
        let (m, a) = (_mm256_set1_ps(0.999_9), _mm256_set1_ps(1e-4));
        let x: [__m256; CHAINS] = std::array::from_fn(|c| _mm256_set1_ps(1.0 + c as f32));
        let mut x = std::hint::black_box(x);
        for _ in 0..reps {
            for v in x.iter_mut() {
                *v = _mm256_fmadd_ps(*v, m, a);
            }
        }
        let mut out = [0.0f32; 8];
        let s = x
            .iter()
            .fold(_mm256_setzero_ps(), |s, v| _mm256_add_ps(s, *v));
        // SAFETY: `out` holds 8 floats.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), s) };
        out.iter().sum()
    }

    #[target_feature(enable = "avx512f,avx2,fma")]
    pub fn avx512(reps: usize) -> f32 {
        let (m, a) = (_mm512_set1_ps(0.999_9), _mm512_set1_ps(1e-4));
        let x: [__m512; CHAINS] = std::array::from_fn(|c| _mm512_set1_ps(1.0 + c as f32));
        let mut x = std::hint::black_box(x);
        for _ in 0..reps {
            for v in x.iter_mut() {
                *v = _mm512_fmadd_ps(*v, m, a);
            }
        }
        _mm512_reduce_add_ps(
            x.iter()
                .fold(_mm512_setzero_ps(), |s, v| _mm512_add_ps(s, *v)),
        )
    }
}

fn run(level: Simd, reps: usize) -> f32 {
    #[cfg(target_arch = "x86_64")]
    match level {
        // SAFETY: called only for levels `simd::cpu_level` reported on this CPU.
        Simd::Avx512 => unsafe { kernels::avx512(reps) },
        Simd::Avx2 => unsafe { kernels::avx2(reps) },
        Simd::Portable => kernels::sse2(reps),
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (level, reps);
        0.0
    }
}

/// Flop/s of `level` on `threads` threads, each running `reps` rounds.
fn rate(level: Simd, threads: usize, reps: usize) -> f64 {
    let t = Instant::now();
    let sink: f32 = std::thread::scope(|s| {
        let hs: Vec<_> = (0..threads)
            .map(|_| s.spawn(move || run(level, reps)))
            .collect();
        hs.into_iter().map(|h| h.join().unwrap_or(0.0)).sum()
    });
    std::hint::black_box(sink);
    (threads * reps * CHAINS * lanes(level) * 2) as f64 / t.elapsed().as_secs_f64()
}

fn main() {
    let secs: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let best = simd::cpu_level();
    println!("widest level here: {best}; {threads} threads; median of 5 runs");
    for level in Simd::ALL.into_iter().filter(|l| *l <= best) {
        // Size the runs to about `secs / 5` each from a short calibration.
        let cal = 20_000;
        let per_rep = (CHAINS * lanes(level) * 2) as f64 / rate(level, 1, cal);
        let reps = ((secs / 5.0) / per_rep).max(1_000.0) as usize;
        for t in [1, threads] {
            let mut r: Vec<f64> = (0..5).map(|_| rate(level, t, reps)).collect();
            r.sort_by(f64::total_cmp);
            println!(
                "{:>8} {t} thread(s): {:7.1} Gflop/s",
                level.name(),
                r[2] / 1e9
            );
        }
    }
}
