//! Second-order IIR section for loop shaping, notably the notch on the stage resonance that
//! commercial piezo controllers carry.

use crate::hysteresis::{ensure, ensure_finite, ParamError};
use crate::real::Real;

/// Biquad `(b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2)`, direct form I.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Biquad<T> {
    b: [T; 3],
    a: [T; 2],
    /// `x[k-1], x[k-2], y[k-1], y[k-2]`.
    s: [T; 4],
}

impl<T: Real> Biquad<T> {
    /// Coefficients as given (`a0 = 1`); must be finite and stable.
    pub fn new(b: [T; 3], a: [T; 2]) -> Result<Self, ParamError> {
        ensure_finite(
            &[b[0], b[1], b[2], a[0], a[1]],
            "biquad: finite coefficients",
        )?;
        // Stability triangle: |a2| < 1, |a1| < 1 + a2.
        ensure(
            a[1].abs() < T::ONE && a[0].abs() < T::ONE + a[1],
            "biquad: poles inside the unit circle",
        )?;
        Ok(Self {
            b,
            a,
            s: [T::ZERO; 4],
        })
    }

    /// Notch `(s^2 + w0^2) / (s^2 + w0/q s + w0^2)` by the bilinear transform prewarped at
    /// `f0_hz`, so the zero sits exactly on `f0_hz`. `q` is centre over -3 dB bandwidth.
    pub fn notch(f0_hz: T, q: T, sample_rate_hz: T) -> Result<Self, ParamError> {
        Self::notch_with_depth(f0_hz, q, T::ZERO, sample_rate_hz)
    }

    /// Notch of finite depth: zeros damped by `depth` (gain at `f0` is `depth`, 0 = infinite
    /// attenuation): `(s^2 + depth w0/q s + w0^2) / (s^2 + w0/q s + w0^2)`, prewarped at `f0`.
    pub fn notch_with_depth(
        f0_hz: T,
        q: T,
        depth: T,
        sample_rate_hz: T,
    ) -> Result<Self, ParamError> {
        ensure_finite(
            &[f0_hz, q, depth, sample_rate_hz],
            "notch: finite parameters",
        )?;
        ensure(sample_rate_hz > T::ZERO, "notch: sample_rate_hz > 0")?;
        ensure(
            f0_hz > T::ZERO && f0_hz < sample_rate_hz * T::HALF,
            "notch: 0 < f0_hz < sample_rate_hz / 2",
        )?;
        ensure(q > T::ZERO, "notch: q > 0")?;
        ensure(depth >= T::ZERO && depth < T::ONE, "notch: 0 <= depth < 1")?;
        let w0 = T::TWO * T::PI * f0_hz / sample_rate_hz;
        let alpha = w0.sin() / (T::TWO * q);
        let cw = w0.cos();
        let a0 = T::ONE + alpha;
        let b = [
            (T::ONE + depth * alpha) / a0,
            -T::TWO * cw / a0,
            (T::ONE - depth * alpha) / a0,
        ];
        let a = [-T::TWO * cw / a0, (T::ONE - alpha) / a0];
        Self::new(b, a)
    }

    /// Gain at DC, `H(1)`.
    pub fn dc_gain(&self) -> T {
        (self.b[0] + self.b[1] + self.b[2]) / (T::ONE + self.a[0] + self.a[1])
    }

    /// Magnitude of `H(exp(j w))` at `f_hz` (for tests and tables).
    pub fn magnitude(&self, f_hz: T, sample_rate_hz: T) -> T {
        let w = T::TWO * T::PI * f_hz / sample_rate_hz;
        let (c1, s1, c2, s2) = (w.cos(), w.sin(), (T::TWO * w).cos(), (T::TWO * w).sin());
        let nr = self.b[0] + self.b[1] * c1 + self.b[2] * c2;
        let ni = -(self.b[1] * s1 + self.b[2] * s2);
        let dr = T::ONE + self.a[0] * c1 + self.a[1] * c2;
        let di = -(self.a[0] * s1 + self.a[1] * s2);
        ((nr * nr + ni * ni) / (dr * dr + di * di)).sqrt()
    }

    /// Filter one sample. A non-finite `x` restarts the filter at its last output.
    #[inline]
    pub fn update(&mut self, x: T) -> T {
        if !x.is_finite() {
            let hold = self.s[2];
            self.settle(hold);
            return hold;
        }
        let [x1, x2, y1, y2] = self.s;
        let y = self.b[0] * x + self.b[1] * x1 + self.b[2] * x2 - self.a[0] * y1 - self.a[1] * y2;
        if !y.is_finite() {
            self.settle(x);
            return x;
        }
        self.s = [x, x1, y, y1];
        y
    }

    /// Steady state for a constant input `x` (output `x * dc_gain`).
    pub fn settle(&mut self, x: T) {
        let y = x * self.dc_gain();
        self.s = [x, x, y, y];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn db(x: f64) -> f64 {
        20.0 * x.log10()
    }

    #[test]
    fn notch_attenuates_centre_by_more_than_30_db() {
        let fs = 100e3;
        let f0 = 1419.0;
        let mut n = Biquad::notch(f0, 2.0, fs).unwrap();
        assert!(db(n.magnitude(f0, fs)) < -30.0);
        // Time domain: steady-state amplitude of a sine at f0.
        let mut peak: f64 = 0.0;
        for k in 0..200_000 {
            let x = (2.0 * core::f64::consts::PI * f0 * k as f64 / fs).sin();
            let y = n.update(x);
            if k > 150_000 {
                peak = peak.max(y.abs());
            }
        }
        assert!(db(peak) < -30.0, "{} dB", db(peak));
        // ... and passes DC and low frequencies.
        assert!((n.dc_gain() - 1.0).abs() < 1e-12);
        assert!(db(n.magnitude(10.0, fs)).abs() < 0.01);
    }

    #[test]
    fn finite_depth_notch_has_that_depth_in_f32() {
        let n = Biquad::notch_with_depth(1000.0f32, 1.0, 0.1, 100e3).unwrap();
        assert!((n.magnitude(1000.0, 100e3) - 0.1).abs() < 1e-3);
    }

    #[test]
    fn rejects_bad_parameters() {
        assert_eq!(
            Biquad::notch(60e3, 1.0, 100e3).unwrap_err().0,
            "notch: 0 < f0_hz < sample_rate_hz / 2"
        );
        assert!(Biquad::new([1.0, 0.0, 0.0], [0.0, 1.5]).is_err());
    }

    #[test]
    fn nan_does_not_stick() {
        let mut n = Biquad::notch(1000.0, 1.0, 100e3).unwrap();
        n.settle(2.0);
        assert_eq!(n.update(f64::NAN), 2.0);
        assert!((n.update(2.0) - 2.0).abs() < 1e-12);
    }
}
