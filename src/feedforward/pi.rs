//! Exact inverses of the Prandtl-Ishlinskii models of 001: PI (eq. 4-5), DPI (eq. 8-10) and
//! PPI (eq. 6-7).
//!
//! Operator banks of any size `N <= MAX_OPS` are stored padded to [`MAX_OPS`] operators
//! (zero weight, thresholds beyond the last), so one non-generic type serves every bank and
//! the [`super::Feedforward`] enum stays generic in the number type only.

use super::ims::{Ims, ImsLoop, ImsModel};
use super::{ensure, FfError};
use crate::hysteresis::Pi;
use crate::hysteresis::{Dpi, Hysteresis, PiState, Ppi};
use crate::real::Real;

/// Largest operator bank the inverses accept.
pub const MAX_OPS: usize = 16;

/// A PI bank padded to [`MAX_OPS`] operators.
pub type PiBank<T> = Pi<T, MAX_OPS>;

/// Pads `w`, `r` (0 < r_1 < ... < r_N) with zero-weight operators to [`MAX_OPS`].
fn pad<T: Real, const N: usize>(
    w: &[T; N],
    r: &[T; N],
) -> Result<([T; MAX_OPS], [T; MAX_OPS]), FfError> {
    ensure(N <= MAX_OPS, "PI inverse: at most MAX_OPS = 16 operators")?;
    let mut wp = [T::ZERO; MAX_OPS];
    let mut rp = [T::ZERO; MAX_OPS];
    let last = r.last().copied().unwrap_or(T::ONE).max(T::ONE);
    for (k, (wp, rp)) in wp.iter_mut().zip(rp.iter_mut()).enumerate() {
        if let (Some(&wk), Some(&rk)) = (w.get(k), r.get(k)) {
            *wp = wk;
            *rp = rk;
        } else {
            *rp = last * T::from_usize(k + 2);
        }
    }
    Ok((wp, rp))
}

/// Inverse PI (Kuhnen): for `y = sum_j omega_j*H_tj[v]` with `t_0 = 0 < t_1 < ...`,
/// `omega_0 > 0` and every partial sum `Omega_j = omega_0 + ... + omega_j > 0`,
/// `v = y/omega_0 + sum_{j>=1} what_j*H_rhat_j[y]` with
/// `rhat_j = sum_{i<=j} omega_i*(t_j - t_i)`,
/// `what_j = -omega_j / (Omega_j * Omega_{j-1})`.
/// Returns `(1/omega_0, what_1.., rhat_1..)`.
fn kuhnen<T: Real>(
    omega0: T,
    w: &[T; MAX_OPS],
    t: &[T; MAX_OPS],
) -> Result<(T, [T; MAX_OPS], [T; MAX_OPS]), FfError> {
    ensure(omega0 > T::ZERO, "PI inverse: linear weight w0 > 0")?;
    let mut what = [T::ZERO; MAX_OPS];
    let mut rhat = [T::ZERO; MAX_OPS];
    let mut omega_prev = omega0;
    for j in 0..MAX_OPS {
        let (wj, tj) = (w[j], t[j]);
        let omega = omega_prev + wj;
        ensure(
            omega > T::ZERO,
            "PI inverse: every partial sum w0 + w_1 + .. + w_j > 0",
        )?;
        // sum_{i<=j} omega_i (t_j - t_i), with t_0 = 0 for omega_0
        let mut r = omega0 * tj;
        for i in 0..j {
            r += w[i] * (tj - t[i]);
        }
        what[j] = -wj / (omega * omega_prev);
        rhat[j] = r;
        omega_prev = omega;
    }
    // Thresholds of zero-weight operators may coincide; keep them strictly increasing.
    for j in 1..MAX_OPS {
        if !(rhat[j] > rhat[j - 1]) {
            rhat[j] = rhat[j - 1] + (rhat[j - 1].abs() + T::ONE) * T::from_f64(1e-6);
        }
    }
    Ok((T::ONE / omega0, what, rhat))
}

/// Exact inverse of a PI model (001 eq. 4-5), itself a PI with thresholds and weights
/// computed at construction.
#[derive(Debug, Clone, PartialEq)]
pub struct PiInverse<T: Real> {
    inv: PiBank<T>,
    /// Forward slope at rest `w0 + sum w_i`.
    fwd_gain: T,
    /// Output offset of the model (`y = offset_um + PI[u]`, see [`PiInverse::with_offset`]).
    offset_um: T,
    volts_min: T,
    volts_max: T,
    state: PiState<T, MAX_OPS>,
    u: T,
}

/// The model output (offset excluded) an inverse of `y = offset_um + M[u]` restarts at for
/// the output `y_um`; a non-finite `y_um` restarts at the model's zero.
fn model_output<T: Real>(y_um: T, offset_um: T) -> T {
    let y = y_um - offset_um;
    if y.is_finite() {
        y
    } else {
        T::ZERO
    }
}

impl<T: Real> PiInverse<T> {
    /// Inverse of `pi` for voltages in `volts_min..volts_max`; starts at rest at 0 V.
    pub fn new<const N: usize>(pi: &Pi<T, N>, volts_min: T, volts_max: T) -> Result<Self, FfError> {
        super::check_range(volts_min, volts_max)?;
        let (w, r) = pad(pi.weights(), pi.thresholds())?;
        let (w0i, what, rhat) = kuhnen(pi.w0(), &w, &r)?;
        let inv = Pi::new(w0i, what, rhat)?;
        let fwd_gain = pi.weights().iter().fold(pi.w0(), |a, &w| a + w);
        let mut s = Self {
            inv,
            fwd_gain,
            offset_um: T::ZERO,
            volts_min,
            volts_max,
            state: inv.init(T::ZERO),
            u: T::ZERO,
        };
        s.reset(T::ZERO);
        Ok(s)
    }

    /// The same inverse for a model `y = offset_um + PI[u]` (`piezo fit` fits an output
    /// offset); restarts at rest at the voltage it last commanded.
    pub fn with_offset(mut self, offset_um: T) -> Result<Self, FfError> {
        ensure(
            offset_um.is_finite(),
            "PI inverse: offset_um must be finite",
        )?;
        self.offset_um = offset_um;
        let u = self.u;
        self.reset_volts(u);
        Ok(self)
    }

    /// The inverse bank (for inspection and tests).
    pub fn inverse_bank(&self) -> &PiBank<T> {
        &self.inv
    }

    #[inline]
    pub fn compensate(&mut self, y_ref_um: T) -> T {
        let y = y_ref_um - self.offset_um;
        if !y.is_finite() {
            return self.u;
        }
        let u = self.inv.step(&mut self.state, y, T::ONE);
        self.u = if u.is_finite() {
            u.clamp_to(self.volts_min, self.volts_max)
        } else {
            self.u
        };
        self.u
    }

    /// The last voltage (V).
    pub fn volts(&self) -> T {
        self.u
    }

    /// Restart at rest at voltage `u0` (the forward model's operators centred there).
    pub fn reset_volts(&mut self, u0: T) {
        let u0 = if u0.is_finite() { u0 } else { T::ZERO };
        self.reset_model(self.fwd_gain * u0);
    }

    /// Restart at rest (operators centred) at output `y_um`.
    pub fn reset(&mut self, y_um: T) {
        self.reset_model(model_output(y_um, self.offset_um));
    }

    /// Restart at rest at the model output `y` (offset excluded).
    fn reset_model(&mut self, y: T) {
        self.state = self.inv.init(y);
        self.u = self
            .inv
            .step(&mut self.state, y, T::ONE)
            .clamp_to(self.volts_min, self.volts_max);
    }
}

/// Exact inverse of the DPI (001 eq. 8-10): the dead-zone sum is piecewise linear and
/// increasing, so it is inverted segment by segment; then the PI. Eq. 10 has no linear term
/// (`w0 = 0`), so the PI is `P'[H_r1[u]]` with `P'` thresholds `r_i - r_1` (linear weight
/// `w_1`): `P'` is inverted exactly (Kuhnen) and `H_r1` by its right inverse
/// `u = v + r_1*sgn(dv)` (a jump of `2*r_1` at each reversal of the reference).
#[derive(Debug, Clone, PartialEq)]
pub struct DpiInverse<T: Real> {
    /// Breakpoints `d_k` and values `Z_k` of the dead-zone sum, slopes `S_k` to the right.
    dz_d: [T; MAX_OPS],
    dz_z: [T; MAX_OPS],
    dz_s: [T; MAX_OPS],
    dz_len: usize,
    inv: PiBank<T>,
    r1: T,
    /// Slope `sum w_i` of the DPI's PI at rest.
    pi_gain: T,
    /// Output offset of the model (`y = offset_um + DPI[u]`, see [`DpiInverse::with_offset`]).
    offset_um: T,
    volts_min: T,
    volts_max: T,
    state: PiState<T, MAX_OPS>,
    v: T,
    dir: T,
    u: T,
}

impl<T: Real> DpiInverse<T> {
    pub fn new<const N: usize, const M: usize>(
        dpi: &Dpi<T, N, M>,
        volts_min: T,
        volts_max: T,
    ) -> Result<Self, FfError> {
        super::check_range(volts_min, volts_max)?;
        ensure(N >= 1, "DPI inverse: at least one backlash operator")?;
        ensure(
            (1..=MAX_OPS).contains(&M),
            "DPI inverse: 1..=16 dead-zone operators",
        )?;
        let ws = dpi.dead_zone_weights();
        let d = dpi.dead_zone_thresholds();
        ensure(
            d.first() == Some(&T::ZERO),
            "DPI inverse: first dead-zone threshold d_1 = 0 (else outputs below 0 are unreachable)",
        )?;
        let (mut dz_d, mut dz_z, mut dz_s) =
            ([T::ZERO; MAX_OPS], [T::ZERO; MAX_OPS], [T::ZERO; MAX_OPS]);
        let mut slope = T::ZERO;
        for k in 0..M {
            slope += ws[k];
            ensure(
                slope > T::ZERO,
                "DPI inverse: every partial sum ws_1 + .. + ws_k > 0",
            )?;
            dz_d[k] = d[k];
            dz_z[k] = dpi.dead_zones(d[k]);
            dz_s[k] = slope;
        }
        // P = P' o H_r1: thresholds r_i - r_1, the first one becomes the linear weight.
        let w = dpi.pi().weights();
        let r = dpi.pi().thresholds();
        let r1 = r[0];
        let mut wt = [T::ZERO; MAX_OPS];
        let mut tt = [T::ZERO; MAX_OPS];
        for i in 1..N {
            wt[i - 1] = w[i];
            tt[i - 1] = r[i] - r1;
        }
        let last = tt
            .get(N.saturating_sub(2))
            .copied()
            .unwrap_or(T::ONE)
            .max(T::ONE);
        for (k, t) in tt.iter_mut().enumerate().skip(N - 1) {
            *t = last * T::from_usize(k + 2);
        }
        let (w0i, what, rhat) = kuhnen(w[0], &wt, &tt)?;
        let inv = Pi::new(w0i, what, rhat)?;
        let mut s = Self {
            dz_d,
            dz_z,
            dz_s,
            dz_len: M,
            inv,
            r1,
            pi_gain: w.iter().fold(T::ZERO, |a, &w| a + w),
            offset_um: T::ZERO,
            volts_min,
            volts_max,
            state: inv.init(T::ZERO),
            v: T::ZERO,
            dir: T::ZERO,
            u: T::ZERO,
        };
        s.reset(T::ZERO);
        Ok(s)
    }

    /// The same inverse for a model `y = offset_um + DPI[u]` (`piezo fit` fits an output
    /// offset); restarts at rest at the voltage it last commanded.
    pub fn with_offset(mut self, offset_um: T) -> Result<Self, FfError> {
        ensure(
            offset_um.is_finite(),
            "DPI inverse: offset_um must be finite",
        )?;
        self.offset_um = offset_um;
        let u = self.u;
        self.reset_volts(u);
        Ok(self)
    }

    /// Inverse of the dead-zone sum: the PI output `p` with `sum ws_k*S_dk[p] = y`.
    #[inline]
    pub fn dead_zone_inverse(&self, y: T) -> T {
        // Below the first breakpoint (d_1 = 0) only the linear operator acts.
        let mut p = y / self.dz_s[0];
        for k in 0..self.dz_len.min(MAX_OPS) {
            if y >= self.dz_z[k] {
                p = self.dz_d[k] + (y - self.dz_z[k]) / self.dz_s[k];
            }
        }
        p
    }

    /// The dead-zone sum `sum ws_k*S_dk[p]` (001 eq. 9) from the tables.
    pub fn dead_zones(&self, p: T) -> T {
        let mut z = p * self.dz_s[0];
        for k in 0..self.dz_len.min(MAX_OPS) {
            if p >= self.dz_d[k] {
                z = self.dz_z[k] + (p - self.dz_d[k]) * self.dz_s[k];
            }
        }
        z
    }

    /// The last voltage (V).
    pub fn volts(&self) -> T {
        self.u
    }

    /// Restart at rest at voltage `u0`.
    pub fn reset_volts(&mut self, u0: T) {
        let u0 = if u0.is_finite() { u0 } else { T::ZERO };
        self.reset_model(self.dead_zones(self.pi_gain * u0));
    }

    #[inline]
    pub fn compensate(&mut self, y_ref_um: T) -> T {
        let y = y_ref_um - self.offset_um;
        if !y.is_finite() {
            return self.u;
        }
        let p = self.dead_zone_inverse(y);
        let v = self.inv.step(&mut self.state, p, T::ONE);
        if !v.is_finite() {
            return self.u;
        }
        let dv = v - self.v;
        if dv != T::ZERO {
            self.dir = dv.sgn();
        }
        self.v = v;
        self.u = (v + self.r1 * self.dir).clamp_to(self.volts_min, self.volts_max);
        self.u
    }

    /// Restart at rest at output `y_um` (operators centred).
    pub fn reset(&mut self, y_um: T) {
        self.reset_model(model_output(y_um, self.offset_um));
    }

    /// Restart at rest at the model output `y` (offset excluded).
    fn reset_model(&mut self, y: T) {
        let p = self.dead_zone_inverse(y);
        self.state = self.inv.init(p);
        self.v = self.inv.step(&mut self.state, p, T::ONE);
        self.dir = T::ZERO;
        self.u = self.v.clamp_to(self.volts_min, self.volts_max);
    }
}

impl<T: Real> ImsModel<T> for PiBankPpi<T> {
    /// The major-loop slope `c2 + sum w_i` (used for the rest position only).
    fn d(&self) -> T {
        self.c2() + self.pi().weights().iter().fold(T::ZERO, |a, &w| a + w)
    }
    fn max_h_slope(&self) -> T {
        // dy/du >= c2 + min over prefixes of the weights (the dragged operators after a
        // reversal are those with the smallest thresholds); c1 >= 0 adds 3*c1*u^2 >= 0.
        let mut prefix = T::ZERO;
        let mut min_prefix = T::ZERO;
        for &w in self.pi().weights() {
            prefix += w;
            min_prefix = min_prefix.min(prefix);
        }
        let min_slope = if self.c1() >= T::ZERO {
            self.c2() + min_prefix
        } else {
            -T::ONE
        };
        self.d() - min_slope
    }
}

/// The PPI padded to [`MAX_OPS`] operators.
pub type PiBankPpi<T> = Ppi<T, MAX_OPS>;

/// Inverse of the PPI (001 eq. 6-7): `c1*u^3 + c2*u + sum w_i*H_ri[u] = y_ref` solved for
/// `u` each sample (strictly increasing in `u` when `c1 >= 0` and `c2` plus every partial
/// sum of the weights is positive; bracketed, bounded solve as for the IMS).
pub type PpiInverse<T> = Ims<T, PiBankPpi<T>>;

/// Builds the PPI inverse of `ppi` (any `N <= 16`).
pub fn ppi_inverse<T: Real, const N: usize>(
    ppi: &Ppi<T, N>,
    volts_min: T,
    volts_max: T,
    dt_s: T,
) -> Result<PpiInverse<T>, FfError> {
    let (w, r) = pad(ppi.pi().weights(), ppi.pi().thresholds())?;
    let padded = Ppi::new(ppi.c1(), ppi.c2(), w, r)?;
    Ims::new(padded, ImsLoop::Solved, volts_min, volts_max, dt_s).map_err(|e| {
        if e.0.starts_with("IMS: d must exceed") {
            crate::hysteresis::ParamError("PPI inverse: need c1 >= 0 and c2 + every partial sum of w_i > 0 (y increasing in u)")
        } else {
            e
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drive<M: Hysteresis<f64>>(model: &M, mut ff: impl FnMut(f64) -> f64, n: usize) -> f64 {
        let mut s = model.init(0.0);
        let mut max_err: f64 = 0.0;
        for k in 0..n {
            let t = k as f64 * 1e-3;
            // Decaying sine with minor loops, from 0.
            let y_ref = 30.0
                * (1.0 - (-0.3 * t).exp())
                * (1.0 + 0.8 * (2.0 * core::f64::consts::PI * t).sin())
                + 5.0 * (2.0 * core::f64::consts::PI * 7.0 * t).sin() * (1.0 - (-t).exp());
            let u = ff(y_ref);
            let y = model.step(&mut s, u, 1e-3);
            max_err = max_err.max((y - y_ref).abs());
        }
        max_err
    }

    fn pi_model() -> Pi<f64, 4> {
        Pi::new(0.5, [0.3, -0.1, 0.2, 0.05], [1.0, 3.0, 6.0, 10.0]).unwrap()
    }

    #[test]
    fn pi_inverse_is_exact() {
        let m = pi_model();
        let mut inv = PiInverse::new(&m, -1e3, 1e3).unwrap();
        let err = drive(&m, |y| inv.compensate(y), 5000);
        assert!(err < 1e-9, "{err}");
    }

    #[test]
    fn pi_inverse_rejects_non_invertible() {
        let m = Pi::new(0.5, [-0.6, 0.2], [1.0, 2.0]).unwrap();
        assert!(PiInverse::new(&m, -1.0, 1.0)
            .unwrap_err()
            .0
            .contains("partial sum"));
        let m = Pi::new(0.0, [0.6, 0.2], [1.0, 2.0]).unwrap();
        assert!(PiInverse::new(&m, -1.0, 1.0)
            .unwrap_err()
            .0
            .contains("w0 > 0"));
    }

    #[test]
    fn dpi_inverse_is_exact() {
        let m = Dpi::new(
            [0.6, 0.2, 0.1],
            [0.5, 2.0, 5.0],
            [1.0, 0.3, -0.2],
            [0.0, 10.0, 25.0],
        )
        .unwrap();
        let mut inv = DpiInverse::new(&m, -1e3, 1e3).unwrap();
        let err = drive(&m, |y| inv.compensate(y), 5000);
        assert!(err < 1e-9, "{err}");
    }

    #[test]
    fn ppi_inverse_solves_to_tolerance() {
        let m = Ppi::new(1e-4, 0.4, [0.3, 0.2, 0.1], [1.0, 4.0, 8.0]).unwrap();
        let mut inv = ppi_inverse(&m, -1e3, 1e3, 1e-3).unwrap();
        let err = drive(&m, |y| inv.compensate(y), 5000);
        assert!(err < 1e-9, "{err}");
        let bad = Ppi::new(-1e-4, 0.4, [0.3], [1.0]).unwrap();
        assert!(ppi_inverse(&bad, -1.0, 1.0, 1e-3)
            .unwrap_err()
            .0
            .contains("PPI inverse"));
    }

    /// An inverse built for `y = offset + model(u)` commands, for `y_ref + offset`, what
    /// the plain inverse commands for `y_ref` (PI, DPI and PPI alike).
    #[test]
    fn offset_shifts_the_reference() {
        let off = 7.5;
        let refs = |k: usize| 20.0 * (0.01 * k as f64).sin() + 0.1 * k as f64 % 3.0;
        let same = |mut a: Box<dyn FnMut(f64) -> f64>, mut b: Box<dyn FnMut(f64) -> f64>| {
            for k in 0..3000 {
                let (ua, ub) = (a(refs(k)), b(refs(k) + off));
                assert!((ua - ub).abs() < 1e-9, "sample {k}: {ua} vs {ub}");
            }
        };
        let m = pi_model();
        let mut p0 = PiInverse::new(&m, -1e3, 1e3).unwrap();
        let mut p1 = PiInverse::new(&m, -1e3, 1e3)
            .unwrap()
            .with_offset(off)
            .unwrap();
        assert_eq!(p0.volts(), p1.volts());
        same(
            Box::new(move |y| p0.compensate(y)),
            Box::new(move |y| p1.compensate(y)),
        );
        let d = Dpi::new([0.6, 0.2], [0.5, 2.0], [1.0, 0.3], [0.0, 10.0]).unwrap();
        let mut d0 = DpiInverse::new(&d, -1e3, 1e3).unwrap();
        let mut d1 = DpiInverse::new(&d, -1e3, 1e3)
            .unwrap()
            .with_offset(off)
            .unwrap();
        same(
            Box::new(move |y| d0.compensate(y)),
            Box::new(move |y| d1.compensate(y)),
        );
        let q = Ppi::new(1e-4, 0.4, [0.3, 0.2], [1.0, 4.0]).unwrap();
        let mut q0 = ppi_inverse(&q, -1e3, 1e3, 1e-3).unwrap();
        let mut q1 = ppi_inverse(&q, -1e3, 1e3, 1e-3)
            .unwrap()
            .with_offset(off)
            .unwrap();
        same(
            Box::new(move |y| q0.compensate(y)),
            Box::new(move |y| q1.compensate(y)),
        );
        assert!(PiInverse::new(&m, -1.0, 1.0)
            .unwrap()
            .with_offset(f64::NAN)
            .is_err());
    }

    #[test]
    fn nan_reference_holds() {
        let m = pi_model();
        let mut inv = PiInverse::new(&m, -1e3, 1e3).unwrap();
        let u = inv.compensate(3.0);
        assert_eq!(inv.compensate(f64::NAN), u);
    }
}
