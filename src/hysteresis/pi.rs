//! Prandtl-Ishlinskii models of 001: PI (eq. 4-5), PPI (eq. 6-7), DPI (eq. 8-10).
//!
//! The backlash (play) operator is exact for any sample rate: between two samples the input
//! moves monotonically (first-order hold), and a monotone segment leaves the operator at
//! `max(u - r, min(u + r, previous))` whatever its duration.

use super::{ensure, ensure_finite, sane_input, Hysteresis, ParamError};
use crate::real::Real;

/// Backlash operator `H_r` (001 eq. 5): `max(u - r, min(u + r, prev))`.
#[inline(always)]
pub fn backlash<T: Real>(u: T, r: T, prev: T) -> T {
    (u + r).min(prev).max(u - r)
}

/// State of an `N`-operator PI bank.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PiState<T, const N: usize> {
    /// Last input (V).
    pub u: T,
    /// Backlash operator outputs `H_ri` (V).
    pub ops: [T; N],
}

/// Checks thresholds `0 < r_1 < r_2 < ... < r_N` and finite weights.
fn check_bank<T: Real>(w: &[T], r: &[T], who: &'static str) -> Result<(), ParamError> {
    ensure_finite(w, who)?;
    ensure_finite(r, who)?;
    ensure(
        r.first().is_none_or(|&r0| r0 > T::ZERO),
        "PI: thresholds r_i > 0",
    )?;
    ensure(
        r.windows(2).all(|p| p[0] < p[1]),
        "PI: thresholds r_i strictly increasing",
    )
}

/// Prandtl-Ishlinskii with backlash operators (001 eq. 4-5):
/// `y = w0*u + sum_i w_i*H_ri[u]`.
///
/// Accepted when every value is finite and `0 < r_1 < ... < r_N`. (Weights may have any
/// sign; an inverse needs `w0 + sum w_i > 0` and positive partial sums, which the inverse
/// checks.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pi<T, const N: usize> {
    w0: T,
    w: [T; N],
    r: [T; N],
}

impl<T: Real, const N: usize> Pi<T, N> {
    /// `w0` linear weight, `w` operator weights, `r` thresholds (V).
    pub fn new(w0: T, w: [T; N], r: [T; N]) -> Result<Self, ParamError> {
        ensure(w0.is_finite(), "PI: weights and thresholds must be finite")?;
        check_bank(&w, &r, "PI: weights and thresholds must be finite")?;
        Ok(Self { w0, w, r })
    }

    pub fn w0(&self) -> T {
        self.w0
    }
    pub fn weights(&self) -> &[T; N] {
        &self.w
    }
    pub fn thresholds(&self) -> &[T; N] {
        &self.r
    }

    /// Operator outputs after moving to `u` (exact for a monotone segment).
    #[inline]
    pub fn advance_ops(&self, ops: &mut [T; N], u: T) {
        for (h, &r) in ops.iter_mut().zip(self.r.iter()) {
            *h = backlash(u, r, *h);
        }
    }

    /// `sum_i w_i*H_ri` without the linear term.
    #[inline]
    pub fn weighted_sum(&self, ops: &[T; N]) -> T {
        self.w
            .iter()
            .zip(ops.iter())
            .fold(T::ZERO, |acc, (&w, &h)| acc + w * h)
    }

    /// `dy/du` in direction `s = sgn(du)` at the operator state `ops` and input `u`: `w0`
    /// plus the weights of the operators that are being dragged.
    #[inline]
    pub fn slope(&self, ops: &[T; N], u: T, s: T) -> T {
        let mut k = self.w0;
        for ((&w, &r), &h) in self.w.iter().zip(self.r.iter()).zip(ops.iter()) {
            // Dragged when on the edge of its play band in the direction of motion.
            if (s > T::ZERO && h <= u - r) || (s < T::ZERO && h >= u + r) {
                k += w;
            }
        }
        k
    }
}

impl<T: Real, const N: usize> Hysteresis<T> for Pi<T, N> {
    type State = PiState<T, N>;

    /// Operators centred on `u0` (no stored play).
    fn init(&self, u0: T) -> PiState<T, N> {
        let u = sane_input(u0, T::ZERO);
        PiState { u, ops: [u; N] }
    }

    #[inline]
    fn step(&self, s: &mut PiState<T, N>, u: T, _dt: T) -> T {
        let u = sane_input(u, s.u);
        self.advance_ops(&mut s.ops, u);
        s.u = u;
        self.w0 * u + self.weighted_sum(&s.ops)
    }
}

/// [`Hysteresis`] for a model built on its PI part `pi`: the PI's state, and its output
/// mapped by `|model, state, y_pi| output`.
macro_rules! on_pi {
    ($model:ty, [$($g:tt)*], |$m:ident, $s:ident, $y:ident| $out:expr) => {
        impl<T: Real, $($g)*> Hysteresis<T> for $model {
            type State = PiState<T, N>;

            fn init(&self, u0: T) -> PiState<T, N> {
                self.pi.init(u0)
            }

            #[inline]
            fn step(&self, $s: &mut PiState<T, N>, u: T, dt: T) -> T {
                let $y = self.pi.step($s, u, dt);
                let $m = self;
                $out
            }
        }
    };
}

/// PI with a cubic polynomial (001 eq. 6-7): `y = c1*u^3 + c2*u + sum_i w_i*H_ri[u]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ppi<T, const N: usize> {
    c1: T,
    /// The PI bank with `w0 = c2`.
    pi: Pi<T, N>,
}

impl<T: Real, const N: usize> Ppi<T, N> {
    /// `c1` cubic weight (um/V^3), `c2` linear weight (um/V), operator weights and
    /// thresholds as in [`Pi::new`].
    pub fn new(c1: T, c2: T, w: [T; N], r: [T; N]) -> Result<Self, ParamError> {
        ensure(
            c1.is_finite() && c2.is_finite(),
            "PPI: c1 and c2 must be finite",
        )?;
        Ok(Self {
            c1,
            pi: Pi::new(c2, w, r)?,
        })
    }

    pub fn c1(&self) -> T {
        self.c1
    }
    pub fn c2(&self) -> T {
        self.pi.w0
    }
    /// The backlash bank (its `w0` is `c2`).
    pub fn pi(&self) -> &Pi<T, N> {
        &self.pi
    }

    /// `dy/du` in direction `s` at state `ops` and input `u`.
    #[inline]
    pub fn slope(&self, ops: &[T; N], u: T, s: T) -> T {
        T::from_f64(3.0) * self.c1 * u * u + self.pi.slope(ops, u, s)
    }
}

on_pi!(Ppi<T, N>, [const N: usize], |m, s, y| y + m.c1 * s.u * s.u * s.u);

/// One-sided dead-zone operator `S_d` (001 eq. 8): `max(y - d, 0)` for `d > 0`, `y` for
/// `d = 0`.
#[inline(always)]
pub fn dead_zone<T: Real>(y: T, d: T) -> T {
    if d > T::ZERO {
        (y - d).max(T::ZERO)
    } else {
        y
    }
}

/// PI cascaded with one-sided dead-zone operators (001 eq. 8-10):
/// `y = sum_k ws_k*S_dk[sum_i w_i*H_ri[u]]`.
///
/// Accepted when every value is finite, `0 < r_1 < ... < r_N` and
/// `0 <= d_1 < d_2 < ... < d_M`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dpi<T, const N: usize, const M: usize> {
    /// Backlash bank with `w0 = 0` (eq. 10 has no linear term).
    pi: Pi<T, N>,
    ws: [T; M],
    d: [T; M],
}

impl<T: Real, const N: usize, const M: usize> Dpi<T, N, M> {
    /// Operator weights `w` and thresholds `r` (V), dead-zone weights `ws` and thresholds
    /// `d` (in units of the PI output).
    pub fn new(w: [T; N], r: [T; N], ws: [T; M], d: [T; M]) -> Result<Self, ParamError> {
        ensure_finite(&ws, "DPI: dead-zone weights and thresholds must be finite")?;
        ensure_finite(&d, "DPI: dead-zone weights and thresholds must be finite")?;
        ensure(
            d.iter().all(|&d| d >= T::ZERO),
            "DPI: dead-zone thresholds d_k >= 0",
        )?;
        ensure(
            d.windows(2).all(|p| p[0] < p[1]),
            "DPI: dead-zone thresholds d_k strictly increasing",
        )?;
        Ok(Self {
            pi: Pi::new(T::ZERO, w, r)?,
            ws,
            d,
        })
    }

    /// The backlash bank (`w0 = 0`).
    pub fn pi(&self) -> &Pi<T, N> {
        &self.pi
    }
    pub fn dead_zone_weights(&self) -> &[T; M] {
        &self.ws
    }
    pub fn dead_zone_thresholds(&self) -> &[T; M] {
        &self.d
    }

    /// The dead-zone cascade `z = sum_k ws_k*S_dk[p]` (001 eq. 9) of a PI output `p`.
    #[inline]
    pub fn dead_zones(&self, p: T) -> T {
        self.ws
            .iter()
            .zip(self.d.iter())
            .fold(T::ZERO, |acc, (&w, &d)| acc + w * dead_zone(p, d))
    }

    /// `dz/dp` of the dead-zone cascade at `p` in direction `s` (right or left derivative).
    #[inline]
    pub fn dead_zone_slope(&self, p: T, s: T) -> T {
        let mut k = T::ZERO;
        for (&w, &d) in self.ws.iter().zip(self.d.iter()) {
            let active = d == T::ZERO || p > d || (p == d && s > T::ZERO);
            if active {
                k += w;
            }
        }
        k
    }
}

on_pi!(Dpi<T, N, M>, [const N: usize, const M: usize], |m, _s, p| m.dead_zones(p));

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::assert_refused;

    #[test]
    fn rejects_bad_thresholds() {
        assert_refused(
            Pi::new(1.0, [0.2, 0.3], [0.0, 1.0]),
            "PI: thresholds r_i > 0",
        );
        assert_refused(
            Pi::new(1.0, [0.2, 0.3], [2.0, 1.0]),
            "PI: thresholds r_i strictly increasing",
        );
        assert!(Pi::new(f64::NAN, [0.2], [1.0]).is_err());
        assert_eq!(
            Dpi::new([0.2], [1.0], [1.0, 0.5], [0.0, -1.0])
                .unwrap_err()
                .0,
            "DPI: dead-zone thresholds d_k >= 0"
        );
        assert!(Ppi::new(f64::INFINITY, 1.0, [0.2], [1.0]).is_err());
    }

    #[test]
    fn backlash_follows_its_play_band() {
        assert_eq!(backlash(5.0, 1.0, 0.0), 4.0);
        assert_eq!(backlash(4.5, 1.0, 4.0), 4.0);
        assert_eq!(backlash(2.0, 1.0, 4.0), 3.0);
    }

    #[test]
    fn slope_matches_finite_difference() {
        let m = Pi::new(0.5, [0.3, 0.2, 0.1], [1.0, 2.0, 4.0]).unwrap();
        let mut s = m.init(0.0);
        for &u in &[3.0, 1.0, 2.5, -1.0, 0.7] {
            m.step(&mut s, u, 1e-3);
        }
        for &dir in &[1.0, -1.0] {
            let mut t = s;
            let y0 = m.weighted_sum(&t.ops) + m.w0() * t.u;
            let y1 = m.step(&mut t, s.u + dir * 1e-6, 1e-3);
            let fd = (y1 - y0) / (dir * 1e-6);
            assert!((fd - m.slope(&s.ops, s.u, dir)).abs() < 1e-6, "{dir}");
        }
    }

    #[test]
    fn dead_zone_cascade() {
        let m = Dpi::new([1.0], [0.5], [1.0, 0.5], [0.0, 1.0]).unwrap();
        // p = 2 -> 1*2 + 0.5*(2-1) = 2.5
        assert_eq!(m.dead_zones(2.0), 2.5);
        assert_eq!(m.dead_zones(0.5), 0.5);
        assert_eq!(m.dead_zone_slope(2.0, 1.0), 1.5);
        assert_eq!(m.dead_zone_slope(0.5, 1.0), 1.0);
    }

    #[test]
    fn nan_input_holds_state() {
        let m = Ppi::new(1e-4, 0.5, [0.3, 0.2], [1.0, 2.0]).unwrap();
        let mut s = m.init(0.0);
        m.step(&mut s, 3.0, 1e-3);
        let before = s;
        assert!(m.step(&mut s, f64::NAN, 1e-3).is_finite());
        assert_eq!(s, before);
    }
}
