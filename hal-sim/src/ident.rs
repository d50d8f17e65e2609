//! Identification and model discovery: the `piezo-ident` library, re-exported, plus the
//! records that hal-sim's simulated actuator writes for it ([`generate`]: hidden causes,
//! [`rate`]: seed 001's rate-dependent comparison).
pub use piezo_ident::*;

pub mod generate;
pub mod rate;
