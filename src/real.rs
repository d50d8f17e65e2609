//! The number type the control core is generic over: `f32` on the target, `f64` on the host.
//!
//! Only what the models, observers and controllers need. Transcendentals go through `libm`
//! so the same code is `no_std`; `sqrt` on an FPU Cortex-M uses the `vsqrt.f32` instruction
//! (libm's `sqrtf` is a ~70-instruction software routine there).

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real number type usable in the per-sample path.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + PartialEq
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
    + Send
    + Sync
    + 'static
{
    const ZERO: Self;
    const ONE: Self;
    const TWO: Self;
    const HALF: Self;
    const PI: Self;
    /// Machine epsilon of the type.
    const EPSILON: Self;
    /// Largest finite value.
    const MAX: Self;

    fn from_f64(x: f64) -> Self;
    fn to_f64(self) -> f64;
    fn abs(self) -> Self;
    fn sqrt(self) -> Self;
    fn exp(self) -> Self;
    /// `exp(x) - 1`, accurate for small `x`.
    fn exp_m1(self) -> Self;
    fn ln(self) -> Self;
    /// `ln(1 + x)`, accurate for small `x`.
    fn ln_1p(self) -> Self;
    fn powf(self, e: Self) -> Self;
    fn sin(self) -> Self;
    fn cos(self) -> Self;
    fn tanh(self) -> Self;
    fn atan2(self, x: Self) -> Self;
    fn floor(self) -> Self;
    fn is_finite(self) -> bool;

    #[inline(always)]
    fn from_usize(n: usize) -> Self {
        Self::from_f64(n as f64)
    }
    /// Sign with `0 -> 0` (the `sgn` of the seeds), NaN -> 0.
    #[inline(always)]
    fn sgn(self) -> Self {
        if self > Self::ZERO {
            Self::ONE
        } else if self < Self::ZERO {
            -Self::ONE
        } else {
            Self::ZERO
        }
    }
    /// Smaller of two; returns `other` when `self` is NaN.
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        if self < other {
            self
        } else {
            other
        }
    }
    /// Larger of two; returns `other` when `self` is NaN.
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        if self > other {
            self
        } else {
            other
        }
    }
    /// Clamp into `[lo, hi]`; NaN maps to `lo` so a bad value never escapes a limit.
    #[inline(always)]
    fn clamp_to(self, lo: Self, hi: Self) -> Self {
        if self >= lo {
            if self <= hi {
                self
            } else {
                hi
            }
        } else {
            lo
        }
    }
    /// `|x|^n` for `n >= 0`, exact and cheap for `n == 1`.
    #[inline(always)]
    fn abs_pow(self, n: Self) -> Self {
        let a = self.abs();
        if n == Self::ONE {
            a
        } else if a == Self::ZERO {
            Self::ZERO
        } else {
            a.powf(n)
        }
    }
}

macro_rules! real_impl {
    ($t:ty, $exp:ident, $expm1:ident, $ln:ident, $ln1p:ident, $pow:ident, $sin:ident, $cos:ident, $tanh:ident, $atan2:ident, $floor:ident, $fabs:ident) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const TWO: Self = 2.0;
            const HALF: Self = 0.5;
            const PI: Self = core::f64::consts::PI as $t;
            const EPSILON: Self = <$t>::EPSILON;
            const MAX: Self = <$t>::MAX;
            #[inline(always)]
            fn from_f64(x: f64) -> Self {
                x as $t
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn abs(self) -> Self {
                libm::$fabs(self)
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                sqrt_impl(self)
            }
            #[inline(always)]
            fn exp(self) -> Self {
                libm::$exp(self)
            }
            #[inline(always)]
            fn exp_m1(self) -> Self {
                libm::$expm1(self)
            }
            #[inline(always)]
            fn ln(self) -> Self {
                libm::$ln(self)
            }
            #[inline(always)]
            fn ln_1p(self) -> Self {
                libm::$ln1p(self)
            }
            #[inline(always)]
            fn powf(self, e: Self) -> Self {
                libm::$pow(self, e)
            }
            #[inline(always)]
            fn sin(self) -> Self {
                libm::$sin(self)
            }
            #[inline(always)]
            fn cos(self) -> Self {
                libm::$cos(self)
            }
            #[inline(always)]
            fn tanh(self) -> Self {
                libm::$tanh(self)
            }
            #[inline(always)]
            fn atan2(self, x: Self) -> Self {
                libm::$atan2(self, x)
            }
            #[inline(always)]
            fn floor(self) -> Self {
                libm::$floor(self)
            }
            #[inline(always)]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
        }
    };
}

real_impl!(f32, expf, expm1f, logf, log1pf, powf, sinf, cosf, tanhf, atan2f, floorf, fabsf);
real_impl!(f64, exp, expm1, log, log1p, pow, sin, cos, tanh, atan2, floor, fabs);

trait SqrtImpl {
    fn sqrt_impl(self) -> Self;
}
#[inline(always)]
fn sqrt_impl<T: SqrtImpl>(x: T) -> T {
    x.sqrt_impl()
}

impl SqrtImpl for f64 {
    #[inline(always)]
    fn sqrt_impl(self) -> Self {
        libm::sqrt(self)
    }
}

impl SqrtImpl for f32 {
    #[inline(always)]
    fn sqrt_impl(self) -> Self {
        #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
        {
            let y: f32;
            // SAFETY: `vsqrt.f32` is a pure single-precision FPU instruction on every
            // eabihf Cortex-M; it touches no memory and no flags used by Rust. Rust does not
            // see the FPU as a target feature here (the `sreg` class needs `vfp2`), so the
            // operands go through core registers and s0 is saved and restored by hand.
            #[allow(unsafe_code)]
            unsafe {
                core::arch::asm!(
                    "vmov {t}, s0",
                    "vmov s0, {x}",
                    "vsqrt.f32 s0, s0",
                    "vmov {y}, s0",
                    "vmov s0, {t}",
                    x = in(reg) self, y = lateout(reg) y, t = out(reg) _,
                    options(pure, nomem, nostack, preserves_flags));
            }
            y
        }
        #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
        {
            libm::sqrtf(self)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clamp_maps_nan_to_lower_limit() {
        assert_eq!(f32::NAN.clamp_to(-1.0, 1.0), -1.0);
        assert_eq!(f64::INFINITY.clamp_to(-1.0, 1.0), 1.0);
        assert_eq!(0.5f64.clamp_to(-1.0, 1.0), 0.5);
    }

    #[test]
    fn sgn_of_zero_is_zero() {
        assert_eq!(0.0f64.sgn(), 0.0);
        assert_eq!((-3.0f32).sgn(), -1.0);
        assert_eq!(f64::NAN.sgn(), 0.0);
    }

    #[test]
    fn abs_pow_matches_powf() {
        for &x in &[-2.5f64, -0.3, 0.0, 0.7, 4.0] {
            for &n in &[1.0f64, 1.5, 2.0, 3.0] {
                let want = if x == 0.0 { 0.0 } else { x.abs().powf(n) };
                assert!((x.abs_pow(n) - want).abs() < 1e-12);
            }
        }
    }
}
