//! Force tracking with a barrier-Lyapunov function and a saturated input (000 Part V, "Force
//! control with deformable objects", backup slide eq. 12).
//!
//! In contact the force responds to the voltage with a positive, bounded sensitivity
//! `b = dF/du in [b_min, b_max]` (object stiffness in series with the stage). With
//! `e = F - F_d` and the BLF `V = 1/2 ln(k_b^2 / (k_b^2 - e^2))` (000 eq. 12), the law
//! ```text
//! u' = sat_r( (F_d' - lambda * k_b^2 e / (k_b^2 - e^2)) / b^ )
//! ```
//! gives `V' = -lambda (b/b^) k_b^2 e^2 / (k_b^2 - e^2)^2 + e (b/b^ - 1) F_d' / (k_b^2 - e^2)`:
//! the first term grows as `(k_b^2 - e^2)^-2` and wins near the barrier, so `V` stays finite
//! and `|e| < k_b` for all time, as long as the rate bound `r` covers `|F_d'| / b_min`.
//! The voltage is the integral of the saturated rate, clamped to `[u_min, u_max]`: the input
//! is bounded by construction and nothing winds up.
//!
//! Discrete time: the barrier factor `k_b^2 / (k_b^2 - e^2)` is capped at [`BARRIER_CAP`]
//! so one sample can never apply an unbounded step; with `lambda dt * BARRIER_CAP < 1` the
//! sampled loop keeps the continuous-time behaviour.

use crate::hysteresis::ParamError;
use crate::real::Real;

/// Largest barrier factor `k_b^2 / (k_b^2 - e^2)` used (reached at `|e| = 0.99 k_b`).
pub const BARRIER_CAP: f64 = 50.0;

/// BLF force law: configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlfForce<T> {
    /// Barrier `k_b` (mN): the prescribed bound of `|F - F_d|`.
    kb_mn: T,
    /// Closed-loop rate `lambda` (1/s).
    lambda: T,
    /// Nominal force sensitivity `b^ = dF/du` (mN/V).
    b_hat: T,
    /// Voltage-rate bound (V/s).
    rate_limit: T,
    u_min: T,
    u_max: T,
    dt: T,
}

/// BLF law state: the voltage it commands.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BlfState<T> {
    pub u_volts: T,
    /// Last barrier value `V` (000 eq. 12), for logging.
    pub v: T,
}

impl<T: Real> BlfForce<T> {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        kb_mn: T,
        lambda: T,
        b_hat_mn_per_volt: T,
        rate_limit_volts_per_s: T,
        u_min: T,
        u_max: T,
        rate_hz: T,
    ) -> Result<Self, ParamError> {
        let pos = |v: T| v.is_finite() && v > T::ZERO;
        if !pos(kb_mn) {
            return Err(ParamError("BLF: k_b > 0 (000 eq. 12)"));
        }
        if !pos(lambda) {
            return Err(ParamError("BLF: lambda > 0"));
        }
        if !pos(b_hat_mn_per_volt) {
            return Err(ParamError("BLF: b_hat > 0 (force must rise with voltage)"));
        }
        if !pos(rate_limit_volts_per_s) {
            return Err(ParamError("BLF: rate_limit > 0"));
        }
        if !(u_min.is_finite() && u_max.is_finite() && u_min < u_max) {
            return Err(ParamError("BLF: u_min < u_max"));
        }
        if !pos(rate_hz) {
            return Err(ParamError("BLF: rate_hz > 0"));
        }
        let dt = T::ONE / rate_hz;
        if !(lambda * dt * T::from_f64(BARRIER_CAP) < T::ONE) {
            return Err(ParamError("BLF: lambda / rate_hz * BARRIER_CAP < 1"));
        }
        Ok(Self {
            kb_mn,
            lambda,
            b_hat: b_hat_mn_per_volt,
            rate_limit: rate_limit_volts_per_s,
            u_min,
            u_max,
            dt,
        })
    }

    pub fn kb_mn(&self) -> T {
        self.kb_mn
    }

    /// Bumpless start from the voltage now applied.
    pub fn init(&self, u_volts: T) -> BlfState<T> {
        BlfState {
            u_volts: u_volts.clamp_to(self.u_min, self.u_max),
            v: T::ZERO,
        }
    }

    /// One sample: force (measured or estimated, mN), desired force and its derivative
    /// (mN, mN/s). Returns the voltage (V), always within `[u_min, u_max]` and moved by at
    /// most `rate_limit * dt`. A non-finite force holds the voltage.
    pub fn update(&self, s: &mut BlfState<T>, force_mn: T, fd_mn: T, dfd: T) -> T {
        let e = force_mn - fd_mn;
        if !e.is_finite() {
            return s.u_volts;
        }
        let kb2 = self.kb_mn * self.kb_mn;
        let room = kb2 - e * e;
        let cap = T::from_f64(BARRIER_CAP);
        // Outside or on the barrier the factor is the cap: maximum effort back inside.
        let factor = if room * cap > kb2 { kb2 / room } else { cap };
        s.v = T::HALF * factor.ln();
        let dfd = if dfd.is_finite() { dfd } else { T::ZERO };
        let rate = ((dfd - self.lambda * factor * e) / self.b_hat)
            .clamp_to(-self.rate_limit, self.rate_limit);
        s.u_volts = (s.u_volts + rate * self.dt).clamp_to(self.u_min, self.u_max);
        s.u_volts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn law() -> BlfForce<f64> {
        BlfForce::new(5.0, 100.0, 5.0, 2000.0, 0.0, 150.0, 10_000.0).unwrap()
    }

    /// Static plant F = b (u - u0) with b off by 2x: the error stays inside k_b and converges.
    #[test]
    fn first_order_plant_stays_inside_barrier() {
        let l = law();
        let mut s = l.init(18.0); // F(0) = F_d(0): start inside the barrier
        let b = 10.0; // true sensitivity, b_hat = 5
        let mut worst: f64 = 0.0;
        for k in 0..20_000 {
            let t = k as f64 * 1e-4;
            let fd = 20.0 + 30.0 * (2.0 * std::f64::consts::PI * 2.0 * t).sin();
            let dfd =
                30.0 * 4.0 * std::f64::consts::PI * (2.0 * std::f64::consts::PI * 2.0 * t).cos();
            let f = b * (s.u_volts - 16.0);
            worst = worst.max((f - fd).abs());
            l.update(&mut s, f, fd, dfd);
        }
        assert!(worst < 5.0, "max |e| = {worst}");
    }

    #[test]
    fn output_is_bounded_and_rate_limited_even_for_nan() {
        let l = law();
        let mut s = l.init(149.99);
        let mut prev = s.u_volts;
        for k in 0..1000 {
            let f = match k % 4 {
                0 => f64::NAN,
                1 => -1e30,
                2 => f64::INFINITY,
                _ => 1e30,
            };
            let u = l.update(&mut s, f, 10.0, f64::NAN);
            assert!((0.0..=150.0).contains(&u));
            assert!((u - prev).abs() <= 2000.0 * 1e-4 + 1e-12);
            prev = u;
        }
    }

    #[test]
    fn rejects_bad_barrier() {
        assert_eq!(
            BlfForce::new(0.0, 100.0, 5.0, 2000.0, 0.0, 150.0, 1e4)
                .unwrap_err()
                .0,
            "BLF: k_b > 0 (000 eq. 12)"
        );
        assert!(BlfForce::new(5.0, 1e4, 5.0, 2000.0, 0.0, 150.0, 1e4).is_err());
    }
}
