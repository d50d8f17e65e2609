//! Fixed-point number type for FPU-less Cortex-M (thumbv7m): the pipeline built without f32.
//!
//! [`Q16`] is a signed Q16.16 number in an `i32`: range `[-32768, 32768)`, resolution
//! `2^-16 = 1.53e-5`. It implements [`Real`], so every model, compensator and law of the
//! core runs on it unchanged.
//!
//! # Semantics
//! * `+ - *` round to nearest and **saturate**; `/` saturates and `x / 0` is the saturated
//!   value of the sign of `x` (`0 / 0 = 0`). Nothing panics or wraps.
//! * The two saturated values `Q16::MAX` and `Q16::MIN` play the part of the infinities
//!   and NaN: `is_finite()` is false for them, so the core's NaN guards also catch overflow.
//!   Functions without a real result (`ln` of `x <= 0`, `sqrt` of `x < 0`) return `MIN`.
//! * Products use one `smull` (32x32 -> 64 bit); a division is one 64/64-bit division
//!   (a library routine on the M3).
//!
//! # Accuracy of the transcendentals (checked by the tests against f64)
//! Evaluated in Q2.30 internally with range reduction and truncated series whose remainder
//! is below 2e-6, so the result is within a few units of the last place (ulp = 1.53e-5) of the
//! exact value, rounded to Q16.16:
//!
//! | function | method | max abs. error (tested range) |
//! |---|---|---|
//! | `sqrt` | bitwise integer square root of `x << 16` | 1 ulp |
//! | `exp` | `2^k * e^r`, `abs(r) <= ln2/2`, Taylor degree 7 | 2 ulp relative, saturates above 10.39 |
//! | `exp_m1` | Taylor degree 7 for `abs(x) < 1/4`, else `exp - 1` | 2 ulp (+ `exp`'s) |
//! | `ln` | `e ln2 + 2 atanh(s)`, `m` in `[0.71, 1.41)`, degree 9 | 2 ulp |
//! | `ln_1p` | Taylor degree 8 for `abs(x) < 1/4`, else `ln(1+x)` | 2 ulp |
//! | `sin`, `cos` | reduction to `[-pi/2, pi/2]`, Taylor degree 11 | 3 ulp |
//! | `atan2` | octant reduction, `pi/4` shift, odd series degree 13 | 3 ulp |
//! | `tanh` | `(e^2x - 1) / (e^2x + 1)`, `+-1` beyond 5.5 | 3 ulp |
//! | `powf` | `exp(e * ln x)` | relative `(1 + abs(e ln x)) * 2^-16` |
//!
//! The input itself is only known to 1 ulp, so e.g. `exp(10)` carries an error of
//! `e^10 * 2^-17 = 0.17`: fixed point keeps absolute, not relative, precision.

use crate::real::Real;
use core::fmt;
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

const FRAC: u32 = 16;
const ONE_RAW: i32 = 1 << FRAC;

/// Signed Q16.16 fixed-point number, saturating (see the module docs).
#[derive(Clone, Copy, Default, PartialEq, Eq, PartialOrd, Hash)]
pub struct Q16(i32);

impl Q16 {
    /// From the raw two's-complement representation (value = raw / 65536).
    pub const fn from_raw(raw: i32) -> Self {
        Self(raw)
    }
    /// The raw representation.
    pub const fn raw(self) -> i32 {
        self.0
    }
    /// From an integer, saturating.
    pub const fn from_int(n: i32) -> Self {
        if n >= 1 << 15 {
            Self(i32::MAX)
        } else if n < -(1 << 15) {
            Self(i32::MIN)
        } else {
            Self(n << FRAC)
        }
    }
    #[inline(always)]
    const fn sat(v: i64) -> Self {
        if v > i32::MAX as i64 {
            Self(i32::MAX)
        } else if v < i32::MIN as i64 {
            Self(i32::MIN)
        } else {
            Self(v as i32)
        }
    }
    /// Value in Q2.30 (|x| < 2 only).
    #[inline(always)]
    fn q30(self) -> i32 {
        self.0.saturating_mul(1 << 14)
    }
    /// From Q2.30, rounded.
    #[inline(always)]
    fn from_q30(v: i64) -> Self {
        Self::sat((v + (1 << 13)) >> 14)
    }
}

/// Q2.30 product, rounded (operands below 2 in magnitude).
#[inline(always)]
fn mul30(a: i32, b: i32) -> i32 {
    ((a as i64 * b as i64 + (1 << 29)) >> 30) as i32
}

/// `1/n` in Q2.30.
const fn inv30(n: i64) -> i32 {
    (((1i64 << 30) + n / 2) / n) as i32
}

const LN2_Q30: i64 = 744_261_118; // ln 2 * 2^30
const INV_LN2_Q30: i64 = 1_549_082_005; // 1/ln 2 * 2^30
const PI_RAW: i32 = 205_887; // pi * 2^16
const QUARTER_PI_Q30: i32 = 843_314_857;
const HALF_PI_Q30: i32 = 1_686_629_713;

impl fmt::Debug for Q16 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

/// Decimal with 5 fractional digits (exact rounding of the raw value), without floats.
impl fmt::Display for Q16 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if !self.is_finite() {
            return f.write_str(if self.0 > 0 { "inf" } else { "-inf" });
        }
        let neg = self.0 < 0;
        let a = (self.0 as i64).unsigned_abs();
        let scaled = (a * 100_000 + (1 << 15)) >> FRAC;
        let (int, frac) = (scaled / 100_000, scaled % 100_000);
        write!(f, "{}{}.{:05}", if neg { "-" } else { "" }, int, frac)
    }
}

impl Add for Q16 {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self(self.0.saturating_add(o.0))
    }
}
impl Sub for Q16 {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self(self.0.saturating_sub(o.0))
    }
}
impl Mul for Q16 {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Self::sat((self.0 as i64 * o.0 as i64 + (1 << (FRAC - 1))) >> FRAC)
    }
}
impl Div for Q16 {
    type Output = Self;
    #[inline]
    fn div(self, o: Self) -> Self {
        if o.0 == 0 {
            return match self.0 {
                0 => Self(0),
                a if a > 0 => Self(i32::MAX),
                _ => Self(i32::MIN),
            };
        }
        let n = (self.0 as i64) << FRAC;
        let d = o.0 as i64;
        // Round half away from zero (the division truncates toward zero).
        let half = d.abs() / 2;
        Self::sat((n + if n < 0 { -half } else { half }) / d)
    }
}
impl Neg for Q16 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        // -MIN saturates to MAX: both stay "infinite".
        Self(self.0.saturating_neg())
    }
}
/// `a op= b` as `a = a op b` for each compound assignment.
macro_rules! op_assign {
    ($($trait:ident $method:ident $op:tt),*) => {
        $(
            impl $trait for Q16 {
                #[inline(always)]
                fn $method(&mut self, o: Self) {
                    *self = *self $op o;
                }
            }
        )*
    };
}
op_assign!(
    AddAssign add_assign +,
    SubAssign sub_assign -,
    MulAssign mul_assign *,
    DivAssign div_assign /
);

/// `e^r` for `abs(r) <= 0.35` in Q2.30 (Taylor degree 7, remainder < 2e-9).
fn exp_small_q30(r: i32) -> i32 {
    let mut acc = inv30(5040);
    for n in [720, 120, 24, 6, 2, 1] {
        acc = mul30(acc, r) + inv30(n);
    }
    mul30(acc, r) + (1 << 30)
}

/// `2 atanh(s) = ln((1+s)/(1-s))` for `abs(s) <= 0.172` in Q2.30 (degree 9, remainder < 1e-8).
fn ln_ratio_q30(s: i32) -> i32 {
    let s2 = mul30(s, s);
    let mut acc = inv30(9);
    for n in [7, 5, 3, 1] {
        acc = mul30(acc, s2) + inv30(n);
    }
    2 * mul30(acc, s)
}

/// `sin r` for `abs(r) <= pi/2` in Q2.30 (Taylor degree 11, remainder < 6e-8).
fn sin_q30(r: i32) -> i32 {
    // r^2 reaches 2.47: kept in i64.
    let r2 = (r as i64 * r as i64) >> 30;
    // r (1 - r2/3! (1 - r2/(4*5) (1 - r2/(6*7) (1 - r2/(8*9) (1 - r2/(10*11))))))
    let mut acc: i64 = 1 << 30;
    for n in [110, 72, 42, 20, 6] {
        acc = (1 << 30) - (((r2 / n) * acc) >> 30);
    }
    mul30(acc as i32, r)
}

/// `atan u` for `abs(u) <= 0.4143` in Q2.30 (odd series to degree 13, remainder < 1e-6).
fn atan_small_q30(u: i32) -> i32 {
    let u2 = mul30(u, u);
    // u (1 - u2/3 + u2^2/5 - ... + u2^6/13), Horner from the top.
    let mut acc = inv30(13);
    for (n, sign) in [(11, -1), (9, 1), (7, -1), (5, 1), (3, -1), (1, 1)] {
        acc = sign * inv30(n) + mul30(u2, acc);
    }
    mul30(acc, u)
}

/// `x` reduced to `[-pi, pi]`, in Q2.30 held in an i64 (2 pi carried to 2^-32).
fn reduce_2pi_q30(x: Q16) -> i64 {
    const TWO_PI_Q32: i64 = 26_986_075_409;
    let v = (x.0 as i64) << 16;
    let k = (v + if v >= 0 {
        TWO_PI_Q32 / 2
    } else {
        -TWO_PI_Q32 / 2
    }) / TWO_PI_Q32;
    (v - k * TWO_PI_Q32) >> 2
}

impl Real for Q16 {
    const ZERO: Self = Self(0);
    const ONE: Self = Self(ONE_RAW);
    const TWO: Self = Self(2 * ONE_RAW);
    const HALF: Self = Self(ONE_RAW / 2);
    const PI: Self = Self(PI_RAW);
    const EPSILON: Self = Self(1);
    /// The largest *finite* value (`i32::MAX` itself is the saturated, "infinite" one).
    const MAX: Self = Self(i32::MAX - 1);
    const OVERFLOW_PROPAGATES: bool = false;
    const IEEE: bool = false;

    #[inline]
    fn from_f64(x: f64) -> Self {
        if x.is_nan() {
            return Self(i32::MIN);
        }
        let v = x * ONE_RAW as f64;
        if v >= i32::MAX as f64 {
            Self(i32::MAX)
        } else if v <= i32::MIN as f64 {
            Self(i32::MIN)
        } else {
            // Round half away from zero without libm.
            Self(if v >= 0.0 { v + 0.5 } else { v - 0.5 } as i32)
        }
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self.0 as f64 / ONE_RAW as f64
    }
    #[inline(always)]
    fn from_usize(n: usize) -> Self {
        if n >= 1 << 15 {
            Self(i32::MAX)
        } else {
            Self((n as i32) << FRAC)
        }
    }
    #[inline(always)]
    fn from_i32(n: i32) -> Self {
        Self::from_int(n)
    }
    #[inline(always)]
    fn to_i32(self) -> i32 {
        // Division truncates toward zero, as `f32 as i32` does.
        self.0 / ONE_RAW
    }
    #[inline(always)]
    fn from_turns(x: u32) -> Self {
        Self((x >> FRAC) as i32)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Self(self.0.saturating_abs())
    }
    fn sqrt(self) -> Self {
        if self.0 < 0 {
            return Self(i32::MIN);
        }
        if self.0 == i32::MAX {
            return self;
        }
        // floor(sqrt(x * 2^16)) of a 48-bit integer, bit by bit (24 result bits).
        let n = (self.0 as u64) << FRAC;
        let mut rem = n;
        let mut root = 0u64;
        let mut bit = 1u64 << 46;
        while bit > rem {
            bit >>= 2;
        }
        while bit != 0 {
            if rem >= root + bit {
                rem -= root + bit;
                root = (root >> 1) + bit;
            } else {
                root >>= 1;
            }
            bit >>= 2;
        }
        // Round to nearest: root^2 <= n < (root+1)^2; compare with (root + 1/2)^2.
        if rem > root {
            root += 1;
        }
        Self(root as i32)
    }
    fn exp(self) -> Self {
        if !self.is_finite() {
            return if self.0 > 0 { self } else { Self(0) };
        }
        // e^10.397 = 32767.9; e^-11.1 < 1/2 ulp.
        if self.0 > 681_391 {
            return Self(i32::MAX);
        }
        if self.0 < -727_450 {
            return Self(0);
        }
        let x = self.0 as i64;
        // k = round(x / ln2), r = x - k ln2 in Q2.30.
        let k = (x * INV_LN2_Q30 + (1i64 << 45)) >> 46;
        let r = (x << 14) - k * LN2_Q30;
        let e = exp_small_q30(r as i32) as i64;
        // e^x = e * 2^k, from Q2.30 to Q16.16: shift by 14 - k.
        let shift = 14 - k;
        let v = if shift > 0 {
            (e + (1i64 << (shift - 1))) >> shift
        } else {
            e << (-shift)
        };
        Self::sat(v)
    }
    fn exp_m1(self) -> Self {
        if self.0.unsigned_abs() < (ONE_RAW as u32) / 4 {
            let x = self.q30();
            let mut acc = inv30(5040);
            for n in [720, 120, 24, 6, 2, 1] {
                acc = mul30(acc, x) + inv30(n);
            }
            Self::from_q30(mul30(acc, x) as i64)
        } else {
            self.exp() - Self::ONE
        }
    }
    fn ln(self) -> Self {
        if self.0 <= 0 {
            return Self(i32::MIN);
        }
        if self.0 == i32::MAX {
            return self;
        }
        // x = m * 2^(e - 16), m in [1, 2) as Q2.30; then m in [0.71, 1.41).
        let v = self.0 as u32;
        let mut e = 31 - v.leading_zeros() as i64;
        let mut m = ((v as u64) << (30 - e)) as i64;
        if m > 1_518_500_250 {
            // > sqrt(2) in Q2.30
            m /= 2;
            e += 1;
        }
        let s = ((m - (1 << 30)) << 30) / (m + (1 << 30));
        let ln_m = ln_ratio_q30(s as i32) as i64;
        let total = (e - FRAC as i64) * LN2_Q30 + ln_m;
        Self::from_q30(total)
    }
    fn ln_1p(self) -> Self {
        if self.0.unsigned_abs() < (ONE_RAW as u32) / 4 {
            let x = self.q30();
            // x - x^2/2 + ... - x^8/8, Horner.
            let mut acc = -inv30(8);
            for (n, sign) in [(7, 1), (6, -1), (5, 1), (4, -1), (3, 1), (2, -1), (1, 1)] {
                acc = mul30(acc, x) + sign * inv30(n);
            }
            Self::from_q30(mul30(acc, x) as i64)
        } else {
            (Self::ONE + self).ln()
        }
    }
    fn powf(self, e: Self) -> Self {
        if self.0 == 0 {
            return if e.0 > 0 { Self(0) } else { Self(i32::MAX) };
        }
        (e * self.ln()).exp()
    }
    fn sin(self) -> Self {
        if !self.is_finite() {
            return Self(i32::MIN);
        }
        const PI_Q30: i64 = 3_373_259_426;
        let mut r = reduce_2pi_q30(self);
        if r > PI_Q30 / 2 {
            r = PI_Q30 - r;
        } else if r < -PI_Q30 / 2 {
            r = -PI_Q30 - r;
        }
        Self::from_q30(sin_q30(r as i32) as i64)
    }
    fn cos(self) -> Self {
        if !self.is_finite() {
            return Self(i32::MIN);
        }
        // cos r = sin(pi/2 - |r|), r in [-pi, pi].
        let r = HALF_PI_Q30 as i64 - reduce_2pi_q30(self).abs();
        Self::from_q30(sin_q30(r as i32) as i64)
    }
    fn tanh(self) -> Self {
        // tanh 5.5 = 1 - 3.3e-5; beyond, e^2x would saturate.
        if self.0.unsigned_abs() >= 360_448 {
            return if self.0 > 0 { Self::ONE } else { -Self::ONE };
        }
        let e = (self.abs() * Self::TWO).exp();
        let t = (e - Self::ONE) / (e + Self::ONE);
        if self.0 < 0 {
            -t
        } else {
            t
        }
    }
    fn atan2(self, x: Self) -> Self {
        let (a, b) = (self.0.unsigned_abs() as i64, x.0.unsigned_abs() as i64);
        if a == 0 && b == 0 {
            return Self(0);
        }
        // t = min/max in [0, 1], Q2.30.
        let swap = a > b;
        let (num, den) = if swap { (b, a) } else { (a, b) };
        let t = (num << 30) / den;
        // atan t = pi/4 + atan((t - 1)/(t + 1)) above tan(pi/8).
        let mut angle = if t > 444_758_110 {
            let u = ((t - (1 << 30)) << 30) / (t + (1 << 30));
            QUARTER_PI_Q30 + atan_small_q30(u as i32)
        } else {
            atan_small_q30(t as i32)
        } as i64;
        if swap {
            angle = HALF_PI_Q30 as i64 - angle;
        }
        if x.0 < 0 {
            angle = 2 * HALF_PI_Q30 as i64 - angle;
        }
        if self.0 < 0 {
            angle = -angle;
        }
        Self::from_q30(angle)
    }
    #[inline(always)]
    fn floor(self) -> Self {
        Self(self.0 & !(ONE_RAW - 1))
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        self.0 != i32::MAX && self.0 != i32::MIN
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ULP: f64 = 1.0 / 65536.0;

    fn q(x: f64) -> Q16 {
        Q16::from_f64(x)
    }

    fn check(name: &str, f: impl Fn(Q16) -> Q16, g: impl Fn(f64) -> f64, xs: &[f64], ulps: f64) {
        for &x in xs {
            let qx = q(x);
            // Compare against the exact function of the *representable* input.
            let want = g(qx.to_f64());
            let got = f(qx).to_f64();
            assert!(
                (got - want).abs() <= ulps * ULP,
                "{name}({x}) = {got}, want {want}, error {} ulp",
                (got - want).abs() / ULP
            );
        }
    }

    fn grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
        (0..=n)
            .map(|i| lo + (hi - lo) * i as f64 / n as f64)
            .collect()
    }

    #[test]
    fn arithmetic_rounds_and_saturates() {
        assert_eq!((q(1.5) * q(-2.25)).to_f64(), -3.375);
        assert_eq!((q(7.0) / q(2.0)).to_f64(), 3.5);
        assert_eq!((q(-1.0) / q(3.0)).raw(), -21845);
        assert!(!(q(20000.0) + q(20000.0)).is_finite());
        assert!(!(q(300.0) * q(300.0)).is_finite());
        assert!(!(q(-300.0) * q(300.0)).is_finite());
        assert!(!(q(1.0) / Q16::ZERO).is_finite());
        assert_eq!(Q16::ZERO / Q16::ZERO, Q16::ZERO);
        assert!(!Q16::from_f64(f64::NAN).is_finite());
        assert!(!(-Q16::from_raw(i32::MIN)).is_finite());
        assert!(Q16::MAX.is_finite());
        assert_eq!(q(-2.5).floor().to_f64(), -3.0);
        assert_eq!(q(2.5).floor().to_f64(), 2.0);
        assert_eq!(Q16::from_usize(3).to_f64(), 3.0);
        assert_eq!(Q16::from_i32(-7).to_f64(), -7.0);
        assert!(!Q16::from_i32(40_000).is_finite());
        assert_eq!(q(-2.75).to_i32(), -2);
        assert_eq!(q(2.75).to_i32(), 2);
        assert_eq!(Q16::from_turns(3 << 30).to_f64(), 0.75);
        assert_eq!(format!("{}", q(-1.25)), "-1.25000");
        assert_eq!(format!("{}", q(3.0) / q(7.0)), "0.42857");
    }

    #[test]
    fn transcendentals_meet_the_documented_accuracy() {
        type Case = (
            &'static str,
            fn(Q16) -> Q16,
            fn(f64) -> f64,
            [f64; 2],
            usize,
            f64,
        );
        // Name, function, reference, input range, grid intervals, error bound (ulp).
        let cases: [Case; 9] = [
            ("sqrt", |x| x.sqrt(), f64::sqrt, [0.0, 30000.0], 997, 1.0),
            ("sqrt", |x| x.sqrt(), f64::sqrt, [0.0, 2.0], 997, 1.0),
            (
                "exp_m1",
                |x| x.exp_m1(),
                f64::exp_m1,
                [-3.0, 3.0],
                1999,
                3.0,
            ),
            ("ln", |x| x.ln(), f64::ln, [0.001, 30000.0], 1999, 2.0),
            ("ln", |x| x.ln(), f64::ln, [0.01, 3.0], 1999, 2.0),
            ("ln_1p", |x| x.ln_1p(), f64::ln_1p, [-0.9, 5.0], 1999, 2.0),
            ("sin", |x| x.sin(), f64::sin, [-100.0, 100.0], 4999, 3.0),
            ("cos", |x| x.cos(), f64::cos, [-100.0, 100.0], 4999, 3.0),
            ("tanh", |x| x.tanh(), f64::tanh, [-10.0, 10.0], 1999, 3.0),
        ];
        for (name, f, g, [lo, hi], n, ulps) in cases {
            check(name, f, g, &grid(lo, hi, n), ulps);
        }
        // exp: relative 2 ulp.
        for x in grid(-11.0, 10.39, 1999) {
            let qx = q(x);
            let want = qx.to_f64().exp();
            let got = qx.exp().to_f64();
            assert!(
                (got - want).abs() <= 2.0 * ULP * want.max(1.0),
                "exp({x}) = {got}, want {want}"
            );
        }
        for y in grid(-50.0, 50.0, 41) {
            for x in grid(-50.0, 50.0, 41) {
                let (qy, qx) = (q(y), q(x));
                let want = qy.to_f64().atan2(qx.to_f64());
                let got = qy.atan2(qx).to_f64();
                assert!(
                    (got - want).abs() <= 3.0 * ULP,
                    "atan2({y}, {x}) = {got}, want {want}"
                );
            }
        }
        // powf: relative error grows with |e ln x|.
        for &(x, e) in &[(2.0, 0.5), (10.0, 1.5), (0.3, 2.0), (5.0, 3.0), (1.7, 0.8)] {
            let want = f64::powf(x, e);
            let got = q(x).powf(q(e)).to_f64();
            let bound = (1.0 + (e * f64::ln(x)).abs()) * 4.0 * ULP * want.max(1.0);
            assert!(
                (got - want).abs() <= bound,
                "powf({x}, {e}) = {got}, want {want}"
            );
        }
    }

    #[test]
    fn out_of_domain_is_not_finite() {
        assert!(!q(-1.0).ln().is_finite());
        assert!(!Q16::ZERO.ln().is_finite());
        assert!(!q(-1.0).sqrt().is_finite());
        assert!(!q(11.0).exp().is_finite());
        assert_eq!(q(-12.0).exp(), Q16::ZERO);
    }

    proptest! {
        /// No operation panics (debug overflow checks are on in tests) on any raw value.
        #[test]
        fn nothing_panics(a in any::<i32>(), b in any::<i32>()) {
            let (x, y) = (Q16::from_raw(a), Q16::from_raw(b));
            let _ = (x + y, x - y, x * y, x / y, -x, x.abs(), x.floor());
            let _ = (x.sqrt(), x.exp(), x.exp_m1(), x.ln(), x.ln_1p(), x.sin(), x.cos());
            let _ = (x.tanh(), x.atan2(y), x.powf(y), x.sgn(), x.clamp_to(y, y), x.abs_pow(y));
            let _ = format!("{x}");
        }

        #[test]
        fn mul_and_div_match_f64(a in -180.0f64..180.0, b in -180.0f64..180.0) {
            let (x, y) = (q(a), q(b));
            let p = x.to_f64() * y.to_f64();
            prop_assert!((x * y).to_f64() - p <= 0.5 * ULP + 1e-12);
            prop_assert!(p - (x * y).to_f64() <= 0.5 * ULP + 1e-12);
            if y.to_f64().abs() > 0.01 {
                let d = x.to_f64() / y.to_f64();
                if d.abs() < 30000.0 {
                    prop_assert!(((x / y).to_f64() - d).abs() <= 0.5 * ULP + 1e-12);
                }
            }
        }
    }
}
