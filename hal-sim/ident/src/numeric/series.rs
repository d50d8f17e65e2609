//! Helpers over sampled series: low-pass, RMS, RMSE.

/// First-order low-pass with time constant `tau_s`, starting at the first value: exact for
/// an input held over each sample (`s = a s + (1 - a) x`, `a = exp(-dt/tau)`).
pub fn lowpass(x: &[f64], tau_s: f64, dt: f64) -> Vec<f64> {
    lowpass_n(x, tau_s, dt, 1)
}

/// `order` first-order sections of time constant `tau_s` in series, `1/(tau s + 1)^order`,
/// starting at the first value, discretised exactly for an input held over each sample (the
/// whole chain at once: each section's input moves within the sample, so this is not
/// [`lowpass`] applied `order` times).
pub fn lowpass_n(x: &[f64], tau_s: f64, dt: f64, order: usize) -> Vec<f64> {
    let Some(first) = x.first().copied() else {
        return Vec::new();
    };
    if order == 0 {
        return x.to_vec();
    }
    // The chain's transition matrix is exp(-h) h^(i-j)/(i-j)! below the diagonal (h =
    // dt/tau), and with a held input the states relax towards it, so section i takes
    // 1 - sum_{m<=i} exp(-h) h^m/m! of the input: a Poisson tail, summed as a tail where
    // 1 - sum would cancel.
    let h = dt / tau_s;
    let a = (-h).exp();
    let mut c = Vec::with_capacity(order);
    let mut term = a;
    for m in 0..order {
        c.push(term);
        term *= h / (m + 1) as f64;
    }
    let b: Vec<f64> = (0..order)
        .map(|i| {
            if i == 0 {
                1.0 - a
            } else if h < 1.0 {
                let mut t = c[i] * h / (i + 1) as f64;
                let mut s = 0.0;
                for m in i + 2..i + 40 {
                    s += t;
                    t *= h / m as f64;
                }
                s
            } else {
                1.0 - c[..=i].iter().sum::<f64>()
            }
        })
        .collect();
    let mut s = vec![first; order];
    x.iter()
        .map(|&v| {
            // Last section first: each uses the sections before it at the sample's start.
            for i in (0..order).rev() {
                let mut acc = b[i] * v;
                for j in 0..=i {
                    acc += c[i - j] * s[j];
                }
                s[i] = acc;
            }
            s[order - 1]
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

    /// The chain against a fine Euler integration of the continuous filter with the input
    /// held over each sample; the first section is the plain low-pass bit for bit.
    #[test]
    fn lowpass_chain_is_exact_for_a_held_input() {
        let dt = 1e-4;
        let tau = 1.0 / (std::f64::consts::TAU * 300.0);
        let x: Vec<f64> = (0..2000)
            .map(|k| (k as f64 * 0.013).sin() + if k > 700 { 1.0 } else { 0.0 })
            .collect();
        let y = lowpass_n(&x, tau, dt, 3);
        let mut z = [x[0]; 3];
        let sub = 2000;
        let hs = dt / sub as f64 / tau;
        for (k, &v) in x.iter().enumerate() {
            for _ in 0..sub {
                let d = [v - z[0], z[0] - z[1], z[1] - z[2]];
                for i in 0..3 {
                    z[i] += hs * d[i];
                }
            }
            assert!((y[k] - z[2]).abs() < 1e-4, "{k}: {} vs {}", y[k], z[2]);
        }
        let one = lowpass_n(&x, tau, dt, 1);
        let a = (-dt / tau).exp();
        let mut s = x[0];
        for (k, &v) in x.iter().enumerate() {
            s = a * s + (1.0 - a) * v;
            assert_eq!(one[k].to_bits(), s.to_bits());
        }
        // Steady state for a constant input; no state moves.
        assert!(lowpass_n(&[2.5; 50], tau, dt, 5)
            .iter()
            .all(|&v| (v - 2.5).abs() < 1e-12));
        assert!(lowpass_n(&[], tau, dt, 3).is_empty());
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
