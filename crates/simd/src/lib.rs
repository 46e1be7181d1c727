//! `simd`: the vector instruction set the hand-written kernels use (the rasterizer's
//! projection, binning and tile kernels, the SSIM bands, the SAM decoder's element-wise
//! kernels).
//!
//! One build runs on every x86-64 CPU: each kernel is compiled for AVX-512F, AVX2 + FMA and
//! the portable baseline, and [`level`] picks one at run time. Most users' CPUs have AVX2
//! and no AVX-512, so the environment variable [`ENV`] (`SEMDYNREG_SIMD=avx2`, say) caps
//! the level: the AVX2 path can be measured and tested on an AVX-512 machine
//! (docs/performance.md, "Instruction sets"). Every level gives bit-identical results
//! (`crates/splat/tests/bit_identical.rs`), so the cap changes speed only.
//!
//! The GEMMs (the deformation field, the image encoders) are gemm's, which dispatches on
//! its own and does not read this cap.

use std::fmt;
use std::sync::OnceLock;

/// The environment variable that caps the vector level: `avx512`, `avx2` or `portable`.
pub const ENV: &str = "SEMDYNREG_SIMD";

/// A vector level, ordered from narrowest to widest.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Simd {
    /// What every x86-64 (or other) CPU runs: scalar code and SSE2 auto-vectorization.
    Portable,
    /// AVX2 + FMA: a 16-pixel row is two 8-lane vectors.
    Avx2,
    /// AVX-512F (+ AVX2/FMA): a row is one 16-lane vector.
    Avx512,
}

impl Simd {
    /// Every level, narrowest first.
    pub const ALL: [Simd; 3] = [Simd::Portable, Simd::Avx2, Simd::Avx512];

    /// The name [`ENV`] takes for this level.
    pub fn name(self) -> &'static str {
        match self {
            Simd::Portable => "portable",
            Simd::Avx2 => "avx2",
            Simd::Avx512 => "avx512",
        }
    }

    /// Parses a level's name (case-insensitive, surrounding blanks ignored).
    pub fn parse(s: &str) -> Option<Simd> {
        let s = s.trim();
        Simd::ALL
            .into_iter()
            .find(|l| l.name().eq_ignore_ascii_case(s))
    }
}

impl fmt::Display for Simd {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// [`ENV`] holds something that is not a level's name.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("{ENV}={value:?} is not a vector level: use avx512, avx2 or portable (or unset it)")]
pub struct BadLevel {
    pub value: String,
}

/// The widest level this CPU supports, whatever [`ENV`] says.
pub fn cpu_level() -> Simd {
    #[cfg(target_arch = "x86_64")]
    {
        let avx2 = is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma");
        if avx2 && is_x86_feature_detected!("avx512f") {
            return Simd::Avx512;
        }
        if avx2 {
            return Simd::Avx2;
        }
    }
    Simd::Portable
}

/// The cap [`ENV`] sets: `Ok(None)` when it is unset or empty.
pub fn env_cap() -> Result<Option<Simd>, BadLevel> {
    match std::env::var(ENV) {
        Ok(v) if v.trim().is_empty() => Ok(None),
        Ok(v) => Simd::parse(&v).map(Some).ok_or(BadLevel { value: v }),
        Err(_) => Ok(None),
    }
}

/// The level the kernels use: the CPU's, capped by [`ENV`]. Read once per process; a value
/// that is not a level's name is ignored here (the `semdynreg` binary refuses it at start,
/// [`env_cap`]).
pub fn level() -> Simd {
    static LEVEL: OnceLock<Simd> = OnceLock::new();
    *LEVEL.get_or_init(|| capped(cpu_level(), env_cap().ok().flatten()))
}

/// `cpu` lowered to `cap` where a cap is given (a cap above the CPU's level changes nothing).
pub fn capped(cpu: Simd, cap: Option<Simd>) -> Simd {
    cap.map_or(cpu, |c| c.min(cpu))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for l in Simd::ALL {
            assert_eq!(Simd::parse(l.name()), Some(l));
            assert_eq!(l.to_string(), l.name());
        }
        assert_eq!(Simd::parse(" AVX2\n"), Some(Simd::Avx2));
        assert_eq!(Simd::parse("avx-2"), None);
        assert_eq!(Simd::parse("sse"), None);
    }

    #[test]
    fn a_cap_only_lowers() {
        assert_eq!(capped(Simd::Avx512, Some(Simd::Avx2)), Simd::Avx2);
        assert_eq!(capped(Simd::Avx2, Some(Simd::Avx512)), Simd::Avx2);
        assert_eq!(capped(Simd::Avx2, Some(Simd::Portable)), Simd::Portable);
        assert_eq!(capped(Simd::Avx2, None), Simd::Avx2);
    }

    #[test]
    fn the_level_never_exceeds_the_cpu() {
        assert!(level() <= cpu_level());
    }

    #[test]
    fn the_error_names_the_variable_and_the_value() {
        let e = BadLevel {
            value: "avx-512".into(),
        };
        let msg = e.to_string();
        assert!(
            msg.contains("SEMDYNREG_SIMD") && msg.contains("avx-512"),
            "{msg}"
        );
    }
}
