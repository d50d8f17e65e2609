//! Classical Bouc-Wen (CBW) in piezo form.

use super::{
    ensure, ensure_finite, rk4_input, step_piecewise_affine, BwState, Hysteresis, ParamError,
};
use crate::real::Real;

/// Classical Bouc-Wen, piezo form: `y = d*u - h` (000 eq. 2, 003 eq. 2, 004 eq. 1) with
/// `dh/dt = alpha*du/dt - beta*|du/dt|*|h|^(n-1)*h - gamma*du/dt*|h|^n`
/// (000 eq. 1 with an exponent `n`; `alpha, beta, gamma` are the lecture's
/// `A_bw, B_bw, G_bw`).
///
/// Exponent form: 001 eq. (2) (and 002 eq. 2) print the `beta` term as
/// `beta*|v'|*|h|^n*h`, i.e. `|h|^(n+1)` against the `gamma` term's `|h|^n`. Their own
/// eq. (3) and 002 eq. (7) (`n = 1`: `beta*|v'|*h`) use `|h|^(n-1)*h`, the usual Bouc-Wen
/// form; that is what is implemented here, so both terms scale as `|h|^n` and `n = 1` is
/// the lecture's eq. (1). The `n` of 001's comparison (`piezo fit --model cbw-n`) is this one.
///
/// Parameters are accepted only when the loops are bounded (004 eq. 3):
/// `alpha > 0`, `beta + gamma > 0`, `beta - gamma >= 0`, and `n >= 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cbw<T> {
    d: T,
    alpha: T,
    beta: T,
    gamma: T,
    n: T,
    /// RK4 sub-step bound in the input domain (V), used only for `n != 1`.
    max_du: T,
    /// `h_bound()`, the invariant `|h|` bound; clamps RK4 when a huge input step hits the
    /// sub-step cap.
    h_max: T,
}

impl<T: Real> Cbw<T> {
    /// `d` piezo coefficient (um/V), `alpha` (um/V), `beta, gamma` (1/V for n = 1), `n`.
    pub fn new(d: T, alpha: T, beta: T, gamma: T, n: T) -> Result<Self, ParamError> {
        ensure_finite(
            &[d, alpha, beta, gamma, n],
            "CBW: all parameters must be finite",
        )?;
        ensure(alpha > T::ZERO, "CBW: alpha > 0 (004 eq. 3)")?;
        ensure(beta + gamma > T::ZERO, "CBW: beta + gamma > 0 (004 eq. 3)")?;
        ensure(
            beta - gamma >= T::ZERO,
            "CBW: beta - gamma >= 0 (004 eq. 3)",
        )?;
        ensure(n >= T::ONE, "CBW: n >= 1")?;
        let h_max = (alpha / (beta + gamma)).powf(T::ONE / n);
        let lipschitz = n * (beta + gamma.abs()) * h_max.abs_pow(n - T::ONE);
        let max_du = T::from_f64(0.1) / lipschitz;
        ensure(
            max_du.is_finite() && max_du > T::ZERO,
            "CBW: parameters out of range",
        )?;
        Ok(Self {
            d,
            alpha,
            beta,
            gamma,
            n,
            max_du,
            h_max,
        })
    }

    /// CBW with `n = 1`, the form used for piezo actuators (003, 004).
    pub fn with_n1(d: T, alpha: T, beta: T, gamma: T) -> Result<Self, ParamError> {
        Self::new(d, alpha, beta, gamma, T::ONE)
    }

    super::getters!(d, alpha, beta, gamma, n);

    /// The bound of `|h|` on the major loop: `(alpha / (beta + gamma))^(1/n)`.
    pub fn h_bound(&self) -> T {
        (self.alpha / (self.beta + self.gamma)).powf(T::ONE / self.n)
    }

    /// `dh/du` at state `h` for input direction `s = sgn(du/dt)`.
    #[inline]
    pub fn slope(&self, h: T, s: T) -> T {
        self.alpha - (self.beta * s * h.sgn() + self.gamma) * h.abs_pow(self.n)
    }

    /// Exact (n = 1) or RK4 (n != 1) input-domain update of `h` over `du`.
    #[inline]
    pub fn advance_h(&self, h: T, u0: T, du: T) -> T {
        let s = du.sgn();
        if self.n == T::ONE {
            self.advance_h_n1(h, du)
        } else {
            rk4_input(h, u0, du, self.max_du, |h, _| self.slope(h, s))
                .clamp_to(-self.h_max, self.h_max)
        }
    }
}

impl<T: Real> Cbw<T> {
    /// The exact `n = 1` update of `h` over `du` (piecewise affine in `h`).
    #[inline(always)]
    fn advance_h_n1(&self, h: T, du: T) -> T {
        let s = du.sgn();
        step_piecewise_affine(h, du, self.alpha, |sigma| {
            self.beta * s + self.gamma * sigma
        })
    }

    /// [`Hysteresis::step`] for a model with `n = 1` (the caller checks [`Self::n`]): the
    /// same result without the RK4 branch, small enough to inline (the simulated stage).
    #[inline]
    pub fn step_n1(&self, s: &mut BwState<T>, u: T) -> T {
        s.step_piezo(self.d, u, |h, _, du| self.advance_h_n1(h, du))
    }
}

super::piezo_form!(Cbw<T>, |m, h, u0, du, _dt| m.advance_h(h, u0, du));

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::{along_sine, assert_refused};

    /// Backup slide of 000, parameter set 1.
    fn set1() -> Cbw<f64> {
        Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap()
    }

    #[test]
    fn rejects_parameters_that_break_004_eq3() {
        assert_refused(
            Cbw::with_n1(0.16, 0.07, 0.01, 0.02),
            "CBW: beta - gamma >= 0 (004 eq. 3)",
        );
        assert_refused(
            Cbw::with_n1(0.16, -0.07, 0.02, 0.01),
            "CBW: alpha > 0 (004 eq. 3)",
        );
        assert!(Cbw::new(0.16, 0.07, 0.02, 0.01, 0.5).is_err());
        assert!(Cbw::with_n1(f64::NAN, 0.07, 0.02, 0.01).is_err());
    }

    #[test]
    fn closed_form_equals_fine_rk4() {
        let m = set1();
        let (h_exact, h_rk4) = along_sine(
            100.0,
            0.01,
            2000,
            |h, u, du| m.advance_h(h, u, du),
            |h, u, du| rk4_input(h, u, du, 1e-3, |h, _| m.slope(h, du.signum())),
        );
        assert!((h_exact - h_rk4).abs() < 1e-8, "{h_exact} vs {h_rk4}");
    }

    #[test]
    fn step_n1_equals_step() {
        let m = set1();
        let (mut a, mut b) = (m.init(0.0), m.init(0.0));
        for k in 0..3000 {
            let u = 80.0 * (k as f64 * 0.013).sin() + if k % 500 == 7 { f64::NAN } else { 0.0 };
            assert_eq!(
                m.step(&mut a, u, 1e-5).to_bits(),
                m.step_n1(&mut b, u).to_bits()
            );
            assert_eq!(a, b);
        }
    }

    #[test]
    fn saturates_at_h_bound() {
        let m = set1();
        let mut s = m.init(0.0);
        m.step(&mut s, 2000.0, 1.0);
        assert!((s.h - m.h_bound()).abs() < 1e-9);
    }

    #[test]
    fn nan_input_holds_state() {
        let m = set1();
        let mut s = m.init(0.0);
        m.step(&mut s, 10.0, 1e-3);
        let before = s;
        let y = m.step(&mut s, f64::NAN, 1e-3);
        assert_eq!(s, before);
        assert!(y.is_finite());
    }
}
