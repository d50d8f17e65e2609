//! Asymmetric Bouc-Wen models (001 eq. 3, 002 eq. 3) and the MBW of 002 (eq. 4-5), all in
//! piezo form `y = d*u - h`.
//!
//! Mapping from the `y = k*v + h` form of 001/002 (`h_piezo = -h`): `d = k`,
//! `alpha -> -alpha`, `gamma -> -gamma`, `beta, n, p, q` unchanged, and `delta` by form:
//! * 002 eq. (3), `+delta*|v'|`: the piezo form [`AbwAbs`] keeps `+delta*|u'|`, so
//!   `delta -> -delta` ([`AbwAbs::from_002`]). E.g. the MBW of 002 table 1 (`alpha =
//!   -0.0656, beta = 0.3922, gamma = -0.15, delta = -0.011`) is `alpha = 0.0656, beta =
//!   0.3922, gamma = 0.15, delta = 0.011` here.
//! * 001 eq. (3), `+delta*u*sgn(u')`: the piezo form [`AbwU`] writes `-delta*u*sgn(u')`
//!   (as 004 eq. 21), so `delta` keeps its sign ([`AbwU::from_001`]). E.g. 001's ABW at
//!   140 V (`[alpha, beta, gamma, delta] = [-0.3, 0.0025, 0.002, 0.18]`) is `alpha = 0.3,
//!   beta = 0.0025, gamma = -0.002, delta = 0.18` here.

use super::{
    ensure, ensure_finite, rk4_kinked, sane_input, step_piecewise_affine, substeps, BwState,
    Hysteresis, ParamError,
};
use crate::real::Real;

/// The CBW part `g(h, s) = alpha - (beta*s*sigma + gamma)*|h|^n` of `dh/du` on piece
/// `sigma` (`|h|` taken as `sigma*h`, the smooth extension of the piece).
#[inline(always)]
fn cbw_slope<T: Real>(alpha: T, beta: T, gamma: T, n: T, h: T, s: T, sigma: T) -> T {
    let m = sigma * h;
    let mag = if n == T::ONE {
        m
    } else {
        m.max(T::ZERO).powf(n)
    };
    alpha - (beta * s * sigma + gamma) * mag
}

/// Which `delta` term an [`Abw`] carries: `delta*u*sgn(u')` ([`AbwU`]) or
/// `delta*|u'|` ([`AbwAbs`]).
pub trait AbwForm: Copy + core::fmt::Debug + PartialEq {
    /// The error texts: non-finite parameter, the four conditions of 004 eq. (3) and the
    /// sub-step bound out of range.
    const MSGS: [&'static str; 6];
}

/// The `delta*u*sgn(u')` form of 001 eq. (3).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DeltaU;

/// The `delta*|u'|` form of 002 eq. (3).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DeltaAbs;

impl AbwForm for DeltaU {
    const MSGS: [&'static str; 6] = [
        "ABW-u: all parameters must be finite",
        "ABW-u: alpha > 0 (004 eq. 3)",
        "ABW-u: beta + gamma > 0 (004 eq. 3)",
        "ABW-u: beta - gamma >= 0 (004 eq. 3)",
        "ABW-u: n >= 1",
        "ABW-u: parameters out of range",
    ];
}

impl AbwForm for DeltaAbs {
    const MSGS: [&'static str; 6] = [
        "ABW-abs: all parameters must be finite",
        "ABW-abs: alpha > 0 (004 eq. 3)",
        "ABW-abs: beta + gamma > 0 (004 eq. 3)",
        "ABW-abs: beta - gamma >= 0 (004 eq. 3)",
        "ABW-abs: n >= 1",
        "ABW-abs: parameters out of range",
    ];
}

/// An asymmetric Bouc-Wen model in piezo form, `F` its `delta` term.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Abw<T, F> {
    d: T,
    alpha: T,
    beta: T,
    gamma: T,
    n: T,
    delta: T,
    /// RK4 sub-step bound (V).
    max_du: T,
    form: F,
}

impl<T: Real, F: AbwForm + Default> Abw<T, F> {
    /// Checks the parameters (finite, the CBW part against 004 eq. 3, then `extra`) and
    /// sets the RK4 sub-step bound `0.1/L` for `|h| <= (alpha_h/(beta + gamma))^(1/n)`.
    fn checked(
        [d, alpha, beta, gamma, n, delta]: [T; 6],
        extra: Result<(), ParamError>,
        alpha_h: T,
    ) -> Result<Self, ParamError> {
        let msgs = F::MSGS;
        ensure_finite(&[d, alpha, beta, gamma, n, delta], msgs[0])?;
        ensure(alpha > T::ZERO, msgs[1])?;
        ensure(beta + gamma > T::ZERO, msgs[2])?;
        ensure(beta - gamma >= T::ZERO, msgs[3])?;
        ensure(n >= T::ONE, msgs[4])?;
        extra?;
        let h_max = (alpha_h / (beta + gamma)).powf(T::ONE / n);
        let lipschitz = n * (beta + gamma.abs()) * h_max.abs_pow(n - T::ONE);
        let max_du = T::from_f64(0.1) / lipschitz;
        ensure(max_du.is_finite() && max_du > T::ZERO, msgs[5])?;
        Ok(Self {
            d,
            alpha,
            beta,
            gamma,
            n,
            delta,
            max_du,
            form: F::default(),
        })
    }

    super::getters!(d, alpha, beta, gamma, n, delta);
}

/// Asymmetric Bouc-Wen with the term `delta*u*sgn(du/dt)` (001 eq. 3; piezo form as in
/// 004 eq. 21): `y = d*u - h`,
/// `dh/dt = alpha*u' - beta*|u'|*|h|^(n-1)*h - gamma*u'*|h|^n - delta*u*sgn(u')`.
///
/// The `delta` term is rate dependent: per unit input it is `delta*u/|u'|`. Over one
/// sample with first-order-hold input (`u' = du/dt`), along `u = u0 + theta*du`:
/// `dh/dtheta = du*g(h, s) - delta*s*dt*(u0 + theta*du)`, integrated by RK4 in `theta`
/// with sub-steps no larger than `0.1/L` of input (split at `h = 0`). Exact for FOH input
/// up to the RK4 error, at any sample rate.
///
/// For a fixed input rate the loop is bounded (the CBW part pulls `h` back with rate
/// `(beta+gamma)*|u'|`, the drift is `delta*|u|`); as `u' -> 0` at a non-zero `u` the drift
/// wins, as in the seed's equation. The CBW part is checked against 004 eq. (3).
pub type AbwU<T> = Abw<T, DeltaU>;

impl<T: Real> AbwU<T> {
    /// `d` (um/V), CBW part `alpha, beta, gamma, n`, asymmetry `delta` (um/(V s)).
    pub fn new(d: T, alpha: T, beta: T, gamma: T, n: T, delta: T) -> Result<Self, ParamError> {
        Self::checked([d, alpha, beta, gamma, n, delta], Ok(()), alpha)
    }

    /// 001's `y = k*v + h` parameters (eq. 3 order) mapped to the piezo form: `alpha` and
    /// `gamma` change sign, `delta` does not (see the module doc).
    pub fn from_001(k: T, alpha: T, beta: T, gamma: T, n: T, delta: T) -> Result<Self, ParamError> {
        Self::new(k, -alpha, beta, -gamma, n, delta)
    }

    /// `dh/du` at state `h`, input `u` and input rate `du_dt` (V/s): the CBW part minus
    /// `delta*u/|u'|`. Zero rate gives the CBW part only (the term then has no meaning).
    #[inline]
    pub fn slope(&self, h: T, u: T, du_dt: T) -> T {
        let s = du_dt.sgn();
        let g = cbw_slope(self.alpha, self.beta, self.gamma, self.n, h, s, h.sgn());
        let rate = du_dt.abs();
        if rate > T::ZERO && rate.is_finite() {
            g - self.delta * u / rate
        } else {
            g
        }
    }

    /// Update of `h` over one sample: input from `u0` by `du` in `dt` seconds (FOH).
    #[inline]
    pub fn advance_h(&self, h: T, u0: T, du: T, dt: T) -> T {
        let s = du.sgn();
        if s == T::ZERO {
            return h; // every term of eq. (3) carries u' or sgn(u')
        }
        let dt = if dt.is_finite() && dt > T::ZERO {
            dt
        } else {
            T::ZERO
        };
        let n = substeps(du, self.max_du);
        let drift = self.delta * s * dt;
        rk4_kinked(h, n, |h, th, sigma| {
            du * cbw_slope(self.alpha, self.beta, self.gamma, self.n, h, s, sigma)
                - drift * (u0 + th * du)
        })
    }
}

super::piezo_form!(AbwU<T>, |m, h, u0, du, dt| {
    let next = m.advance_h(h, u0, du, dt);
    // Only a non-finite result (impossible for validated parameters and finite dt) is
    // refused.
    if next.is_finite() {
        next
    } else {
        h
    }
});

/// Asymmetric Bouc-Wen with the term `delta*|du/dt|` (002 eq. 3), piezo form
/// `y = d*u - h`, `dh/dt = alpha*u' - beta*|u'|*|h|^(n-1)*h - gamma*u'*|h|^n + delta*|u'|`.
///
/// Rate independent: `dh/du = g(h, s) + delta*s`; exact for `n = 1` (the constant term is
/// `alpha + delta*s` on each direction), RK4 otherwise.
///
/// Accepted when the CBW part meets 004 eq. (3) and `alpha > |delta|` (`h` moves with the
/// input in both directions); then `|h| <= ((alpha + |delta|)/(beta + gamma))^(1/n)`.
pub type AbwAbs<T> = Abw<T, DeltaAbs>;

impl<T: Real> AbwAbs<T> {
    /// `d` (um/V), CBW part `alpha, beta, gamma, n`, asymmetry `delta` (um/V).
    pub fn new(d: T, alpha: T, beta: T, gamma: T, n: T, delta: T) -> Result<Self, ParamError> {
        let extra = ensure(alpha > delta.abs(), "ABW-abs: alpha > |delta|");
        Self::checked(
            [d, alpha, beta, gamma, n, delta],
            extra,
            alpha + delta.abs(),
        )
    }

    /// 002's `y = k*v + h` parameters (table 1 order) mapped to the piezo form.
    pub fn from_002(k: T, alpha: T, beta: T, gamma: T, n: T, delta: T) -> Result<Self, ParamError> {
        Self::new(k, -alpha, beta, -gamma, n, -delta)
    }

    /// Bound of `|h|`: `((alpha + |delta|)/(beta + gamma))^(1/n)`.
    pub fn h_bound(&self) -> T {
        ((self.alpha + self.delta.abs()) / (self.beta + self.gamma)).powf(T::ONE / self.n)
    }

    /// `dh/du` at state `h` for input direction `s = sgn(du/dt)`.
    #[inline]
    pub fn slope(&self, h: T, s: T) -> T {
        cbw_slope(self.alpha, self.beta, self.gamma, self.n, h, s, h.sgn()) + self.delta * s
    }

    /// Input-domain update of `h` over `du`: exact for `n = 1`, RK4 otherwise.
    #[inline]
    pub fn advance_h(&self, h: T, du: T) -> T {
        let s = du.sgn();
        if s == T::ZERO {
            return h;
        }
        if self.n == T::ONE {
            step_piecewise_affine(h, du, self.alpha + self.delta * s, |sigma| {
                self.beta * s + self.gamma * sigma
            })
        } else {
            let n = substeps(du, self.max_du);
            let b = self.h_bound();
            rk4_kinked(h, n, |h, _, sigma| {
                du * (cbw_slope(self.alpha, self.beta, self.gamma, self.n, h, s, sigma)
                    + self.delta * s)
            })
            .clamp_to(-b, b) // invariant; only matters when a huge step hits the cap
        }
    }
}

super::piezo_form!(AbwAbs<T>, |m, h, _, du, _dt| m.advance_h(h, du));

/// State of [`Mbw002`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MbwState<T> {
    /// Last input (V).
    pub u: T,
    /// Hysteresis variable of the ABW part.
    pub h: T,
    /// Input rate over the last sample (V/s).
    pub du_dt: T,
}

/// Modified Bouc-Wen of 002 (eq. 4-5), piezo form:
/// `y = d*u - h + p*u' + q*u'^3`, `h` the [`AbwAbs`] of 002 eq. (3), `u'` the input rate
/// over the last sample (first-order hold).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mbw002<T> {
    abw: AbwAbs<T>,
    p: T,
    q: T,
}

impl<T: Real> Mbw002<T> {
    /// The ABW part and the rate terms `p` (um s/V), `q` (um s^3/V^3).
    pub fn new(abw: AbwAbs<T>, p: T, q: T) -> Result<Self, ParamError> {
        ensure(
            p.is_finite() && q.is_finite(),
            "MBW-002: p and q must be finite",
        )?;
        Ok(Self { abw, p, q })
    }

    /// 002 table 1 order in the `y = k*v + h` form (`p, q` keep their sign).
    #[allow(clippy::too_many_arguments)]
    pub fn from_002(
        k: T,
        alpha: T,
        beta: T,
        gamma: T,
        n: T,
        delta: T,
        p: T,
        q: T,
    ) -> Result<Self, ParamError> {
        Self::new(AbwAbs::from_002(k, alpha, beta, gamma, n, delta)?, p, q)
    }

    pub fn abw(&self) -> &AbwAbs<T> {
        &self.abw
    }
    super::getters!(p, q);

    /// The rate term `p*u' + q*u'^3` (002 eq. 4).
    #[inline]
    pub fn rate_term(&self, du_dt: T) -> T {
        self.p * du_dt + self.q * du_dt * du_dt * du_dt
    }
}

impl<T: Real> Hysteresis<T> for Mbw002<T> {
    type State = MbwState<T>;

    fn init(&self, u0: T) -> MbwState<T> {
        MbwState {
            u: sane_input(u0, T::ZERO),
            h: T::ZERO,
            du_dt: T::ZERO,
        }
    }

    #[inline]
    fn step(&self, s: &mut MbwState<T>, u: T, dt: T) -> T {
        let u = sane_input(u, s.u);
        let du = u - s.u;
        s.h = self.abw.advance_h(s.h, du);
        let rate = du / dt;
        s.du_dt = if rate.is_finite() { rate } else { T::ZERO };
        s.u = u;
        self.abw.d * u - s.h + self.rate_term(s.du_dt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::{along_sine, assert_refused, rk4_input, rk4_time, Cbw};

    #[test]
    fn rejects_bad_parameters() {
        assert_refused(
            AbwAbs::new(1.0, 0.05, 0.4, 0.15, 1.0, 0.06),
            "ABW-abs: alpha > |delta|",
        );
        assert_refused(
            AbwU::new(1.0, 0.05, 0.1, 0.15, 1.0, 0.0),
            "ABW-u: beta - gamma >= 0 (004 eq. 3)",
        );
        assert!(Mbw002::new(
            AbwAbs::new(1.0, 0.1, 0.4, 0.1, 1.0, 0.0).unwrap(),
            f64::NAN,
            0.0
        )
        .is_err());
    }

    #[test]
    fn zero_delta_reduces_to_cbw() {
        let cbw = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
        let a = AbwU::new(0.16, 0.07, 0.02, 0.01, 1.0, 0.0).unwrap();
        let b = AbwAbs::new(0.16, 0.07, 0.02, 0.01, 1.0, 0.0).unwrap();
        let (mut sc, mut sa, mut sb) = (cbw.init(0.0), a.init(0.0), b.init(0.0));
        for k in 1..3000 {
            let u = 100.0 * (k as f64 * 0.004).sin() * (-(k as f64) * 5e-4).exp();
            let yc = cbw.step(&mut sc, u, 1e-3);
            let ya = a.step(&mut sa, u, 1e-3);
            let yb = b.step(&mut sb, u, 1e-3);
            assert!((yc - ya).abs() < 1e-7, "{k}: {yc} {ya}");
            assert!((yc - yb).abs() < 1e-12, "{k}: {yc} {yb}");
        }
    }

    #[test]
    fn abs_closed_form_equals_fine_rk4_and_is_bounded() {
        let m = AbwAbs::from_002(1.0998, -0.0656, 0.3922, -0.15, 1.0, -0.011).unwrap();
        let (h, h_ref) = along_sine(
            10.0,
            0.01,
            3000,
            |h, _, du| {
                let h = m.advance_h(h, du);
                assert!(h.abs() <= m.h_bound() * (1.0 + 1e-12));
                h
            },
            |h, u, du| rk4_input(h, u, du, 1e-4, |h, _| m.slope(h, du.signum())),
        );
        assert!((h - h_ref).abs() < 1e-7, "{h} vs {h_ref}");
    }

    #[test]
    fn u_delta_term_matches_time_domain_rk4() {
        // Reference: fine RK4 in time of eq. (3) with the FOH input.
        let m = AbwU::new(1.0, 0.3, 0.6, 0.16, 1.0, 0.04).unwrap();
        let dt = 1e-2;
        let (mut s, mut h_ref, mut u) = (m.init(0.0), 0.0, 0.0);
        for k in 1..400 {
            let un = 4.0 * (1.0 - (k as f64 * dt * 2.0 * std::f64::consts::PI).cos());
            m.step(&mut s, un, dt);
            let rate = (un - u) / dt;
            let f = |h: f64, t: f64| {
                let uu = u + rate * t;
                rate * 0.3
                    - 0.6 * rate.abs() * h
                    - 0.16 * rate * h.abs()
                    - 0.04 * uu * rate.signum()
            };
            h_ref = rk4_time(h_ref, dt, 2000, f);
            u = un;
        }
        assert!((s.h - h_ref).abs() < 1e-6, "{} vs {h_ref}", s.h);
    }

    /// 001 eq. (3) integrated as printed (`y = k*u + h`, fine RK4 in time) against
    /// `AbwU::from_001`: the mapping (delta keeps its sign) gives the same output.
    #[test]
    fn from_001_reproduces_the_seed_form() {
        // 001 sec. IV's ABW at 140 V: [alpha, beta, gamma, delta] = [-0.3, 0.0025, 0.002, 0.18].
        let (k, al, be, ga, de) = (0.2, -0.3, 0.0025, 0.002, 0.18);
        let m = AbwU::from_001(k, al, be, ga, 1.0, de).unwrap();
        let dt = 1e-2;
        let (mut s, mut h, mut u) = (m.init(0.0), 0.0f64, 0.0);
        let mut worst = 0.0f64;
        for j in 1..300 {
            let un = 70.0 * (1.0 - (j as f64 * dt * std::f64::consts::TAU).cos());
            let y = m.step(&mut s, un, dt);
            let rate = (un - u) / dt;
            // 001 eq. (3) with n = 1: h' = alpha u' - beta |u'| h - gamma u' |h| + delta u sgn(u').
            let f = |h: f64, t: f64| {
                al * rate - be * rate.abs() * h - ga * rate * h.abs()
                    + de * (u + rate * t) * rate.signum()
            };
            h = rk4_time(h, dt, 400, f);
            u = un;
            worst = worst.max((y - (k * un + h)).abs());
        }
        assert!(worst < 1e-6 * (k * 140.0), "largest difference {worst}");
    }

    #[test]
    fn mbw_adds_the_rate_terms() {
        let m =
            Mbw002::from_002(1.0998, -0.0656, 0.3922, -0.15, 1.0, -0.011, 0.0108, 3.68e-5).unwrap();
        let mut s = m.init(0.0);
        let y = m.step(&mut s, 0.5, 0.1);
        let want = 1.0998 * 0.5 - s.h + 0.0108 * 5.0 + 3.68e-5 * 125.0;
        assert!((y - want).abs() < 1e-12);
        // dt = 0 never yields a non-finite output.
        assert!(m.step(&mut s, 0.7, 0.0).is_finite());
        assert!(m.step(&mut s, f64::NAN, 1e-3).is_finite());
    }
}
