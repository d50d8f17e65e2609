//! hal-sim's numerics, each written once: the seeded random generator ([`Rng`]), the
//! symmetric positive definite solve behind every least-squares and Levenberg-Marquardt step
//! ([`solve_spd`]), and the series helpers (first-order low-pass, RMS and RMSE).
pub mod rng;
pub mod series;
pub mod solve;

pub use rng::Rng;
pub use series::{lowpass, lowpass_n, rms, rmse, rmse_all};
pub use solve::solve_spd;
