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

/// One period of `lines - 1` harmonics of random phase (seeded), each of amplitude 1/6:
/// the periodic test input of the state-space tests.
#[cfg(test)]
pub(crate) fn random_phase_period(period: usize, lines: usize, seed: u64) -> Vec<f64> {
    let mut r = Rng::new(seed);
    let phases: Vec<f64> = (1..lines)
        .map(|_| r.range(0.0, std::f64::consts::TAU))
        .collect();
    (0..period)
        .map(|k| {
            phases
                .iter()
                .enumerate()
                .map(|(l, p)| {
                    (std::f64::consts::TAU * (l + 1) as f64 * k as f64 / period as f64 + p).cos()
                })
                .sum::<f64>()
                / 6.0
        })
        .collect()
}
