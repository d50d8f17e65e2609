//! Identification and model discovery (`piezo fit`, `piezo diagnose`).
pub mod diagnose;
pub mod fast;
pub mod fit;
pub mod generate;
pub mod multibw;
pub mod optim;
pub mod rate;
pub mod ss;
