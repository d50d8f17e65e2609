//! Polynomials of the linear dynamics: roots (Aberth-Ehrlich iteration) and the factoring
//! of 004 eq. (8), `sum a_i s^i y = sum b_j s^j v`, into unity-DC-gain sections.
//!
//! Construction-time f64 on fixed arrays (no allocation): the core has no allocator and
//! runs this on the target when a model arrives over serial, so no crate with `Vec`
//! polynomials fits.

// Index loops over coefficient arrays read clearer here.
#![allow(clippy::needless_range_loop)]

use super::{Section, MAX_SECTIONS};
use crate::hysteresis::{ensure, ParamError};

/// Largest polynomial degree handled (two per section).
pub const MAX_DEGREE: usize = 2 * MAX_SECTIONS;

/// A complex number (construction-time arithmetic only).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Complex {
    pub re: f64,
    pub im: f64,
}

impl Complex {
    pub const fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }
    pub fn abs(self) -> f64 {
        libm::hypot(self.re, self.im)
    }
    pub fn conj(self) -> Self {
        Self::new(self.re, -self.im)
    }
    /// `e^self`.
    pub fn exp(self) -> Self {
        let m = libm::exp(self.re);
        Self::new(m * libm::cos(self.im), m * libm::sin(self.im))
    }
}

impl core::ops::Add for Complex {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self::new(self.re + o.re, self.im + o.im)
    }
}

impl core::ops::Sub for Complex {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self::new(self.re - o.re, self.im - o.im)
    }
}

impl core::ops::Mul for Complex {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        Self::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
}

impl core::ops::Div for Complex {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let n = o.re * o.re + o.im * o.im;
        Self::new(
            (self.re * o.re + self.im * o.im) / n,
            (self.im * o.re - self.re * o.im) / n,
        )
    }
}

impl From<f64> for Complex {
    fn from(re: f64) -> Self {
        Self::new(re, 0.0)
    }
}

/// `p(x)` and `p'(x)` for ascending real coefficients `c[..=deg]` (Horner).
fn eval(c: &[f64], x: Complex) -> (Complex, Complex) {
    let mut p = Complex::default();
    let mut dp = Complex::default();
    for &ci in c.iter().rev() {
        dp = dp * x + p;
        p = p * x + Complex::from(ci);
    }
    (p, dp)
}

/// The roots of `sum c[i] x^i` (real, ascending, `c[deg] != 0`, `deg = c.len() - 1 <=
/// MAX_DEGREE`) into `out[..deg]`, by the Aberth-Ehrlich simultaneous iteration (cubic
/// convergence, at most 200 sweeps) started on a circle of the Cauchy-bound radius.
/// Conjugate pairs are made exactly conjugate and real roots exactly real. Returns `deg`.
pub fn roots(c: &[f64], out: &mut [Complex; MAX_DEGREE]) -> Result<usize, ParamError> {
    ensure(
        !c.is_empty() && c.len() <= MAX_DEGREE + 1,
        "linear: polynomial degree 0..=2*MAX_SECTIONS",
    )?;
    ensure(
        c.iter().all(|v| v.is_finite()),
        "linear: polynomial coefficients must be finite",
    )?;
    let deg = c.len() - 1;
    ensure(
        c[deg] != 0.0,
        "linear: leading coefficient must be non-zero",
    )?;
    if deg == 0 {
        return Ok(0);
    }
    // Cauchy bound 1 + max |c_i / c_deg|; a start off the axes breaks symmetry.
    let lead = c[deg];
    let radius = 1.0
        + c[..deg]
            .iter()
            .fold(0.0f64, |m, v| m.max(libm::fabs(v / lead)));
    // Start near the geometric mean of the roots' magnitudes, not the bound: roots of
    // 004's denominator span four decades.
    let g = libm::pow(libm::fabs(c[0] / lead), 1.0 / deg as f64);
    let r0 = if g > 0.0 && g.is_finite() { g } else { radius };
    for k in 0..deg {
        let th = 2.0 * core::f64::consts::PI * (k as f64 + 0.25) / deg as f64 + 0.4;
        out[k] = Complex::new(r0 * libm::cos(th), r0 * libm::sin(th));
    }
    for _ in 0..200 {
        let mut moved = 0.0f64;
        for k in 0..deg {
            let (p, dp) = eval(c, out[k]);
            if p.abs() == 0.0 {
                continue;
            }
            let ratio = p / dp;
            let mut sum = Complex::default();
            for j in 0..deg {
                if j != k {
                    let d = out[k] - out[j];
                    if d.abs() > 0.0 {
                        sum = sum + Complex::from(1.0) / d;
                    }
                }
            }
            let denom = Complex::from(1.0) - ratio * sum;
            let step = if denom.abs() > 0.0 {
                ratio / denom
            } else {
                ratio
            };
            if step.re.is_finite() && step.im.is_finite() {
                out[k] = out[k] - step;
                moved = moved.max(step.abs() / out[k].abs().max(f64::MIN_POSITIVE));
            }
        }
        if moved < 1e-15 {
            break;
        }
    }
    ensure(
        out[..deg]
            .iter()
            .all(|z| z.re.is_finite() && z.im.is_finite()),
        "linear: root finding failed",
    )?;
    // Real coefficients: clean near-real roots and pair conjugates exactly.
    for k in 0..deg {
        if libm::fabs(out[k].im) <= 1e-9 * out[k].abs() {
            out[k].im = 0.0;
        }
    }
    for k in 0..deg {
        if out[k].im > 0.0 {
            // The closest root to the conjugate becomes exactly the conjugate.
            let want = out[k].conj();
            let mut best = None;
            let mut dist = f64::INFINITY;
            for j in 0..deg {
                if j != k && out[j].im < 0.0 {
                    let d = (out[j] - want).abs();
                    if d < dist {
                        dist = d;
                        best = Some(j);
                    }
                }
            }
            let j = best.ok_or(ParamError("linear: complex root without conjugate"))?;
            let mid = Complex::new(0.5 * (out[k].re + out[j].re), 0.5 * (out[k].im - out[j].im));
            out[k] = mid;
            out[j] = mid.conj();
        }
    }
    Ok(deg)
}

/// Leading and trailing zero coefficients trimmed: `(first non-zero index, last + 1)`.
fn trim(c: &[f64]) -> (usize, usize) {
    let end = c.iter().rposition(|v| *v != 0.0).map_or(0, |i| i + 1);
    let start = c.iter().position(|v| *v != 0.0).unwrap_or(0);
    (start, end)
}

/// Roots split into conjugate pairs (upper member kept) and real roots.
struct Split {
    pairs: [Complex; MAX_SECTIONS],
    np: usize,
    reals: [f64; MAX_DEGREE],
    nr: usize,
}

fn split(r: &[Complex]) -> Split {
    let mut s = Split {
        pairs: [Complex::default(); MAX_SECTIONS],
        np: 0,
        reals: [0.0; MAX_DEGREE],
        nr: 0,
    };
    for z in r {
        if z.im > 0.0 {
            s.pairs[s.np] = *z;
            s.np += 1;
        } else if z.im == 0.0 {
            s.reals[s.nr] = z.re;
            s.nr += 1;
        }
    }
    // Real roots by magnitude, so the two paired in one section are neighbours.
    s.reals[..s.nr].sort_unstable_by(|a, b| libm::fabs(*a).total_cmp(&libm::fabs(*b)));
    s
}

/// Normalised quadratic `1 + c1 s + c2 s^2` with roots `r1, r2` (`r1*r2 != 0`).
fn quad_from_reals(r1: f64, r2: f64) -> [f64; 2] {
    [-(r1 + r2) / (r1 * r2), 1.0 / (r1 * r2)]
}

fn quad_from_pair(z: Complex) -> [f64; 2] {
    let m2 = z.re * z.re + z.im * z.im;
    [-2.0 * z.re / m2, 1.0 / m2]
}

/// Factors `sum b_j s^j / sum a_i s^i` (ascending coefficients) into unity-DC-gain
/// sections: each complex pole pair, or two real poles, makes a second-order section, an
/// odd real pole a first-order one; complex zero pairs go to second-order sections first,
/// real zeros fill the rest. Returns `(b_0/a_0, sections, count)`, `count = ceil(n/2)`.
///
/// Refused: unstable or marginal poles (`Re p >= 0`), zeros or poles at `s = 0`
/// (`a_0` or `b_0` zero: no finite non-zero DC gain), improper (`m > n`).
pub fn sections(b: &[f64], a: &[f64]) -> Result<(f64, [Section; MAX_SECTIONS], usize), ParamError> {
    let (a0, an) = trim(a);
    let (b0, bm) = trim(b);
    ensure(an > 0 && bm > 0, "linear: a and b must not be all zero")?;
    ensure(
        a0 == 0 && b0 == 0,
        "linear: a_0 and b_0 must be non-zero (no pole or zero at s = 0)",
    )?;
    let (n, m) = (an - 1, bm - 1);
    ensure(n >= 1, "linear: at least one pole (n >= 1)")?;
    ensure(m <= n, "linear: improper transfer function (m > n)")?;
    ensure(n <= MAX_DEGREE, "linear: order n at most 2*MAX_SECTIONS")?;
    let gain = b[0] / a[0];
    ensure(gain.is_finite(), "linear: DC gain b_0/a_0 must be finite")?;
    let mut pr = [Complex::default(); MAX_DEGREE];
    let mut zr = [Complex::default(); MAX_DEGREE];
    roots(&a[..an], &mut pr)?;
    roots(&b[..bm], &mut zr)?;
    ensure(
        pr[..n].iter().all(|p| p.re < 0.0),
        "linear: poles must be stable (Re p < 0)",
    )?;
    let poles = split(&pr[..n]);
    let zeros = split(&zr[..m]);
    // Pole polynomials per section: [p1, p2] of 1 + p1 s + p2 s^2.
    let mut den = [[0.0f64; 2]; MAX_SECTIONS];
    let mut cnt = 0;
    for z in &poles.pairs[..poles.np] {
        den[cnt] = quad_from_pair(*z);
        cnt += 1;
    }
    let mut k = 0;
    while k + 1 < poles.nr {
        den[cnt] = quad_from_reals(poles.reals[k], poles.reals[k + 1]);
        cnt += 1;
        k += 2;
    }
    if k < poles.nr {
        den[cnt] = [-1.0 / poles.reals[k], 0.0];
        cnt += 1;
    }
    // Zeros: pairs into second-order sections, then reals one by one into free room.
    let mut num = [[0.0f64; 2]; MAX_SECTIONS];
    let mut room = [0usize; MAX_SECTIONS];
    for (r, d) in room.iter_mut().zip(&den[..cnt]) {
        *r = if d[1] > 0.0 { 2 } else { 1 };
    }
    for z in &zeros.pairs[..zeros.np] {
        let i = (0..cnt).find(|&i| room[i] == 2).ok_or(ParamError(
            "linear: more zero pairs than second-order sections",
        ))?;
        num[i] = quad_from_pair(*z);
        room[i] = 0;
    }
    for &r in &zeros.reals[..zeros.nr] {
        let i = (0..cnt)
            .find(|&i| room[i] > 0)
            .ok_or(ParamError("linear: no room for a real zero"))?;
        // Multiply the section's numerator by (1 - s/r).
        let q = num[i];
        num[i] = [q[0] - 1.0 / r, q[1] - q[0] / r];
        room[i] -= 1;
    }
    let mut out = [Section::First { w: 1.0, wz: None }; MAX_SECTIONS];
    for i in 0..cnt {
        out[i] = Section::Quadratic {
            q: num[i],
            p: den[i],
        };
    }
    Ok((gain, out, cnt))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_the_seed_004_polynomials() {
        // 004 sec. 4.2: a_4..a_0 and b_2..b_0, ascending here.
        let a = [5.421e12, 1.183e10, 1.046e7, 8.753e3, 1.0];
        let b = [5.421e12, -4.002e8, 4.083e6];
        let mut r = [Complex::default(); MAX_DEGREE];
        assert_eq!(roots(&a, &mut r).unwrap(), 4);
        for z in &r[..4] {
            let (p, _) = eval(&a, *z);
            assert!(p.abs() < 1e-9 * 5.421e12, "{z:?}: {p:?}");
            assert!(z.re < 0.0);
        }
        assert_eq!(roots(&b, &mut r).unwrap(), 2);
        // The non-minimum-phase pair: Re z = 4.002e8 / (2 * 4.083e6) = 49.0 rad/s.
        assert!((r[0].re - 49.008).abs() < 1e-3, "{r:?}");
        assert_eq!(r[0].im, -r[1].im);
        assert!((r[0].abs() - (5.421e12f64 / 4.083e6).sqrt()).abs() < 1e-6 * r[0].abs());
    }

    #[test]
    fn sections_keep_the_transfer_function() {
        let a = [5.421e12, 1.183e10, 1.046e7, 8.753e3, 1.0];
        let b = [5.421e12, -4.002e8, 4.083e6];
        let (gain, secs, n) = sections(&b, &a).unwrap();
        assert_eq!(n, 2);
        assert!((gain - 1.0).abs() < 1e-15);
        // Product of the sections equals b(s)/a(s) * a_0/b_0 at a few frequencies.
        for w in [0.0, 100.0, 1151.0, 5000.0, 3e4] {
            let s = Complex::new(0.0, w);
            let mut h = Complex::new(1.0, 0.0);
            for sec in &secs[..n] {
                let (q, p) = super::super::normalised(sec);
                let one = Complex::from(1.0);
                let num = one + s * q[0].into() + s * s * q[1].into();
                let den = one + s * p[0].into() + s * s * p[1].into();
                h = h * (num / den);
            }
            let want = eval(&b, s).0 / eval(&a, s).0;
            assert!(
                (h - want).abs() < 1e-9 * want.abs().max(1e-6),
                "{w}: {h:?} vs {want:?}"
            );
        }
    }

    #[test]
    fn refuses_bad_transfer_functions() {
        let e = |b: &[f64], a: &[f64]| sections(b, a).unwrap_err().0;
        assert!(e(&[1.0], &[-1.0, 1.0]).contains("stable"));
        assert!(e(&[0.0, 1.0], &[1.0, 1.0]).contains("s = 0"));
        assert!(e(&[1.0, 1.0, 1.0], &[1.0, 1.0]).contains("improper"));
        assert!(e(&[1.0], &[1.0, f64::NAN]).contains("finite"));
        // Real zeros of opposite sign in one second-order section are fine.
        let (_, s, n) = sections(&[-2.0, 1.0, 1.0], &[2.0, 3.0, 1.0]).unwrap();
        assert_eq!(n, 1);
        assert!(matches!(s[0], Section::Quadratic { .. }));
    }
}
