//! The diagnosis model's linear dynamics `G` (004 eq. 8, second order, unit DC gain) and its
//! amplitude-dependent form (`amplitude-dynamics`).
//!
//! The amplitude-dependent form moves the natural frequency and damping with the structure's
//! oscillation amplitude `a` (output units, its free motion about its input), as in the fine
//! steering mirror and hal-sim's `stage.amplitude_dynamics`: with
//! `rho = a/(a + level)`, `wn = wn0*(1 + freq_shift*rho)` and
//! `zeta = zeta0*(1 + zeta_scale*rho)`. Given the course of `rho` it is a linear
//! time-varying filter, so the model's linear coefficients are still solved by least squares;
//! the course itself is a fixed point, taken from the last iterate's simulation
//! ([`super::output::fit_linear`]).

/// Exact transition matrix of `x'' + 2 zeta wn x' + wn^2 x = wn^2 u` over `dt` for an input
/// held over the step (state: deviation from the held input, velocity); `None` when not
/// finite.
pub fn transition(wn_hz: f64, zeta: f64, dt: f64) -> Option<[[f64; 2]; 2]> {
    let wn = 2.0 * std::f64::consts::PI * wn_hz;
    // exp(A h) for A = [[0, 1], [-wn^2, -2 zeta wn]]: e^(s h) (c I + sn (A - s I)), s = -zeta wn.
    let s = -zeta * wn;
    let q2 = wn * wn * (zeta * zeta - 1.0);
    let (c, sn) = if q2.abs() < 1e-12 * wn * wn {
        (1.0, dt)
    } else if q2 > 0.0 {
        let q = q2.sqrt();
        ((q * dt).cosh(), (q * dt).sinh() / q)
    } else {
        let q = (-q2).sqrt();
        ((q * dt).cos(), (q * dt).sin() / q)
    };
    let e = (s * dt).exp();
    let phi = [
        [e * (c - s * sn), e * sn],
        [-e * sn * wn * wn, e * (c + sn * (-2.0 * zeta * wn - s))],
    ];
    phi.iter().flatten().all(|v| v.is_finite()).then_some(phi)
}

/// One held-input step of the state `(p, v)` towards input `u`.
#[inline]
fn step(phi: &[[f64; 2]; 2], p: &mut f64, v: &mut f64, u: f64) {
    let d = *p - u;
    *p = u + phi[0][0] * d + phi[0][1] * *v;
    *v = phi[1][0] * d + phi[1][1] * *v;
}

/// Second-order low-pass with unit DC gain (004 eq. 8 with n = 2, m = 0), discretised
/// exactly for an input held over each sample (a DAC drives the stage), output at the end of
/// the hold; starting at rest at the first sample. `wn_hz` infinite: no dynamics.
pub fn dynamics(x: &mut [f64], wn_hz: f64, zeta: f64, dt: f64) {
    dynamics_all(&mut [x], wn_hz, zeta, dt);
}

/// [`dynamics`] on each of `cols`, the independent recurrences side by side
/// ([`crate::fast::held_second_order`]: `step`'s arithmetic, to the bit).
pub fn dynamics_all(cols: &mut [&mut [f64]], wn_hz: f64, zeta: f64, dt: f64) {
    if !wn_hz.is_finite() {
        return;
    }
    let Some(phi) = transition(wn_hz, zeta, dt) else {
        return;
    };
    crate::fast::held_second_order(cols, &phi);
}

/// Table entries over `rho` in `[0, 1]`.
const TABLE: usize = 32;
/// Smallest amplitude level (output units): `rho` stays below 1 for a finite amplitude.
pub const AMP_LEVEL_MIN: f64 = 1e-12;
/// Largest damping ratio the amplitude may reach.
const ZETA_MAX: f64 = 0.95;

/// The amplitude-dependent dynamics of one record (its sample period).
#[derive(Debug, Clone)]
pub struct AmpFilter {
    /// The transitions at `rho = k/TABLE` and their steps to the next entry: fixed-size, so
    /// the per-sample lookup has no bounds check (the recurrence is the diagnosis' hot loop).
    table: [[[f64; 2]; 2]; TABLE],
    delta: [[[f64; 2]; 2]; TABLE],
    level: f64,
    inv_w0: f64,
}

impl AmpFilter {
    /// The filter for sample period `dt` of small-amplitude natural frequency `wn_hz` and
    /// damping `zeta`, moving by `freq_shift` and `zeta_scale` (relative) at large amplitude,
    /// half of it at `level` (output units); `None` without dynamics (`wn_hz` infinite).
    pub fn new(
        wn_hz: f64,
        zeta: f64,
        level: f64,
        freq_shift: f64,
        zeta_scale: f64,
        dt: f64,
    ) -> Option<Self> {
        if !wn_hz.is_finite() {
            return None;
        }
        let entries = (0..=TABLE)
            .map(|k| {
                let rho = k as f64 / TABLE as f64;
                let f = wn_hz * (1.0 + freq_shift * rho).max(0.05);
                let z = (zeta * (1.0 + zeta_scale * rho)).clamp(1e-4, ZETA_MAX);
                transition(f, z, dt)
            })
            .collect::<Option<Vec<_>>>()?;
        let mut table = [[[0.0; 2]; 2]; TABLE];
        let mut delta = [[[0.0; 2]; 2]; TABLE];
        for (k, (t, d)) in table.iter_mut().zip(delta.iter_mut()).enumerate() {
            let (a, b) = (&entries[k], &entries[k + 1]);
            for i in 0..2 {
                for j in 0..2 {
                    t[i][j] = a[i][j];
                    d[i][j] = b[i][j] - a[i][j];
                }
            }
        }
        Some(Self {
            table,
            delta,
            level: level.max(AMP_LEVEL_MIN),
            inv_w0: 1.0 / (2.0 * std::f64::consts::PI * wn_hz),
        })
    }

    /// The transition at `rho` (linear in the table).
    #[inline]
    fn at(&self, rho: f64) -> [[f64; 2]; 2] {
        let pos = rho.clamp(0.0, 1.0) * TABLE as f64;
        let k = (pos as usize).min(TABLE - 1);
        let f = pos - k as f64;
        let (a, d) = (&self.table[k], &self.delta[k]);
        let mut m = [[0.0; 2]; 2];
        for i in 0..2 {
            for j in 0..2 {
                m[i][j] = a[i][j] + f * d[i][j];
            }
        }
        m
    }

    /// Runs the filter on `x` in place (from rest at its first sample); returns the course of
    /// `rho`, the weight each step's transition was taken at.
    pub fn run(&self, x: &mut [f64]) -> Vec<f64> {
        let mut rho = vec![0.0; x.len()];
        let Some(&first) = x.first() else {
            return rho;
        };
        let (mut p, mut v) = (first, 0.0);
        for (u, rho) in x.iter_mut().zip(rho.iter_mut()) {
            // The free motion about the input held over this step: the DAC's staircase, not
            // a ramp through it (a ramp reference missed the velocity the steps excite and
            // left a rate-dependent part that `rate-dependence` then took, seed 5 of the
            // hidden amplitude cases).
            let dx = p - *u;
            let dv = v * self.inv_w0;
            let a = (dx * dx + dv * dv).sqrt();
            let r = a / (a + self.level);
            *rho = r;
            step(&self.at(r), &mut p, &mut v, *u);
            *u = p;
        }
        rho
    }

    /// The linear time-varying filter with a given course of `rho` (from [`AmpFilter::run`]),
    /// on `x` in place: [`AmpFilter::run`] on the same input gives the same output.
    #[cfg(test)]
    pub fn follow(&self, x: &mut [f64], rho: &[f64]) {
        self.follow_all(&mut [x], rho);
    }

    /// [`AmpFilter::follow`] on each of `cols` (of one length), side by side: each step's
    /// transition is interpolated once for all columns, and their independent recurrences
    /// overlap. The same arithmetic per column, so the same bits.
    pub fn follow_all(&self, cols: &mut [&mut [f64]], rho: &[f64]) {
        let n = cols
            .iter()
            .map(|c| c.len())
            .min()
            .unwrap_or(0)
            .min(rho.len());
        let mut state: Vec<(f64, f64)> = cols
            .iter()
            .map(|c| (c.first().copied().unwrap_or(0.0), 0.0))
            .collect();
        for (k, &r) in rho.iter().enumerate().take(n) {
            let m = self.at(r);
            for (c, (p, v)) in cols.iter_mut().zip(state.iter_mut()) {
                step(&m, p, v, c[k]);
                c[k] = *p;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn steps(n: usize, big: f64) -> Vec<f64> {
        (0..n)
            .map(|k| if (k / 400) % 2 == 1 { big } else { 0.0 })
            .collect()
    }

    #[test]
    fn amplitude_moves_the_ringing_and_follow_repeats_run() {
        let f = AmpFilter::new(100.0, 0.05, 1.0, -0.3, 2.0, 1e-4).unwrap();
        // Small steps ring nearly as the plain dynamics, large ones differ.
        for (big, close) in [(0.01, true), (20.0, false)] {
            let mut a = steps(4000, big);
            let rho = f.run(&mut a);
            let mut b = steps(4000, big);
            dynamics(&mut b, 100.0, 0.05, 1e-4);
            let diff = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            assert_eq!(diff / big < 0.02, close, "{big}: {diff}");
            let mut c = steps(4000, big);
            f.follow(&mut c, &rho);
            assert!(a.iter().zip(&c).all(|(x, y)| (x - y).abs() < 1e-12));
            // Side by side: the same bits as one column at a time.
            let mut d = steps(4000, big);
            let mut e: Vec<f64> = d.iter().map(|x| 0.5 * x + 1.0).collect();
            f.follow_all(&mut [&mut d, &mut e], &rho);
            let mut e1: Vec<f64> = steps(4000, big).iter().map(|x| 0.5 * x + 1.0).collect();
            f.follow(&mut e1, &rho);
            assert_eq!(c, d);
            assert_eq!(e, e1);
        }
        // On a staircase ramp (10 units/s) the velocity is motion about the held input:
        // a = 10/wn0 = 0.0159 (and a lag of 0.0026), rho = a/(a + 1).
        let mut ramp: Vec<f64> = (0..4000).map(|k| k as f64 * 1e-3).collect();
        let rho = f.run(&mut ramp);
        assert!(
            rho[2000..].iter().all(|r| (0.0150..0.0170).contains(r)),
            "{}",
            rho[3999]
        );
        // Zero shifts: the plain dynamics.
        let plain = AmpFilter::new(100.0, 0.05, 1.0, 0.0, 0.0, 1e-4).unwrap();
        let mut a = steps(2000, 5.0);
        plain.run(&mut a);
        let mut b = steps(2000, 5.0);
        dynamics(&mut b, 100.0, 0.05, 1e-4);
        assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-9));
    }
}
