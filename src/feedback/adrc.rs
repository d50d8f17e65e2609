//! Extended-state observer (ESO) and ADRC law, 000 eq. (10)-(11).
//!
//! Plant of 000 (Dahl section): `y'' = -a1 y' - a2 y + b0 (d_p u - h) + delta_y`. With
//! `b = b0*d_p` known, everything else is the total disturbance
//! `Delta = -a1 y' - a2 y - b0 h + delta_y`, so `y'' = Delta + b u`. The Dahl model bounds
//! `|h| <= h_c`, so `Delta` is bounded and the ESO can track it. (Eq. 10 writes `d_p u`
//! inside `Delta` and `B u` outside; here `b u` is the known input channel and `Delta` the
//! rest, which is what the ADRC law (11) divides by `b0 d_p` for.)
//!
//! As in the seed, the ESO (eq. 10) is the chain `y' = y', y'' = Delta + b u, Delta' = 0`
//! when `a1 = a2 = 0` (the `adrc` of `piezo sim` and the firmware), and the law (eq. 11)
//! `u = (y_d'' + lambda1 (y_d' - y'^) + lambda0 (y_d - y) - Delta^) / b` takes the measured
//! `y` in its position term and the ESO's `y'^` and `Delta^`. With a known structure
//! (`a1, a2 > 0`) the ESO estimates only the rest of `Delta` and the law adds the known part
//! back, `+ a1 y'^ + a2 y`.
//!
//! # Discretisation (stable for every `eps > 0`)
//! The chain `y, y', Delta` is discretised exactly (zero-order hold of `u`), and the
//! correction is a current estimator with `y[k]` whose gains put all three poles of the
//! discrete error matrix `(I - L C) Ad` at `beta = exp(-dt/eps)`: the exact image of the
//! continuous design `L(eps) = (3/eps, 3/eps^2, 1/eps^3)` (triple pole at `-1/eps`):
//! `l1 = 1 - beta^3`, `l2 = 3 (1-beta)^2 (1+beta) / (2 dt)`, `l3 = (1-beta)^3 / dt^2`.

use super::guard::InputGuard;
use crate::hysteresis::{ensure, ensure_finite, ParamError};
use crate::real::Real;
use crate::signals::LoopSignals;

/// ADRC configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdrcConfig<T> {
    /// Input gain `b = b0*d_p` (um/(s^2 V)).
    pub b: T,
    /// Known linear structure `y'' = -a1 y' - a2 y + ...` (1/s, 1/s^2); zeros give the plain
    /// chain-of-integrators ESO. With them the ESO only has to estimate what the linear
    /// model leaves over: `-b0 h + delta_y`, bounded by the Dahl model's `b0 h_c`.
    pub a1: T,
    pub a2: T,
    /// ESO `epsilon` (s): triple observer pole at `-1/eps`.
    pub eps_s: T,
    /// Closed-loop bandwidth `omega_c` (rad/s): `lambda0 = omega_c^2`, `lambda1 = 2 omega_c`.
    pub omega_c: T,
    /// Add `io.u_ff`; the ESO then estimates what the feedforward leaves over.
    pub feedforward: bool,
    /// Sample period (s).
    pub dt_s: T,
}

/// ESO + ADRC law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Adrc<T> {
    cfg: AdrcConfig<T>,
    l: [T; 3],
    lambda0: T,
    lambda1: T,
    state: AdrcState<T>,
    pub(crate) guard: InputGuard<T>,
}

/// ESO estimates `(y, y', Delta)` and the feedforward of the previous sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AdrcState<T> {
    pub z: [T; 3],
    pub u_ff_prev: T,
    pub fresh: bool,
}

impl<T: Real> Adrc<T> {
    pub fn new(cfg: AdrcConfig<T>) -> Result<Self, ParamError> {
        ensure_finite(
            &[cfg.b, cfg.a1, cfg.a2, cfg.eps_s, cfg.omega_c, cfg.dt_s],
            "ADRC: parameters must be finite",
        )?;
        ensure(cfg.b > T::ZERO, "ADRC: input gain b = b0*d_p > 0")?;
        ensure(
            cfg.a1 >= T::ZERO && cfg.a2 >= T::ZERO,
            "ADRC: a1 >= 0 and a2 >= 0 (stable linear part)",
        )?;
        ensure(cfg.eps_s > T::ZERO, "ADRC: eps_s > 0")?;
        ensure(cfg.omega_c > T::ZERO, "ADRC: omega_c > 0")?;
        ensure(cfg.dt_s > T::ZERO, "ADRC: dt_s > 0")?;
        let dt = cfg.dt_s;
        let beta = (-dt / cfg.eps_s).exp();
        let m = T::ONE - beta;
        let l = [
            T::ONE - beta * beta * beta,
            T::from_f64(1.5) * m * m * (T::ONE + beta) / dt,
            m * m * m / (dt * dt),
        ];
        ensure(
            l.iter().all(|x| x.is_finite()),
            "ADRC: eps_s or dt_s out of range for this number type",
        )?;
        Ok(Self {
            cfg,
            l,
            lambda0: cfg.omega_c * cfg.omega_c,
            lambda1: T::TWO * cfg.omega_c,
            state: AdrcState {
                fresh: true,
                ..Default::default()
            },
            guard: InputGuard::default(),
        })
    }

    pub fn config(&self) -> &AdrcConfig<T> {
        &self.cfg
    }
    pub fn state(&self) -> &AdrcState<T> {
        &self.state
    }
    pub fn gains(&self) -> [T; 3] {
        self.l
    }

    /// Error-propagation matrix `(I - L C) Ad` (row major).
    pub fn error_matrix(&self) -> [[T; 3]; 3] {
        let dt = self.cfg.dt_s;
        let ad = [
            [T::ONE, dt, dt * dt * T::HALF],
            [T::ZERO, T::ONE, dt],
            [T::ZERO, T::ZERO, T::ONE],
        ];
        let mut f = ad;
        for (fi, li) in f.iter_mut().zip(self.l.iter()) {
            for (fij, a0j) in fi.iter_mut().zip(ad[0].iter()) {
                *fij -= *li * *a0j;
            }
        }
        f
    }

    /// One ESO step with the input `u_fb` applied since the last sample and measurement `y`.
    #[inline]
    fn observe(&mut self, y: T, u_fb: T) {
        let dt = self.cfg.dt_s;
        let z = &mut self.state.z;
        // Known linear part at the current estimates (semi-implicit; its poles are far
        // below the observer's), the rest is the extended state.
        let acc = z[2] + self.cfg.b * u_fb - self.cfg.a1 * z[1] - self.cfg.a2 * z[0];
        let p0 = z[0] + dt * z[1] + dt * dt * T::HALF * acc;
        let p1 = z[1] + dt * acc;
        let e = y - p0;
        z[0] = p0 + self.l[0] * e;
        z[1] = p1 + self.l[1] * e;
        z[2] += self.l[2] * e;
    }

    #[inline]
    pub fn update(&mut self, io: &LoopSignals<T>) -> T {
        let io = self.guard.clean(io);
        if self.state.fresh {
            self.prime(&io);
            return io.u_applied;
        }
        let ff = if self.cfg.feedforward {
            io.u_ff
        } else {
            T::ZERO
        };
        // The ESO sees the part of the applied voltage the feedforward did not supply.
        let u_fb_applied = io.u_applied - self.state.u_ff_prev;
        self.observe(io.y_um, u_fb_applied);
        self.state.u_ff_prev = ff;
        let z = self.state.z;
        let sp = &io.setpoint;
        // 000 eq. (11): the measured y in the position term, the ESO's y' and Delta (and,
        // with a known linear structure, its part of Delta evaluated at the same signals).
        let u_fb = (sp.ddy + self.lambda1 * (sp.dy - z[1]) + self.lambda0 * (sp.y_um - io.y_um)
            - z[2]
            + self.cfg.a1 * z[1]
            + self.cfg.a2 * io.y_um)
            / self.cfg.b;
        let u = ff + u_fb;
        if u.is_finite() && z.iter().all(|v| v.is_finite()) {
            u
        } else {
            self.prime(&io);
            io.u_applied
        }
    }

    /// At rest at `y` with `u_applied`: `Delta = a2 y - b u_fb`.
    fn prime(&mut self, io: &LoopSignals<T>) {
        let ff = if self.cfg.feedforward {
            io.u_ff
        } else {
            T::ZERO
        };
        self.state = AdrcState {
            z: [
                io.y_um,
                T::ZERO,
                self.cfg.a2 * io.y_um - self.cfg.b * (io.u_applied - ff),
            ],
            u_ff_prev: ff,
            fresh: false,
        };
    }

    /// Bumpless: the next command is `u_applied`, the ESO starts at rest at `y`.
    pub fn reset(&mut self, _io: &LoopSignals<T>) {
        self.state.fresh = true;
        self.guard.restart();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn char_poly3(f: [[f64; 3]; 3]) -> [f64; 3] {
        // z^3 + c2 z^2 + c1 z + c0
        let tr = f[0][0] + f[1][1] + f[2][2];
        let m2 = f[0][0] * f[1][1] - f[0][1] * f[1][0] + f[0][0] * f[2][2] - f[0][2] * f[2][0]
            + f[1][1] * f[2][2]
            - f[1][2] * f[2][1];
        let det = f[0][0] * (f[1][1] * f[2][2] - f[1][2] * f[2][1])
            - f[0][1] * (f[1][0] * f[2][2] - f[1][2] * f[2][0])
            + f[0][2] * (f[1][0] * f[2][1] - f[1][1] * f[2][0]);
        [-tr, m2, -det]
    }

    #[test]
    fn eso_poles_are_the_mapped_triple_pole() {
        for &eps in &[1e-5, 1e-4, 1e-3] {
            let a = Adrc::new(AdrcConfig {
                b: 1e7,
                a1: 0.0,
                a2: 0.0,
                eps_s: eps,
                omega_c: 1000.0,
                feedforward: false,
                dt_s: 1e-5,
            })
            .unwrap();
            let beta = (-1e-5f64 / eps).exp();
            let c = char_poly3(a.error_matrix());
            let want = [-3.0 * beta, 3.0 * beta * beta, -beta * beta * beta];
            for (ci, wi) in c.iter().zip(want.iter()) {
                assert!((ci - wi).abs() < 1e-9, "eps {eps}: {c:?} vs {want:?}");
            }
        }
    }

    /// Eq. (11) takes the measured `y` in its position term (not the ESO's `y^`).
    #[test]
    fn law_uses_the_measured_position() {
        let cfg = AdrcConfig {
            b: 1e7,
            a1: 0.0,
            a2: 0.0,
            eps_s: 2e-4,
            omega_c: 1000.0,
            feedforward: false,
            dt_s: 1e-5,
        };
        let mut a = Adrc::new(cfg).unwrap();
        let io = |y: f64| LoopSignals {
            setpoint: crate::signals::Setpoint {
                y_um: 5.0,
                dy: 30.0,
                ddy: 100.0,
            },
            y_um: y,
            u_ff: 0.0,
            u_applied: 1.0,
        };
        a.update(&io(4.0)); // primes
        let u = a.update(&io(4.2));
        let z = a.state.z;
        assert!(
            (z[0] - 4.2).abs() > 1e-3,
            "the ESO does not jump to y: {z:?}"
        );
        let want = (100.0 + 2000.0 * (30.0 - z[1]) + 1e6 * (5.0 - 4.2) - z[2]) / 1e7;
        assert!((u - want).abs() < 1e-12, "{u} vs {want}");
    }

    #[test]
    fn eso_estimates_constant_disturbance() {
        // y'' = Delta + b u with Delta = -3e5, u = 0.01: the ESO finds Delta.
        let dt = 1e-5;
        let b = 1e7;
        let mut a = Adrc::new(AdrcConfig {
            b,
            a1: 0.0,
            a2: 0.0,
            eps_s: 2e-4,
            omega_c: 1000.0,
            feedforward: false,
            dt_s: dt,
        })
        .unwrap();
        a.state = AdrcState {
            z: [1.0, 0.0, 0.0],
            u_ff_prev: 0.0,
            fresh: false,
        };
        let (mut y, mut v) = (0.0, 0.0);
        let u = 0.01;
        let delta = -3e5;
        for _ in 0..2000 {
            let acc = delta + b * u;
            y += v * dt + 0.5 * acc * dt * dt;
            v += acc * dt;
            a.observe(y, u);
        }
        assert!(
            (a.state.z[2] - delta).abs() < 1e-3 * delta.abs(),
            "{:?}",
            a.state.z
        );
        assert!((a.state.z[0] - y).abs() < 1e-9);
    }
}
