//! The simulated actuator: amplifier, hysteresis, creep, structural dynamics, drift, noise, delay, coupling.
