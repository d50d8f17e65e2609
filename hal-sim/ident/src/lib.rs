//! piezo-ident: identification and model discovery for piezo stages, as a library.
//!
//! Records ([`record`]: the project's CSV convention, units checked), the models and their fits
//! ([`fit`]: the Bouc-Wen family and the Prandtl-Ishlinskii family of `piezo-core`, one axis or
//! several; [`ss`]: multivariable state space, Hammerstein, scheduled), their saved form
//! ([`saved`]: `fit.json`), and discovery ([`diagnose`]: what a model gets wrong, named as a
//! cause from a catalogue, with its gain on held-out data). It knows no simulator and no
//! command line: `hal-sim` (the simulated stage and the `piezo` CLI) and the Python package
//! stand on it.
pub mod diagnose;
pub mod fast;
pub mod fit;
pub mod multibw;
pub mod numeric;
pub mod optim;
pub mod plot;
pub mod record;
pub mod saved;
pub mod ss;

/// Format tag of every `fit.json` (the saved model, [`saved`]).
pub const FORMAT: &str = "piezo-fit/1";
