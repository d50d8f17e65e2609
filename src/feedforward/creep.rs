//! Exact inverse of linear creep in parallel first-order elements.

use super::{ensure, FfError};
use crate::real::Real;

/// Most creep elements [`CreepInverse`] holds.
pub const MAX_CREEP: usize = 4;

/// Creep of the stage model `y = y_s + sum_i c_i`, `c_i' = (g_i*y_s - c_i)/tau_i`
/// (`y_s` the static hysteresis output): a stable, minimum-phase linear operator on `y_s`
/// (all `g_i >= 0`), inverted exactly per sample. With `y_s` held over a sample
/// (`e_i = exp(-dt/tau_i)`): `c_i <- e_i*c_i + (1 - e_i)*g_i*y_s`, so the static target for
/// a reference `y` is `y_s = (y - sum e_i*c_i) / (1 + sum (1 - e_i)*g_i)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CreepInverse<T> {
    gain: [T; MAX_CREEP],
    decay: [T; MAX_CREEP],
    len: usize,
    denom: T,
    c: [T; MAX_CREEP],
}

impl<T: Real> CreepInverse<T> {
    /// `gains` (dimensionless, >= 0) and `taus_s` (s, > 0), at most [`MAX_CREEP`]; `dt_s`
    /// the sample period.
    pub fn new(gains: &[T], taus_s: &[T], dt_s: T) -> Result<Self, FfError> {
        super::check_dt(dt_s)?;
        ensure(
            gains.len() == taus_s.len() && gains.len() <= MAX_CREEP,
            "creep inverse: as many gains as time constants, at most 4",
        )?;
        let mut s = Self {
            gain: [T::ZERO; MAX_CREEP],
            decay: [T::ONE; MAX_CREEP],
            len: gains.len(),
            denom: T::ONE,
            c: [T::ZERO; MAX_CREEP],
        };
        for (k, (&g, &tau)) in gains.iter().zip(taus_s).enumerate() {
            ensure(
                g.is_finite() && g >= T::ZERO,
                "creep inverse: gains finite and >= 0",
            )?;
            ensure(
                tau.is_finite() && tau > T::ZERO,
                "creep inverse: time constants finite and > 0",
            )?;
            s.gain[k] = g;
            s.decay[k] = (-dt_s / tau).exp();
            s.denom += (T::ONE - s.decay[k]) * g;
        }
        Ok(s)
    }

    /// The static output that brings the total to `y_um` this sample.
    #[inline]
    pub fn static_target(&self, y_um: T) -> T {
        let mut acc = y_um;
        for (&e, &c) in self.decay.iter().zip(self.c.iter()).take(self.len) {
            acc -= e * c;
        }
        acc / self.denom
    }

    /// Advances the creep states with the static output actually reached.
    #[inline]
    pub fn commit(&mut self, y_static_um: T) {
        if !y_static_um.is_finite() {
            return;
        }
        for k in 0..self.len.min(MAX_CREEP) {
            self.c[k] =
                self.decay[k] * self.c[k] + (T::ONE - self.decay[k]) * self.gain[k] * y_static_um;
        }
    }

    /// Creep at rest for a static output held at `y_static_um` forever.
    pub fn settle(&mut self, y_static_um: T) {
        let y = if y_static_um.is_finite() {
            y_static_um
        } else {
            T::ZERO
        };
        for k in 0..self.len.min(MAX_CREEP) {
            self.c[k] = self.gain[k] * y;
        }
    }

    /// Total output for a static output held at rest: `(1 + sum g_i) * y_s`.
    pub fn dc_gain(&self) -> T {
        T::ONE + self.gain.iter().take(self.len).fold(T::ZERO, |a, &g| a + g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverts_forward_creep_exactly() {
        let (g, tau, dt) = ([0.01, 0.015, 0.02], [0.02, 0.3, 5.0], 1e-3);
        let mut inv = CreepInverse::new(&g, &tau, dt).unwrap();
        let mut c = [0.0f64; 3];
        let mut max_err: f64 = 0.0;
        for k in 0..5000 {
            let y_ref = 50.0 + 40.0 * (k as f64 * 0.01).sin();
            let ys = inv.static_target(y_ref);
            inv.commit(ys);
            // forward: the stage's recursion with y_s held over the sample
            let mut y = ys;
            for i in 0..3 {
                let e = (-dt / tau[i]).exp();
                c[i] = e * c[i] + (1.0 - e) * g[i] * ys;
                y += c[i];
            }
            max_err = max_err.max((y - y_ref).abs());
        }
        assert!(max_err < 1e-10, "{max_err}");
        assert!(CreepInverse::new(&[0.1], &[0.0], dt).is_err());
        assert!(CreepInverse::new(&[-0.1], &[1.0], dt).is_err());
    }
}
