//! The modified Bouc-Wen of 004 in `rho, lambda, mu` (eq. 4-6) and the weighted polynomial
//! MBW (WPMBW, eq. 7).

use super::{ensure, ensure_finite, rk4_input, sane_input, Hysteresis, ParamError};
use crate::real::Real;

/// State of [`MbwRlm`] and [`Wpmbw`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RlmState<T> {
    /// Last input (V).
    pub u: T,
    /// MBW operator output `w`.
    pub w: T,
}

/// Modified Bouc-Wen of 004 eq. (6) (eq. 4 with `sgn(w') = sgn(u')`, eq. 5):
/// `dw/du = rho / (1 - s*rho*(lambda*u - mu*w))`, `s = sgn(du/dt)`; output `w`.
///
/// Counterclockwise loops iff `lambda >= rho*mu` (004 eq. 14); then `w` stays between
/// `lambda/mu*u -+ (lambda - rho*mu)/(rho*mu*lambda)` (004 eq. 16). With
/// `z = mu*w - lambda*u`, the band is invariant and the denominator `1 + s*rho*z` stays at
/// least `min(1, rho*mu/lambda)` from rest, for either orientation. It is still floored at
/// half that value so a state set from outside can never divide by ~0.
///
/// Integrated by RK4 in `u` with sub-steps no larger than `0.1/L`, `L` the Lipschitz bound
/// `rho^2*mu/den_min^2` of `dw/du` in `w`.
///
/// Accepted when `rho, lambda, mu > 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MbwRlm<T> {
    rho: T,
    lambda: T,
    mu: T,
    den_min: T,
    max_du: T,
}

impl<T: Real> MbwRlm<T> {
    pub fn new(rho: T, lambda: T, mu: T) -> Result<Self, ParamError> {
        ensure_finite(&[rho, lambda, mu], "MBW-RLM: all parameters must be finite")?;
        ensure(rho > T::ZERO, "MBW-RLM: rho > 0 (004 eq. 4)")?;
        ensure(lambda > T::ZERO, "MBW-RLM: lambda > 0 (004 eq. 4)")?;
        ensure(mu > T::ZERO, "MBW-RLM: mu > 0 (004 eq. 4)")?;
        let den_min = T::HALF * (rho * mu / lambda).min(T::ONE);
        let lipschitz = rho * rho * mu / (den_min * den_min);
        let max_du = T::from_f64(0.1) / lipschitz;
        ensure(
            den_min > T::ZERO && max_du.is_finite() && max_du > T::ZERO,
            "MBW-RLM: parameters out of range",
        )?;
        Ok(Self {
            rho,
            lambda,
            mu,
            den_min,
            max_du,
        })
    }

    pub fn rho(&self) -> T {
        self.rho
    }
    pub fn lambda(&self) -> T {
        self.lambda
    }
    pub fn mu(&self) -> T {
        self.mu
    }

    /// Counterclockwise loops (004 eq. 14: `lambda >= rho*mu`).
    pub fn counterclockwise(&self) -> bool {
        self.lambda >= self.rho * self.mu
    }

    /// Slope `k_w = lambda/mu` of the bounds of 004 eq. (16).
    pub fn k_w(&self) -> T {
        self.lambda / self.mu
    }

    /// Intercept `b_w = (lambda - rho*mu)/(rho*mu*lambda)` of 004 eq. (16).
    pub fn b_w(&self) -> T {
        (self.lambda - self.rho * self.mu) / (self.rho * self.mu * self.lambda)
    }

    /// The denominator `1 - s*rho*(lambda*u - mu*w)` of eq. (6), floored.
    #[inline]
    pub fn denominator(&self, u: T, w: T, s: T) -> T {
        (T::ONE - s * self.rho * (self.lambda * u - self.mu * w)).max(self.den_min)
    }

    /// `dw/du` of eq. (6) at input `u`, state `w`, direction `s` (`s = 0` counts as rising,
    /// as in eq. 6).
    #[inline]
    pub fn slope(&self, u: T, w: T, s: T) -> T {
        let s = if s < T::ZERO { -T::ONE } else { T::ONE };
        self.rho / self.denominator(u, w, s)
    }

    /// Update of `w` from `(u0, w)` over the input increment `du`.
    #[inline]
    pub fn advance_w(&self, w: T, u0: T, du: T) -> T {
        let s = du.sgn();
        if s == T::ZERO {
            return w;
        }
        let w1 = rk4_input(w, u0, du, self.max_du, |w, u| self.slope(u, w, s));
        // The band |mu*w - lambda*u| <= |lambda - rho*mu|/(rho*lambda) (004 eq. 16) is
        // invariant; clamping only matters when a huge step hits the sub-step cap.
        let u1 = u0 + du;
        let zb = ((self.lambda - self.rho * self.mu) / (self.rho * self.lambda)).abs();
        let z = (self.mu * w1 - self.lambda * u1).clamp_to(-zb, zb);
        if (self.mu * w - self.lambda * u0).abs() <= zb {
            (z + self.lambda * u1) / self.mu
        } else {
            w1 // started outside the band (state set from outside): no clamp
        }
    }
}

impl<T: Real> Hysteresis<T> for MbwRlm<T> {
    type State = RlmState<T>;

    /// `w` on the centre line `lambda/mu*u0` of the band of 004 eq. (16) (0 at `u0 = 0`).
    fn init(&self, u0: T) -> RlmState<T> {
        let u = sane_input(u0, T::ZERO);
        RlmState {
            u,
            w: self.k_w() * u,
        }
    }

    #[inline]
    fn step(&self, s: &mut RlmState<T>, u: T, _dt: T) -> T {
        let u = sane_input(u, s.u);
        s.w = self.advance_w(s.w, s.u, u - s.u);
        s.u = u;
        s.w
    }
}

/// Weighted polynomial MBW (004 eq. 7): `v = sum_{i=1..L} c_i*w^i`, `w` the [`MbwRlm`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wpmbw<T, const L: usize> {
    mbw: MbwRlm<T>,
    c: [T; L],
}

impl<T: Real, const L: usize> Wpmbw<T, L> {
    /// The MBW operator and the coefficients `c_1..c_L`.
    pub fn new(mbw: MbwRlm<T>, c: [T; L]) -> Result<Self, ParamError> {
        ensure(L >= 1, "WPMBW: order L >= 1")?;
        ensure_finite(&c, "WPMBW: coefficients c_i must be finite")?;
        Ok(Self { mbw, c })
    }

    pub fn mbw(&self) -> &MbwRlm<T> {
        &self.mbw
    }
    /// `c_1..c_L`.
    pub fn coefficients(&self) -> &[T; L] {
        &self.c
    }

    /// `v = sum c_i*w^i` (Horner).
    #[inline]
    pub fn poly(&self, w: T) -> T {
        self.c.iter().rev().fold(T::ZERO, |acc, &c| (acc + c) * w)
    }

    /// `dv/dw = sum i*c_i*w^(i-1)`.
    #[inline]
    pub fn poly_slope(&self, w: T) -> T {
        self.c
            .iter()
            .enumerate()
            .rev()
            .fold(T::ZERO, |acc, (i, &c)| acc * w + T::from_usize(i + 1) * c)
    }
}

impl<T: Real, const L: usize> Hysteresis<T> for Wpmbw<T, L> {
    type State = RlmState<T>;

    fn init(&self, u0: T) -> RlmState<T> {
        self.mbw.init(u0)
    }

    #[inline]
    fn step(&self, s: &mut RlmState<T>, u: T, dt: T) -> T {
        let w = self.mbw.step(s, u, dt);
        self.poly(w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::assert_refused;

    #[test]
    fn rejects_bad_parameters() {
        assert_refused(
            MbwRlm::new(0.5, 0.0, 0.45),
            "MBW-RLM: lambda > 0 (004 eq. 4)",
        );
        assert!(MbwRlm::new(f64::NAN, 0.4, 0.45).is_err());
        let m = MbwRlm::new(0.5, 0.4, 0.45).unwrap();
        assert!(Wpmbw::new(m, [1.0, f64::INFINITY]).is_err());
    }

    #[test]
    fn rk4_matches_finer_rk4() {
        let m = MbwRlm::new(0.6485, 0.7217, 0.7440).unwrap();
        let (mut w, mut w_ref, mut u) = (0.0, 0.0, 0.0);
        for k in 1..2000 {
            let un = 5.45 * (-0.21 * k as f64 * 2e-3).exp() * ((k as f64 * 0.0126).sin() + 1.0);
            let du = un - u;
            w = m.advance_w(w, u, du);
            w_ref = rk4_input(w_ref, u, du, 1e-4, |w, u| m.slope(u, w, du.signum()));
            u = un;
        }
        assert!((w - w_ref).abs() < 1e-8, "{w} vs {w_ref}");
    }

    #[test]
    fn polynomial_and_its_slope() {
        let m = Wpmbw::new(MbwRlm::new(0.5, 0.4, 0.45).unwrap(), [0.9268, 0.0048, 0.01]).unwrap();
        let w = 1.7;
        assert!((m.poly(w) - (0.9268 * w + 0.0048 * w * w + 0.01 * w * w * w)).abs() < 1e-12);
        let fd = (m.poly(w + 1e-6) - m.poly(w - 1e-6)) / 2e-6;
        assert!((m.poly_slope(w) - fd).abs() < 1e-6);
    }

    #[test]
    fn nan_input_holds_state() {
        let m = MbwRlm::new(0.5, 0.4, 0.45).unwrap();
        let mut s = m.init(0.0);
        m.step(&mut s, 3.0, 1e-3);
        let before = s;
        assert!(m.step(&mut s, f64::NAN, 1e-3).is_finite());
        assert_eq!(s, before);
    }
}
