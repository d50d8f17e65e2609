//! Feedforward hysteresis compensation: IMS, MBW without inversion, direct WPMBW inverse,
//! PI inverses, multivariable IMS. One enum selects the compensator at run time; each variant
//! holds its own configuration and state.
//!
//! Every compensator: parameters validated at construction ([`FfError`] names the violated
//! condition), no allocation, bounded work per sample, a finite output for any input (a
//! non-finite reference holds the previous output), voltages inside the configured range.

pub mod creep;
pub mod ims;
pub mod mbw;
pub mod multi;
pub mod pi;
pub mod prefilter;
pub mod solve;
pub mod wpmbw;
pub mod zpetc;

pub use creep::CreepInverse;
pub use ims::{Ims, ImsDynamics, ImsLoop, ImsModel};
pub use mbw::MbwFf;
pub use multi::{pseudo_inverse, MultiIms};
pub use pi::{ppi_inverse, DpiInverse, PiInverse, PpiInverse, MAX_OPS};
pub use prefilter::FullPass;
pub use wpmbw::{InverseDynamics, LinearPart, WpmbwInverse};
pub use zpetc::Zpetc;

use crate::hysteresis::{AbwAbs, Cbw, Dahl, Gbw, Mbw002, ParamError};
use crate::real::Real;
use crate::signals::Setpoint;

/// A compensator parameter broke a condition; the text names it.
pub type FfError = ParamError;

pub(crate) use crate::hysteresis::ensure;

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

/// The voltage a compensator restarts at: `u0` (0 V when not finite) clamped to the range.
#[inline]
pub(crate) fn rest_volts<T: Real>(u0: T, lo: T, hi: T) -> T {
    crate::hysteresis::sane_input(u0, T::ZERO).clamp_to(lo, hi)
}

/// A compensator's voltage range and sample period ([`check_range`], then [`check_dt`]).
pub(crate) fn check_range_dt<T: Real>(lo: T, hi: T, dt_s: T) -> Result<(), FfError> {
    check_range(lo, hi)?;
    check_dt(dt_s)
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
    /// Usable: `um_per_volt` finite and non-zero, `offset_um` finite.
    pub fn is_valid(&self) -> bool {
        self.um_per_volt.is_finite() && self.um_per_volt != T::ZERO && self.offset_um.is_finite()
    }

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
    /// IMS around a generalized Bouc-Wen model (000 eq. 3).
    ImsGbw(Ims<T, Gbw<T>>),
    /// IMS around a Dahl model (000 eq. 4).
    ImsDahl(Ims<T, Dahl<T>>),
    /// IMS around the asymmetric Bouc-Wen with `delta*|u'|` (002 eq. 3).
    ImsAbw(Ims<T, AbwAbs<T>>),
    /// IMS around the modified Bouc-Wen of 002 (eq. 4-5), solved exactly.
    ImsMbw(Ims<T, Mbw002<T>>),
    /// 002's feedforward without inversion (eq. 8-12).
    Mbw(MbwFf<T>),
    /// Direct WPMBW inverse with inverse linear dynamics and prefilter (004 eq. 17-18, 27-28).
    Wpmbw(WpmbwInverse<T>),
    /// Exact PI inverse (a PI with computed thresholds and weights).
    PiInverse(PiInverse<T>),
    /// PPI inverse by a bounded monotone solve.
    PpiInverse(PpiInverse<T>),
    /// Exact DPI inverse (dead zones, then PI).
    DpiInverse(DpiInverse<T>),
}

fn ims_name(closure: ImsLoop, solved: &'static str, delayed: &'static str) -> &'static str {
    match closure {
        ImsLoop::Solved => solved,
        ImsLoop::Delayed => delayed,
    }
}

impl<T: Real> Feedforward<T> {
    /// Voltage (V) that should bring the stage to the setpoint.
    #[inline]
    pub fn compensate(&mut self, sp: &Setpoint<T>) -> T {
        match self {
            Feedforward::Linear(l) => l.compensate(sp.y_um),
            Feedforward::ImsCbw(c) => c.compensate(sp.y_um),
            Feedforward::ImsGbw(c) => c.compensate(sp.y_um),
            Feedforward::ImsDahl(c) => c.compensate(sp.y_um),
            Feedforward::ImsAbw(c) => c.compensate(sp.y_um),
            Feedforward::ImsMbw(c) => c.compensate(sp.y_um),
            Feedforward::Mbw(c) => c.compensate(sp.y_um),
            Feedforward::Wpmbw(c) => c.compensate(sp),
            Feedforward::PiInverse(c) => c.compensate(sp.y_um),
            Feedforward::PpiInverse(c) => c.compensate(sp.y_um),
            Feedforward::DpiInverse(c) => c.compensate(sp.y_um),
        }
    }

    /// Restart from rest (mode switch, fault recovery). The stage does not jump to the
    /// setpoint: the pipeline holds the applied voltage and slew-limits any difference. So
    /// a model-based compensator relaxes its model at the voltage it last commanded (at
    /// power-up: 0 V, where the stage rests) and only restarts its filters from `sp`.
    /// Use [`Feedforward::reset_at`] when the applied voltage is known.
    pub fn reset(&mut self, sp: &Setpoint<T>) {
        let u = self.volts(sp);
        self.reset_at(sp, u);
    }

    /// The voltage this compensator last commanded (linear: the one for `sp`).
    pub fn volts(&self, sp: &Setpoint<T>) -> T {
        match self {
            Feedforward::Linear(l) => l.compensate(sp.y_um),
            Feedforward::ImsCbw(c) => c.volts(),
            Feedforward::ImsGbw(c) => c.volts(),
            Feedforward::ImsDahl(c) => c.volts(),
            Feedforward::ImsAbw(c) => c.volts(),
            Feedforward::ImsMbw(c) => c.volts(),
            Feedforward::Mbw(c) => c.volts(),
            Feedforward::Wpmbw(c) => c.volts(),
            Feedforward::PiInverse(c) => c.volts(),
            Feedforward::PpiInverse(c) => c.volts(),
            Feedforward::DpiInverse(c) => c.volts(),
        }
    }

    /// Restart with the model relaxed at the applied voltage `u_applied` (V).
    pub fn reset_at(&mut self, _sp: &Setpoint<T>, u_applied: T) {
        let u = u_applied;
        match self {
            Feedforward::Linear(_) => {}
            Feedforward::ImsCbw(c) => c.reset_volts(u),
            Feedforward::ImsGbw(c) => c.reset_volts(u),
            Feedforward::ImsDahl(c) => c.reset_volts(u),
            Feedforward::ImsAbw(c) => c.reset_volts(u),
            Feedforward::ImsMbw(c) => c.reset_volts(u),
            Feedforward::Mbw(c) => c.reset_volts(u),
            Feedforward::Wpmbw(c) => c.reset_volts(u),
            Feedforward::PiInverse(c) => c.reset_volts(u),
            Feedforward::PpiInverse(c) => c.reset_volts(u),
            Feedforward::DpiInverse(c) => c.reset_volts(u),
        }
    }

    /// Short name for tables and logs.
    pub fn name(&self) -> &'static str {
        match self {
            Feedforward::Linear(_) => "linear",
            Feedforward::ImsCbw(c) => ims_name(c.closure(), "ims-cbw", "ims-cbw-delayed"),
            Feedforward::ImsGbw(c) => ims_name(c.closure(), "ims-gbw", "ims-gbw-delayed"),
            Feedforward::ImsDahl(c) => ims_name(c.closure(), "ims-dahl", "ims-dahl-delayed"),
            Feedforward::ImsAbw(c) => ims_name(c.closure(), "ims-abw", "ims-abw-delayed"),
            Feedforward::ImsMbw(c) => ims_name(c.closure(), "ims-mbw", "ims-mbw-delayed"),
            Feedforward::Mbw(_) => "mbw-no-inverse",
            Feedforward::Wpmbw(_) => "wpmbw-inverse",
            Feedforward::PiInverse(_) => "pi-inverse",
            Feedforward::PpiInverse(_) => "ppi-inverse",
            Feedforward::DpiInverse(_) => "dpi-inverse",
        }
    }
}

/// Feedforward for an `N`-axis stage: one compensator per axis, or a multivariable one
/// (003 eq. 14-20) that maps all references to all voltages at once.
// The multivariable variant holds its matrices inline (no heap).
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum MultiFeedforward<T: Real, const N: usize> {
    /// Independent axes.
    PerAxis([Feedforward<T>; N]),
    /// Multivariable IMS `U = D^-1 (y_ref + h)` (003 eq. 16), `N` actuators for `N` axes.
    /// Under- and over-actuated systems use [`MultiIms`] with `N != K` directly.
    Ims(MultiIms<T, N, N>),
    /// Per-axis compensators behind a linear decoupler: for a stage whose axis outputs mix
    /// as `y = C * y_axis` (cross-talk after each axis' own hysteresis), the axes get
    /// `C^-1 * y_ref`. Build with [`MultiFeedforward::decoupled`].
    Decoupled {
        c_inv: [[T; N]; N],
        axes: [Feedforward<T>; N],
    },
}

impl<T: Real, const N: usize> MultiFeedforward<T, N> {
    /// Per-axis compensators behind the inverse of the output mixing matrix `c`
    /// (`c[i][j]`: share of axis `j`'s own output in output `i`; identity = no coupling).
    pub fn decoupled(c: [[T; N]; N], axes: [Feedforward<T>; N]) -> Result<Self, FfError> {
        ensure(
            c.iter().flatten().all(|x| x.is_finite()),
            "decoupler: coupling matrix must be finite",
        )?;
        let c_inv = multi::invert(&c, T::from_f64(1e-6))
            .ok_or(ParamError("decoupler: coupling matrix must be invertible"))?;
        Ok(MultiFeedforward::Decoupled { c_inv, axes })
    }

    /// Voltages (V) that should bring every axis to its setpoint.
    #[inline(always)]
    pub fn compensate(&mut self, sp: &[Setpoint<T>; N]) -> [T; N] {
        match self {
            MultiFeedforward::PerAxis(ff) => {
                let mut u = [T::ZERO; N];
                for ((u, f), s) in u.iter_mut().zip(ff.iter_mut()).zip(sp) {
                    *u = f.compensate(s);
                }
                u
            }
            MultiFeedforward::Ims(m) => {
                let mut y = [T::ZERO; N];
                for (y, s) in y.iter_mut().zip(sp) {
                    *y = s.y_um;
                }
                m.compensate(&y)
            }
            MultiFeedforward::Decoupled { c_inv, axes } => {
                let mut u = [T::ZERO; N];
                for ((u, f), row) in u.iter_mut().zip(axes.iter_mut()).zip(c_inv.iter()) {
                    let mut y = T::ZERO;
                    let mut dy = T::ZERO;
                    let mut ddy = T::ZERO;
                    for (&c, s) in row.iter().zip(sp.iter()) {
                        y += c * s.y_um;
                        dy += c * s.dy;
                        ddy += c * s.ddy;
                    }
                    // A non-finite reference on any axis holds every axis.
                    let y = if sp.iter().all(|s| s.y_um.is_finite()) {
                        y
                    } else {
                        T::from_f64(f64::NAN)
                    };
                    *u = f.compensate(&Setpoint { y_um: y, dy, ddy });
                }
                u
            }
        }
    }

    /// Restart from rest at the voltages last commanded (see [`Feedforward::reset`]).
    pub fn reset(&mut self, sp: &[Setpoint<T>; N]) {
        match self {
            MultiFeedforward::PerAxis(ff) => ff.iter_mut().zip(sp).for_each(|(f, s)| f.reset(s)),
            MultiFeedforward::Ims(m) => {
                let u = m.volts();
                m.reset_volts(&u);
            }
            MultiFeedforward::Decoupled { axes, .. } => {
                axes.iter_mut().zip(sp).for_each(|(f, s)| f.reset(s))
            }
        }
    }

    /// Restart with every model relaxed at the applied voltages.
    pub fn reset_at(&mut self, sp: &[Setpoint<T>; N], u_applied: &[T; N]) {
        match self {
            MultiFeedforward::PerAxis(ff) | MultiFeedforward::Decoupled { axes: ff, .. } => ff
                .iter_mut()
                .zip(sp)
                .zip(u_applied)
                .for_each(|((f, s), &u)| f.reset_at(s, u)),
            MultiFeedforward::Ims(m) => m.reset_volts(u_applied),
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            MultiFeedforward::PerAxis(ff) => ff.first().map_or("none", |f| f.name()),
            MultiFeedforward::Ims(m) => ims_name(m.closure(), "multi-ims", "multi-ims-delayed"),
            MultiFeedforward::Decoupled { axes, .. } => axes.first().map_or("none", |f| f.name()),
        }
    }
}
