//! hal-sim's numerics, each written once: the seeded random generator ([`Rng`]), the
//! symmetric positive definite solve behind every normal-equations and Levenberg-Marquardt
//! step ([`solve_spd`]), least squares by SVD ([`least_squares`]), and the series helpers
//! (low-pass chains, RMS and RMSE).
pub mod rng;
pub mod series;
pub mod solve;

pub use rng::Rng;
pub use series::{lowpass, lowpass_n, rms, rmse, rmse_all};
pub use solve::{least_squares, solve_spd};
