//! Stable inversion of linear dynamics with zeros anywhere: zero-phase-error tracking
//! control (ZPETC, Tomizuka 1987) with preview, for the inverse linear dynamics of 004
//! eq. (27) when the identified model (004 eq. 8) has non-minimum-phase zeros.
//!
//! The plant `G(z) = B(z)/A(z)` is the exact ZOH equivalent of the continuous sections.
//! Its numerator is split `B = beta * B_a * B_u` (monic factors): `B_a` holds the accepted
//! zeros (inside `|z| < accept_radius` with a positive real part), `B_u` the others: the
//! right-half-plane zeros of the continuous model (outside the unit circle after
//! sampling) and the sampling zeros near `z = -1` that a relative degree of two or more
//! leaves. Then `G = G_a * B_u(z)` with the minimum-phase part `G_a = beta*B_a/A`, realised
//! on the plant's own well-scaled state `x` with a second output map `C_a`, and
//!
//! * `w_d(k) = sum_i b_i * y_d(k - i) / B_u(1)^2` (`B_u = sum b_i z^i`: the zero-phase
//!   filter `B_u(q^-1)/B_u(1)^2`, causal),
//! * `v(k)` from the exact inverse of `G_a` with a preview of `P = d + s` samples
//!   (`d` the plant's delay, `s = deg B_u`): `v(k) = (w_d(k+P) - C_a Phi^P x(k)) /
//!   (C_a Phi^(P-1) Gamma)`, `x(k+1) = Phi x(k) + Gamma v(k)`. Its own dynamics are the
//!   accepted zeros, so it is stable.
//!
//! So `y(k) = B_u(q) B_u(q^-1) / B_u(1)^2 y_d(k)`: zero phase error at every frequency,
//! unity gain at DC, a gain error growing as `|B_u(e^jw)|^2/B_u(1)^2` departs from one. The
//! caller supplies the reference [`Zpetc::preview`] samples ahead.
//!
//! Construction runs in f64 (once, on the target too: no allocation); the per-sample work
//! is `n^2 + 3n + s` multiply-adds in `T`.

// Dense index loops read clearer here.
#![allow(clippy::needless_range_loop)]

use super::{ensure, FfError};
use crate::hysteresis::ParamError;
use crate::linear::poly::{roots, Complex, MAX_DEGREE};
use crate::linear::{design, Discretisation, Section};
use crate::real::Real;

/// Largest number of states (three second-order sections: 004's `n = 4` and a spare).
pub const MAX_ORDER: usize = 6;

type M = [[f64; MAX_ORDER]; MAX_ORDER];

/// The ZPETC inverse of a linear model (see the module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct Zpetc<T> {
    n: usize,
    phi: [[T; MAX_ORDER]; MAX_ORDER],
    gamma: [T; MAX_ORDER],
    /// `v = g * w_d - k . x`.
    k: [T; MAX_ORDER],
    g: T,
    /// Zero-phase filter taps on the previewed reference, newest first.
    fir: [T; MAX_ORDER + 1],
    taps: usize,
    /// Preview in design samples.
    preview: usize,
    /// Loop samples per design sample; the input is held in between.
    decimation: usize,
    phase: usize,
    /// State per unit input at DC, and input per unit output at DC.
    x_dc: [T; MAX_ORDER],
    v_per_y: T,
    // state
    x: [T; MAX_ORDER],
    /// The last `taps` previewed references, newest first.
    ring: [T; MAX_ORDER + 1],
    v: T,
}

/// Plant and construction results in f64.
struct Plant {
    n: usize,
    phi: M,
    gamma: [f64; MAX_ORDER],
    c: [f64; MAX_ORDER],
    d: f64,
    x_dc: [f64; MAX_ORDER],
    dc: f64,
    /// Discrete poles (eigenvalues of `phi`).
    poles: [Complex; MAX_ORDER],
}

/// The plant's discrete state space without the undriven states of first-order sections.
fn plant(gain: f64, sections: &[Section], dt: f64) -> Result<Plant, FfError> {
    let des = design(gain, sections, dt, Discretisation::Zoh)?;
    // Keep a state unless it is decoupled: zero input, zero output, no coupling.
    let mut keep = [0usize; 2 * crate::linear::MAX_SECTIONS];
    let mut n = 0;
    for i in 0..des.n {
        let coupled = (0..des.n).any(|j| j != i && (des.phi[i][j] != 0.0 || des.phi[j][i] != 0.0));
        if coupled || des.gamma[i] != 0.0 || des.c[i] != 0.0 {
            ensure(n < MAX_ORDER, "ZPETC: at most MAX_ORDER states")?;
            keep[n] = i;
            n += 1;
        }
    }
    let mut p = Plant {
        n,
        phi: [[0.0; MAX_ORDER]; MAX_ORDER],
        gamma: [0.0; MAX_ORDER],
        c: [0.0; MAX_ORDER],
        d: des.gain * des.d,
        x_dc: [0.0; MAX_ORDER],
        dc: 0.0,
        poles: [Complex::default(); MAX_ORDER],
    };
    for (a, &i) in keep[..n].iter().enumerate() {
        for (b, &j) in keep[..n].iter().enumerate() {
            p.phi[a][b] = des.phi[i][j];
        }
        p.gamma[a] = des.gamma[i];
        p.c[a] = des.gain * des.c[i];
        p.x_dc[a] = des.x_dc[i];
    }
    p.dc = p.d + (0..n).map(|i| p.c[i] * p.x_dc[i]).sum::<f64>();
    ensure(
        p.dc.is_finite() && libm::fabs(p.dc) > 0.0,
        "ZPETC: the model needs a non-zero DC gain",
    )?;
    // Discrete poles: e^(p dt) of every section's continuous poles (ZOH).
    let mut np = 0;
    for sec in sections {
        let mut r = [Complex::default(); MAX_DEGREE];
        let den = section_den(sec);
        let deg = if den[2] != 0.0 { 3 } else { 2 };
        let cnt = roots(&den[..deg], &mut r)?;
        for z in &r[..cnt] {
            ensure(np < MAX_ORDER, "ZPETC: at most MAX_ORDER states")?;
            p.poles[np] = Complex::new(z.re * dt, z.im * dt).exp();
            np += 1;
        }
    }
    ensure(np == n, "ZPETC: poles and states disagree")?;
    Ok(p)
}

/// Denominator `1 + p1 s + p2 s^2` of a section, ascending.
fn section_den(sec: &Section) -> [f64; 3] {
    match *sec {
        Section::First { w, .. } => [1.0, 1.0 / w, 0.0],
        Section::Second { wn, zeta, .. } => [1.0, 2.0 * zeta / wn, 1.0 / (wn * wn)],
        Section::Quadratic { p, .. } => [1.0, p[0], p[1]],
    }
}

/// Monic polynomial (descending: `c[0] = 1` for `z^deg`) with the given roots.
fn monic(rs: &[Complex]) -> [f64; MAX_ORDER + 1] {
    let mut c = [Complex::default(); MAX_ORDER + 1];
    c[0] = Complex::from(1.0);
    for (k, r) in rs.iter().enumerate() {
        for i in (1..=k + 1).rev() {
            c[i] = c[i] - *r * c[i - 1];
        }
    }
    c.map(|z| z.re)
}

fn mat_vec(m: &M, v: &[f64; MAX_ORDER], n: usize) -> [f64; MAX_ORDER] {
    let mut o = [0.0; MAX_ORDER];
    for i in 0..n {
        o[i] = (0..n).map(|j| m[i][j] * v[j]).sum();
    }
    o
}

fn row_mat(r: &[f64; MAX_ORDER], m: &M, n: usize) -> [f64; MAX_ORDER] {
    let mut o = [0.0; MAX_ORDER];
    for j in 0..n {
        o[j] = (0..n).map(|i| r[i] * m[i][j]).sum();
    }
    o
}

fn dot(a: &[f64; MAX_ORDER], b: &[f64; MAX_ORDER], n: usize) -> f64 {
    (0..n).map(|i| a[i] * b[i]).sum()
}

/// Solves `m x = v` (`n x n`, Gauss with partial pivoting); `None` when singular or the
/// solution is not finite.
fn gauss(m: M, v: [f64; MAX_ORDER], n: usize) -> Option<[f64; MAX_ORDER]> {
    crate::linear::gauss(m, v, n, 0.0).filter(|x| x.iter().all(|v| v.is_finite()))
}

/// `x` converted to `T`, refused when `T` cannot hold it to 1e-3 of `scale` (a fixed-point
/// `T` saturates or rounds away coefficients of a fast-sampled model).
fn to_t<T: Real>(x: f64, scale: f64) -> Result<T, FfError> {
    let t = T::from_f64(x);
    ensure(
        t.is_finite() && libm::fabs(t.to_f64() - x) <= 1e-3 * scale,
        "ZPETC: a coefficient does not fit the number type (sample faster than the model \
         needs, or use floating point)",
    )?;
    Ok(t)
}

impl<T: Real> Zpetc<T> {
    /// The ZPETC inverse of `gain` times the cascade of `sections` (the plant's linear
    /// dynamics, e.g. from [`crate::linear::poly::sections`]) sampled every `dt` s through a
    /// zero-order hold. Zeros with `|z| < accept_radius` and a positive real part are
    /// inverted exactly, the others by the zero-phase filter (`0 < accept_radius <= 1`;
    /// above one an unstable zero would be inverted, which the constructor refuses).
    pub fn new(
        gain: f64,
        sections: &[Section],
        dt: f64,
        accept_radius: f64,
    ) -> Result<Self, FfError> {
        ensure(
            accept_radius > 0.0 && accept_radius <= 1.0,
            "ZPETC: accept_radius in (0, 1]",
        )?;
        Self::build(gain, sections, dt, accept_radius, true)
    }

    /// The ZPETC designed for the slower period `decimation * dt_s` (ZOH-exact there) and
    /// run in a loop of period `dt_s`: a new input every `decimation` loop samples, held in
    /// between, the setpoint still handed over every loop sample ([`Zpetc::preview`] loop
    /// samples ahead). Sampling far faster than the model's dynamics makes the exact inverse
    /// ill-conditioned (its gain grows as `dt^-P`: f32 loses the 004 model's inverse at
    /// 10 kHz, Q16.16 at 100 kHz), so design it near the model's bandwidth.
    pub fn decimated(
        gain: f64,
        sections: &[Section],
        dt_s: f64,
        decimation: usize,
        accept_radius: f64,
    ) -> Result<Self, FfError> {
        ensure(
            (1..=1000).contains(&decimation),
            "ZPETC: decimation 1 ..= 1000",
        )?;
        let mut z = Self::new(gain, sections, dt_s * decimation as f64, accept_radius)?;
        z.decimation = decimation;
        Ok(z)
    }

    /// As [`Zpetc::new`] but inverting every zero with a positive real part inside
    /// `radius`, even outside the unit circle: the naive inverse, unstable for a
    /// non-minimum-phase model. For tests that show why ZPETC is needed.
    #[doc(hidden)]
    pub fn naive(gain: f64, sections: &[Section], dt: f64, radius: f64) -> Result<Self, FfError> {
        Self::build(gain, sections, dt, radius, false)
    }

    fn build(
        gain: f64,
        sections: &[Section],
        dt: f64,
        radius: f64,
        check_stable: bool,
    ) -> Result<Self, FfError> {
        let p = plant(gain, sections, dt)?;
        let n = p.n;
        // A(z), descending, monic, from the discrete poles.
        let a = monic(&p.poles[..n]);
        // Markov parameters h_j = C Phi^j Gamma and the numerator
        // B(z) = A(z) (D + sum_j h_j z^-(j+1)), descending, degree n.
        let mut h = [0.0; MAX_ORDER];
        let mut pg = p.gamma;
        for j in 0..n {
            h[j] = dot(&p.c, &pg, n);
            pg = mat_vec(&p.phi, &pg, n);
        }
        let mut b = [0.0; MAX_ORDER + 1];
        for k in 0..=n {
            b[k] = p.d * a[k] + (0..k).map(|i| a[i] * h[k - 1 - i]).sum::<f64>();
        }
        // Delay d: D = 0 makes the ZOH plant strictly proper with b[0] = 0 exactly.
        let d = if p.d == 0.0 { 1 } else { 0 };
        let beta = b[d];
        ensure(
            beta != 0.0 && beta.is_finite(),
            "ZPETC: the model's first Markov parameter is zero",
        )?;
        let mut asc = [0.0; MAX_DEGREE + 1];
        let deg = n - d;
        for j in 0..=deg {
            asc[j] = b[n - j];
        }
        let mut zs = [Complex::default(); MAX_DEGREE];
        let nz = roots(&asc[..=deg], &mut zs)?;
        let (mut acc, mut una) = (
            [Complex::default(); MAX_ORDER],
            [Complex::default(); MAX_ORDER],
        );
        let (mut na, mut nu) = (0, 0);
        for z in &zs[..nz] {
            if z.abs() < radius && z.re > 0.0 {
                acc[na] = *z;
                na += 1;
            } else {
                una[nu] = *z;
                nu += 1;
            }
        }
        let bu = monic(&una[..nu]); // descending, degree s = nu
        let bu1: f64 = bu[..=nu].iter().sum();
        ensure(
            libm::fabs(bu1) > 0.0,
            "ZPETC: a refused zero lies at z = 1 (zero DC gain)",
        )?;
        let preview = d + nu;
        // G_a = beta * B_a / A * B_u(1): unit-DC zero-phase filter, w scaled like y.
        let ba = monic(&acc[..na]);
        let mut bt = [0.0; MAX_ORDER + 1]; // beta*B_u(1)*B_a padded to degree n, descending
        for j in 0..=na {
            bt[n - na + j] = beta * bu1 * ba[j];
        }
        // D_a and Markov parameters of G_a by long division by A.
        let da = bt[0];
        let mut ha = [0.0; MAX_ORDER];
        for k in 1..=n {
            ha[k - 1] = bt[k] - da * a[k] - (1..k).map(|i| a[i] * ha[k - 1 - i]).sum::<f64>();
        }
        // C_a from C_a [Gamma, Phi Gamma, ...] = ha (the controllability matrix).
        let mut wt = [[0.0; MAX_ORDER]; MAX_ORDER]; // rows: (Phi^j Gamma)^T
        let mut pg = p.gamma;
        for j in 0..n {
            wt[j][..n].copy_from_slice(&pg[..n]);
            pg = mat_vec(&p.phi, &pg, n);
        }
        let ca = gauss(wt, ha, n).ok_or(ParamError(
            "ZPETC: the model is not controllable from its input",
        ))?;
        // v = g w_d - k x.
        let (g, k) = if preview == 0 {
            let mut k = ca;
            k.iter_mut().for_each(|v| *v /= da);
            (1.0 / da, k)
        } else {
            let mut row = ca;
            for _ in 0..preview - 1 {
                row = row_mat(&row, &p.phi, n);
            }
            let m = dot(&row, &p.gamma, n);
            ensure(
                m != 0.0 && m.is_finite(),
                "ZPETC: the minimum-phase part has no leading Markov parameter",
            )?;
            let mut k = row_mat(&row, &p.phi, n);
            k.iter_mut().for_each(|v| *v /= m);
            (1.0 / m, k)
        };
        // Taps newest first: w_d(k+P) = sum_i bu_asc[i] y_d(k+P-i) / B_u(1), i = 0..=s.
        let taps = nu + 1;
        let mut fir = [0.0; MAX_ORDER + 1];
        for i in 0..taps {
            fir[i] = bu[nu - i] / bu1;
        }
        // Convert, refusing what T cannot hold.
        let amax = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(libm::fabs(*x)));
        let phi_s = (0..n).map(|i| amax(&p.phi[i][..n])).fold(0.0, f64::max);
        let mut out = Self {
            n,
            phi: [[T::ZERO; MAX_ORDER]; MAX_ORDER],
            gamma: [T::ZERO; MAX_ORDER],
            k: [T::ZERO; MAX_ORDER],
            g: to_t(g, libm::fabs(g))?,
            fir: [T::ZERO; MAX_ORDER + 1],
            taps,
            preview,
            decimation: 1,
            phase: 0,
            x_dc: [T::ZERO; MAX_ORDER],
            v_per_y: to_t(1.0 / p.dc, libm::fabs(1.0 / p.dc))?,
            x: [T::ZERO; MAX_ORDER],
            ring: [T::ZERO; MAX_ORDER + 1],
            v: T::ZERO,
        };
        for i in 0..n {
            for j in 0..n {
                out.phi[i][j] = to_t(p.phi[i][j], phi_s)?;
            }
            out.gamma[i] = to_t(p.gamma[i], amax(&p.gamma[..n]))?;
            out.k[i] = to_t(k[i], amax(&k[..n]))?;
            out.x_dc[i] = to_t(p.x_dc[i], amax(&p.x_dc[..n]))?;
        }
        for i in 0..taps {
            out.fir[i] = to_t(fir[i], amax(&fir[..taps]))?;
        }
        // The inverse's own dynamics `Phi - Gamma k` (the accepted zeros, the rest at 0) with
        // the coefficients as `T` holds them: a deadbeat block is so sensitive that rounding
        // to fixed point can make it unstable. Stable iff its 4096th power has decayed.
        let mut m = [[0.0; MAX_ORDER]; MAX_ORDER];
        for i in 0..n {
            for j in 0..n {
                m[i][j] = out.phi[i][j].to_f64() - out.gamma[i].to_f64() * out.k[j].to_f64();
            }
        }
        for _ in 0..12 {
            let mut sq = [[0.0; MAX_ORDER]; MAX_ORDER];
            for i in 0..n {
                for j in 0..n {
                    sq[i][j] = (0..n).map(|l| m[i][l] * m[l][j]).sum();
                }
            }
            m = sq;
        }
        let decayed = (0..n).all(|i| (0..n).all(|j| libm::fabs(m[i][j]) < 1e-3));
        ensure(
            decayed || !check_stable,
            "ZPETC: rounded to the number type the inverse is unstable (sample slower, or use \
             floating point)",
        )?;
        out.reset(T::ZERO);
        Ok(out)
    }

    /// Loop samples of preview the reference needs: `command` at loop sample `k` takes
    /// `y_d(k + preview)`.
    pub fn preview(&self) -> usize {
        self.preview * self.decimation
    }

    /// Number of zeros refused (inverted by the zero-phase filter).
    pub fn refused_zeros(&self) -> usize {
        self.taps - 1
    }

    /// The constant input that holds the output at `y` (DC inverse).
    pub fn dc_input(&self, y: T) -> T {
        y * self.v_per_y
    }

    /// Rest at output `y0`: the state of the model at the constant input that gives `y0`,
    /// the reference history at `y0`.
    pub fn reset(&mut self, y0: T) {
        let y0 = if y0.is_finite() { y0 } else { T::ZERO };
        self.v = y0 * self.v_per_y;
        // Iterators, not indices: the control path has no bounds-check panic.
        for (x, &xd) in self.x.iter_mut().zip(self.x_dc.iter()).take(self.n) {
            *x = xd * self.v;
        }
        self.ring = [y0; MAX_ORDER + 1];
        self.phase = 0;
    }

    /// The input `v(k)` for the reference `y_d(k + P)` (a non-finite reference holds the
    /// last input). ZPETC is a linear filter of the reference: its state follows the input
    /// it commands, not what a saturated amplifier delivered (following that, the deadbeat
    /// inverse would wind up trying to undo the saturation within `P` samples). A reference
    /// too rough for the number type (its input overflows) restarts the filter at rest on
    /// that reference.
    #[inline]
    pub fn command(&mut self, y_ahead: T) -> T {
        if !y_ahead.is_finite() {
            return self.v;
        }
        // A new input at the first loop sample of each design sample, held for the rest.
        let due = self.phase == 0;
        self.phase = if self.phase + 1 >= self.decimation {
            0
        } else {
            self.phase + 1
        };
        if !due {
            return self.v;
        }
        let taps = self.taps.min(MAX_ORDER + 1);
        let n = self.n.min(MAX_ORDER);
        // Shift the reference history by one, newest first.
        let mut carry = y_ahead;
        for r in self.ring.iter_mut().take(taps) {
            carry = core::mem::replace(r, carry);
        }
        let w = self
            .fir
            .iter()
            .zip(self.ring.iter())
            .take(taps)
            .fold(T::ZERO, |acc, (&f, &r)| acc + f * r);
        let v = self
            .k
            .iter()
            .zip(self.x.iter())
            .take(n)
            .fold(self.g * w, |acc, (&k, &x)| acc - k * x);
        let mut next = [T::ZERO; MAX_ORDER];
        for ((nx, row), &g) in next
            .iter_mut()
            .zip(self.phi.iter())
            .zip(self.gamma.iter())
            .take(n)
        {
            *nx = row
                .iter()
                .zip(self.x.iter())
                .take(n)
                .fold(g * v, |acc, (&p, &x)| acc + p * x);
        }
        if v.is_finite() && next.iter().take(n).all(|x| x.is_finite()) {
            self.x = next;
            self.v = v;
        } else {
            self.reset(y_ahead);
        }
        self.v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::{poly, Linear};
    use core::f64::consts::PI;

    /// 004 eq. (8), identified (sec. 4.2), ascending.
    const A: [f64; 5] = [5.421e12, 1.183e10, 1.046e7, 8.753e3, 1.0];
    const B: [f64; 3] = [5.421e12, -4.002e8, 4.083e6];

    /// The plant driven by its own ZPETC with the reference `r(k)` previewed; returns the
    /// output and the preview.
    fn track<const S: usize>(
        secs: [Section; S],
        dt: f64,
        r: impl Fn(usize) -> f64,
        n: usize,
    ) -> (Vec<f64>, usize) {
        let mut z = Zpetc::<f64>::new(1.0, &secs, dt, 0.99).unwrap();
        let lin = Linear::<f64, S>::new(1.0, secs, dt, Discretisation::Zoh).unwrap();
        let mut s = lin.init(0.0);
        let p = z.preview();
        let y = (0..n)
            .map(|k| lin.step(&mut s, z.command(r(k + p))))
            .collect();
        (y, p)
    }

    #[test]
    fn minimum_phase_plants_are_inverted_exactly() {
        // A rough reference (steps and a ramp): the inverse is exact, not smoothing.
        let r = |k: usize| ((k / 37) % 3) as f64 * 0.7 + 1e-3 * k as f64;
        let dt = 1e-4;
        // Relative degree 1 after ZOH, no zeros: one sample of preview.
        let (y, p) = track([Section::First { w: 900.0, wz: None }], dt, r, 500);
        assert_eq!(p, 1);
        let worst = y.iter().enumerate().map(|(k, y)| (y - r(k)).abs());
        assert!(worst.fold(0.0, f64::max) < 1e-9);
        // Biproper with a left-half-plane zero pair: no preview, exact.
        let sec = Section::Second {
            wn: 2.0 * PI * 100.0,
            zeta: 0.3,
            zero: Some((2.0 * PI * 300.0, 0.5)),
        };
        let (y, p) = track([sec], dt, r, 500);
        assert_eq!(p, 0);
        let worst = y.iter().enumerate().map(|(k, y)| (y - r(k)).abs());
        assert!(worst.fold(0.0, f64::max) < 1e-9);
    }

    #[test]
    fn non_minimum_phase_tracking_has_zero_phase_error() {
        // 004's model at 10 kHz: a 20 Hz sine comes out in phase, scaled by
        // |B_u(e^jw)|^2 / B_u(1)^2 (slightly below one).
        let dt = 1e-4;
        let (_, secs, n) = poly::sections(&B, &A).unwrap();
        assert_eq!(n, 2);
        let w = 2.0 * PI * 20.0 * dt;
        let (y, p) = track([secs[0], secs[1]], dt, |k| (w * k as f64).sin(), 20_000);
        assert_eq!(p, 4);
        // Least-squares amplitude and phase over whole periods after the start.
        let (mut sc, mut cc, mut n) = (0.0, 0.0, 0.0);
        for (k, y) in y.iter().enumerate().skip(10_000) {
            sc += y * (w * k as f64).sin();
            cc += y * (w * k as f64).cos();
            n += 1.0;
        }
        let (a, b) = (2.0 * sc / n, 2.0 * cc / n);
        let phase = b.atan2(a);
        let gain = (a * a + b * b).sqrt();
        assert!(phase.abs() < 1e-6, "{phase}");
        assert!(gain < 1.0 && gain > 0.97, "{gain}");
    }

    #[test]
    fn refusals_and_non_finite_references() {
        let (gain, secs, n) = poly::sections(&B, &A).unwrap();
        assert!(Zpetc::<f64>::new(gain, &secs[..n], 1e-4, 1.5).is_err());
        assert!(Zpetc::<f64>::new(gain, &secs[..n], 1e-4, 0.0).is_err());
        // At 100 kHz the coefficients outgrow Q16.16 (refused at construction).
        use crate::fixed::Q16;
        // Q16.16 and f32 against f64, each at 10 kHz: designed there (the gain of the exact
        // inverse, 2.8e3 here, amplifies their rounding) and decimated to a 1 kHz design.
        let mut report = std::vec::Vec::new();
        for dec in [1, 10] {
            let dt = 1e-4;
            let mut zq = Zpetc::<Q16>::decimated(gain, &secs[..n], dt, dec, 0.99).unwrap();
            let mut z32 = Zpetc::<f32>::decimated(gain, &secs[..n], dt, dec, 0.99).unwrap();
            let mut zf = Zpetc::<f64>::decimated(gain, &secs[..n], dt, dec, 0.99).unwrap();
            assert_eq!(zf.preview(), 4 * dec);
            let (mut wq, mut w32) = (0.0f64, 0.0f64);
            for k in 0..(1.0 / dt) as usize {
                // Starts at rest without a jump in slope (a rougher start overflows Q16).
                let r = 1.5 * (1.0 - (2.0 * PI * 2.0 * k as f64 * dt).cos());
                let vf = zf.command(r);
                wq = wq.max((zq.command(Q16::from_f64(r)).to_f64() - vf).abs());
                w32 = w32.max((z32.command(r as f32) as f64 - vf).abs());
            }
            report.push((dec, wq, w32));
        }
        std::eprintln!("max |v - v_f64| (decimation, Q16, f32): {report:?}");
        // Designed at 10 kHz: f32 off by a sizeable fraction of v (about 3), Q16 useless.
        assert!(report[0].1 > 1.0 && report[0].2 > 0.05, "{report:?}");
        // Designed at 1 kHz: both close.
        assert!(report[1].1 < 2e-3 && report[1].2 < 1e-5, "{report:?}");
        // A step overflows the Q16 inverse designed at 10 kHz; it restarts at rest and
        // stays finite.
        let mut zq = Zpetc::<Q16>::new(gain, &secs[..n], 1e-4, 0.99).unwrap();
        for k in 0..50 {
            let v = zq.command(Q16::from_f64(if k < 10 { 0.0 } else { 2.0 }));
            assert!(v.is_finite(), "{k}");
        }
        assert!((zq.command(Q16::from_f64(2.0)).to_f64() - 2.0).abs() < 0.05);
        let e = Zpetc::<Q16>::new(gain, &secs[..n], 1e-5, 0.99)
            .unwrap_err()
            .0;
        assert!(e.contains("number type"), "{e}");
        // f32 keeps it at 100 kHz.
        assert!(Zpetc::<f32>::new(gain, &secs[..n], 1e-5, 0.99).is_ok());
        let mut z = Zpetc::<f64>::new(gain, &secs[..n], 1e-4, 0.99).unwrap();
        let v = z.command(0.5);
        assert_eq!(z.command(f64::NAN), v);
        assert_eq!(z.command(f64::INFINITY), v);
        assert!(z.command(0.6).is_finite());
    }
}
