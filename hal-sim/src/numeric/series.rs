//! Helpers over sampled series: low-pass, RMS, RMSE.

/// First-order low-pass with time constant `tau_s`, starting at the first value: exact for
/// an input held over each sample (`a = exp(-dt/tau)`).
pub fn lowpass(x: &[f64], tau_s: f64, dt: f64) -> Vec<f64> {
    let a = (-dt / tau_s).exp();
    let mut s = x.first().copied().unwrap_or(0.0);
    x.iter()
        .map(|&v| {
            s = a * s + (1.0 - a) * v;
            s
        })
        .collect()
}

/// Root mean square; NaN for no values.
pub fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

/// RMS of `a - b` over their common length; NaN if either is empty.
pub fn rmse(a: &[f64], b: &[f64]) -> f64 {
    rms(a.iter().zip(b).map(|(a, b)| a - b))
}

/// RMSE over all outputs together (each output weighted by its length).
pub fn rmse_all(y: &[Vec<f64>], y_model: &[Vec<f64>]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (a, b) in y.iter().zip(y_model) {
        let e = rmse(a, b);
        s += e * e * a.len() as f64;
        n += a.len();
    }
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lowpass_steps_towards_the_input_with_its_time_constant() {
        let dt = 1e-3;
        let x: Vec<f64> = std::iter::once(0.0).chain([1.0; 1000]).collect();
        let y = lowpass(&x, 0.1, dt);
        // After 100 steps (one tau) of a unit step: 1 - e^-1.
        assert!(
            (y[100] - (1.0 - (-1.0f64).exp())).abs() < 1e-12,
            "{}",
            y[100]
        );
        assert!(y.windows(2).all(|w| w[1] >= w[0]));
    }

    #[test]
    fn rms_and_rmse() {
        assert!(rms(std::iter::empty()).is_nan());
        assert!(rmse(&[], &[1.0]).is_nan());
        assert_eq!(rms([3.0, -3.0].into_iter()), 3.0);
        assert_eq!(rmse(&[1.0, 2.0, 9.0], &[1.0, 0.0]), 2.0f64.sqrt());
        let y = vec![vec![1.0, 1.0], vec![0.0; 4]];
        let m = vec![vec![0.0, 0.0], vec![0.0; 4]];
        assert!((rmse_all(&y, &m) - (2.0f64 / 6.0).sqrt()).abs() < 1e-15);
    }
}
