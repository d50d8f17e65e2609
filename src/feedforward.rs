//! Feedforward hysteresis compensation: IMS, MBW without inversion, direct WPMBW inverse,
//! PI inverses, multivariable IMS. One enum selects the compensator at run time; each variant
//! holds its own configuration and state.
//!
//! Every compensator: parameters validated at construction ([`FfError`] names the violated
//! condition), no allocation, bounded work per sample, a finite output for any input (a
//! non-finite reference holds the previous output), voltages inside the configured range.

pub mod ims;
pub mod solve;

pub use ims::{Ims, ImsLoop, ImsModel};

use crate::hysteresis::{Cbw, ParamError};
use crate::real::Real;
use crate::signals::Setpoint;

/// A compensator parameter broke a condition; the text names it.
pub type FfError = ParamError;

#[inline]
pub(crate) fn ensure(cond: bool, msg: &'static str) -> Result<(), FfError> {
    if cond {
        Ok(())
    } else {
        Err(ParamError(msg))
    }
}

pub(crate) fn check_range<T: Real>(lo: T, hi: T) -> Result<(), FfError> {
    ensure(
        lo.is_finite() && hi.is_finite() && lo < hi,
        "feedforward: voltage range must be finite with volts_min < volts_max",
    )
}

pub(crate) fn check_dt<T: Real>(dt_s: T) -> Result<(), FfError> {
    ensure(
        dt_s.is_finite() && dt_s > T::ZERO,
        "feedforward: sample period dt_s must be finite and > 0",
    )
}

/// Linear scaling only: `u = (y_ref - offset) / d`, no hysteresis model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearFf<T> {
    /// Static gain of the stage (um/V).
    pub um_per_volt: T,
    /// Position at 0 V (um).
    pub offset_um: T,
}

impl<T: Real> LinearFf<T> {
    #[inline]
    pub fn compensate(&self, y_ref_um: T) -> T {
        (y_ref_um - self.offset_um) / self.um_per_volt
    }
}

/// The selectable feedforward compensator.
// Variants hold fixed-size parameter and state arrays (no heap); the size spread is intended.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Feedforward<T: Real> {
    /// Linear scaling only (open loop without a hysteresis model).
    Linear(LinearFf<T>),
    /// IMS around a classical Bouc-Wen model (003 eq. 16, 004 eq. 25).
    ImsCbw(Ims<T, Cbw<T>>),
}

impl<T: Real> Feedforward<T> {
    /// Voltage (V) that should bring the stage to the setpoint.
    #[inline]
    pub fn compensate(&mut self, sp: &Setpoint<T>) -> T {
        match self {
            Feedforward::Linear(l) => l.compensate(sp.y_um),
            Feedforward::ImsCbw(c) => c.compensate(sp.y_um),
        }
    }

    /// Restart from rest at setpoint `sp` (mode switch, fault recovery).
    pub fn reset(&mut self, sp: &Setpoint<T>) {
        match self {
            Feedforward::Linear(_) => {}
            Feedforward::ImsCbw(c) => c.reset(sp.y_um),
        }
    }

    /// Short name for tables and logs.
    pub fn name(&self) -> &'static str {
        match self {
            Feedforward::Linear(_) => "linear",
            Feedforward::ImsCbw(c) => match c.closure() {
                ImsLoop::Solved => "ims-cbw",
                ImsLoop::Delayed => "ims-cbw-delayed",
            },
        }
    }
}

/// Feedforward for an `N`-axis stage: one compensator per axis, or a multivariable one
/// (003 eq. 14-20) that maps all references to all voltages at once.
#[derive(Debug, Clone, PartialEq)]
pub enum MultiFeedforward<T: Real, const N: usize> {
    /// Independent axes.
    PerAxis([Feedforward<T>; N]),
}

impl<T: Real, const N: usize> MultiFeedforward<T, N> {
    /// Voltages (V) that should bring every axis to its setpoint.
    #[inline]
    pub fn compensate(&mut self, sp: &[Setpoint<T>; N]) -> [T; N] {
        match self {
            MultiFeedforward::PerAxis(ff) => {
                let mut u = [T::ZERO; N];
                for ((u, f), s) in u.iter_mut().zip(ff.iter_mut()).zip(sp) {
                    *u = f.compensate(s);
                }
                u
            }
        }
    }

    /// Restart from rest at the given setpoints.
    pub fn reset(&mut self, sp: &[Setpoint<T>; N]) {
        match self {
            MultiFeedforward::PerAxis(ff) => ff.iter_mut().zip(sp).for_each(|(f, s)| f.reset(s)),
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            MultiFeedforward::PerAxis(ff) => ff.first().map_or("none", |f| f.name()),
        }
    }
}
