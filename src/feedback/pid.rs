//! PID baseline: parallel form, derivative on the measurement through a first-order filter,
//! back-calculation anti-windup from the applied voltage.

use super::guard::{finite_or, InputGuard};
use crate::hysteresis::{ensure, ensure_finite, ParamError};
use crate::real::Real;
use crate::signals::LoopSignals;

/// PID gains and filter, fixed per sample period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidConfig<T> {
    /// Proportional gain (V/um).
    pub kp: T,
    /// Integral gain (V/(um s)).
    pub ki: T,
    /// Derivative gain (V s/um).
    pub kd: T,
    /// Time constant of the derivative filter (s).
    pub tf_s: T,
    /// Back-calculation rate in `[0, 1]` per sample: the share of last sample's
    /// `u_applied - u_command` fed back into the integrator (1 = clamp to the applied voltage).
    pub kb: T,
    /// Add the feedforward voltage `io.u_ff` (feedforward + PID).
    pub feedforward: bool,
    /// Sample period (s).
    pub dt_s: T,
}

/// PID with the state it needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pid<T> {
    cfg: PidConfig<T>,
    /// `ki*dt`, `Tf/(Tf+dt)` and `kd/(Tf+dt)` precomputed.
    ki_dt: T,
    d_pole: T,
    d_gain: T,
    state: PidState<T>,
    pub(crate) guard: InputGuard<T>,
}

/// Integrator, filtered derivative and the values of the previous sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PidState<T> {
    pub integral: T,
    pub derivative: T,
    pub y_prev: T,
    pub u_prev: T,
    pub fresh: bool,
}

impl<T: Real> Pid<T> {
    pub fn new(cfg: PidConfig<T>) -> Result<Self, ParamError> {
        let c = &cfg;
        ensure_finite(
            &[c.kp, c.ki, c.kd, c.tf_s, c.kb, c.dt_s],
            "PID: all parameters must be finite",
        )?;
        ensure(c.dt_s > T::ZERO, "PID: dt_s > 0")?;
        ensure(
            c.kp >= T::ZERO && c.ki >= T::ZERO && c.kd >= T::ZERO,
            "PID: gains kp, ki, kd >= 0",
        )?;
        ensure(c.tf_s >= T::ZERO, "PID: derivative filter tf_s >= 0")?;
        ensure(c.kb >= T::ZERO && c.kb <= T::ONE, "PID: 0 <= kb <= 1")?;
        let den = c.tf_s + c.dt_s;
        Ok(Self {
            cfg,
            ki_dt: c.ki * c.dt_s,
            d_pole: c.tf_s / den,
            d_gain: c.kd / den,
            state: PidState {
                fresh: true,
                ..Default::default()
            },
            guard: InputGuard::default(),
        })
    }

    pub fn config(&self) -> &PidConfig<T> {
        &self.cfg
    }

    pub fn state(&self) -> &PidState<T> {
        &self.state
    }

    #[inline]
    fn ff(&self, io: &LoopSignals<T>) -> T {
        if self.cfg.feedforward {
            io.u_ff
        } else {
            T::ZERO
        }
    }

    #[inline]
    pub fn update(&mut self, io: &LoopSignals<T>) -> T {
        let io = self.guard.clean(io);
        if self.state.fresh {
            self.prime(&io);
        }
        let ff = self.ff(&io);
        let s = &mut self.state;
        let e = io.setpoint.y_um - io.y_um;
        // Back-calculation: what the limits removed last sample comes off the integrator.
        s.integral += self.ki_dt * e + self.cfg.kb * (io.u_applied - s.u_prev);
        // Backward-Euler filtered derivative of -y (no kick on setpoint steps).
        s.derivative = self.d_pole * s.derivative - self.d_gain * (io.y_um - s.y_prev);
        s.y_prev = io.y_um;
        let u = ff + self.cfg.kp * e + s.integral + s.derivative;
        if !u.is_finite() {
            self.prime(&io);
            return io.u_applied;
        }
        s.u_prev = u;
        u
    }

    /// Integrator set so that `update(io)` with the same `io` returns `io.u_applied`.
    fn prime(&mut self, io: &LoopSignals<T>) {
        let e = io.setpoint.y_um - io.y_um;
        let u0 = io.u_applied;
        let ff = self.ff(io);
        let s = &mut self.state;
        s.derivative = T::ZERO;
        s.y_prev = io.y_um;
        s.u_prev = u0;
        // update adds ki*dt*e and kb*(u_applied - u_prev) = 0.
        s.integral = finite_or(u0 - ff - self.cfg.kp * e - self.ki_dt * e, T::ZERO);
        s.fresh = false;
    }

    /// Bumpless: the next `update` returns `u_applied`.
    pub fn reset(&mut self, _io: &LoopSignals<T>) {
        self.state.fresh = true;
        self.guard.restart();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pid(feedforward: bool) -> Pid<f64> {
        Pid::new(PidConfig {
            kp: 0.5,
            ki: 2000.0,
            kd: 1e-4,
            tf_s: 1e-4,
            kb: 1.0,
            feedforward,
            dt_s: 1e-5,
        })
        .unwrap()
    }

    #[test]
    fn rejects_bad_parameters() {
        let mut c = *pid(false).config();
        c.kb = 1.5;
        assert_eq!(Pid::new(c).unwrap_err().0, "PID: 0 <= kb <= 1");
        c.kb = 1.0;
        c.dt_s = 0.0;
        assert_eq!(Pid::new(c).unwrap_err().0, "PID: dt_s > 0");
    }

    #[test]
    fn anti_windup_keeps_integrator_bounded_under_saturation() {
        // Unreachable setpoint, output clamped to [0, 10] V: without back-calculation the
        // integrator would reach ki * e * t = 2000 * 50 * 1 = 1e5.
        let mut p = pid(false);
        let mut u_applied = 0.0;
        let mut max_i: f64 = 0.0;
        for _ in 0..100_000 {
            let io = LoopSignals::hold(50.0, 0.0, 0.0, u_applied);
            let u = p.update(&io);
            u_applied = u.clamp(0.0, 10.0);
            max_i = max_i.max(p.state().integral.abs());
        }
        assert!(max_i < 30.0, "integrator wound up to {max_i}");
        // ...and it recovers at once when the error changes sign.
        let io = LoopSignals::hold(0.0, 5.0, 0.0, u_applied);
        assert!(p.update(&io) < 10.0);
    }

    #[test]
    fn without_back_calculation_it_winds_up() {
        // The test above can fail: the same run with kb = 0 winds up.
        let mut c = *pid(false).config();
        c.kb = 0.0;
        let mut p = Pid::new(c).unwrap();
        let mut u_applied = 0.0;
        for _ in 0..100_000 {
            let io = LoopSignals::hold(50.0, 0.0, 0.0, u_applied);
            u_applied = p.update(&io).clamp(0.0, 10.0);
        }
        assert!(p.state().integral > 1e4);
    }

    #[test]
    fn reset_is_bumpless() {
        let mut p = pid(true);
        let io = LoopSignals::hold(3.0, 1.0, 20.0, 42.0);
        p.reset(&io);
        assert!((p.update(&io) - 42.0).abs() < 1e-9);
    }

    #[test]
    fn feedforward_passes_through_at_zero_error() {
        let mut p = pid(true);
        let mut io = LoopSignals::hold(1.0, 1.0, 7.0, 7.0);
        p.reset(&io);
        for _ in 0..10 {
            let u = p.update(&io);
            io.u_applied = u;
        }
        assert!((io.u_applied - 7.0).abs() < 1e-9);
    }
}
