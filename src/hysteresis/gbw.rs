//! Generalized Bouc-Wen (GBW) in piezo form.

use super::{
    ensure, ensure_finite, rk4_input, sane_input, step_piecewise_affine, BwState, Hysteresis,
    ParamError,
};
use crate::real::Real;

/// Generalized Bouc-Wen, piezo form `y = d*u - h` with
/// `dh/dt = alpha*[du/dt*(A - (B*sgn(du/dt) + G)*|h|^n)]` (000 eq. 3).
///
/// Unlike CBW the `B` term multiplies `|h|^n`, not `|h|^(n-1)*h`: moving up, `h` settles at
/// `h_up = (A/(B+G))^(1/n)`, moving down at `-h_down = -(A/(G-B))^(1/n)`, so `B != 0` makes
/// the loop asymmetric.
///
/// Taken literally eq. (3) is not bounded for `B != 0`: with `B > 0`, a long descent takes
/// `h` below `-h_up`, where the slope on the next ascent is negative and `h` runs away
/// (and symmetrically for `B < 0`). The model therefore keeps `dh/du >= 0` (`h`
/// never moves against the input, as in CBW inside its bounds): in the run-away region
/// `h` holds. This changes nothing for sweeps that stay out of that region and bounds
/// `-h_down <= h <= h_up` ([`Gbw::h_bound`]).
///
/// Because the rise settles at `h_up` and the fall at `-h_down`, a zero-mean periodic input
/// ratchets `h` toward the larger equilibrium: the loops drift until they sit against it
/// (visible in `piezo demo`); this is eq. (3)'s own behaviour, not a discretisation effect.
///
/// Accepted when `alpha > 0`, `A > 0`, `G > |B|` (both equilibria exist), `n >= 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gbw<T> {
    d: T,
    alpha: T,
    a: T,
    b: T,
    g: T,
    n: T,
    /// RK4 sub-step bound in the input domain (V), used only for `n != 1`.
    max_du: T,
    /// `[-h_down, h_up]` is invariant; clamps RK4 when a huge step hits the sub-step cap.
    h_lo: T,
    h_hi: T,
}

impl<T: Real> Gbw<T> {
    /// `d` piezo coefficient (um/V), `alpha` (scale), `a, b, g` (the lecture's
    /// `A_bw, B_bw, G_bw`), exponent `n`.
    pub fn new(d: T, alpha: T, a: T, b: T, g: T, n: T) -> Result<Self, ParamError> {
        ensure_finite(
            &[d, alpha, a, b, g, n],
            "GBW: all parameters must be finite",
        )?;
        ensure(alpha > T::ZERO, "GBW: alpha > 0")?;
        ensure(a > T::ZERO, "GBW: A > 0")?;
        ensure(g > b.abs(), "GBW: G > |B| (bounded up and down equilibria)")?;
        ensure(n >= T::ONE, "GBW: n >= 1")?;
        let h_max = (a / (g - b.abs())).powf(T::ONE / n);
        let lipschitz = alpha * n * (b.abs() + g) * h_max.abs_pow(n - T::ONE);
        let max_du = T::from_f64(0.1) / lipschitz;
        ensure(
            max_du.is_finite() && max_du > T::ZERO && h_max.is_finite(),
            "GBW: parameters out of range",
        )?;
        Ok(Self {
            d,
            alpha,
            a,
            b,
            g,
            n,
            max_du,
            h_lo: -(a / (g - b)).powf(T::ONE / n),
            h_hi: (a / (g + b)).powf(T::ONE / n),
        })
    }

    pub fn d(&self) -> T {
        self.d
    }
    pub fn alpha(&self) -> T {
        self.alpha
    }
    /// `A_bw`.
    pub fn a(&self) -> T {
        self.a
    }
    /// `B_bw`.
    pub fn b(&self) -> T {
        self.b
    }
    /// `G_bw`.
    pub fn g(&self) -> T {
        self.g
    }
    pub fn n(&self) -> T {
        self.n
    }

    /// Equilibrium of `h` for a long rise: `(A/(B+G))^(1/n)`.
    pub fn h_up(&self) -> T {
        (self.a / (self.b + self.g)).powf(T::ONE / self.n)
    }

    /// Magnitude of the equilibrium of `h` for a long fall: `(A/(G-B))^(1/n)`.
    pub fn h_down(&self) -> T {
        (self.a / (self.g - self.b)).powf(T::ONE / self.n)
    }

    /// Bound of `|h|`: `max(h_up, h_down)`.
    pub fn h_bound(&self) -> T {
        self.h_up().max(self.h_down())
    }

    /// `dh/du` of eq. (3) at state `h` for input direction `s = sgn(du/dt)`, without the
    /// run-away guard.
    #[inline]
    pub fn slope_raw(&self, h: T, s: T) -> T {
        self.alpha * (self.a - (self.b * s + self.g) * h.abs_pow(self.n))
    }

    /// `dh/du` of the model (eq. 3 with the guard `dh/du >= 0`).
    #[inline]
    pub fn slope(&self, h: T, s: T) -> T {
        self.slope_raw(h, s).max(T::ZERO)
    }

    /// Input-domain update of `h` over `du`: exact for `n = 1`, RK4 otherwise.
    #[inline]
    pub fn advance_h(&self, h: T, u0: T, du: T) -> T {
        let s = du.sgn();
        if s == T::ZERO {
            return h;
        }
        // The run-away region (slope < 0) is invariant under the guarded dynamics and the
        // region slope >= 0 never enters it (its boundary is an unstable equilibrium).
        if self.slope_raw(h, s) < T::ZERO {
            return h;
        }
        if self.n == T::ONE {
            // |h| = sigma*h: dh/du = alpha*A - alpha*(B*s + G)*sigma*h.
            step_piecewise_affine(h, du, self.alpha * self.a, |sigma| {
                self.alpha * (self.b * s + self.g) * sigma
            })
        } else {
            rk4_input(h, u0, du, self.max_du, |h, _| self.slope(h, s))
                .clamp_to(self.h_lo, self.h_hi)
        }
    }
}

impl<T: Real> Hysteresis<T> for Gbw<T> {
    type State = BwState<T>;

    fn init(&self, u0: T) -> BwState<T> {
        BwState {
            u: sane_input(u0, T::ZERO),
            h: T::ZERO,
        }
    }

    #[inline]
    fn step(&self, s: &mut BwState<T>, u: T, _dt: T) -> T {
        let u = sane_input(u, s.u);
        s.h = self.advance_h(s.h, s.u, u - s.u);
        s.u = u;
        self.d * u - s.h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> Gbw<f64> {
        Gbw::new(0.16, 1.2, 0.07, 0.005, 0.02, 1.0).unwrap()
    }

    #[test]
    fn rejects_unbounded_parameters() {
        assert_eq!(
            Gbw::new(0.16, 1.0, 0.07, 0.03, 0.02, 1.0).unwrap_err().0,
            "GBW: G > |B| (bounded up and down equilibria)"
        );
        assert_eq!(
            Gbw::new(0.16, 0.0, 0.07, 0.0, 0.02, 1.0).unwrap_err().0,
            "GBW: alpha > 0"
        );
        assert!(Gbw::new(0.16, 1.0, 0.07, 0.0, 0.02, 0.5).is_err());
        assert!(Gbw::new(0.16, 1.0, f64::INFINITY, 0.0, 0.02, 1.0).is_err());
    }

    #[test]
    fn settles_at_the_asymmetric_equilibria() {
        let m = model();
        let mut s = m.init(0.0);
        m.step(&mut s, 3000.0, 1.0);
        assert!((s.h - m.h_up()).abs() < 1e-9, "{} vs {}", s.h, m.h_up());
        m.step(&mut s, -3000.0, 1.0);
        assert!((s.h + m.h_down()).abs() < 1e-9, "{} vs {}", s.h, m.h_down());
        assert!(m.h_up() < m.h_down());
        // Ascent from below -h_up: held by the guard, bounded.
        m.step(&mut s, 3000.0, 1.0);
        assert!(s.h.abs() <= m.h_bound() + 1e-12);
    }

    #[test]
    fn closed_form_equals_fine_rk4() {
        let m = model();
        let mut h_exact = 0.0;
        let mut h_rk4 = 0.0;
        let mut u = 0.0;
        for k in 1..2000 {
            let un = 60.0 * (k as f64 * 0.01).sin();
            let du = un - u;
            h_exact = m.advance_h(h_exact, u, du);
            h_rk4 = if m.slope_raw(h_rk4, du.signum()) < 0.0 {
                h_rk4
            } else {
                rk4_input(h_rk4, u, du, 1e-3, |h, _| m.slope(h, du.signum()))
            };
            u = un;
        }
        assert!((h_exact - h_rk4).abs() < 1e-8, "{h_exact} vs {h_rk4}");
    }

    #[test]
    fn n2_is_bounded_and_matches_fine_rk4() {
        let m = Gbw::new(0.16, 1.0, 0.07, 0.002, 0.01, 2.0).unwrap();
        let mut s = m.init(0.0);
        let mut h_ref = 0.0;
        let mut u = 0.0;
        for k in 1..3000 {
            let un = 80.0 * (k as f64 * 0.003).sin();
            m.step(&mut s, un, 1e-3);
            let du = un - u;
            h_ref = rk4_input(h_ref, u, du, 1e-4, |h, _| m.slope(h, du.signum()));
            u = un;
            assert!(s.h.abs() <= m.h_bound() * (1.0 + 1e-9));
        }
        assert!(
            (s.h - h_ref).abs() < 1e-6 * m.h_bound(),
            "{} {}",
            s.h,
            h_ref
        );
    }

    #[test]
    fn nan_input_holds_state() {
        let m = model();
        let mut s = m.init(0.0);
        m.step(&mut s, 10.0, 1e-3);
        let before = s;
        assert!(m.step(&mut s, f64::INFINITY, 1e-3).is_finite());
        assert_eq!(s, before);
    }
}
