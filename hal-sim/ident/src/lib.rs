//! piezo-ident: identification and model discovery for piezo stages, as a library.
//!
//! Records ([`record`]: the project's CSV convention, units checked), the models and their fits
//! ([`fit`]: the Bouc-Wen family and the Prandtl-Ishlinskii family of `piezo-core`, one axis or
//! several; [`ss`]: multivariable state space, Hammerstein, scheduled), their saved form
//! ([`saved`]: `fit.json`), and discovery ([`diagnose`]: what a model gets wrong, named as a
//! cause from a catalogue, with its gain on held-out data). It knows no simulator and no
//! command line: `hal-sim` (the simulated stage and the `piezo` CLI) and the Python package
//! stand on it.
//!
//! # A tour
//!
//! A record (here made by a known classical Bouc-Wen model, 000 eq. 1-2; usually read from a
//! CSV file with [`record::Record::read`]), the model identified on it ([`identify::fit`],
//! what `piezo fit` runs), saved as `fit.json` and loaded back ([`saved::Loaded`], what
//! `piezo predict` reads), and simulated on the inputs:
//!
//! ```
//! # fn main() -> anyhow::Result<()> {
//! use piezo_ident::fit::{models, resample::Edge, FitOptions, Fitted};
//! use piezo_ident::identify::{self, FitInput};
//! use piezo_ident::record::Record;
//! use piezo_ident::saved::Loaded;
//!
//! // Two cycles of a 0..100 V cosine at 1 kHz through a CBW with d, alpha, beta, gamma/beta.
//! let cbw = models::find("cbw")?;
//! let truth = Fitted::from_params(cbw, &[1.0, 0.4, 0.02, 0.3], 1.0, 0.0, 1)?;
//! let t: Vec<f64> = (0..1000).map(|k| k as f64 * 1e-3).collect();
//! let u: Vec<f64> = t.iter().map(|t| 50.0 * (1.0 - (4.0 * std::f64::consts::PI * t).cos())).collect();
//! let y = truth.simulate(&u, 1e-3, Edge::Hold)?;
//! let rec = Record::new(t, vec![u], vec![y])?;
//!
//! let opts = FitOptions { generations: 30, lm_iterations: 30, ..FitOptions::default() };
//! let fit = identify::fit(FitInput::train(cbw, &rec, "synthetic"), &opts)?;
//! assert!(fit.report.train_metrics[0].metrics.rmse < 0.01 * 100.0); // um, of a 100 um span
//!
//! let model = Loaded::parse(&fit.report.to_json()?, "fit.json")?;
//! let sim = model.simulate(&rec)?;
//! let diff = sim[0].iter().zip(&fit.train_sim[0]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
//! assert!(diff < 1e-9, "{diff}"); // the saved model is the fitted one
//! # Ok(())
//! # }
//! ```
//!
//! [`diagnose::diagnose`] then names what such a model misses on a measured record.
pub mod diagnose;
pub mod fast;
pub mod fit;
pub mod identify;
pub mod multibw;
pub mod numeric;
pub mod optim;
pub mod plot;
pub mod record;
pub mod saved;
pub mod ss;

/// Format tag of every `fit.json` (the saved model, [`saved`]).
pub const FORMAT: &str = "piezo-fit/1";
