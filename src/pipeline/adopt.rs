//! Hand-over of a configuration built elsewhere: the firmware's command task validates and
//! builds a change on its own replica of the pipeline (outside the control task's lock),
//! then [`Pipeline::adopt`] copies the changed parts into the live pipeline under the lock:
//! a copy, never a law rebuild, a validation or the restart (the next step restarts
//! bumplessly, in the control task).

use super::Pipeline;
use crate::real::Real;

/// Which parts of a configuration [`Pipeline::adopt`] takes (a bit set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Parts(u16);

impl Parts {
    pub const NONE: Self = Self(0);
    pub const FEEDFORWARD: Self = Self(1);
    pub const FEEDBACK: Self = Self(1 << 1);
    pub const OPEN_LOOP: Self = Self(1 << 2);
    pub const LIMITS: Self = Self(1 << 3);
    pub const MODE: Self = Self(1 << 4);
    pub const CLEAR_FAULT: Self = Self(1 << 5);
    /// The sensor scaling and window of every axis.
    pub const SENSOR: Self = Self(1 << 6);
    /// The feedforward, the open-loop scaling and the law with its mode (a model change).
    pub const MODEL: Self =
        Self(Self::FEEDFORWARD.0 | Self::FEEDBACK.0 | Self::OPEN_LOOP.0 | Self::MODE.0);
    const WAVE0: u16 = 1 << 8;

    /// The reference of `axis` (a new wave; the other axes' waves keep their phase).
    pub const fn wave(axis: usize) -> Self {
        if axis < 8 {
            Self(Self::WAVE0 << axis)
        } else {
            Self::NONE
        }
    }
    /// The references of every axis.
    pub const WAVES: Self = Self(0xff00);

    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
    const fn any(self, other: Self) -> bool {
        self.0 & other.0 != 0
    }
    /// These parts less `other`'s.
    pub const fn without(self, other: Self) -> Self {
        Self(self.0 & !other.0)
    }
}

impl<T: Real, const N: usize> Pipeline<T, N> {
    /// Takes `parts` of `from`'s configuration (a replica with this pipeline's configuration
    /// that a change was validated and built on); the next step restarts once, bumplessly,
    /// from this pipeline's state. A copy: bounded, no panic, nothing validated here (`from`
    /// was built through the checked setters).
    pub fn adopt(&mut self, from: &Self, parts: Parts) {
        if parts.contains(Parts::FEEDFORWARD) {
            self.feedforward.clone_from(&from.feedforward);
        }
        if parts.contains(Parts::FEEDBACK) {
            for (d, s) in self.feedback.iter_mut().zip(&from.feedback) {
                d.clone_from(s);
            }
        }
        if parts.contains(Parts::MODE) {
            self.state.mode = from.state.mode;
        }
        if parts.contains(Parts::CLEAR_FAULT) {
            self.state.fault = None;
        }
        for (axis, (d, s)) in self
            .config
            .axes
            .iter_mut()
            .zip(&from.config.axes)
            .enumerate()
        {
            if parts.contains(Parts::OPEN_LOOP) {
                d.open_loop = s.open_loop;
            }
            if parts.contains(Parts::SENSOR) {
                d.sensor = s.sensor;
            }
            if parts.contains(Parts::LIMITS) {
                d.limits = s.limits;
                d.safe_volts = s.safe_volts;
                if let (Some(o), Some(so)) = (self.output.get_mut(axis), from.output.get(axis)) {
                    *o = *so;
                }
            }
        }
        if parts.contains(Parts::LIMITS) {
            for axis in 0..N {
                self.clamp_code(axis);
            }
        }
        for (axis, (d, s)) in self.reference.iter_mut().zip(&from.reference).enumerate() {
            if parts.contains(Parts::wave(axis)) {
                d.clone_from(s);
            }
        }
        let restart = Parts::FEEDFORWARD
            .union(Parts::FEEDBACK)
            .union(Parts::OPEN_LOOP)
            .union(Parts::MODE)
            .union(Parts::CLEAR_FAULT);
        if parts.any(restart) {
            // The restart (the IMS inverse from the setpoint, the observer's reset) runs at
            // the next step: this stays a copy. The generic step takes it first (it is the
            // path while the flag is up) and decides the fused path again.
            self.pending = super::Pending::Restart;
            self.fused = false;
        } else if parts.any(Parts::LIMITS.union(Parts::SENSOR)) {
            // A restart still due keeps the generic path until it ran.
            self.decide_fused();
        }
    }

    /// Takes `from`'s state (the replica learns the live trace, codes and fault before a
    /// command runs on it). A copy.
    pub fn sync_state(&mut self, from: &Self) {
        self.state = from.state;
        // The fault came with it.
        self.decide_fused();
    }
}
