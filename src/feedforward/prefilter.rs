//! The full-pass prefilter of 004 eq. (28), and its critically damped generalisation to
//! order `q`, for inverse dynamics that need a smoother start.
//!
//! Eq. (28) passes the reference unchanged (transfer function one) but starts it where the
//! stage is: `y_d = y_r + e` with the homogeneous error dynamics
//! `(D + wn)^2 e = 0` (`zeta = 1`), `e(0) = y_start - y_r(0)`, `e'(0) = -y_r'(0)`, so `y_d`
//! starts at rest at `y_start` and joins `y_r` without overshoot. The inverse of eq. (27)
//! differentiates `y_d` up to the model's relative degree; at order two `y_d''` jumps at the
//! start, which a fourth-order inverse (004's `n = 4`) turns into a burst of input. Order
//! `q` uses `(D + wn)^q e = 0` with `e'' (0) = -y_r''(0)` and the higher derivatives zero,
//! so `y_d` starts with zero derivatives up to the third (order 2 is eq. 28 itself).
//!
//! Exact discretisation in the scaled Jordan coordinates `s_i = (D + wn)^i e / wn^i`:
//! `s' = wn (N - I) s` (`N` the shift), so one sample is
//! `s_i <- e^(-x) sum_k x^k/k! s_(i+k)`, `x = wn*dt`, with every entry of order one
//! (the fixed-point `Real` keeps its digits).

use super::{ensure, FfError};
use crate::real::Real;
use crate::signals::Setpoint;

/// Highest prefilter order.
pub const MAX_PREFILTER_ORDER: usize = 6;

/// The full-pass prefilter (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FullPass<T> {
    wn: T,
    order: usize,
    /// `e^(-x) x^k / k!`, `k = 0..order`.
    c: [T; MAX_PREFILTER_ORDER],
    s: [T; MAX_PREFILTER_ORDER],
    armed: bool,
    y_start: T,
}

impl<T: Real> FullPass<T> {
    /// 004 eq. (28): order 2, `zeta = 1`, natural frequency `wn` (rad/s), sample period
    /// `dt_s`.
    pub fn eq28(wn: T, dt_s: T) -> Result<Self, FfError> {
        Self::new(wn, 2, dt_s)
    }

    /// Order `q` in `2..=MAX_PREFILTER_ORDER`.
    pub fn new(wn: T, order: usize, dt_s: T) -> Result<Self, FfError> {
        ensure(
            wn.is_finite() && wn > T::ZERO,
            "prefilter: wn finite and > 0 (004 eq. 28)",
        )?;
        super::check_dt(dt_s)?;
        ensure(
            (2..=MAX_PREFILTER_ORDER).contains(&order),
            "prefilter: order 2 ..= MAX_PREFILTER_ORDER",
        )?;
        let x = wn.to_f64() * dt_s.to_f64();
        let mut c = [T::ZERO; MAX_PREFILTER_ORDER];
        let mut term = libm::exp(-x);
        for (k, ck) in c.iter_mut().enumerate().take(order) {
            *ck = T::from_f64(term);
            term *= x / (k + 1) as f64;
        }
        Ok(Self {
            wn,
            order,
            c,
            s: [T::ZERO; MAX_PREFILTER_ORDER],
            armed: false,
            y_start: T::ZERO,
        })
    }

    pub fn order(&self) -> usize {
        self.order
    }

    /// Start again from the output `y_start` at the next setpoint.
    pub fn restart(&mut self, y_start: T) {
        self.armed = false;
        self.y_start = if y_start.is_finite() {
            y_start
        } else {
            T::ZERO
        };
        self.s = [T::ZERO; MAX_PREFILTER_ORDER];
    }

    /// `(y_d, y_d', y_d'')` for the setpoint (`y_r` finite; non-finite derivatives count as
    /// zero).
    #[inline]
    pub fn apply(&mut self, sp: &Setpoint<T>) -> (T, T, T) {
        let fin = |x: T| if x.is_finite() { x } else { T::ZERO };
        let (y_r, dy_r, ddy_r) = (sp.y_um, fin(sp.dy), fin(sp.ddy));
        let q = self.order.min(MAX_PREFILTER_ORDER);
        if !self.armed {
            // e, e', e'' at the start (004 eq. 28: e' = -y_r'; order >= 3 also e'' = -y_r'').
            let e = [
                self.y_start - y_r,
                -dy_r / self.wn,
                if q >= 3 {
                    -ddy_r / (self.wn * self.wn)
                } else {
                    T::ZERO
                },
            ];
            // s_i = sum_j C(i, j) e^(j) / wn^j (derivatives beyond the second are zero).
            // Iterators, not indices: the control path has no bounds-check panic.
            for (i, s) in self.s.iter_mut().enumerate().take(q) {
                let mut acc = e[0];
                if i >= 1 {
                    acc += T::from_usize(i) * e[1];
                }
                if i >= 2 {
                    acc += T::from_usize(i * (i - 1) / 2) * e[2];
                }
                *s = acc;
            }
            self.armed = true;
        } else {
            // In place: s_i reads s_i.. s_q-1, none of them written yet.
            for i in 0..q {
                let acc = self
                    .c
                    .iter()
                    .zip(self.s.iter().skip(i))
                    .take(q - i)
                    .fold(T::ZERO, |acc, (&c, &s)| acc + c * s);
                if let Some(s) = self.s.get_mut(i) {
                    *s = acc;
                }
            }
        }
        let (s0, s1, s2) = (self.s[0], self.s[1], self.s[2]);
        let e1 = self.wn * (s1 - s0);
        let e2 = self.wn * self.wn * (s2 - T::TWO * s1 + s0);
        (y_r + s0, dy_r + e1, ddy_r + e2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_two_is_eq28_exactly() {
        // Resting stage at 0, reference at 1 with slope 2 and curvature 5: e(t) is the
        // critically damped solution with e(0) = -1, e'(0) = -2.
        let (wn, dt) = (300.0, 1e-4);
        let mut f = FullPass::<f64>::eq28(wn, dt).unwrap();
        f.restart(0.0);
        let mut worst = 0.0f64;
        for k in 0..400 {
            let t = k as f64 * dt;
            let sp = Setpoint {
                y_um: 1.0 + 2.0 * t,
                dy: 2.0,
                ddy: 0.0,
            };
            let (yd, dyd, _) = f.apply(&sp);
            let e = (-1.0 + (-wn - 2.0) * t) * (-wn * t).exp();
            let de = (-2.0 + wn * (wn + 2.0) * t) * (-wn * t).exp();
            worst = worst
                .max((yd - sp.y_um - e).abs())
                .max(1e-3 * (dyd - 2.0 - de).abs());
        }
        assert!(worst < 1e-12, "{worst}");
    }

    #[test]
    fn higher_order_starts_smoother_and_never_overshoots() {
        let (wn, dt) = (100.0 * core::f64::consts::PI, 1e-4);
        for q in 2..=MAX_PREFILTER_ORDER {
            let mut f = FullPass::<f64>::new(wn, q, dt).unwrap();
            f.restart(0.0);
            let (mut prev, mut d2_first) = (0.0, 0.0);
            for k in 0..2000 {
                let (yd, _, ddyd) = f.apply(&Setpoint::hold(1.0));
                // Monotone from 0 to 1 (critically damped, no overshoot).
                assert!(yd >= prev - 1e-12 && yd <= 1.0 + 1e-12, "q {q}, {k}: {yd}");
                prev = yd;
                if k == 0 {
                    d2_first = ddyd;
                }
            }
            assert!((prev - 1.0).abs() < 1e-6, "q {q}: {prev}");
            // Order 2 starts with a jump of wn^2 in y_d''; higher orders at zero.
            if q == 2 {
                assert!((d2_first - wn * wn).abs() < 1e-6 * wn * wn, "{d2_first}");
            } else {
                assert!(d2_first.abs() < 1e-9 * wn * wn, "q {q}: {d2_first}");
            }
        }
        assert!(FullPass::<f64>::new(1.0, 7, 1e-3).is_err());
        assert!(FullPass::<f64>::new(-1.0, 2, 1e-3).is_err());
    }
}
