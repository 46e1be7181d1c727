//! Number types for code written once and run on one Gaussian or on sixteen.
//!
//! The projection (`project.rs`) is written over [`Lane`]: with `f32` it is the scalar
//! reference (one Gaussian, branches), with [`F16`] each value holds sixteen Gaussians and
//! every branch is a [`Lane::select`]. Each `F16` operation is the `f32` operation applied
//! lane by lane (no fused multiply-add, no reassociation), so the two give bit-identical
//! results, and a plain loop over 16 lanes is what LLVM turns into one AVX-512 or two AVX2
//! instructions inside the `#[target_feature]` functions of `project_batch.rs`.

use crate::sh::Real;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Gaussians per [`F16`].
pub(crate) const LANES: usize = 16;

/// A float type the projection runs on: `f32` or [`F16`].
pub(crate) trait Lane: Real + Div<Output = Self> {
    /// Per-lane truth value (`bool` for `f32`).
    type Mask: Copy
        + BitAnd<Output = Self::Mask>
        + BitOr<Output = Self::Mask>
        + Not<Output = Self::Mask>;
    fn splat(v: f32) -> Self;
    fn sqrt(self) -> Self;
    fn max(self, o: Self) -> Self;
    fn min(self, o: Self) -> Self;
    fn ceil(self) -> Self;
    fn exp(self) -> Self;
    fn lt(self, o: Self) -> Self::Mask;
    fn le(self, o: Self) -> Self::Mask;
    fn gt(self, o: Self) -> Self::Mask;
    fn ge(self, o: Self) -> Self::Mask;
    /// `a` where `m`, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
}

impl Lane for f32 {
    type Mask = bool;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        v
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        f32::max(self, o)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        f32::min(self, o)
    }
    #[inline(always)]
    fn ceil(self) -> Self {
        f32::ceil(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        f32::exp(self)
    }
    #[inline(always)]
    fn lt(self, o: Self) -> bool {
        self < o
    }
    #[inline(always)]
    fn le(self, o: Self) -> bool {
        self <= o
    }
    #[inline(always)]
    fn gt(self, o: Self) -> bool {
        self > o
    }
    #[inline(always)]
    fn ge(self, o: Self) -> bool {
        self >= o
    }
    #[inline(always)]
    fn select(m: bool, a: Self, b: Self) -> Self {
        if m {
            a
        } else {
            b
        }
    }
}

/// Sixteen `f32`, one per Gaussian.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct F16(pub [f32; LANES]);

/// Sixteen truth values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct M16(pub [bool; LANES]);

/// `[e(0), e(1), …]` for a literal length of 2, 3 or 4, without a closure. Inside the
/// `#[target_feature]` functions of `project_batch.rs` a closure (`std::array::from_fn`,
/// `array::map`) is a separate function that LLVM may leave un-inlined, and it then runs
/// without AVX on arrays in memory (measured on 100k Gaussians: the projection forward 1.3×
/// and its backward 1.7× slower with them).
macro_rules! arr {
    ($i:ident in 2 => $e:expr) => {
        [{ let $i = 0usize; $e }, { let $i = 1usize; $e }]
    };
    ($i:ident in 3 => $e:expr) => {
        [{ let $i = 0usize; $e }, { let $i = 1usize; $e }, { let $i = 2usize; $e }]
    };
    ($i:ident in 4 => $e:expr) => {
        [
            { let $i = 0usize; $e },
            { let $i = 1usize; $e },
            { let $i = 2usize; $e },
            { let $i = 3usize; $e },
        ]
    };
}
pub(crate) use arr;

/// `[e(a[l], b[l]) for l in 0..16]` as a plain loop, so that it vectorizes.
macro_rules! lanewise {
    ($a:expr, $b:expr, |$x:ident, $y:ident| $e:expr) => {{
        let (a, b) = ($a, $b);
        let mut r = [Default::default(); LANES];
        for l in 0..LANES {
            let ($x, $y) = (a[l], b[l]);
            r[l] = $e;
        }
        r
    }};
    ($a:expr, |$x:ident| $e:expr) => {{
        let a = $a;
        let mut r = [Default::default(); LANES];
        for l in 0..LANES {
            let $x = a[l];
            r[l] = $e;
        }
        r
    }};
}

macro_rules! f16_binop {
    ($tr:ident, $m:ident, $op:tt) => {
        impl $tr for F16 {
            type Output = F16;
            #[inline(always)]
            fn $m(self, o: F16) -> F16 {
                F16(lanewise!(self.0, o.0, |a, b| a $op b))
            }
        }
    };
}
f16_binop!(Add, add, +);
f16_binop!(Sub, sub, -);
f16_binop!(Mul, mul, *);
f16_binop!(Div, div, /);

impl Neg for F16 {
    type Output = F16;
    #[inline(always)]
    fn neg(self) -> F16 {
        F16(lanewise!(self.0, |a| -a))
    }
}

impl BitAnd for M16 {
    type Output = M16;
    #[inline(always)]
    fn bitand(self, o: M16) -> M16 {
        M16(lanewise!(self.0, o.0, |a, b| a & b))
    }
}

impl BitOr for M16 {
    type Output = M16;
    #[inline(always)]
    fn bitor(self, o: M16) -> M16 {
        M16(lanewise!(self.0, o.0, |a, b| a | b))
    }
}

impl Not for M16 {
    type Output = M16;
    #[inline(always)]
    fn not(self) -> M16 {
        M16(lanewise!(self.0, |a| !a))
    }
}

impl Real for F16 {
    #[inline(always)]
    fn c(v: f64) -> Self {
        F16([v as f32; LANES])
    }
}

impl Lane for F16 {
    type Mask = M16;
    #[inline(always)]
    fn splat(v: f32) -> Self {
        F16([v; LANES])
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        F16(lanewise!(self.0, |a| a.sqrt()))
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        F16(lanewise!(self.0, o.0, |a, b| a.max(b)))
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        F16(lanewise!(self.0, o.0, |a, b| a.min(b)))
    }
    #[inline(always)]
    fn ceil(self) -> Self {
        F16(lanewise!(self.0, |a| a.ceil()))
    }
    #[inline(always)]
    fn exp(self) -> Self {
        F16(lanewise!(self.0, |a| a.exp()))
    }
    #[inline(always)]
    fn lt(self, o: Self) -> M16 {
        M16(lanewise!(self.0, o.0, |a, b| a < b))
    }
    #[inline(always)]
    fn le(self, o: Self) -> M16 {
        M16(lanewise!(self.0, o.0, |a, b| a <= b))
    }
    #[inline(always)]
    fn gt(self, o: Self) -> M16 {
        M16(lanewise!(self.0, o.0, |a, b| a > b))
    }
    #[inline(always)]
    fn ge(self, o: Self) -> M16 {
        M16(lanewise!(self.0, o.0, |a, b| a >= b))
    }
    #[inline(always)]
    fn select(m: M16, a: Self, b: Self) -> Self {
        let mut r = [0.0; LANES];
        for (l, v) in r.iter_mut().enumerate() {
            *v = if m.0[l] { a.0[l] } else { b.0[l] };
        }
        F16(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type Case = (F16, fn(f32, f32) -> f32);

    #[test]
    fn f16_ops_are_the_f32_ops_per_lane() {
        let a: [f32; LANES] = std::array::from_fn(|l| (l as f32 - 7.3) * 0.61);
        let b: [f32; LANES] = std::array::from_fn(|l| ((l * 5 % 16) as f32 - 4.1) * 1.7);
        let (fa, fb) = (F16(a), F16(b));
        let cases: [Case; 6] = [
            (fa + fb, |x, y| x + y),
            (fa - fb, |x, y| x - y),
            (fa * fb, |x, y| x * y),
            (fa / fb, |x, y| x / y),
            (fa.max(fb), f32::max),
            (
                Lane::select(fa.lt(fb), (fa * fa).sqrt(), fb.ceil()),
                |x, y| {
                    if x < y {
                        (x * x).sqrt()
                    } else {
                        y.ceil()
                    }
                },
            ),
        ];
        for (k, (got, want)) in cases.iter().enumerate() {
            for l in 0..LANES {
                let w = want(a[l], b[l]);
                assert_eq!(got.0[l].to_bits(), w.to_bits(), "op {k}, lane {l}");
            }
        }
        let e = (-fa).exp();
        let m = !(fa.ge(fb) & fa.le(F16::splat(1.0))) | fa.gt(fb);
        for (l, (&x, &y)) in a.iter().zip(&b).enumerate() {
            assert_eq!(e.0[l].to_bits(), (-x).exp().to_bits());
            assert_eq!(m.0[l], !(x >= y && x <= 1.0) || x > y);
        }
    }
}
