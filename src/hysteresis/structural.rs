//! Structural Bouc-Wen oscillator (003 eq. 1; the Bouc-Wen benchmark form).
//!
//! A mass on a linear spring and damper in parallel with a Bouc-Wen hysteretic force `z`,
//! driven by the force `u`; the output is the displacement `y`:
//! ```text
//! m y'' + c y' + k y + z = u
//! z' = alpha y' - beta (gamma |y'| |z|^(nu-1) z + delta y' |z|^nu)
//! ```
//! (003 eq. (1) with the restoring force split as in the benchmark of Noel & Schoukens 2016.)
//! Unlike the rate-independent models of this module the oscillator has inertia, so it is
//! integrated in time: classical RK4 on `(y, y', z)` with a fixed number of sub-steps per
//! sample and the input held (ZOH) or interpolated linearly (FOH) inside the sample.

use super::{ensure, ensure_finite, sane_input, Hysteresis, ParamError};
use crate::real::Real;

/// How the input moves between two samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Hold {
    /// Held at the previous sample (zero-order hold, a DAC).
    Zero,
    /// Linear from the previous to the new sample (first-order hold).
    #[default]
    First,
}

/// Time integration of the oscillator between samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Integrator {
    /// Classical RK4 (4th order).
    #[default]
    Rk4,
    /// Newmark average acceleration (`a = 0.5, b = 0.25`) with the trapezoidal rule for `z`
    /// (`c = 0.5`), solved by Newton-Raphson: the scheme that generated the Bouc-Wen
    /// benchmark data (Noel & Schoukens 2016, eq. 4-5). 2nd order, unconditionally stable.
    Newmark,
}

/// Newton-Raphson iterations per Newmark step (quadratic convergence; bounded work).
const NEWTON_ITERATIONS: usize = 8;

/// Structural Bouc-Wen oscillator parameters (SI units in the benchmark: kg, N s/m, N/m,
/// N/m, 1/m^nu ...). Only finiteness, `m > 0`, `c, k >= 0`-free signs are not imposed
/// beyond what keeps the integration defined: `m > 0`, `beta >= 0`, `nu >= 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StructuralBw<T> {
    m: T,
    c: T,
    k: T,
    alpha: T,
    beta: T,
    gamma: T,
    delta: T,
    nu: T,
    substeps: usize,
    hold: Hold,
    integrator: Integrator,
    inv_m: T,
}

/// State of the oscillator.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StructuralState<T> {
    /// Last input (N).
    pub u: T,
    /// Displacement (m).
    pub y: T,
    /// Velocity (m/s).
    pub v: T,
    /// Hysteretic force (N).
    pub z: T,
}

/// Upper bound of RK4 sub-steps per sample.
pub const MAX_STRUCTURAL_SUBSTEPS: usize = 1000;

impl<T: Real> StructuralBw<T> {
    /// Benchmark form (see the module doc). `substeps` RK4 steps per sample (1..=1000).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        m: T,
        c: T,
        k: T,
        alpha: T,
        beta: T,
        gamma: T,
        delta: T,
        nu: T,
        substeps: usize,
        hold: Hold,
    ) -> Result<Self, ParamError> {
        ensure_finite(
            &[m, c, k, alpha, beta, gamma, delta, nu],
            "structural BW: all parameters must be finite",
        )?;
        ensure(m > T::ZERO, "structural BW: mass m > 0")?;
        ensure(beta >= T::ZERO, "structural BW: beta >= 0")?;
        ensure(nu >= T::ONE, "structural BW: nu >= 1")?;
        ensure(
            (1..=MAX_STRUCTURAL_SUBSTEPS).contains(&substeps),
            "structural BW: substeps in 1..=1000",
        )?;
        Ok(Self {
            m,
            c,
            k,
            alpha,
            beta,
            gamma,
            delta,
            nu,
            substeps,
            hold,
            integrator: Integrator::Rk4,
            inv_m: T::ONE / m,
        })
    }

    /// The same oscillator integrated with `integrator`.
    pub fn with_integrator(mut self, integrator: Integrator) -> Self {
        self.integrator = integrator;
        self
    }

    pub fn integrator(&self) -> Integrator {
        self.integrator
    }

    /// `z'` and its partial derivatives in `v` and `z`.
    #[inline(always)]
    fn dz(&self, v: T, z: T) -> (T, T, T) {
        let za = z.abs();
        let zn = za.abs_pow(self.nu);
        // |z|^(nu-1), with 0^0 = 1 for nu = 1
        let zn1 = if self.nu == T::ONE {
            T::ONE
        } else {
            za.abs_pow(self.nu - T::ONE)
        };
        let sz = z.sgn();
        let f = self.alpha * v - self.beta * (self.gamma * v.abs() * sz * zn + self.delta * v * zn);
        let df_dv = self.alpha - self.beta * (self.gamma * v.sgn() * sz * zn + self.delta * zn);
        let df_dz = -self.beta * self.nu * zn1 * (self.gamma * v.abs() + self.delta * v * sz);
        (f, df_dv, df_dz)
    }

    /// One Newmark step of length `h` to input `u1` (benchmark eq. 4-5).
    #[inline]
    fn newmark(&self, y: &mut T, v: &mut T, z: &mut T, u0: T, u1: T, h: T) {
        let q = T::from_f64(0.25);
        let a0 = (u0 - self.c * *v - self.k * *y - *z) * self.inv_m;
        let (zd0, _, _) = self.dz(*v, *z);
        // Predictor: a1 = 0, z' = 0 at the end of the step.
        let mut a1 = T::ZERO;
        let mut z1 = *z + T::HALF * h * zd0;
        for _ in 0..NEWTON_ITERATIONS {
            let v1 = *v + T::HALF * h * (a0 + a1);
            let y1 = *y + h * *v + q * h * h * (a0 + a1);
            let (zd1, dv, dzz) = self.dz(v1, z1);
            let r1 = self.m * a1 + self.c * v1 + self.k * y1 + z1 - u1;
            let r2 = z1 - *z - T::HALF * h * (zd0 + zd1);
            let j11 = self.m + self.c * T::HALF * h + self.k * q * h * h;
            let j21 = -T::HALF * h * dv * T::HALF * h;
            let j22 = T::ONE - T::HALF * h * dzz;
            let det = j11 * j22 - j21; // j12 = 1
            if !(det.abs() > T::ZERO) || !det.is_finite() {
                break;
            }
            let da = (r1 * j22 - r2) / det;
            let dzs = (j11 * r2 - j21 * r1) / det;
            a1 -= da;
            z1 -= dzs;
            if da.abs() <= T::EPSILON * (T::ONE + a1.abs())
                && dzs.abs() <= T::EPSILON * (T::ONE + z1.abs())
            {
                break;
            }
        }
        let sa = a0 + a1;
        *y += h * *v + q * h * h * sa;
        *v += T::HALF * h * sa;
        *z = z1;
    }

    /// The benchmark system of Noel & Schoukens (2016), Table 1.
    pub fn benchmark(substeps: usize, hold: Hold) -> Result<Self, ParamError> {
        let f = T::from_f64;
        Self::new(
            f(2.0),
            f(10.0),
            f(5e4),
            f(5e4),
            f(1e3),
            f(0.8),
            f(-1.1),
            T::ONE,
            substeps,
            hold,
        )
    }

    /// `[m, c, k, alpha, beta, gamma, delta, nu]`.
    pub fn params(&self) -> [T; 8] {
        [
            self.m, self.c, self.k, self.alpha, self.beta, self.gamma, self.delta, self.nu,
        ]
    }

    pub fn substeps(&self) -> usize {
        self.substeps
    }

    pub fn hold(&self) -> Hold {
        self.hold
    }

    /// Time derivative of `(y, v, z)` at input force `u`.
    #[inline(always)]
    fn deriv(&self, v: T, z: T, y: T, u: T) -> (T, T, T) {
        let a = (u - self.c * v - self.k * y - z) * self.inv_m;
        let zn = z.abs_pow(self.nu); // |z|^nu
                                     // |z|^(nu-1) z = sgn(z) |z|^nu
        let dz = self.alpha * v
            - self.beta * (self.gamma * v.abs() * z.sgn() * zn + self.delta * v * zn);
        (v, a, dz)
    }

    /// Advances `s` over `dt` to input `u`.
    #[inline]
    fn advance(&self, s: &mut StructuralState<T>, u: T, dt: T) {
        let n = self.substeps;
        let h = dt / T::from_usize(n);
        let half = h * T::HALF;
        let sixth = h / T::from_f64(6.0);
        let (u0, du) = match self.hold {
            Hold::Zero => (s.u, T::ZERO),
            Hold::First => (s.u, (u - s.u) / T::from_usize(n)),
        };
        let (mut y, mut v, mut z) = (s.y, s.v, s.z);
        if self.integrator == Integrator::Newmark {
            for i in 0..n {
                let ua = u0 + du * T::from_usize(i);
                let ub = match self.hold {
                    Hold::Zero => ua,
                    Hold::First => ua + du,
                };
                self.newmark(&mut y, &mut v, &mut z, ua, ub, h);
            }
            s.y = y;
            s.v = v;
            s.z = z;
            s.u = u;
            return;
        }
        for i in 0..n {
            let ua = u0 + du * T::from_usize(i);
            let um = ua + du * T::HALF;
            let ub = ua + du;
            let (k1y, k1v, k1z) = self.deriv(v, z, y, ua);
            let (k2y, k2v, k2z) = self.deriv(v + half * k1v, z + half * k1z, y + half * k1y, um);
            let (k3y, k3v, k3z) = self.deriv(v + half * k2v, z + half * k2z, y + half * k2y, um);
            let (k4y, k4v, k4z) = self.deriv(v + h * k3v, z + h * k3z, y + h * k3y, ub);
            y += sixth * (k1y + T::TWO * (k2y + k3y) + k4y);
            v += sixth * (k1v + T::TWO * (k2v + k3v) + k4v);
            z += sixth * (k1z + T::TWO * (k2z + k3z) + k4z);
        }
        s.y = y;
        s.v = v;
        s.z = z;
        s.u = u;
    }
}

impl<T: Real> Hysteresis<T> for StructuralBw<T> {
    type State = StructuralState<T>;

    /// At rest: zero displacement, velocity and hysteretic force.
    fn init(&self, u0: T) -> StructuralState<T> {
        StructuralState {
            u: sane_input(u0, T::ZERO),
            ..Default::default()
        }
    }

    /// Non-finite `u` or `dt` hold the state. A parameter set whose response diverges
    /// returns non-finite outputs (the identification rejects it); the state then restarts
    /// from rest so it never stays poisoned.
    #[inline]
    fn step(&self, s: &mut StructuralState<T>, u: T, dt: T) -> T {
        let u = sane_input(u, s.u);
        if !(dt > T::ZERO) || !dt.is_finite() {
            return s.y;
        }
        self.advance(s, u, dt);
        let y = s.y;
        if !(y.is_finite() && s.v.is_finite() && s.z.is_finite()) {
            *s = self.init(u);
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::assert_refused;

    fn sine(n: usize, fs: f64, f: f64, a: f64) -> Vec<f64> {
        (0..n)
            .map(|i| a * (2.0 * core::f64::consts::PI * f * i as f64 / fs).sin())
            .collect()
    }

    fn simulate(m: &StructuralBw<f64>, u: &[f64], dt: f64) -> Vec<f64> {
        let mut s = m.init(0.0);
        u.iter().map(|&u| m.step(&mut s, u, dt)).collect()
    }

    #[test]
    fn rejects_bad_parameters() {
        let bad = |m, beta, nu, n| {
            StructuralBw::new(m, 10.0, 5e4, 5e4, beta, 0.8, -1.1, nu, n, Hold::First)
        };
        assert_refused(bad(0.0, 1e3, 1.0, 4), "structural BW: mass m > 0");
        assert_refused(bad(2.0, -1.0, 1.0, 4), "structural BW: beta >= 0");
        assert_refused(bad(2.0, 1e3, 0.5, 4), "structural BW: nu >= 1");
        assert!(bad(2.0, 1e3, 1.0, 0).is_err());
        assert!(bad(f64::NAN, 1e3, 1.0, 4).is_err());
        assert!(bad(2.0, 1e3, 1.0, 4).is_ok());
    }

    #[test]
    fn linear_case_matches_static_gain_and_resonance() {
        // beta = 0: a linear oscillator with stiffness k + alpha.
        let m =
            StructuralBw::new(2.0, 10.0, 5e4, 5e4, 0.0, 0.8, -1.1, 1.0, 4, Hold::First).unwrap();
        let fs = 750.0;
        // Slow sine: y = u / (k + alpha).
        let u = sine(30_000, fs, 0.5, 100.0);
        let y = simulate(&m, &u, 1.0 / fs);
        let gain = y[20_000..].iter().cloned().fold(0.0f64, f64::max) / 100.0;
        assert!((gain - 1e-5).abs() < 1e-8, "{gain}");
        // Free decay frequency: sqrt((k + alpha) / m) / 2 pi = 35.59 Hz (benchmark Table 2).
        // z = alpha y: the hysteretic spring is relaxed at the start.
        let mut s = StructuralState {
            y: 1e-3,
            z: 50.0,
            ..m.init(0.0)
        };
        let mut prev = s.y;
        let mut crossings = Vec::new();
        for i in 0..7500 {
            let y = m.step(&mut s, 0.0, 1.0 / fs);
            if prev < 0.0 && y >= 0.0 {
                crossings.push(i as f64 - y / (y - prev));
            }
            prev = y;
        }
        let periods = (crossings.len() - 1) as f64;
        let f = periods / ((crossings[crossings.len() - 1] - crossings[0]) / fs);
        let f_damped = 35.59 * (1.0f64 - 0.0112 * 0.0112).sqrt();
        assert!((f - f_damped).abs() < 0.02, "{f}");
    }

    #[test]
    fn substeps_converge_and_hold_matters() {
        let fs = 750.0;
        let u = sine(3000, fs, 20.0, 60.0);
        let fine = simulate(
            &StructuralBw::benchmark(200, Hold::First).unwrap(),
            &u,
            1.0 / fs,
        );
        let coarse = simulate(
            &StructuralBw::benchmark(20, Hold::First).unwrap(),
            &u,
            1.0 / fs,
        );
        let zoh = simulate(
            &StructuralBw::benchmark(20, Hold::Zero).unwrap(),
            &u,
            1.0 / fs,
        );
        let err = |a: &[f64]| {
            a.iter()
                .zip(&fine)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        };
        let amp = fine.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!(amp > 1e-4, "{amp}");
        assert!(err(&coarse) < 1e-5 * amp, "{}", err(&coarse));
        assert!(err(&zoh) > 1e-2 * amp, "{}", err(&zoh));
    }

    #[test]
    fn newmark_converges_to_rk4_at_second_order() {
        let fs = 750.0;
        let u = sine(1500, fs, 30.0, 60.0);
        let rk4 = simulate(
            &StructuralBw::benchmark(100, Hold::First).unwrap(),
            &u,
            1.0 / fs,
        );
        let nm = |n| {
            let m = StructuralBw::benchmark(n, Hold::First)
                .unwrap()
                .with_integrator(Integrator::Newmark);
            let y = simulate(&m, &u, 1.0 / fs);
            y.iter()
                .zip(&rk4)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        };
        let (e20, e40) = (nm(20), nm(40));
        let amp = rk4.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!(e20 < 1e-2 * amp, "{e20} {amp}");
        // Halving the step quarters the error.
        assert!((e20 / e40 - 4.0).abs() < 0.5, "{e20} {e40}");
    }

    #[test]
    fn hysteresis_loop_is_open_and_bounded() {
        // Quasi-static 1 Hz, 120 N (benchmark Fig. 1a): loop around +-1 mm.
        let fs = 750.0;
        let m = StructuralBw::benchmark(2, Hold::First).unwrap();
        let u = sine(3000, fs, 1.0, 120.0);
        let y = simulate(&m, &u, 1.0 / fs);
        let peak = y[750..].iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!(peak > 0.5e-3 && peak < 1.5e-3, "{peak}");
        // At u = 0 rising vs falling, y differs (open loop).
        let rising = y[1500]; // u(2 s) = 0, rising
        let falling = y[1875]; // u(2.5 s) = 0, falling
        assert!((rising - falling).abs() > 1e-4, "{rising} {falling}");
    }

    #[test]
    fn survives_nan_and_divergence() {
        let m = StructuralBw::benchmark(2, Hold::First).unwrap();
        let mut s = m.init(0.0);
        m.step(&mut s, 10.0, 1e-3);
        let before = s;
        assert!(m.step(&mut s, 10.0, f64::NAN).is_finite());
        assert_eq!(s, before);
        m.step(&mut s, f64::INFINITY, 1e-3);
        assert!(s.y.is_finite() && s.u == 10.0);
        // Unstable parameters: the state restarts instead of staying NaN.
        let wild =
            StructuralBw::new(1e-9, -1e9, -1e9, 1.0, 0.0, 0.0, 0.0, 1.0, 1, Hold::First).unwrap();
        let mut s = wild.init(0.0);
        for _ in 0..100 {
            wild.step(&mut s, 1.0, 1.0);
        }
        assert!(s.y.is_finite() && s.v.is_finite() && s.z.is_finite());
    }
}
