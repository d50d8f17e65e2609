//! Output-feedback laws from position only (000 Part III): HGO, robust virtual-control law,
//! ADRC, PID baselines, notch. One enum selects the law at run time; each variant holds its
//! own configuration and state.

use crate::real::Real;
use crate::signals::LoopSignals;

/// The selectable feedback law. Its output is the voltage command (V) before the
/// pipeline's range and slew limits.
#[derive(Debug, Clone, PartialEq)]
pub enum Feedback<T: Real> {
    /// No feedback: the feedforward voltage passes through.
    OpenLoop,
    #[doc(hidden)]
    _Unused(core::marker::PhantomData<T>),
}

impl<T: Real> Feedback<T> {
    /// One control step.
    #[inline]
    pub fn update(&mut self, io: &LoopSignals<T>) -> T {
        match self {
            Feedback::OpenLoop | Feedback::_Unused(_) => io.u_ff,
        }
    }

    /// Bumpless restart: internal states are set so the next command equals `io.u_applied`.
    pub fn reset(&mut self, _io: &LoopSignals<T>) {}

    /// Short name for tables and logs.
    pub fn name(&self) -> &'static str {
        match self {
            Feedback::OpenLoop | Feedback::_Unused(_) => "open-loop",
        }
    }
}
