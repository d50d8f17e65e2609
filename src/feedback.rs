//! Output-feedback laws from position only (000 Part III): HGO, robust virtual-control law,
//! ADRC, PID baselines, notch. One enum selects the law at run time; each variant holds its
//! own configuration and state.
//!
//! Every law:
//! * returns the voltage command before the pipeline's range and slew limits;
//! * integrates and observes with `io.u_applied` (the voltage really applied), so
//!   saturation never winds it up;
//! * holds the last finite value of any non-finite input and never returns a non-finite
//!   command (it restarts bumplessly instead);
//! * accepts the feedforward `io.u_ff` (each law's `feedforward` flag says how it is used);
//! * can filter the measurement through a [`Biquad`] (notch on the stage resonance).
//!
//! Laws: PID ([`Pid`]); HGO (000 eq. 6, [`Hgo`]) + robust virtual-hysteresis law
//! (000 eq. 7-8) or its finite-time variant (000 Part IV), both [`Robust`]; ESO + ADRC
//! (000 eq. 10-11, [`Adrc`]); HGO + NMPC with the hysteresis model as predictor
//! (000 Part IV, [`Nmpc`]). The barrier-Lyapunov force law (000 eq. 12) is a force loop,
//! not a position law, and lives with the object model in `crate::manipulation`.

pub mod adrc;
pub mod biquad;
pub mod guard;
pub mod hgo;
pub mod nmpc;
pub mod pid;
pub mod robust;

pub use adrc::{Adrc, AdrcConfig};
pub use biquad::Biquad;
pub use hgo::{Hgo, HgoState, ObserverModel};
pub use nmpc::{Nmpc, NmpcConfig};
pub use pid::{Pid, PidConfig};
pub use robust::{Convergence, Robust, RobustConfig};

use crate::real::Real;
use crate::signals::LoopSignals;

/// The selectable feedback law. Its output is the voltage command (V) before the
/// pipeline's range and slew limits.
#[derive(Debug, Clone, PartialEq)]
pub enum Feedback<T: Real> {
    /// No feedback: the feedforward voltage passes through.
    OpenLoop,
    /// PID baseline (with `feedforward`: feedforward + PID).
    Pid(Pid<T>),
    /// HGO (000 eq. 6) + robust virtual-hysteresis law (000 eq. 7-8).
    Robust(Robust<T>),
    /// Extended-state observer + ADRC (000 eq. 10-11).
    Adrc(Adrc<T>),
    /// HGO + nonlinear MPC with the hysteresis model as prediction model (000 Part IV).
    Nmpc(Nmpc<T>),
}

impl<T: Real> Feedback<T> {
    /// One control step.
    #[inline(always)]
    pub fn update(&mut self, io: &LoopSignals<T>) -> T {
        match self {
            Feedback::OpenLoop => {
                if io.u_ff.is_finite() {
                    io.u_ff
                } else if io.u_applied.is_finite() {
                    io.u_applied
                } else {
                    T::ZERO
                }
            }
            Feedback::Pid(l) => l.update(io),
            Feedback::Robust(l) => l.update(io),
            Feedback::Adrc(l) => l.update(io),
            Feedback::Nmpc(l) => l.update(io),
        }
    }

    /// Bumpless restart: internal states are set so the next command equals `io.u_applied`.
    pub fn reset(&mut self, io: &LoopSignals<T>) {
        match self {
            Feedback::OpenLoop => {}
            Feedback::Pid(l) => l.reset(io),
            Feedback::Robust(l) => l.reset(io),
            Feedback::Adrc(l) => l.reset(io),
            Feedback::Nmpc(l) => l.reset(io),
        }
    }

    /// Puts `notch` (or any unity-DC-gain biquad) on the measured position; `None` removes it.
    pub fn set_measurement_filter(&mut self, notch: Option<Biquad<T>>) {
        let g = match self {
            Feedback::OpenLoop => return,
            Feedback::Pid(l) => &mut l.guard,
            Feedback::Robust(l) => &mut l.guard,
            Feedback::Adrc(l) => &mut l.guard,
            Feedback::Nmpc(l) => &mut l.guard,
        };
        g.notch = notch;
        g.restart();
    }
}
