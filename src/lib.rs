//! Control core for piezoelectric nanopositioning stages.
//!
//! `no_std`, allocation-free, generic over the number type ([`real::Real`]): `f32` on the
//! Cortex-M target, `f64` on the host. The same code runs in the firmware, in `hal-sim`
//! and in the identification tools.
//!
//! Equations are cited by seed document and number, e.g. `000 eq. (6)` (see
//! `../shared/seeds/README.md`).
#![cfg_attr(not(test), no_std)]
// `!(x < y)` is how NaN is kept out of limits here; it is intended.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bulk;
pub mod command;
pub mod drivers;
pub mod feedback;
pub mod feedforward;
pub mod firmware;
pub mod fixed;
pub mod hysteresis;
pub mod linear;
pub mod manipulation;
pub mod pipeline;
pub mod real;
pub mod recorder;
pub mod registry;
pub mod signals;

pub use real::Real;
