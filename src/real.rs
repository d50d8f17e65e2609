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
    /// An overflow stays non-finite through every later operation (IEEE: an infinity, then
    /// NaN), so a finite result proves finite operands. False for saturating fixed point,
    /// where a saturated operand can still give a finite result.
    const OVERFLOW_PROPAGATES: bool = true;
    /// An IEEE binary float (its compares are float compares). Picks the cheaper code
    /// where the two kinds of type differ: the output stage clamps a command's code in
    /// integers (float to integer first, range and slew limit as one integer clamp), while
    /// fixed point, whose compares are integer ones already, clamps the real into the
    /// range; and [`crate::pipeline::Pipeline::step`] calls the generic step out of line
    /// on the target (fixed point inlines it).
    const IEEE: bool = true;

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

    /// `(phi(x), exp(-x) - 1)` with `phi(x) = (1 - exp(-x)) / x` (`phi(0) = 1`): the two
    /// factors of the exact input-domain step of the Bouc-Wen models for `n = 1`.
    #[inline(always)]
    fn phi_expm1_neg(self) -> (Self, Self) {
        let em = (-self).exp_m1();
        let phi = if self == Self::ZERO {
            Self::ONE
        } else {
            -em / self
        };
        (phi, em)
    }
    /// [`Real::phi_expm1_neg`] for `self >= 0` or NaN (the same values; the per-sample
    /// test of `f32` skips its `abs`).
    #[inline(always)]
    fn phi_expm1_neg_nonneg(self) -> (Self, Self) {
        self.phi_expm1_neg()
    }

    #[inline(always)]
    fn from_usize(n: usize) -> Self {
        Self::from_f64(n as f64)
    }
    /// `n` as a real without going through f64 (soft-float on an SP-only FPU).
    #[inline(always)]
    fn from_i32(n: i32) -> Self {
        Self::from_f64(n as f64)
    }
    /// Truncated toward zero, saturating, NaN -> 0 (as `as i32`), without f64.
    #[inline(always)]
    fn to_i32(self) -> i32 {
        self.to_f64() as i32
    }
    /// A 32-bit phase accumulator as turns, `x / 2^32`, without f64.
    #[inline(always)]
    fn from_turns(x: u32) -> Self {
        Self::from_f64(x as f64 / 4_294_967_296.0)
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
    /// `self` negated when `sign_of` is negative: `self * sgn(sign_of)` for a nonzero,
    /// non-NaN `sign_of` (the callers' case). IEEE types flip the sign bit (integer
    /// instructions, no compare; `-0.0` counts as negative there).
    #[inline(always)]
    fn mul_sign(self, sign_of: Self) -> Self {
        if sign_of < Self::ZERO {
            -self
        } else {
            self
        }
    }
    /// 1 when the sign is negative, else 0: [`Real::mul_sign`]'s test as an index (IEEE
    /// types read the sign bit: `-0.0` counts as negative there, as in `mul_sign`).
    #[inline(always)]
    fn sign_index(self) -> usize {
        usize::from(self < Self::ZERO)
    }
    /// Neither zero nor NaN.
    #[inline(always)]
    fn is_nonzero(self) -> bool {
        // Not `!= 0`: NaN is neither.
        let up = self > Self::ZERO;
        up || self < Self::ZERO
    }
    /// [`Real::clamp_to`] into `[-b, b]`.
    #[inline(always)]
    fn clamp_sym(self, b: Self) -> Self {
        self.clamp_to(-b, b)
    }
    /// `self` and `other` of opposite signs (neither zero nor NaN): `self * other < 0`,
    /// which IEEE types compute (one product and one compare); fixed point compares instead
    /// (its product is a 64-bit multiply with rounding and saturation).
    #[inline(always)]
    fn opposite_signs(self, other: Self) -> bool {
        if self < Self::ZERO {
            other > Self::ZERO
        } else {
            self > Self::ZERO && other < Self::ZERO
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
    ($t:ty, $turn_shift:expr, $exp:ident, $expm1:path, $ln:ident, $ln1p:ident, $pow:ident, $sin:path, $cos:path, $tanh:ident, $atan2:ident, $floor:path, $fabs:path, $phi:path, $phi_nn:path) => {
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
            fn mul_sign(self, sign_of: Self) -> Self {
                // `sign_of`'s sign bit XORed into `self`'s.
                let sign = (-0.0 as $t).to_bits();
                <$t>::from_bits(self.to_bits() ^ (sign_of.to_bits() & sign))
            }
            /// The sign bit (integer instructions, no compare).
            #[inline(always)]
            fn sign_index(self) -> usize {
                (self.to_bits() >> (8 * core::mem::size_of::<$t>() - 1)) as usize
            }
            /// One compare of `|x|` (two on fixed point's integers are cheaper than its `abs`).
            #[inline(always)]
            fn is_nonzero(self) -> bool {
                self.abs() > 0.0
            }
            /// The product's sign (an underflow to 0 counts as the same signs).
            #[inline(always)]
            fn opposite_signs(self, other: Self) -> bool {
                self * other < 0.0
            }
            /// Strictly inside the bound (the usual case) on one compare, the clamp otherwise
            /// (NaN: `-b`): the same value.
            #[inline(always)]
            fn clamp_sym(self, b: Self) -> Self {
                if self.abs() < b {
                    self
                } else {
                    self.clamp_to(-b, b)
                }
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline(always)]
            fn from_usize(n: usize) -> Self {
                n as $t
            }
            #[inline(always)]
            fn from_i32(n: i32) -> Self {
                n as $t
            }
            #[inline(always)]
            fn to_i32(self) -> i32 {
                self as i32
            }
            /// Exact: the phase keeps as many bits as the mantissa holds.
            #[inline(always)]
            fn from_turns(x: u32) -> Self {
                (x >> $turn_shift) as $t * (1.0 / (1u64 << (32 - $turn_shift)) as $t)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                $fabs(self)
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
                $expm1(self)
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
                $sin(self)
            }
            #[inline(always)]
            fn cos(self) -> Self {
                $cos(self)
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
                $floor(self)
            }
            #[inline(always)]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            #[inline(always)]
            fn phi_expm1_neg(self) -> (Self, Self) {
                $phi(self)
            }
            #[inline(always)]
            fn phi_expm1_neg_nonneg(self) -> (Self, Self) {
                $phi_nn(self)
            }
        }
    };
}

real_impl!(
    f32,
    8,
    expf,
    expm1_f32,
    logf,
    log1pf,
    powf,
    sin_f32,
    cos_f32,
    tanhf,
    atan2f,
    floor_f32,
    abs_f32,
    phi_expm1_neg_f32,
    phi_expm1_neg_nonneg_f32
);
real_impl!(
    f64,
    0,
    exp,
    libm::expm1,
    log,
    log1p,
    pow,
    libm::sin,
    libm::cos,
    tanh,
    atan2,
    libm::floor,
    libm::fabs,
    phi_expm1_neg_f64,
    phi_expm1_neg_f64
);

/// The trait's default, for `f64`.
#[inline(always)]
fn phi_expm1_neg_f64(x: f64) -> (f64, f64) {
    let em = libm::expm1(-x);
    let phi = if x == 0.0 { 1.0 } else { -em / x };
    (phi, em)
}

/// [`Real::phi_expm1_neg`] in single precision: for the per-sample `|x| <= 1/32`, `phi` by
/// its Taylor polynomial (degree 4, remainder `x^5/720 < 5e-11` relative) and `exp(-x) - 1
/// = -x phi`: no division and no test for `x = 0`; elsewhere from `exp_m1`.
#[inline(always)]
fn phi_expm1_neg_f32(x: f32) -> (f32, f32) {
    phi_expm1_neg_f32_abs(x, x.abs())
}

/// [`phi_expm1_neg_f32`] for `x >= 0` or NaN, where `|x| = x`.
#[inline(always)]
fn phi_expm1_neg_nonneg_f32(x: f32) -> (f32, f32) {
    if x <= 1.0 / 32.0 {
        // Degree 3: the remainder x^4/120 is below 8e-9 relative (0.07 ulp) here.
        let p = 1.0 / 6.0 - x * (1.0 / 24.0);
        let p = 0.5 - x * p;
        let phi = 1.0 - x * p;
        (phi, -x * phi)
    } else {
        phi_expm1_neg_f32_abs(x, x)
    }
}

/// [`phi_expm1_neg_f32`] with `ax = |x|`.
#[inline(always)]
fn phi_expm1_neg_f32_abs(x: f32, ax: f32) -> (f32, f32) {
    if ax <= 1.0 / 32.0 {
        let p = 1.0 / 24.0 - x * (1.0 / 120.0);
        let p = 1.0 / 6.0 - x * p;
        let p = 0.5 - x * p;
        let phi = 1.0 - x * p;
        (phi, -x * phi)
    } else {
        let em = expm1_f32(-x);
        (-em / x, em)
    }
}

/// `exp(x) - 1` in single precision. The models' exact input-domain steps need it with
/// `|x| = k*du` tiny at high sample rates (1e-3 at 100 kHz), where libm's `expm1f` (~100
/// instructions, range reduction for any `x`) is mostly overhead: Taylor polynomials in
/// Horner form, degree 5 for `|x| <= 1/32` and 8 for `|x| <= 1/4` (remainders below
/// `5e-11` relative to `x` in both, far below half an ulp); elsewhere libm.
#[inline(always)]
fn expm1_f32(x: f32) -> f32 {
    const C: [f32; 7] = [
        1.0 / 2.0,
        1.0 / 6.0,
        1.0 / 24.0,
        1.0 / 120.0,
        1.0 / 720.0,
        1.0 / 5040.0,
        1.0 / 40320.0,
    ];
    let a = x.abs();
    if a <= 1.0 / 32.0 {
        // The per-sample case: degree 5 leaves x^5/720 < 5e-11 relative.
        let p = C[2] + x * C[3];
        let p = C[1] + x * p;
        let p = C[0] + x * p;
        x + (x * x) * p
    } else if a <= 0.25 {
        let p = C[5] + x * C[6];
        let p = C[4] + x * p;
        let p = C[3] + x * p;
        let p = C[2] + x * p;
        let p = C[1] + x * p;
        let p = C[0] + x * p;
        x + (x * x) * p
    } else {
        expm1_f32_libm(x)
    }
}

/// The rare large arguments, out of line so the per-sample polynomial inlines.
#[inline(never)]
#[cold]
fn expm1_f32_libm(x: f32) -> f32 {
    libm::expm1f(x)
}

/// `|x|` in single precision: core's `abs` is the FPU's `vabs.f32` (one instruction);
/// libm's `fabsf` clears the sign bit in a core register (three, with the moves).
#[inline(always)]
fn abs_f32(x: f32) -> f32 {
    x.abs()
}

/// `floor(x)` in single precision without libm's bit manipulation: below `2^23` in
/// magnitude the truncating conversion is exact and one compare fixes negative
/// non-integers; larger, infinite and NaN values are returned as they are (all of them are
/// their own floor).
#[inline(always)]
fn floor_f32(x: f32) -> f32 {
    if x.abs() < 8_388_608.0 {
        let t = x as i32 as f32;
        if t > x {
            t - 1.0
        } else {
            t
        }
    } else {
        x
    }
}

/// `(sin x, cos x)` in single precision only: libm's `sinf`/`cosf` evaluate in f64, which an
/// SP-only FPU (Cortex-M4F/M7 `eabihf` builds) emulates in software (~1000 instructions).
/// Octant reduction with pi/2 split in three parts (exact products for `|x| <= 8192`), then
/// the minimax polynomials of Cephes `sinf`/`cosf` on `[-pi/4, pi/4]`; error below 2.5e-7
/// absolute for `|x| <= 100` (tested). Larger or non-finite arguments go to libm.
#[inline]
fn sin_cos_f32(x: f32) -> (f32, f32) {
    if !(x.abs() <= 8192.0) {
        return (libm::sinf(x), libm::cosf(x));
    }
    const P1: f32 = 1.570_312_5;
    const P2: f32 = 4.837_513e-4;
    const P3: f32 = 7.549_79e-8;
    let q = x * core::f32::consts::FRAC_2_PI;
    let j = (q + if q >= 0.0 { 0.5 } else { -0.5 }) as i32;
    let jf = j as f32;
    let r = ((x - jf * P1) - jf * P2) - jf * P3;
    let z = r * r;
    let s = r + r * z * (-1.666_665_5e-1 + z * (8.332_161e-3 + z * -1.951_529_6e-4));
    let c = 1.0 - 0.5 * z + z * z * (4.166_664_6e-2 + z * (-1.388_731_6e-3 + z * 2.443_315_7e-5));
    match j & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

#[inline(always)]
fn sin_f32(x: f32) -> f32 {
    sin_cos_f32(x).0
}

#[inline(always)]
fn cos_f32(x: f32) -> f32 {
    sin_cos_f32(x).1
}

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

    /// The sign flip of the IEEE types is the select the fixed point type runs.
    #[test]
    fn opposite_signs_is_the_sign_of_the_product() {
        use crate::fixed::Q16;
        let xs = [-3.0, -1e-3, -0.0, 0.0, 1e-3, 2.5];
        for &a in &xs {
            for &b in &xs {
                let want = a * b < 0.0;
                assert_eq!(a.opposite_signs(b), want, "f64 {a} {b}");
                assert_eq!((a as f32).opposite_signs(b as f32), want, "f32 {a} {b}");
                let (qa, qb) = (Q16::from_f64(a), Q16::from_f64(b));
                assert_eq!(qa.opposite_signs(qb), want, "Q16 {a} {b}");
            }
        }
        assert!(!f32::NAN.opposite_signs(1.0) && !1.0f32.opposite_signs(f32::NAN));
    }

    #[test]
    fn mul_sign_is_the_product_with_the_sign() {
        use crate::fixed::Q16;
        let xs = [-2.5, -1e-30, 0.0, 0.75, 3e20];
        let signs = [-7.0, -1e-40, 1e-40, 0.5, f64::INFINITY, f64::NEG_INFINITY];
        for &x in &xs {
            for &s in &signs {
                let want = if s < 0.0 { -x } else { x };
                assert_eq!(x.mul_sign(s).to_bits(), want.to_bits(), "{x} {s}");
                let (xf, sf) = (x as f32, s as f32);
                let want = if sf < 0.0 || (sf == 0.0 && s < 0.0) {
                    -xf
                } else {
                    xf
                };
                assert_eq!(xf.mul_sign(sf).to_bits(), want.to_bits(), "{x} {s}");
                let (xq, sq) = (Q16::from_f64(x.clamp(-3e4, 3e4)), Q16::from_f64(s));
                let want = if sq < Q16::ZERO { -xq } else { xq };
                assert_eq!(xq.mul_sign(sq), want, "{x} {s}");
            }
        }
        // -0.0 counts as negative where the sign is a bit (callers never pass a zero).
        assert_eq!(2.0f32.mul_sign(-0.0), -2.0);
    }

    #[test]
    fn sgn_of_zero_is_zero() {
        assert_eq!(0.0f64.sgn(), 0.0);
        assert_eq!((-3.0f32).sgn(), -1.0);
        assert_eq!(f64::NAN.sgn(), 0.0);
    }

    #[test]
    fn f32_sin_cos_match_f64() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let x = i as f32 * 5e-4; // [-100, 100]
            let (s, c) = (x.sin() as f64, x.cos() as f64);
            let xd = x as f64;
            worst = worst.max((s - xd.sin()).abs()).max((c - xd.cos()).abs());
        }
        assert!(worst < 2.5e-7, "f32 sin/cos error {worst}");
        assert!(f32::NAN.sin().is_nan());
        assert!((1e6f32.sin() as f64 - (1e6f64).sin()).abs() < 1e-6);
    }

    #[test]
    fn f32_phi_expm1_neg_matches_f64() {
        let mut worst = (0.0f64, 0.0f64);
        for i in -100_000..=100_000 {
            let x = i as f32 * 1e-6; // [-0.1, 0.1], across the polynomial's edge at 1/32
            let (phi, em) = x.phi_expm1_neg();
            let (want_phi, want_em) = (x as f64).phi_expm1_neg();
            worst.0 = worst.0.max((phi as f64 - want_phi).abs() / want_phi);
            worst.1 = worst
                .1
                .max((em as f64 - want_em).abs() / want_em.abs().max(1e-30));
        }
        assert!(
            worst.0 < 2.5e-7 && worst.1 < 2.5e-7,
            "f32 relative errors {worst:?}"
        );
        assert_eq!(0.0f32.phi_expm1_neg(), (1.0, 0.0));
        assert_eq!(0.0f64.phi_expm1_neg(), (1.0, 0.0));
        let (phi, em) = 1e3f32.phi_expm1_neg();
        assert_eq!((phi, em), (1e-3, -1.0));
        assert!(f32::NAN.phi_expm1_neg().0.is_nan());
        // The variant for x >= 0 (a shorter polynomial): as close.
        let mut worst: f64 = 0.0;
        for i in 0..=100_000 {
            let x = i as f32 * 1e-6;
            let want = (x as f64).phi_expm1_neg().0;
            worst = worst.max((x.phi_expm1_neg_nonneg().0 as f64 - want).abs() / want);
        }
        assert!(worst < 2.5e-7, "f32 nonneg relative error {worst}");
        assert_eq!(0.0f32.phi_expm1_neg_nonneg(), (1.0, -0.0));
        assert!(f32::NAN.phi_expm1_neg_nonneg().0.is_nan());
    }

    #[test]
    fn f32_expm1_and_floor_match_f64() {
        let mut worst = 0.0f64;
        for i in -100_000..=100_000 {
            let x = i as f32 * 3e-6; // [-0.3, 0.3], across the polynomial's edge
            let want = (x as f64).exp_m1();
            let got = x.exp_m1() as f64;
            worst = worst.max((got - want).abs() / want.abs().max(1e-30));
        }
        assert!(worst < 2.5e-7, "f32 exp_m1 relative error {worst}");
        assert_eq!(0.0f32.exp_m1(), 0.0);
        assert!(f32::NAN.exp_m1().is_nan());
        assert_eq!((-1e3f32).exp_m1(), -1.0);
        for &x in &[
            -2.5f32,
            -2.0,
            -0.5,
            -0.0,
            0.0,
            0.5,
            2.0,
            2.5,
            8_388_607.5,
            -8_388_607.5,
            1e9,
            -1e9,
        ] {
            assert_eq!(x.floor(), libm::floorf(x), "{x}");
        }
        assert!(f32::NAN.floor().is_nan());
        assert_eq!(f32::NEG_INFINITY.floor(), f32::NEG_INFINITY);
    }

    #[test]
    fn integer_and_phase_conversions() {
        assert_eq!(<f32 as Real>::from_i32(-70_000), -70_000.0);
        assert_eq!(2.9f32.to_i32(), 2);
        assert_eq!((-2.9f64).to_i32(), -2);
        assert_eq!(f32::NAN.to_i32(), 0);
        assert_eq!(<f32 as Real>::from_turns(1 << 31), 0.5);
        assert_eq!(<f64 as Real>::from_turns(1), 1.0 / 4_294_967_296.0);
        assert_eq!(<f32 as Real>::from_usize(3), 3.0);
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
