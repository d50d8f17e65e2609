//! Dahl model in piezo form.

use super::{ensure, ensure_finite, BwState, Hysteresis, ParamError};
use crate::real::Real;

/// Dahl hysteresis, piezo form `y = d*u - h` (000 eq. 2 structure) with
/// `dh/dt = sigma0*du/dt*(1 - h/hc*sgn(du/dt))^i` (000 eq. 4).
///
/// Exact input-domain update for any `i`: with `x = 1 - s*h/hc` (`s = sgn(du)`),
/// `dx/d|u| = -(sigma0/hc)*x^i`, so
/// * `i = 1`: `x1 = x0*exp(-sigma0/hc*|du|)`,
/// * `i != 1`: `x1^(1-i) = x0^(1-i) + (i-1)*sigma0/hc*|du|` (for `i < 1`, `x` reaches 0
///   after a finite input travel and stays there).
///
/// `x` only decays toward 0 and starts in `[0, 2]` when `|h| <= hc`, so `|h| <= hc` always.
///
/// Accepted when `sigma0 > 0`, `hc > 0`, `i > 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dahl<T> {
    d: T,
    sigma0: T,
    hc: T,
    i: T,
}

impl<T: Real> Dahl<T> {
    /// `d` piezo coefficient (um/V), `sigma0` initial stiffness (um/V), `hc` saturation of
    /// `h` (um), `i` shape exponent.
    pub fn new(d: T, sigma0: T, hc: T, i: T) -> Result<Self, ParamError> {
        ensure_finite(&[d, sigma0, hc, i], "Dahl: all parameters must be finite")?;
        ensure(sigma0 > T::ZERO, "Dahl: sigma0 > 0")?;
        ensure(hc > T::ZERO, "Dahl: hc > 0")?;
        ensure(i > T::ZERO, "Dahl: i > 0")?;
        ensure((sigma0 / hc).is_finite(), "Dahl: sigma0/hc out of range")?;
        Ok(Self { d, sigma0, hc, i })
    }

    super::getters!(d, sigma0, hc, i);

    /// `dh/du` at state `h` for input direction `s = sgn(du/dt)`.
    #[inline]
    pub fn slope(&self, h: T, s: T) -> T {
        let x = (T::ONE - s * h / self.hc).clamp_to(T::ZERO, T::TWO);
        self.sigma0 * x.abs_pow(self.i)
    }

    /// Exact input-domain update of `h` over `du`.
    #[inline]
    pub fn advance_h(&self, h: T, du: T) -> T {
        let s = du.sgn();
        if s == T::ZERO {
            return h;
        }
        let c = self.sigma0 / self.hc * du.abs();
        let x0 = (T::ONE - s * h / self.hc).clamp_to(T::ZERO, T::TWO);
        let x1 = if self.i == T::ONE {
            x0 * (-c).exp()
        } else if x0 == T::ZERO {
            T::ZERO
        } else {
            let e = T::ONE - self.i;
            let base = x0.powf(e) - e * c;
            if base > T::ZERO {
                base.powf(T::ONE / e)
            } else {
                T::ZERO // i < 1: reached saturation within the step
            }
        };
        let x1 = x1.clamp_to(T::ZERO, x0);
        s * self.hc * (T::ONE - x1)
    }
}

super::piezo_form!(Dahl<T>, |m, h, _, du, _dt| m.advance_h(h, du));

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::{along_sine, assert_refused, rk4_input};

    #[test]
    fn rejects_bad_parameters() {
        assert_refused(Dahl::new(0.16, 0.07, 0.0, 1.0), "Dahl: hc > 0");
        assert_refused(Dahl::new(0.16, 0.07, 2.0, -1.0), "Dahl: i > 0");
        assert!(Dahl::new(0.16, f64::NAN, 2.0, 1.0).is_err());
    }

    #[test]
    fn exact_update_equals_fine_rk4_for_several_exponents() {
        for &i in &[0.5, 1.0, 1.7, 3.0] {
            let m = Dahl::new(0.16, 0.3, 2.0, i).unwrap();
            let (h, h_ref) = along_sine(
                30.0,
                0.01,
                1500,
                |h, _, du| m.advance_h(h, du),
                |h, u, du| rk4_input(h, u, du, 1e-3, |h, _| m.slope(h, du.signum())),
            );
            assert!((h - h_ref).abs() < 1e-6, "i = {i}: {h} vs {h_ref}");
        }
    }

    #[test]
    fn saturates_at_hc() {
        let m = Dahl::new(0.16, 0.3, 2.0, 0.5).unwrap();
        let mut s = m.init(0.0);
        m.step(&mut s, 1000.0, 1.0);
        assert_eq!(s.h, 2.0);
        m.step(&mut s, -1000.0, 1.0);
        assert_eq!(s.h, -2.0);
    }

    #[test]
    fn nan_input_holds_state() {
        let m = Dahl::new(0.16, 0.3, 2.0, 2.0).unwrap();
        let mut s = m.init(0.0);
        m.step(&mut s, 5.0, 1e-3);
        let before = s;
        assert!(m.step(&mut s, f64::NAN, 1e-3).is_finite());
        assert_eq!(s, before);
    }
}
