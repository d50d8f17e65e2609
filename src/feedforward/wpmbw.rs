//! Direct inverse of the WPMBW model with inverse linear dynamics and the full-pass
//! prefilter (004 eq. 17, 18, 27, 28).

use super::{ensure, FfError};
use crate::hysteresis::phi;
use crate::hysteresis::{MbwRlm, Wpmbw};
use crate::real::Real;
use crate::signals::Setpoint;

/// Second-order linear part `a2*y'' + a1*y' + a0*y = b0*v` (004 eq. 8 with `n = 2`,
/// zeros ignored as in 004 eq. 27).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearPart<T> {
    pub a0: T,
    pub a1: T,
    pub a2: T,
    pub b0: T,
}

impl<T: Real> LinearPart<T> {
    /// Unit-gain second-order lag with natural frequency `wn_rad_s` and damping `zeta`.
    pub fn second_order(wn_rad_s: T, zeta: T) -> Self {
        Self {
            a0: wn_rad_s * wn_rad_s,
            a1: T::TWO * zeta * wn_rad_s,
            a2: T::ONE,
            b0: wn_rad_s * wn_rad_s,
        }
    }
}

/// Exact discretisation of the critically damped (`zeta = 1`) homogeneous error dynamics of
/// the full-pass filter (004 eq. 28): `y_d = y_r + e`, `e'' + 2*wn*e' + wn^2*e = 0`, so
/// `y_d` starts where the stage is and joins `y_r` without overshoot.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Prefilter<T> {
    wn: T,
    phi: [[T; 2]; 2],
}

impl<T: Real> Prefilter<T> {
    fn new(wn: T, dt: T) -> Self {
        let x = wn * dt;
        let ex = (-x).exp();
        Self {
            wn,
            phi: [
                [ex * (T::ONE + x), ex * dt],
                [-ex * wn * x, ex * (T::ONE - x)],
            ],
        }
    }
}

/// Inverse WPMBW feedforward (004 eq. 27): `v_hat` from the inverse linear dynamics,
/// `w_hat` from the inverse polynomial (eq. 17, `L <= 2`), `u` from the inverse MBW
/// (eq. 18).
///
/// Eq. (18) is, on a piece of fixed direction `s`, the linear ODE
/// `du/dw = 1/rho - s*lambda*u + s*mu*w`; it is integrated exactly over each sample's
/// `dw`: `du = (mu/lambda)*dw + (e0 - mu/lambda)*dw*phi(lambda*|dw|)`, `e0` the slope at
/// the start, `phi(x) = (1 - exp(-x))/x`. Eq. (17) is evaluated as
/// `w = 2*v / (c1 + sqrt(c1^2 + 4*c2*v))`, free of the cancellation of the textbook form.
#[derive(Debug, Clone, PartialEq)]
pub struct WpmbwInverse<T> {
    mbw: MbwRlm<T>,
    c1: T,
    c2: T,
    linear: Option<LinearPart<T>>,
    prefilter: Option<Prefilter<T>>,
    volts_min: T,
    volts_max: T,
    // state
    u: T,
    w: T,
    e: T,
    e_dot: T,
    armed: bool,
    y_start: T,
}

impl<T: Real> WpmbwInverse<T> {
    /// `linear`: the identified linear dynamics to invert (None: static), `prefilter_wn`:
    /// natural frequency (rad/s) of the eq. (28) filter (None: no prefilter), `dt_s` the
    /// sample period. Starts at rest at 0 V.
    pub fn new<const L: usize>(
        model: &Wpmbw<T, L>,
        linear: Option<LinearPart<T>>,
        prefilter_wn: Option<T>,
        volts_min: T,
        volts_max: T,
        dt_s: T,
    ) -> Result<Self, FfError> {
        super::check_range(volts_min, volts_max)?;
        super::check_dt(dt_s)?;
        ensure(
            (1..=2).contains(&L),
            "WPMBW inverse: polynomial order L = 1 or 2 (004 eq. 17)",
        )?;
        let c = model.coefficients();
        let c1 = c.first().copied().unwrap_or(T::ZERO);
        let c2 = c.get(1).copied().unwrap_or(T::ZERO);
        ensure(
            c1 > T::ZERO,
            "WPMBW inverse: c1 > 0 (v increasing in w at w = 0)",
        )?;
        if let Some(l) = linear {
            ensure(
                [l.a0, l.a1, l.a2, l.b0].iter().all(|x| x.is_finite()) && l.b0 != T::ZERO,
                "WPMBW inverse: linear coefficients finite and b0 != 0",
            )?;
        }
        let prefilter = match prefilter_wn {
            Some(wn) => {
                ensure(
                    wn.is_finite() && wn > T::ZERO,
                    "WPMBW inverse: prefilter wn finite and > 0 (004 eq. 28)",
                )?;
                Some(Prefilter::new(wn, dt_s))
            }
            None => None,
        };
        let mut s = Self {
            mbw: *model.mbw(),
            c1,
            c2,
            linear,
            prefilter,
            volts_min,
            volts_max,
            u: T::ZERO,
            w: T::ZERO,
            e: T::ZERO,
            e_dot: T::ZERO,
            armed: false,
            y_start: T::ZERO,
        };
        s.reset_volts(T::ZERO);
        Ok(s)
    }

    /// 004 eq. (17), cancellation free; outside the invertible range (past the vertex of
    /// the parabola) the vertex.
    #[inline]
    pub fn poly_inverse(&self, v: T) -> T {
        if self.c2 == T::ZERO {
            return v / self.c1;
        }
        let vertex = -self.c1 * self.c1 / (T::from_f64(4.0) * self.c2);
        let v = if self.c2 > T::ZERO {
            v.max(vertex)
        } else {
            v.min(vertex)
        };
        let disc = (self.c1 * self.c1 + T::from_f64(4.0) * self.c2 * v).max(T::ZERO);
        T::TWO * v / (self.c1 + disc.sqrt())
    }

    /// 004 eq. (18) integrated exactly from `(u, w)` over `dw`.
    #[inline]
    pub fn inverse_mbw_step(&self, u: T, w: T, dw: T) -> T {
        let s = dw.sgn();
        if s == T::ZERO {
            return u;
        }
        let (rho, lambda, mu) = (self.mbw.rho(), self.mbw.lambda(), self.mbw.mu());
        let e0 = T::ONE / rho - s * lambda * u + s * mu * w;
        let c = mu / lambda;
        u + c * dw + (e0 - c) * dw * phi(lambda * dw.abs())
    }

    #[inline]
    pub fn compensate(&mut self, sp: &Setpoint<T>) -> T {
        let y_r = sp.y_um;
        if !y_r.is_finite() {
            return self.u;
        }
        let fin = |x: T| if x.is_finite() { x } else { T::ZERO };
        let (dy_r, ddy_r) = (fin(sp.dy), fin(sp.ddy));
        // 004 eq. (28): y_d = y_r + e.
        let (mut y_d, mut dy_d, mut ddy_d) = (y_r, dy_r, ddy_r);
        if let Some(f) = &self.prefilter {
            if !self.armed {
                self.e = self.y_start - y_r;
                self.e_dot = -dy_r;
                self.armed = true;
            } else {
                let (e, ed) = (self.e, self.e_dot);
                self.e = f.phi[0][0] * e + f.phi[0][1] * ed;
                self.e_dot = f.phi[1][0] * e + f.phi[1][1] * ed;
            }
            let e_ddot = -T::TWO * f.wn * self.e_dot - f.wn * f.wn * self.e;
            y_d += self.e;
            dy_d += self.e_dot;
            ddy_d += e_ddot;
        }
        // 004 eq. (27), third line (zeros ignored).
        let v = match &self.linear {
            Some(l) => (l.a0 * y_d + l.a1 * dy_d + l.a2 * ddy_d) / l.b0,
            None => y_d,
        };
        let w = self.poly_inverse(v);
        let u = self.inverse_mbw_step(self.u, self.w, w - self.w);
        if !(u.is_finite() && w.is_finite()) {
            return self.u;
        }
        let u_cl = u.clamp_to(self.volts_min, self.volts_max);
        // Saturated: follow what the stage's operator does with the clamped voltage.
        self.w = if u_cl == u {
            w
        } else {
            self.mbw.advance_w(self.w, self.u, u_cl - self.u)
        };
        self.u = u_cl;
        self.u
    }

    /// The last voltage (V).
    pub fn volts(&self) -> T {
        self.u
    }

    /// Restart at rest at voltage `u0` (operator state zero); the prefilter starts from
    /// the output there.
    pub fn reset_volts(&mut self, u0: T) {
        let u0 = if u0.is_finite() { u0 } else { T::ZERO };
        self.u = u0.clamp_to(self.volts_min, self.volts_max);
        self.w = T::ZERO;
        self.e = T::ZERO;
        self.e_dot = T::ZERO;
        self.armed = false;
        self.y_start = T::ZERO;
    }

    /// Restart at the setpoint: the stage is assumed at rest there (`w` from eq. 17, `u`
    /// on the band centre `mu/lambda*w`), and the prefilter starts on the reference.
    pub fn reset(&mut self, y_um: T) {
        let y = if y_um.is_finite() { y_um } else { T::ZERO };
        let v = match &self.linear {
            Some(l) if l.a0 != T::ZERO => l.a0 * y / l.b0,
            _ => y,
        };
        self.w = self.poly_inverse(v);
        self.u =
            (self.mbw.mu() / self.mbw.lambda() * self.w).clamp_to(self.volts_min, self.volts_max);
        self.e = T::ZERO;
        self.e_dot = T::ZERO;
        self.armed = false;
        self.y_start = y;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::Hysteresis;
    use core::f64::consts::PI;

    /// 004 identified WPMBW (section 4.2).
    fn model() -> Wpmbw<f64, 2> {
        Wpmbw::new(
            MbwRlm::new(0.6485, 0.7217, 0.7440).unwrap(),
            [0.9268, 0.0048],
        )
        .unwrap()
    }

    fn reference(t: f64) -> Setpoint<f64> {
        // 004 eq. (29) without the bias term's jump: starts at 1 mrad.
        let a = 3.45 * (-0.21 * t).exp();
        let ph = 2.0 * PI * t + 1.5 * PI;
        let y = a * (ph.sin() + 1.0) + 1.0;
        let dy = -0.21 * a * (ph.sin() + 1.0) + a * 2.0 * PI * ph.cos();
        Setpoint {
            y_um: y,
            dy,
            ddy: 0.0,
        }
    }

    #[test]
    fn direct_inverse_tracks_exact_static_model() {
        let m = model();
        let dt = 1e-3;
        let mut inv = WpmbwInverse::new(&m, None, None, -50.0, 50.0, dt).unwrap();
        let mut s = m.init(0.0);
        let mut max_err: f64 = 0.0;
        for k in 0..10_000 {
            let sp = reference(k as f64 * dt);
            let u = inv.compensate(&sp);
            let y = m.step(&mut s, u, dt);
            if k > 0 {
                max_err = max_err.max((y - sp.y_um).abs());
            }
        }
        // Limited by the forward model's RK4, not by the inverse.
        assert!(max_err < 1e-6, "{max_err}");
    }

    #[test]
    fn poly_inverse_is_cancellation_free() {
        let m = model();
        let inv = WpmbwInverse::new(&m, None, None, -50.0, 50.0, 1e-3).unwrap();
        for &w in &[1e-9, 1e-3, 0.5, 3.0, -2.0] {
            let v = m.poly(w);
            let back = inv.poly_inverse(v);
            assert!(
                (back - w).abs() <= 1e-15 * w.abs().max(1.0) * 4.0,
                "{w} {back}"
            );
        }
        // f32: the textbook form loses all digits for small v, this one none.
        let c1 = 0.9268f32;
        let c2 = 0.0048f32;
        let v = 1e-4f32;
        let textbook = (-c1 + (c1 * c1 + 4.0 * c2 * v).sqrt()) / (2.0 * c2);
        let m32 = Wpmbw::new(MbwRlm::new(0.6485f32, 0.7217, 0.7440).unwrap(), [c1, c2]).unwrap();
        let ours = WpmbwInverse::new(&m32, None, None, -50.0, 50.0, 1e-3)
            .unwrap()
            .poly_inverse(v);
        let exact = 2.0 * 1e-4 / (0.9268 + (0.9268f64.powi(2) + 4.0 * 0.0048 * 1e-4).sqrt());
        assert!(
            ((ours as f64) - exact).abs() < 1e-6 * exact,
            "{ours} vs {exact}"
        );
        assert!(
            ((textbook as f64) - exact).abs() > 1e-3 * exact,
            "{textbook} vs {exact}"
        );
    }

    #[test]
    fn linear_inverse_and_prefilter_track_hammerstein_model() {
        let m = model();
        let lin = LinearPart::second_order(2.0 * PI * 100.0, 0.8);
        let dt = 1e-4;
        let run = |linear: Option<LinearPart<f64>>| {
            let mut inv = WpmbwInverse::new(&m, linear, Some(100.0 * PI), -50.0, 50.0, dt).unwrap();
            let mut s = m.init(0.0);
            let (mut y, mut yd) = (0.0, 0.0);
            let mut se = 0.0;
            let n = 20_000;
            for k in 0..n {
                let t = k as f64 * dt;
                // 10 Hz sine around 3 mrad, derivatives exact
                let w = 2.0 * PI * 10.0;
                let sp = Setpoint {
                    y_um: 3.0 + 2.0 * (w * t).sin(),
                    dy: 2.0 * w * (w * t).cos(),
                    ddy: -2.0 * w * w * (w * t).sin(),
                };
                let u = inv.compensate(&sp);
                let v = m.step(&mut s, u, dt);
                // forward linear dynamics, fine semi-implicit Euler
                for _ in 0..20 {
                    let h = dt / 20.0;
                    let ydd = (lin.b0 * v - lin.a1 * yd - lin.a0 * y) / lin.a2;
                    yd += h * ydd;
                    y += h * yd;
                }
                if k >= n / 2 {
                    se += (y - sp.y_um).powi(2);
                }
            }
            (se / (n / 2) as f64).sqrt()
        };
        let with = run(Some(lin));
        let without = run(None);
        assert!(with < 0.05 * without, "{with} vs {without}");
        assert!(with < 5e-3, "{with}");
    }

    #[test]
    fn rejects_cubic_and_bad_filter() {
        let m3 = Wpmbw::new(MbwRlm::new(0.6, 0.7, 0.8).unwrap(), [0.8, 0.02, 0.001]).unwrap();
        assert!(WpmbwInverse::new(&m3, None, None, 0.0, 1.0, 1e-3)
            .unwrap_err()
            .0
            .contains("L = 1 or 2"));
        assert!(WpmbwInverse::new(&model(), None, Some(-1.0), 0.0, 1.0, 1e-3).is_err());
    }
}
