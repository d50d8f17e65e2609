//! Direct inverse of the WPMBW model with inverse linear dynamics and the full-pass
//! prefilter (004 eq. 17, 18, 27, 28).

use super::prefilter::FullPass;
use super::zpetc::Zpetc;
use super::{ensure, FfError};
use crate::hysteresis::phi;
use crate::hysteresis::{MbwRlm, Wpmbw};
use crate::real::Real;
use crate::signals::Setpoint;

/// Largest polynomial order `L` of 004 eq. (7) the inverse takes.
pub const MAX_POLY: usize = 4;

/// Newton steps of the polynomial inverse for `L >= 3` (each halves the bracket at worst).
const POLY_ITER: usize = 40;

/// The inverse linear dynamics of 004 eq. (27).
#[derive(Debug, Clone, PartialEq)]
pub enum InverseDynamics<T> {
    /// None (a static model).
    Static,
    /// `v = (a0*y + a1*y' + a2*y'')/b0` from the setpoint's derivatives: 004 eq. (27) with
    /// `n = 2`, its zeros ignored as 004 does.
    Derivatives(LinearPart<T>),
    /// Stable inversion of a model of any order with zeros anywhere (ZPETC); the setpoint
    /// must come [`Zpetc::preview`] samples ahead.
    Zpetc(Zpetc<T>),
}

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

/// Inverse WPMBW feedforward (004 eq. 27): `v_hat` from the inverse linear dynamics
/// ([`InverseDynamics`]), `w_hat` from the inverse polynomial (eq. 17 for `L <= 2`; for
/// `L >= 3`, which 004 leaves to Cardano or Newton, a safeguarded Newton iteration on the
/// monotone branch through `w = 0`), `u` from the inverse MBW (eq. 18).
///
/// Eq. (18) is, on a piece of fixed direction `s`, the linear ODE
/// `du/dw = 1/rho - s*lambda*u + s*mu*w`; it is integrated exactly over each sample's
/// `dw`: `du = (mu/lambda)*dw + (e0 - mu/lambda)*dw*phi(lambda*|dw|)`, `e0` the slope at
/// the start, `phi(x) = (1 - exp(-x))/x`. Eq. (17) is evaluated as
/// `w = 2*v / (c1 + sqrt(c1^2 + 4*c2*v))`, free of the cancellation of the textbook form.
#[derive(Debug, Clone, PartialEq)]
pub struct WpmbwInverse<T> {
    mbw: MbwRlm<T>,
    /// `c_1..c_L`, zero beyond `L`.
    c: [T; MAX_POLY],
    order: usize,
    /// `L >= 3`: the monotone branch through `w = 0` bracketed, `[w_lo, w_hi]` with
    /// `v(w_lo), v(w_hi)`.
    branch: [T; 4],
    dynamics: InverseDynamics<T>,
    prefilter: Option<FullPass<T>>,
    volts_min: T,
    volts_max: T,
    // state
    u: T,
    w: T,
}

impl<T: Real> WpmbwInverse<T> {
    /// `linear`: the identified second-order linear dynamics to invert from the setpoint's
    /// derivatives (None: static), `prefilter_wn`: natural frequency (rad/s) of the eq. (28)
    /// filter (None: no prefilter), `dt_s` the sample period. Starts at rest at 0 V.
    pub fn new<const L: usize>(
        model: &Wpmbw<T, L>,
        linear: Option<LinearPart<T>>,
        prefilter_wn: Option<T>,
        volts_min: T,
        volts_max: T,
        dt_s: T,
    ) -> Result<Self, FfError> {
        if let Some(l) = linear {
            ensure(
                [l.a0, l.a1, l.a2, l.b0].iter().all(|x| x.is_finite()) && l.b0 != T::ZERO,
                "WPMBW inverse: linear coefficients finite and b0 != 0",
            )?;
        }
        let dynamics = match linear {
            Some(l) => InverseDynamics::Derivatives(l),
            None => InverseDynamics::Static,
        };
        let prefilter = prefilter_wn
            .map(|wn| FullPass::eq28(wn, dt_s))
            .transpose()?;
        Self::with_dynamics(model, dynamics, prefilter, volts_min, volts_max, dt_s)
    }

    /// As [`WpmbwInverse::new`] with any [`InverseDynamics`], e.g. the ZPETC of 004's
    /// identified `n = 4, m = 2` model with its right-half-plane zeros, and any
    /// [`FullPass`] prefilter (eq. 28 or a smoother order for a high-order inverse).
    pub fn with_dynamics<const L: usize>(
        model: &Wpmbw<T, L>,
        dynamics: InverseDynamics<T>,
        prefilter: Option<FullPass<T>>,
        volts_min: T,
        volts_max: T,
        dt_s: T,
    ) -> Result<Self, FfError> {
        super::check_range_dt(volts_min, volts_max, dt_s)?;
        ensure(
            (1..=MAX_POLY).contains(&L),
            "WPMBW inverse: polynomial order L = 1 ..= MAX_POLY",
        )?;
        let mut c = [T::ZERO; MAX_POLY];
        c[..L].copy_from_slice(model.coefficients());
        ensure(
            c[0] > T::ZERO,
            "WPMBW inverse: c1 > 0 (v increasing in w at w = 0)",
        )?;
        ensure(
            c.iter().all(|x| x.is_finite()),
            "WPMBW inverse: coefficients must be finite",
        )?;
        // Trailing zero coefficients do not count (a fitted c_3 = 0 is order 2).
        let order = c.iter().rposition(|x| *x != T::ZERO).map_or(1, |i| i + 1);
        let mbw = *model.mbw();
        let branch = if order >= 3 {
            monotone_branch(&c[..order], &mbw, volts_min, volts_max)?
        } else {
            [T::ZERO; 4]
        };
        let mut s = Self {
            mbw,
            c,
            order,
            branch,
            dynamics,
            prefilter,
            volts_min,
            volts_max,
            u: T::ZERO,
            w: T::ZERO,
        };
        s.reset_volts(T::ZERO);
        Ok(s)
    }

    /// Samples the setpoint must come ahead of the sample it is for (ZPETC's preview).
    pub fn preview(&self) -> usize {
        match &self.dynamics {
            InverseDynamics::Zpetc(z) => z.preview(),
            _ => 0,
        }
    }

    /// `v = sum c_i w^i` (004 eq. 7).
    #[inline]
    fn poly(&self, w: T) -> T {
        self.c
            .iter()
            .take(self.order)
            .rev()
            .fold(T::ZERO, |acc, &c| (acc + c) * w)
    }

    /// 004 eq. (17), cancellation free; outside the invertible range (past the vertex of
    /// the parabola) the vertex. For `L >= 3` the root on the monotone branch through
    /// `w = 0` (bracketed at construction), by Newton steps kept inside the bracket,
    /// warm-started from the last `w`; outside the branch its end.
    #[inline]
    pub fn poly_inverse(&self, v: T) -> T {
        let (c1, c2) = (self.c[0], self.c[1]);
        if self.order >= 3 {
            return self.poly_newton(v);
        }
        if c2 == T::ZERO {
            return v / c1;
        }
        let vertex = -c1 * c1 / (T::from_f64(4.0) * c2);
        let v = if c2 > T::ZERO {
            v.max(vertex)
        } else {
            v.min(vertex)
        };
        let disc = (c1 * c1 + T::from_f64(4.0) * c2 * v).max(T::ZERO);
        T::TWO * v / (c1 + disc.sqrt())
    }

    fn poly_newton(&self, v: T) -> T {
        let [mut lo, mut hi, v_lo, v_hi] = self.branch;
        if !(v > v_lo) {
            return lo;
        }
        if !(v < v_hi) {
            return hi;
        }
        let tol = T::EPSILON * T::from_f64(8.0) * (v.abs() + T::ONE);
        let mut w = self.w.clamp_to(lo, hi);
        for _ in 0..POLY_ITER {
            let f = self.poly(w) - v;
            if f.abs() <= tol {
                break;
            }
            if f > T::ZERO {
                hi = w;
            } else {
                lo = w;
            }
            let slope = self
                .c
                .iter()
                .take(self.order)
                .enumerate()
                .rev()
                .fold(T::ZERO, |acc, (i, &c)| acc * w + T::from_usize(i + 1) * c);
            let step = w - f / slope;
            // Newton inside the bracket, else bisection.
            w = if step > lo && step < hi {
                step
            } else {
                T::HALF * (lo + hi)
            };
        }
        w
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
        // 004 eq. (28): y_d = y_r + e.
        let (y_d, dy_d, ddy_d) = match &mut self.prefilter {
            Some(f) => f.apply(sp),
            None => (y_r, fin(sp.dy), fin(sp.ddy)),
        };
        // 004 eq. (27), third line.
        let v = match &mut self.dynamics {
            InverseDynamics::Static => y_d,
            InverseDynamics::Derivatives(l) => (l.a0 * y_d + l.a1 * dy_d + l.a2 * ddy_d) / l.b0,
            InverseDynamics::Zpetc(z) => z.command(y_d),
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
        self.u = super::rest_volts(u0, self.volts_min, self.volts_max);
        self.w = T::ZERO;
        if let InverseDynamics::Zpetc(z) = &mut self.dynamics {
            z.reset(T::ZERO);
        }
        if let Some(f) = &mut self.prefilter {
            f.restart(T::ZERO);
        }
    }

    /// Restart at the setpoint: the stage is assumed at rest there (`w` from eq. 17, `u`
    /// on the band centre `mu/lambda*w`), and the prefilter starts on the reference.
    pub fn reset(&mut self, y_um: T) {
        let y = if y_um.is_finite() { y_um } else { T::ZERO };
        let v = match &mut self.dynamics {
            InverseDynamics::Derivatives(l) if l.a0 != T::ZERO => l.a0 * y / l.b0,
            InverseDynamics::Zpetc(z) => {
                z.reset(y);
                z.dc_input(y)
            }
            _ => y,
        };
        self.w = self.poly_inverse(v);
        self.u =
            (self.mbw.mu() / self.mbw.lambda() * self.w).clamp_to(self.volts_min, self.volts_max);
        if let Some(f) = &mut self.prefilter {
            f.restart(y);
        }
    }
}

/// The monotone branch of `v(w) = sum c_i w^i` through `w = 0` (between the nearest real
/// roots of `v'`), limited to twice the MBW output bound over the voltage range (004
/// eq. 16), as `[w_lo, w_hi, v(w_lo), v(w_hi)]`. Construction time, f64.
fn monotone_branch<T: Real>(
    c: &[T],
    mbw: &MbwRlm<T>,
    volts_min: T,
    volts_max: T,
) -> Result<[T; 4], FfError> {
    use crate::linear::poly::{roots, Complex, MAX_DEGREE};
    let mut dc = [0.0f64; MAX_POLY];
    for (i, ci) in c.iter().enumerate() {
        dc[i] = (i + 1) as f64 * ci.to_f64();
    }
    let mut r = [Complex::default(); MAX_DEGREE];
    let nr = roots(&dc[..c.len()], &mut r)?;
    let (rho, lambda, mu) = (mbw.rho().to_f64(), mbw.lambda().to_f64(), mbw.mu().to_f64());
    let umax = libm::fmax(
        libm::fabs(volts_min.to_f64()),
        libm::fabs(volts_max.to_f64()),
    );
    let wb = 2.0 * (lambda / mu * umax + libm::fabs((lambda - rho * mu) / (rho * mu * lambda)));
    let (mut lo, mut hi) = (-wb, wb);
    for z in r[..nr].iter().filter(|z| z.im == 0.0) {
        if z.re > 0.0 {
            hi = libm::fmin(hi, z.re);
        } else if z.re < 0.0 {
            lo = libm::fmax(lo, z.re);
        }
    }
    let poly = |w: f64| c.iter().rev().fold(0.0, |acc, ci| (acc + ci.to_f64()) * w);
    let out = [lo, hi, poly(lo), poly(hi)];
    ensure(
        lo < 0.0 && hi > 0.0 && out.iter().all(|x| x.is_finite()),
        "WPMBW inverse: no monotone branch of the polynomial through w = 0",
    )?;
    Ok(out.map(T::from_f64))
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
    fn inverts_any_fitted_order_and_rejects_bad_filter() {
        // The fit's WPMBW is cubic (004 eq. 7 with L = 3); L = 4 too; a cubic with a
        // negative c3 has a bounded monotone branch.
        let mbw = MbwRlm::new(0.6, 0.7, 0.8).unwrap();
        let dt = 1e-3;
        for c in [
            [0.8, 0.02, 0.001, 0.0],
            [0.8, -0.02, 0.004, 1e-4],
            [0.9, 0.01, -0.002, 0.0],
        ] {
            let m4 = Wpmbw::new(mbw, c).unwrap();
            let mut inv = WpmbwInverse::new(&m4, None, None, -20.0, 20.0, dt).unwrap();
            for &w in &[-3.0, -0.5, 1e-6, 0.7, 4.0] {
                let back = inv.poly_inverse(m4.poly(w));
                assert!(
                    (back - w).abs() < 1e-12 * w.abs().max(1.0),
                    "{c:?} {w} {back}"
                );
            }
            // The whole inverse tracks the exact model.
            let mut s = m4.init(0.0);
            let mut worst = 0.0f64;
            for k in 1..5000 {
                let t = k as f64 * dt;
                let sp = Setpoint::hold(4.0 * (2.0 * PI * t).sin() + 2.0 * (7.0 * t).sin());
                let u = inv.compensate(&sp);
                worst = worst.max((m4.step(&mut s, u, dt) - sp.y_um).abs());
            }
            assert!(worst < 1e-6, "{c:?}: {worst}");
        }
        let m5 = Wpmbw::new(mbw, [0.8, 0.02, 0.001, 0.0, 1e-5]).unwrap();
        assert!(WpmbwInverse::new(&m5, None, None, 0.0, 1.0, 1e-3)
            .unwrap_err()
            .0
            .contains("MAX_POLY"));
        assert!(WpmbwInverse::new(&model(), None, Some(-1.0), 0.0, 1.0, 1e-3).is_err());
    }
}
