//! A branch-free `exp` for f32 that LLVM vectorizes (std's `f32::exp` is a libm call per
//! lane). Cody–Waite range reduction `x = n·ln2 + r`, |r| ≤ ln2/2, degree-6 Taylor
//! polynomial for e^r (truncation ≤ 1.2e-7 relative), scaled by 2^n built in the exponent
//! bits. Rounding to n uses the 1.5·2^23 trick so only add/sub/int ops are needed.

const LOG2E: f32 = std::f32::consts::LOG2_E;
const LN2_HI: f32 = 0.693_145_75;
const LN2_LO: f32 = 1.428_606_8e-6;
const MAGIC: f32 = 12_582_912.0; // 1.5·2^23

/// e^x for x in any range; inputs are clamped to ±87 (finite result, no NaN for finite x).
#[inline(always)]
pub(crate) fn exp(x: f32) -> f32 {
    let x = x.clamp(-87.0, 87.0);
    let t = x * LOG2E + MAGIC;
    let n = t - MAGIC;
    let ni = (t.to_bits() as i32).wrapping_sub(0x4B40_0000);
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    // wrapping: no overflow-check branch (it would stop vectorization in checked builds).
    let scale = f32::from_bits((ni.wrapping_add(127) << 23) as u32);
    p * scale
}

#[cfg(test)]
mod tests {
    #[test]
    fn close_to_std_exp() {
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            let x = -80.0 + i as f32 * 0.0004;
            let (a, b) = (super::exp(x) as f64, (x as f64).exp());
            worst = worst.max(((a - b) / b).abs());
        }
        assert!(worst < 5e-7, "worst relative error {worst}");
        assert_eq!(super::exp(-1e9), super::exp(-87.0));
        assert!(super::exp(f32::NEG_INFINITY) >= 0.0);
    }
}
