//! Identification and model discovery (`piezo fit`, `piezo diagnose`).
pub mod diagnose;
pub mod fast;
pub mod fit;
pub mod generate;
pub mod multibw;
pub mod optim;
pub mod rate;
pub mod saved;
pub mod ss;

/// Format tag of every `fit.json` (the saved model, [`saved`]).
pub const FORMAT: &str = "piezo-fit/1";
