//! Number parsing: decimal text into `f32` (correctly rounded) and `usize`, with bounded
//! work and no panic path.

use super::error::Error;

/// Most significant decimal digits a number may have. Leading zeros and trailing zeros
/// do not count (`0.000150000` has 2); 19 digits fit a `u64`, more than `f32`'s 9 needed.
pub const MAX_DIGITS: u32 = 19;

/// A finite `f32` from decimal text, correctly rounded (nearest, ties to even), without
/// core's float parser (bounded work, no panic path in the firmware's serial handler).
///
/// Accepted syntax: `[+-]digits[.digits][(e|E)[+-]digits]`, also `5.` and `.5`, with at
/// most [`MAX_DIGITS`] significant digits. Values that round to zero give `0` (`-0` with a
/// minus sign), as core's parser does.
/// * [`Error::BadNumber`]: not that syntax (`nan`, `inf`, `0x10`, `1e`, `1.2.3`, ...), or a
///   value beyond `f32::MAX` once rounded;
/// * [`Error::TooManyDigits`]: more than [`MAX_DIGITS`] significant digits.
pub fn parse_f32(s: &str) -> Result<f32, Error> {
    let b = s.as_bytes();
    let (neg, b) = match b.split_first() {
        Some((b'-', r)) => (true, r),
        Some((b'+', r)) => (false, r),
        _ => (false, b),
    };
    // Value = m * 10^exp10, m the significant digits; zeros after the last nonzero digit
    // wait in `zeros` (they only move the exponent).
    let (mut m, mut n_sig, mut zeros, mut exp10) = (0u64, 0u32, 0u32, 0i32);
    let (mut digits, mut dot) = (0u32, false);
    let mut rest: &[u8] = &[];
    for (i, &c) in b.iter().enumerate() {
        match c {
            b'0'..=b'9' => {
                digits = digits.saturating_add(1);
                if dot {
                    exp10 = exp10.saturating_sub(1);
                }
                if c == b'0' {
                    if n_sig > 0 {
                        zeros = zeros.saturating_add(1);
                    }
                    continue;
                }
                let n = n_sig.saturating_add(zeros).saturating_add(1);
                if n > MAX_DIGITS {
                    return Err(Error::TooManyDigits);
                }
                let scale = POW10_U64
                    .get(zeros as usize + 1)
                    .ok_or(Error::TooManyDigits)?;
                m = m
                    .checked_mul(*scale)
                    .and_then(|m| m.checked_add((c - b'0') as u64))
                    .ok_or(Error::TooManyDigits)?;
                n_sig = n;
                zeros = 0;
            }
            b'.' if !dot => dot = true,
            b'e' | b'E' => {
                rest = b.get(i + 1..).unwrap_or(&[]);
                if rest.is_empty() {
                    return Err(Error::BadNumber);
                }
                break;
            }
            _ => return Err(Error::BadNumber),
        }
    }
    if digits == 0 {
        return Err(Error::BadNumber);
    }
    exp10 = exp10.saturating_add(zeros as i32);
    if !rest.is_empty() {
        let (eneg, ed) = match rest.split_first() {
            Some((b'-', r)) => (true, r),
            Some((b'+', r)) => (false, r),
            _ => (false, rest),
        };
        if ed.is_empty() {
            return Err(Error::BadNumber);
        }
        let mut e = 0i32;
        for &c in ed {
            if !c.is_ascii_digit() {
                return Err(Error::BadNumber);
            }
            // Saturate far beyond f32's range: the value is then 0 or too large anyway.
            e = (e * 10 + (c - b'0') as i32).min(100_000);
        }
        exp10 = exp10.saturating_add(if eneg { -e } else { e });
    }
    let sign = |v: f32| if neg { -v } else { v };
    // V in [10^(n_sig-1+exp10), 10^(n_sig+exp10)).
    let top = (n_sig as i32).saturating_add(exp10);
    if m == 0 || top <= -46 {
        // Below half the smallest subnormal (7.0e-46): rounds to zero.
        return Ok(sign(0.0));
    }
    if top > 39 {
        return Err(Error::BadNumber);
    }
    // Candidate from f64 arithmetic (relative error < 1e-15, far below f32's 6e-8), then
    // exact comparisons with the rounding midpoints around it decide.
    let p = pow10_f64(exp10.unsigned_abs());
    let approx = if exp10 >= 0 {
        m as f64 * p
    } else {
        m as f64 / p
    };
    let mut bits = (approx as f32).to_bits().min(F32_INF_BITS);
    for _ in 0..8 {
        let up = bits < F32_INF_BITS && {
            let c = cmp_midpoint(m, exp10, bits);
            c.is_gt() || (c.is_eq() && bits & 1 == 1)
        };
        if up {
            bits += 1;
            continue;
        }
        let down = bits > 0 && {
            let c = cmp_midpoint(m, exp10, bits - 1);
            c.is_lt() || (c.is_eq() && bits & 1 == 1)
        };
        if down {
            bits -= 1;
            continue;
        }
        break;
    }
    if bits >= F32_INF_BITS {
        return Err(Error::BadNumber);
    }
    Ok(sign(f32::from_bits(bits)))
}

/// Bit pattern of `f32::INFINITY`; one above `f32::MAX`.
const F32_INF_BITS: u32 = 0x7F80_0000;

/// 10^0 ..= 10^19.
pub(super) const POW10_U64: [u64; 20] = {
    let mut t = [1u64; 20];
    let mut i = 1;
    while i < 20 {
        t[i] = t[i - 1] * 10;
        i += 1;
    }
    t
};

/// 10^n as f64 (exact up to 10^22, then within a few ulp); `n` is at most 65 here.
pub(super) fn pow10_f64(n: u32) -> f64 {
    const EXACT: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let mut p = 1.0;
    let mut n = n.min(330);
    while n > 22 {
        p *= 1e22;
        n -= 22;
    }
    p * EXACT.get(n as usize).copied().unwrap_or(1.0)
}

/// Compares `m * 10^exp10` with the midpoint between the positive f32 of bit pattern
/// `bits` and the next one up, exactly (integers of up to 384 bits).
fn cmp_midpoint(m: u64, exp10: i32, bits: u32) -> core::cmp::Ordering {
    let (ef, frac) = (bits >> 23, bits & 0x7F_FFFF);
    let (sig, e2) = if ef == 0 {
        (frac, -149)
    } else {
        (frac | 0x80_0000, ef as i32 - 150)
    };
    // Midpoint = (2 sig + 1) * 2^(e2 - 1).
    let (mut lhs, mut rhs) = (Big::new(m), Big::new(2 * sig as u64 + 1));
    if exp10 >= 0 {
        lhs.mul_pow10(exp10.unsigned_abs());
    } else {
        rhs.mul_pow10(exp10.unsigned_abs());
    }
    let e = e2 - 1;
    if e >= 0 {
        rhs.shl(e.unsigned_abs());
    } else {
        lhs.shl(e.unsigned_abs());
    }
    lhs.cmp(&rhs)
}

/// Unsigned integer of [`Big::WORDS`] 64-bit words, least significant first; a result
/// that does not fit saturates to "larger than any that does" (never wraps, never panics).
#[derive(Clone, Copy, PartialEq, Eq)]
struct Big {
    w: [u64; Big::WORDS],
    overflow: bool,
}

impl Big {
    const WORDS: usize = 6;

    fn new(v: u64) -> Self {
        let mut w = [0; Self::WORDS];
        w[0] = v;
        Self { w, overflow: false }
    }

    fn mul_small(&mut self, x: u64) {
        let mut carry = 0u128;
        for w in self.w.iter_mut() {
            let t = *w as u128 * x as u128 + carry;
            *w = t as u64;
            carry = t >> 64;
        }
        self.overflow |= carry != 0;
    }

    fn mul_pow10(&mut self, mut n: u32) {
        while n > 0 {
            let k = n.min(19);
            self.mul_small(POW10_U64.get(k as usize).copied().unwrap_or(1));
            n -= k;
        }
    }

    fn bit_len(&self) -> u32 {
        let mut len = 0;
        for (i, w) in self.w.iter().enumerate() {
            if *w != 0 {
                len = i as u32 * 64 + (64 - w.leading_zeros());
            }
        }
        len
    }

    fn shl(&mut self, n: u32) {
        if self.bit_len() == 0 {
            return;
        }
        if self.bit_len().saturating_add(n) > 64 * Self::WORDS as u32 {
            self.overflow = true;
            return;
        }
        let (words, bits) = ((n / 64) as usize, n % 64);
        let src = self.w;
        let at = |j: Option<usize>| j.and_then(|j| src.get(j)).copied().unwrap_or(0);
        for (i, w) in self.w.iter_mut().enumerate() {
            let lo = at(i.checked_sub(words));
            let below = at(i.checked_sub(words + 1));
            *w = if bits == 0 {
                lo
            } else {
                (lo << bits) | (below >> (64 - bits))
            };
        }
    }
}

impl PartialOrd for Big {
    fn partial_cmp(&self, other: &Self) -> Option<core::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Big {
    fn cmp(&self, other: &Self) -> core::cmp::Ordering {
        match (self.overflow, other.overflow) {
            (true, false) => return core::cmp::Ordering::Greater,
            (false, true) => return core::cmp::Ordering::Less,
            _ => {}
        }
        for (a, b) in self.w.iter().rev().zip(other.w.iter().rev()) {
            if a != b {
                return a.cmp(b);
            }
        }
        core::cmp::Ordering::Equal
    }
}

/// A non-negative integer (`[+]digits`), without core's integer parser.
pub fn parse_usize(s: &str) -> Result<usize, Error> {
    let b = s.as_bytes();
    let b = b.strip_prefix(b"+").unwrap_or(b);
    if b.is_empty() {
        return Err(Error::BadNumber);
    }
    let mut v = 0usize;
    for &c in b {
        if !c.is_ascii_digit() {
            return Err(Error::BadNumber);
        }
        v = v
            .checked_mul(10)
            .and_then(|v| v.checked_add((c - b'0') as usize))
            .ok_or(Error::OutOfRange)?;
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::Reply;
    use proptest::prelude::*;

    /// Significant digits of a decimal string (what [`MAX_DIGITS`] counts).
    fn significant_digits(s: &str) -> usize {
        let mant = s.split(['e', 'E']).next().unwrap_or("");
        let d: String = mant.chars().filter(|c| c.is_ascii_digit()).collect();
        d.trim_start_matches('0').trim_end_matches('0').len()
    }

    /// Our parser against core's: same bits, or the documented error.
    fn check_against_std(s: &str) {
        let ours = parse_f32(s);
        match s.parse::<f32>() {
            Ok(v) if significant_digits(s) > MAX_DIGITS as usize => {
                assert_eq!(ours, Err(Error::TooManyDigits), "{s} (std {v})")
            }
            Ok(v) if v.is_finite() => {
                let got = ours.unwrap_or_else(|e| panic!("{s}: {e:?}, std {v}"));
                assert_eq!(got.to_bits(), v.to_bits(), "{s}: {got:e} vs std {v:e}");
            }
            _ => assert_eq!(ours, Err(Error::BadNumber), "{s}"),
        }
    }

    #[test]
    fn float_parser_matches_std_on_edge_cases() {
        for s in [
            "0",
            "-0",
            "+0",
            "0.0",
            "00012",
            "1",
            "-1",
            "1.5e-3",
            "12.5",
            ".5",
            "5.",
            "-.5e1",
            "150",
            "0.16",
            "1e10",
            "1E10",
            "1e+10",
            "3.4028235e38",
            "3.4028236e38",
            "3.40282356e38",
            "3.40282357e38",
            "1e39",
            "1e-45",
            "7e-46",
            "7.006e-46",
            "7.0064923216240862e-46",
            "7.0064923216240863e-46",
            "1.4012984e-45",
            "1.1754942e-38",
            "1.17549435e-38",
            "16777217",
            "16777219",
            "33554433",
            "0.000000000000000000000000000000000000000000001",
            "9999999999999999999",
            "99999999999999999999",
            "1000000000000000000000000",
            "0.1000000000000000000001",
            "123456789.123456789",
            "2.5",
            "8388608.5",
            "8388609.5",
            "1e-65",
            "1e-99999",
            "1e99999",
            "0e99999",
            "",
            ".",
            "-",
            "+",
            "e5",
            "1e",
            "1e+",
            "1e-",
            "--1",
            "+-1",
            "1.2.3",
            "0x10",
            "1_000",
            "inf",
            "-inf",
            "nan",
            "NaN",
            "infinity",
            "1 ",
            " 1",
            "1e5.5",
            "1..2",
            "1ee5",
            "١",
        ] {
            check_against_std(s);
        }
        assert_eq!(parse_f32("-0").map(|v| v.is_sign_negative()), Ok(true));
        assert_eq!(parse_f32("1e39"), Err(Error::BadNumber));
        assert_eq!(parse_f32("12345678901234567891"), Err(Error::TooManyDigits));
        // Leading and trailing zeros are not significant digits.
        assert_eq!(
            parse_f32("0.000000000000000000000000001500000000000000000000"),
            Ok(1.5e-27)
        );
        assert_eq!(parse_usize("+17"), Ok(17));
        assert_eq!(parse_usize("-1"), Err(Error::BadNumber));
        assert_eq!(parse_usize(""), Err(Error::BadNumber));
        assert_eq!(
            parse_usize("99999999999999999999999"),
            Err(Error::OutOfRange)
        );
    }

    proptest! {
        #[test]
        fn float_parser_matches_std_on_printed_floats(bits in any::<u32>(), prec in 0usize..12) {
            let v = f32::from_bits(bits);
            prop_assume!(v.is_finite());
            for s in [
                format!("{v}"),
                format!("{v:e}"),
                format!("{v:.prec$e}"),
                format!("{v:.prec$}"),
                format!("{:.prec$e}", v as f64 * 1.000_000_03),
            ] {
                check_against_std(&s);
            }
        }

        #[test]
        fn float_parser_matches_std_on_decimal_strings(
            neg in any::<bool>(),
            digits in "[0-9]{1,22}",
            dot in 0usize..23,
            exp in proptest::option::of(-70i32..45),
        ) {
            let dot = dot.min(digits.len());
            let mut s = String::new();
            if neg {
                s.push('-');
            }
            s.push_str(&digits[..dot]);
            s.push('.');
            s.push_str(&digits[dot..]);
            if let Some(e) = exp {
                s.push_str(&format!("e{e}"));
            }
            check_against_std(&s);
        }

        #[test]
        fn printed_numbers_read_back(bits in any::<u32>()) {
            let v = f32::from_bits(bits);
            prop_assume!(v.is_finite());
            let mut r = Reply::<32>::new();
            r.push_f32(v);
            let back = parse_f32(r.as_str()).unwrap();
            prop_assert_eq!(back.to_bits(), v.to_bits(), "{:e} -> {} -> {:e}", v, r.as_str(), back);
            // No longer than needed by more than 3 digits: core's shortest form.
            let shortest = significant_digits(&format!("{:e}", v));
            prop_assert!(significant_digits(r.as_str()) <= shortest.max(6));
        }
    }
}
