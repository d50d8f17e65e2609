//! Signals passed between the blocks of the per-sample path.

/// The reference at one sample and its time derivatives (the reference generator knows
/// them exactly; the robust law (000 eq. 7) and ADRC (000 eq. 11) need them).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Setpoint<T> {
    /// Desired position (um).
    pub y_um: T,
    /// First derivative (um/s).
    pub dy: T,
    /// Second derivative (um/s^2).
    pub ddy: T,
}

impl<T: crate::Real> Setpoint<T> {
    /// A constant setpoint.
    pub fn hold(y_um: T) -> Self {
        Self {
            y_um,
            dy: T::ZERO,
            ddy: T::ZERO,
        }
    }
}

/// What a feedback law sees at one sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LoopSignals<T> {
    pub setpoint: Setpoint<T>,
    /// Measured position (um), already scaled and range-checked.
    pub y_um: T,
    /// Feedforward voltage for this sample (V).
    pub u_ff: T,
    /// Voltage actually applied at the previous sample, after range and slew limits (V).
    /// Integral laws and observers use this, so saturation never winds them up.
    pub u_applied: T,
}

impl<T: crate::Real> LoopSignals<T> {
    /// The signals at a constant setpoint `r_um` ([`Setpoint::hold`]).
    pub fn hold(r_um: T, y_um: T, u_ff: T, u_applied: T) -> Self {
        Self {
            setpoint: Setpoint::hold(r_um),
            y_um,
            u_ff,
            u_applied,
        }
    }
}
