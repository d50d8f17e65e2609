//! Reply writing: a reply line in a fixed buffer, numbers written without `core::fmt`.

use core::fmt;

use super::error::Error;
use super::number::{parse_f32, pow10_f64, POW10_U64};

/// A reply line built with `write!` into a fixed buffer; text beyond the capacity is cut
/// (and [`Reply::truncated`] says so) instead of failing.
#[derive(Debug, Clone)]
pub struct Reply<const N: usize> {
    buf: [u8; N],
    len: usize,
    truncated: bool,
}

impl<const N: usize> Default for Reply<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Reply<N> {
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            truncated: false,
        }
    }
    pub fn clear(&mut self) {
        self.len = 0;
        self.truncated = false;
    }
    pub fn as_bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(self.as_bytes()).unwrap_or("")
    }
    pub fn truncated(&self) -> bool {
        self.truncated
    }

    /// Appends text (cut at the capacity). The `push_*` writers are what the firmware uses:
    /// no `core::fmt`, so no indirect calls and a known stack bound in its handlers.
    pub fn push_str(&mut self, s: &str) {
        self.push_bytes(s.as_bytes());
    }

    fn push_bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = b;
                    self.len += 1;
                }
                None => {
                    self.truncated = true;
                    break;
                }
            }
        }
    }

    /// `s`, then spaces up to `width` bytes (left-aligned column).
    pub fn push_padded(&mut self, s: &str, width: usize) {
        self.push_str(s);
        for _ in s.len()..width {
            self.push_bytes(b" ");
        }
    }

    /// Spaces, then `s`, `width` bytes in all (right-aligned column).
    pub fn push_right(&mut self, s: &str, width: usize) {
        for _ in s.len()..width {
            self.push_bytes(b" ");
        }
        self.push_str(s);
    }

    /// `v / 10^decimals` with exactly `decimals` digits after the point (`1234, 2` ->
    /// `12.34`): fixed-point counters without floats.
    pub fn push_fixed(&mut self, v: u32, decimals: u32) {
        let scale = POW10_U64.get(decimals as usize).copied().unwrap_or(1);
        let v = v as u64;
        self.push_u64(v / scale);
        if decimals == 0 {
            return;
        }
        self.push_bytes(b".");
        let mut frac = Reply::<20>::new();
        frac.push_u64(v % scale);
        for _ in frac.len..decimals as usize {
            self.push_bytes(b"0");
        }
        self.push_bytes(frac.as_bytes());
    }

    /// Decimal integer.
    pub fn push_u64(&mut self, mut v: u64) {
        let mut digits = [0u8; 20];
        let mut n = 0;
        for d in digits.iter_mut().rev() {
            *d = b'0' + (v % 10) as u8;
            v /= 10;
            n += 1;
            if v == 0 {
                break;
            }
        }
        self.push_bytes(digits.get(digits.len() - n..).unwrap_or(&[]));
    }

    pub fn push_u32(&mut self, v: u32) {
        self.push_u64(v as u64);
    }

    pub fn push_usize(&mut self, v: usize) {
        self.push_u64(v as u64);
    }

    pub fn push_i32(&mut self, v: i32) {
        if v < 0 {
            self.push_bytes(b"-");
        }
        self.push_u64(v.unsigned_abs() as u64);
    }

    /// `err <code> <message>`, the reply to a failed command.
    pub fn push_error(&mut self, e: Error) {
        self.push_str("err ");
        self.push_u32(e.code() as u32);
        self.push_bytes(b" ");
        self.push_str(e.message());
    }

    /// A number in the fewest of 6 to 9 significant digits that [`parse_f32`] reads back to
    /// the same `f32` (9 always do), trailing zeros dropped, `%g` style: positional for
    /// 1e-4 <= |v| < 1e9 (`0.16`, `150`, `20000`, `0.0001`), else `1.5e-5`,
    /// `3.4028235e38`; `nan`, `inf`, `-inf`.
    pub fn push_f32(&mut self, v: f32) {
        if v.is_nan() {
            return self.push_str("nan");
        }
        if v.is_sign_negative() && v != 0.0 {
            self.push_bytes(b"-");
        }
        let a = v.abs();
        if a.is_infinite() {
            return self.push_str("inf");
        }
        let mut text = Reply::<24>::new();
        for p in 6..=9 {
            text.clear();
            text.push_g(a, p);
            if p == 9 || parse_f32(text.as_str()).map(f32::to_bits) == Ok(a.to_bits()) {
                break;
            }
        }
        self.push_bytes(text.as_bytes());
    }

    /// Finite non-negative `v` to `p` (1..=9) significant digits, `%g` style.
    fn push_g(&mut self, v: f32, p: u32) {
        let x = v as f64;
        if x <= 0.0 {
            return self.push_bytes(b"0");
        }
        // Decimal exponent: 10^e <= x < 10^(e+1), from the binary one, then corrected.
        let e2 = ((x.to_bits() >> 52) & 0x7FF) as i32 - 1023;
        let mut e = (e2 * 30103).div_euclid(100_000);
        for _ in 0..3 {
            if x < pow10_signed(e) {
                e -= 1;
            } else if x >= pow10_signed(e + 1) {
                e += 1;
            }
        }
        // p digits, rounded; 999.5 (p = 3) rounds up to the next decade.
        let p = p.clamp(1, 9);
        let full = POW10_U64.get(p as usize).copied().unwrap_or(1);
        let mut d = (x * pow10_signed(p as i32 - 1 - e) + 0.5) as u64;
        if d >= full {
            d /= 10;
            e += 1;
        }
        let mut buf = [b'0'; 9];
        let digits = buf.get_mut(..p as usize).unwrap_or(&mut []);
        for slot in digits.iter_mut().rev() {
            *slot = b'0' + (d % 10) as u8;
            d /= 10;
        }
        let mut n = digits.len();
        while n > 1 && digits.get(n - 1) == Some(&b'0') {
            n -= 1;
        }
        let digits = digits.get(..n).unwrap_or(&[]);
        if (-4..9).contains(&e) {
            if e < 0 {
                self.push_bytes(b"0.");
                for _ in 0..(-e - 1) {
                    self.push_bytes(b"0");
                }
                self.push_bytes(digits);
            } else {
                let int = e as usize + 1;
                for i in 0..int {
                    self.push_bytes(&[digits.get(i).copied().unwrap_or(b'0')]);
                }
                if let Some(frac) = digits.get(int..).filter(|f| !f.is_empty()) {
                    self.push_bytes(b".");
                    self.push_bytes(frac);
                }
            }
        } else {
            let (first, rest) = digits.split_first().unwrap_or((&b'0', &[]));
            self.push_bytes(&[*first]);
            if !rest.is_empty() {
                self.push_bytes(b".");
                self.push_bytes(rest);
            }
            self.push_bytes(b"e");
            self.push_i32(e);
        }
    }
}

/// 10^n as f64 for |n| <= 330 (approximate beyond 10^22).
fn pow10_signed(n: i32) -> f64 {
    let p = pow10_f64(n.unsigned_abs());
    if n < 0 {
        1.0 / p
    } else {
        p
    }
}

impl<const N: usize> fmt::Write for Reply<N> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        self.push_str(s);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::fmt::Write;

    #[test]
    fn reply_truncates_instead_of_failing() {
        let mut r = Reply::<8>::new();
        write!(r, "ok {}", 123456789).unwrap();
        assert_eq!(r.as_str(), "ok 12345");
        assert!(r.truncated());
        r.clear();
        write!(r, "ok").unwrap();
        assert_eq!(r.as_str(), "ok");
        assert!(!r.truncated());
    }

    #[test]
    fn number_writer_prints_like_g8() {
        let f = |v: f32| {
            let mut r = Reply::<32>::new();
            r.push_f32(v);
            r.as_str().to_string()
        };
        assert_eq!(f(0.16), "0.16");
        assert_eq!(f(150.0), "150");
        assert_eq!(f(20_000.0), "20000");
        assert_eq!(f(-2.5), "-2.5");
        assert_eq!(f(0.0), "0");
        assert_eq!(f(1.5e-5), "1.5e-5");
        assert_eq!(f(0.0001), "0.0001");
        assert_eq!(f(12_345_678.0), "12345678");
        assert_eq!(f(123_456_790.0), "123456790");
        assert_eq!(f(1.5e9), "1.5e9");
        assert_eq!(f(f32::MAX), "3.4028235e38");
        assert_eq!(f(f32::MIN_POSITIVE), "1.1754944e-38");
        assert_eq!(f(1e-45), "1.4013e-45");
        assert_eq!(f(f32::from_bits(3_351_468_226)), "-100017.516");
        assert_eq!(f(f32::NAN), "nan");
        assert_eq!(f(f32::NEG_INFINITY), "-inf");
        let mut r = Reply::<64>::new();
        r.push_str("ok ");
        r.push_i32(-42);
        r.push_bytes(b" ");
        r.push_u32(u32::MAX);
        r.push_bytes(b" ");
        r.push_padded("ab", 4);
        r.push_str("|");
        r.push_right("ab", 4);
        r.push_bytes(b" ");
        r.push_fixed(1205, 2);
        r.push_bytes(b" ");
        r.push_fixed(40_000, 3);
        assert_eq!(r.as_str(), "ok -42 4294967295 ab  |  ab 12.05 40.000");
        r.clear();
        r.push_error(Error::UnknownParam);
        assert_eq!(r.as_str(), Error::UnknownParam.to_string());
    }
}
