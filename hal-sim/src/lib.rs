//! hal-sim: the laptop stand-in for a piezo stage.
//!
//! A simulated actuator behind mock converters that implement embedded-hal 1.0, driven by
//! the firmware's own pipeline from `piezo-core`; plus the host tools of the `piezo` CLI.

pub mod beam;
pub mod cli;
pub mod console;
pub mod faults;
pub mod ident;
pub mod manipulation;
pub mod mock;
pub mod numeric;
pub mod object;
pub mod plot;
pub mod record;
pub mod scenario;
pub mod serial;
pub mod sim;
pub mod stage;
