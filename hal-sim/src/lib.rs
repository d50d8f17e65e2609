//! hal-sim: the laptop stand-in for a piezo stage.
//!
//! A simulated actuator behind mock converters that implement embedded-hal 1.0, driven by
//! the firmware's own pipeline from `piezo-core`; plus the host tools of the `piezo` CLI.

pub mod beam;
pub mod cli;
pub mod console;
pub mod docs;
pub mod faults;
pub mod ident;
pub mod independent;
pub mod manipulation;
pub mod mock;
pub mod object;
pub mod report;
pub mod scenario;
pub mod serial;
pub mod sim;
pub mod stage;

// The identification library's records, numerics and plots, where hal-sim's modules use them.
pub use piezo_ident::{numeric, plot, record};
