//! Manipulation (000 Part V): force estimation without a force sensor, barrier-Lyapunov force
//! control, and observers for the distributed-parameter beam.
//!
//! * [`force::ForceEso`]: extended-state observer on the actuator model (CBW hysteresis +
//!   second-order mechanics loaded by the interaction force), estimates `F = psi[y]` from
//!   position and voltage only (000, "Object characterization via piezoelectric manipulation").
//! * [`blf::BlfForce`]: force tracking with the barrier-Lyapunov function of 000 eq. (12) and a
//!   saturated voltage rate, so `|F - F_d| < k_b` and the input stays bounded.
//! * [`beam::Hgo`] and [`beam::Nno`]: position at a point `x != L` of the Euler-Bernoulli beam
//!   (000 eq. 9) from the tip sensor, by a high-gain observer and by a neural-network observer.
//!
//! Everything here is `no_std`, allocation-free and generic over [`Real`](crate::Real).
//! Configuration (validated once by `new`) is kept apart from the per-sample state.

pub mod beam;
pub mod blf;
pub mod force;
pub mod linalg;

pub use beam::{Hgo, HgoState, ModalModel, Nno, NnoConfig, NnoState};
pub use blf::{BlfForce, BlfState};
pub use force::{ForceEso, ForceEsoState, StageDynamics, VoltageInput, VoltageInputState};
