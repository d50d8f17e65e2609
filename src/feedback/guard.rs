//! Input sanitising shared by every law: a non-finite input holds its last finite value, and
//! magnitudes are bounded so no product in a law can overflow to infinity. The optional
//! measurement filter (e.g. a notch on the stage resonance) sits here too, so it serves every
//! law the same way.

use super::biquad::Biquad;
use crate::real::Real;
use crate::signals::{LoopSignals, Setpoint};

/// Largest magnitude a law accepts for a position, a velocity or a voltage (um, um/s, V).
/// Far outside any physical stage, small enough that the laws' products stay finite in
/// `f32`.
pub const INPUT_BOUND: f64 = 1.0e6;

/// Largest magnitude a law accepts for the setpoint's acceleration (um/s^2): 10 km/s^2, a
/// 1 kHz sine of 250 um. [`INPUT_BOUND`] would clip a 100 Hz, 5 um sine (2e6 um/s^2); the
/// laws scale the acceleration by `dt^2` or add it to their own (finite) terms, so `f32`
/// stays far from overflow.
pub const ACCEL_BOUND: f64 = 1.0e10;

/// Last finite value of every input, and the measurement filter.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct InputGuard<T> {
    last: LoopSignals<T>,
    /// Filter on the measured position (unity DC gain expected).
    pub notch: Option<Biquad<T>>,
    /// The filter state matches the measurement (false: settle it on the next sample).
    settled: bool,
}

/// `x` clamped into the bound, or the last accepted value if `x` is not finite. The usual
/// case first: one compare accepts a value inside the bound (strict: in fixed point the
/// bound saturates to the largest value, which stands for infinity there).
#[inline(always)]
fn hold<T: Real>(x: T, prev: T) -> T {
    hold_within(x, prev, INPUT_BOUND)
}

/// [`hold`] with the bound `bound`.
#[inline(always)]
fn hold_within<T: Real>(x: T, prev: T, bound: f64) -> T {
    let b = T::from_f64(bound);
    if x.abs() < b {
        x
    } else if x.is_finite() {
        x.clamp_to(-b, b)
    } else {
        prev
    }
}

#[inline(always)]
fn hold_setpoint<T: Real>(sp: &Setpoint<T>, prev: &Setpoint<T>) -> Setpoint<T> {
    Setpoint {
        y_um: hold(sp.y_um, prev.y_um),
        dy: hold(sp.dy, prev.dy),
        ddy: hold_within(sp.ddy, prev.ddy, ACCEL_BOUND),
    }
}

/// `x` passes [`hold`]'s bound `bound` unchanged, decided ahead of time: strictly inside it
/// as `T` rounds it, with a margin for the rounding of whatever computed `x`. False for NaN
/// and infinities.
pub(crate) fn inside_bound<T: Real>(x: f64, bound: f64) -> bool {
    x.abs() < T::from_f64(bound).to_f64() * 0.999
}

/// A setpoint whose magnitudes are at most these (um, um/s, um/s^2) passes
/// [`InputGuard::clean`] unchanged ([`inside_bound`]).
pub(crate) fn setpoint_within_bounds<T: Real>(y_um: f64, dy: f64, ddy: f64) -> bool {
    inside_bound::<T>(y_um, INPUT_BOUND)
        && inside_bound::<T>(dy, INPUT_BOUND)
        && inside_bound::<T>(ddy, ACCEL_BOUND)
}

impl<T: Real> InputGuard<T> {
    /// Finite, bounded copy of `io`; remembers it for the next sample.
    #[inline]
    pub fn clean(&mut self, io: &LoopSignals<T>) -> LoopSignals<T> {
        let l = &self.last;
        let c = LoopSignals {
            setpoint: hold_setpoint(&io.setpoint, &l.setpoint),
            y_um: hold(io.y_um, l.y_um),
            u_ff: hold(io.u_ff, l.u_ff),
            u_applied: hold(io.u_applied, l.u_applied),
        };
        self.last = c;
        let mut out = c;
        if let Some(n) = self.notch.as_mut() {
            if !self.settled {
                n.settle(c.y_um);
            }
            out.y_um = n.update(c.y_um);
        }
        self.settled = true;
        out
    }

    /// [`InputGuard::clean`] without a measurement filter, for inputs the caller knows to
    /// be finite and inside [`INPUT_BOUND`] (measurement, feedforward and applied voltage:
    /// the pipeline's fused step checks their ranges once per configuration), where `hold`
    /// returns them unchanged: only the setpoint is held, and not even that when `known` to
    /// lie inside the bounds (the reference generator proves it for a sine,
    /// [`crate::pipeline::reference`]). This part remembers the setpoint,
    /// [`InputGuard::remember_fused`] the rest: the same results and remembered values.
    #[inline(always)]
    pub(crate) fn clean_setpoint_fused(&mut self, sp: &Setpoint<T>, known: bool) -> Setpoint<T> {
        let sp = if known {
            *sp
        } else {
            hold_setpoint(sp, &self.last.setpoint)
        };
        self.last.setpoint = sp;
        // `settled` is already true: the fused update runs on a primed law only, and the
        // law primes itself in an update after `clean` (a restart clears both together).
        sp
    }

    /// The other inputs of [`InputGuard::clean_setpoint_fused`]'s sample.
    #[inline(always)]
    pub(crate) fn remember_fused(&mut self, y_um: T, u_ff: T, u_applied: T) {
        self.last.y_um = y_um;
        self.last.u_ff = u_ff;
        self.last.u_applied = u_applied;
    }

    /// The inputs remembered last.
    #[inline(always)]
    pub(crate) fn last(&self) -> LoopSignals<T> {
        self.last
    }

    /// No measurement filter is set.
    pub(crate) fn is_unfiltered(&self) -> bool {
        self.notch.is_none()
    }

    /// The filter restarts at the next measurement (bumpless reset).
    pub fn restart(&mut self) {
        self.settled = false;
    }
}

/// `x` if finite, else `fallback`.
#[inline(always)]
pub fn finite_or<T: Real>(x: T, fallback: T) -> T {
    if x.is_finite() {
        x
    } else {
        fallback
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clamps_large_and_holds_non_finite() {
        let mut g = InputGuard::<f32>::default();
        let mut io = LoopSignals::default();
        io.setpoint.ddy = 2e6; // a 100 Hz, 5 um sine: inside the acceleration's bound
        io.setpoint.dy = -2e6; // beyond the velocity's
        io.y_um = 3.0;
        let c = g.clean(&io);
        assert_eq!(c.setpoint.ddy, 2e6);
        assert_eq!(c.setpoint.dy, -INPUT_BOUND as f32);
        assert_eq!(c.y_um, 3.0);
        io.setpoint.ddy = 2e10;
        assert_eq!(g.clean(&io).setpoint.ddy, ACCEL_BOUND as f32);
        io.setpoint.ddy = -5.0;
        io.y_um = f32::NAN;
        io.u_ff = f32::INFINITY;
        let c = g.clean(&io);
        assert_eq!(c.setpoint.ddy, -5.0);
        assert_eq!(c.y_um, 3.0);
        assert_eq!(c.u_ff, 0.0);
    }
}
