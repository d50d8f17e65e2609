//! Hammerstein linear dynamics (004 eq. 8): a cascade of first- and second-order sections
//! built from continuous poles and zeros, discretised once at construction.
//!
//! Two discretisations:
//! * [`Discretisation::Zoh`] (default): the exact discrete equivalent of the continuous
//!   section driven through a zero-order hold, `Phi = e^(A*dt)`, `Gamma = int e^(A*t) dt B`,
//!   from one matrix exponential of the augmented matrix `[[A, B], [0, 0]]*dt`
//!   (scaling and squaring + Taylor). The DAC holds each voltage for a sample, so ZOH is
//!   what the stage really sees: the step response is exact at the sample instants.
//! * [`Discretisation::Tustin`]: bilinear transform prewarped at the section's own
//!   frequency (its zero pair if it has one, else its poles), so a resonance peak or a
//!   notch stays at exactly the right frequency; use it for notch filters / inverses.
//!
//! Each section has unity DC gain; the cascade's DC gain is `gain`. The per-sample update
//! is a few multiply-adds per section, no allocation.

// Construction-time dense linear algebra reads clearer with index loops.
#![allow(clippy::needless_range_loop)]

use crate::hysteresis::{ensure, ParamError};
use crate::real::Real;

/// A continuous section, unity DC gain. Frequencies in rad/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Section {
    /// `w/(s + w)`, optionally times `(s + wz)/wz`.
    First { w: f64, wz: Option<f64> },
    /// `wn^2/(s^2 + 2 zeta wn s + wn^2)`, optionally times
    /// `(s^2 + 2 zeta_z wz s + wz^2)/wz^2` (a zero pair: notch for `zeta_z` small).
    Second {
        wn: f64,
        zeta: f64,
        zero: Option<(f64, f64)>,
    },
}

impl Section {
    /// Second-order poles from natural frequency (Hz) and damping.
    pub fn poles_hz(f_hz: f64, zeta: f64) -> Self {
        Section::Second {
            wn: 2.0 * core::f64::consts::PI * f_hz,
            zeta,
            zero: None,
        }
    }

    /// Continuous state space `(A, B, C, D)` (2 states; a first-order section leaves the
    /// second state undriven and decaying) and its prewarp frequency.
    fn state_space(&self) -> ([[f64; 2]; 2], [f64; 2], [f64; 2], f64, f64) {
        match *self {
            Section::First { w, wz } => {
                let (c, d) = match wz {
                    None => (w, 0.0),
                    Some(wz) => (w / wz * (wz - w), w / wz),
                };
                (
                    [[-w, 0.0], [0.0, -w]],
                    [1.0, 0.0],
                    [c, 0.0],
                    d,
                    wz.unwrap_or(w),
                )
            }
            Section::Second { wn, zeta, zero } => {
                let a0 = wn * wn;
                let a1 = 2.0 * zeta * wn;
                // numerator n2 s^2 + n1 s + n0, scaled so that H(0) = 1
                let (n2, n1, n0, w0) = match zero {
                    None => (0.0, 0.0, a0, wn),
                    Some((wz, zz)) => {
                        let k = a0 / (wz * wz);
                        (k, k * 2.0 * zz * wz, a0, wz)
                    }
                };
                // controllable canonical form, strictly proper part + feedthrough n2
                let a = [[0.0, 1.0], [-a0, -a1]];
                let c = [n0 - n2 * a0, n1 - n2 * a1];
                (a, [0.0, 1.0], c, n2, w0)
            }
        }
    }

    fn check(&self) -> Result<(), ParamError> {
        match *self {
            Section::First { w, wz } => {
                ensure(w.is_finite() && w > 0.0, "linear: first-order pole w > 0")?;
                ensure(
                    wz.is_none_or(|z| z.is_finite() && z > 0.0),
                    "linear: first-order zero wz > 0",
                )
            }
            Section::Second { wn, zeta, zero } => {
                ensure(
                    wn.is_finite() && wn > 0.0,
                    "linear: natural frequency wn > 0",
                )?;
                ensure(zeta.is_finite() && zeta > 0.0, "linear: damping zeta > 0")?;
                ensure(
                    zero.is_none_or(|(wz, zz)| {
                        wz.is_finite() && wz > 0.0 && zz.is_finite() && zz >= 0.0
                    }),
                    "linear: zero pair needs wz > 0 and zeta_z >= 0",
                )
            }
        }
    }
}

/// How the continuous sections become discrete.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Discretisation {
    /// Exact zero-order-hold equivalent (the DAC is a zero-order hold).
    #[default]
    Zoh,
    /// Bilinear transform prewarped at each section's frequency.
    Tustin,
}

/// Largest number of sections (the ZOH design works on a `2S+1` square matrix).
pub const MAX_SECTIONS: usize = 8;
const NMAX: usize = 2 * MAX_SECTIONS + 1;
type Mat = [[f64; NMAX]; NMAX];

/// State of [`Linear`]: two states per section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearState<T, const S: usize> {
    pub x: [[T; 2]; S],
}

/// A cascade of `S` sections times `gain` (004 eq. 8 in factored form), as one discrete
/// state space `x' = Phi x + Gamma v`, `y = C x + D v` (block lower triangular).
///
/// ZOH discretises the whole cascade at once: discretising each section separately would
/// hold every intermediate signal as well and add half a sample of delay per section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linear<T, const S: usize> {
    gain: T,
    /// `phi[i][j]`: 2x2 block from section `j`'s states to section `i`'s.
    phi: [[[[T; 2]; 2]; S]; S],
    gamma: [[T; 2]; S],
    c: [[T; 2]; S],
    d: T,
    /// DC steady state per unit input (for `init`).
    x_dc: [[T; 2]; S],
}

/// Cascade composition of per-section state spaces (continuous or discrete alike):
/// section `i` is driven by `v_i = C_(i-1) x_(i-1) + D_(i-1) v_(i-1)`, `v_1 = u`.
#[allow(clippy::type_complexity)]
fn compose(
    secs: &[([[f64; 2]; 2], [f64; 2], [f64; 2], f64)],
) -> (Mat, [f64; NMAX], [f64; NMAX], f64) {
    let mut a = [[0.0; NMAX]; NMAX];
    let mut b = [0.0; NMAX];
    let mut c = [0.0; NMAX];
    // `drive`: how the current section's input depends on (x, u): row over states + u.
    let mut drive_x = [0.0; NMAX];
    let mut drive_u = 1.0;
    for (i, (ai, bi, ci, di)) in secs.iter().enumerate() {
        for r in 0..2 {
            for col in 0..NMAX {
                a[2 * i + r][col] += bi[r] * drive_x[col];
            }
            a[2 * i + r][2 * i] += ai[r][0];
            a[2 * i + r][2 * i + 1] += ai[r][1];
            b[2 * i + r] = bi[r] * drive_u;
        }
        // output of section i = C_i x_i + D_i * input_i
        let mut out_x = drive_x.map(|v| v * di);
        out_x[2 * i] += ci[0];
        out_x[2 * i + 1] += ci[1];
        drive_x = out_x;
        drive_u *= di;
    }
    c[..].copy_from_slice(&drive_x);
    (a, b, c, drive_u)
}

/// Solves `m x = v` for the leading `n x n` block (Gauss, partial pivoting). `None` when
/// singular.
fn solve(m: &Mat, v: &[f64; NMAX], n: usize) -> Option<[f64; NMAX]> {
    let mut m = *m;
    let mut v = *v;
    for k in 0..n {
        let p = (k..n).max_by(|&i, &j| libm::fabs(m[i][k]).total_cmp(&libm::fabs(m[j][k])))?;
        if !(libm::fabs(m[p][k]) > 1e-300) {
            return None;
        }
        m.swap(k, p);
        v.swap(k, p);
        for i in k + 1..n {
            let f = m[i][k] / m[k][k];
            for j in k..n {
                m[i][j] -= f * m[k][j];
            }
            v[i] -= f * v[k];
        }
    }
    let mut x = [0.0; NMAX];
    for k in (0..n).rev() {
        let s: f64 = (k + 1..n).map(|j| m[k][j] * x[j]).sum();
        x[k] = (v[k] - s) / m[k][k];
    }
    Some(x)
}

impl<T: Real, const S: usize> Linear<T, S> {
    /// Builds the cascade for sample period `dt` (s). `gain` is the DC gain (1 for unity).
    pub fn new(
        gain: f64,
        sections: [Section; S],
        dt: f64,
        method: Discretisation,
    ) -> Result<Self, ParamError> {
        ensure(gain.is_finite(), "linear: gain must be finite")?;
        ensure(dt.is_finite() && dt > 0.0, "linear: sample period dt > 0")?;
        ensure(
            (1..=MAX_SECTIONS).contains(&S),
            "linear: 1 to MAX_SECTIONS sections",
        )?;
        let mut ss = [([[0.0; 2]; 2], [0.0; 2], [0.0; 2], 0.0); MAX_SECTIONS];
        for (sec, o) in sections.iter().zip(ss.iter_mut()) {
            sec.check()?;
            let (a, b, c, d, w0) = sec.state_space();
            *o = match method {
                Discretisation::Zoh => (a, b, c, d),
                Discretisation::Tustin => {
                    ensure(
                        w0 * dt < core::f64::consts::PI,
                        "linear: Tustin prewarp frequency must be below Nyquist",
                    )?;
                    tustin(&a, &b, &c, d, 2.0 / w0 * libm::tan(w0 * dt / 2.0))
                }
            };
        }
        let n = 2 * S;
        let (a, b, c, d) = compose(&ss[..S]);
        let (phi, gamma) = match method {
            Discretisation::Tustin => (a, b),
            Discretisation::Zoh => {
                // expm([[A, B], [0, 0]] dt) = [[Phi, Gamma], [0, 1]]
                let mut m = [[0.0; NMAX]; NMAX];
                for i in 0..n {
                    for j in 0..n {
                        m[i][j] = a[i][j] * dt;
                    }
                    m[i][n] = b[i] * dt;
                }
                let e = expm(&m, n + 1);
                let mut gamma = [0.0; NMAX];
                for i in 0..n {
                    gamma[i] = e[i][n];
                }
                (e, gamma)
            }
        };
        // DC steady state x = (I - Phi)^-1 Gamma per unit input.
        let mut i_phi = [[0.0; NMAX]; NMAX];
        for i in 0..n {
            for j in 0..n {
                i_phi[i][j] = if i == j { 1.0 } else { 0.0 } - phi[i][j];
            }
        }
        let x_dc = solve(&i_phi, &gamma, n);
        let finite = phi
            .iter()
            .flatten()
            .chain(gamma.iter())
            .all(|v| v.is_finite());
        let x_dc = match x_dc {
            Some(x) if finite && x.iter().all(|v| v.is_finite()) => x,
            _ => {
                return Err(ParamError(
                    "linear: discretisation failed (frequency too high for dt?)",
                ))
            }
        };
        let t = T::from_f64;
        let mut out = Self {
            gain: t(gain),
            phi: [[[[T::ZERO; 2]; 2]; S]; S],
            gamma: [[T::ZERO; 2]; S],
            c: [[T::ZERO; 2]; S],
            d: t(d),
            x_dc: [[T::ZERO; 2]; S],
        };
        for i in 0..S {
            for r in 0..2 {
                for j in 0..S {
                    for q in 0..2 {
                        out.phi[i][j][r][q] = t(phi[2 * i + r][2 * j + q]);
                    }
                }
                out.gamma[i][r] = t(gamma[2 * i + r]);
                out.c[i][r] = t(c[2 * i + r]);
                out.x_dc[i][r] = t(x_dc[2 * i + r]);
            }
        }
        Ok(out)
    }

    /// DC gain of the cascade.
    pub fn gain(&self) -> T {
        self.gain
    }

    /// Steady state for a constant input `v0`.
    pub fn init(&self, v0: T) -> LinearState<T, S> {
        let v0 = if v0.is_finite() { v0 } else { T::ZERO };
        LinearState {
            x: self.x_dc.map(|x| [x[0] * v0, x[1] * v0]),
        }
    }

    /// One sample: input `v` (held over the next period), output `y`. A non-finite input
    /// is treated as 0 so the state stays finite.
    #[inline]
    pub fn step(&self, s: &mut LinearState<T, S>, v: T) -> T {
        let v = if v.is_finite() { v } else { T::ZERO };
        let mut y = self.d * v;
        let mut next = [[T::ZERO; 2]; S];
        for (i, (xn, (row, g))) in next
            .iter_mut()
            .zip(self.phi.iter().zip(self.gamma.iter()))
            .enumerate()
        {
            y += self.c[i][0] * s.x[i][0] + self.c[i][1] * s.x[i][1];
            let mut acc = [g[0] * v, g[1] * v];
            // block lower triangular: only sections j <= i feed section i
            for (blk, x) in row.iter().zip(s.x.iter()).take(i + 1) {
                acc[0] += blk[0][0] * x[0] + blk[0][1] * x[1];
                acc[1] += blk[1][0] * x[0] + blk[1][1] * x[1];
            }
            *xn = acc;
        }
        s.x = next;
        self.gain * y
    }

    /// Frequency response `(re, im)` of the discrete cascade at `f_hz` for sample period
    /// `dt` (analysis helper, not for the per-sample path).
    pub fn response(&self, f_hz: f64, dt: f64) -> (f64, f64) {
        let th = 2.0 * core::f64::consts::PI * f_hz * dt;
        let (zr, zi) = (libm::cos(th), libm::sin(th));
        let n = 2 * S;
        // (z I - Phi) x = Gamma, real and imaginary parts of the matrix.
        let mut m = [[[0.0; NMAX]; NMAX]; 2];
        let mut g = [0.0; NMAX];
        for i in 0..n {
            for j in 0..n {
                let p = self.phi[i / 2][j / 2][i % 2][j % 2].to_f64();
                m[0][i][j] = if i == j { zr } else { 0.0 } - p;
            }
            m[1][i][i] = zi;
            g[i] = self.gamma[i / 2][i % 2].to_f64();
        }
        let x = csolve(&m, &g, n);
        let mut h = (self.d.to_f64(), 0.0);
        for i in 0..n {
            let c = self.c[i / 2][i % 2].to_f64();
            h.0 += c * x[0][i];
            h.1 += c * x[1][i];
        }
        let k = self.gain.to_f64();
        (h.0 * k, h.1 * k)
    }
}

/// Complex Gauss elimination: `(m[0] + j m[1]) x = g` (real `g`), leading `n x n` block.
fn csolve(m: &[Mat; 2], g: &[f64; NMAX], n: usize) -> [[f64; NMAX]; 2] {
    let (mut a, mut b) = (m[0], m[1]);
    let (mut vr, mut vi) = (*g, [0.0; NMAX]);
    for k in 0..n {
        let p = (k..n)
            .max_by(|&i, &j| {
                libm::hypot(a[i][k], b[i][k]).total_cmp(&libm::hypot(a[j][k], b[j][k]))
            })
            .unwrap_or(k);
        a.swap(k, p);
        b.swap(k, p);
        vr.swap(k, p);
        vi.swap(k, p);
        let den = a[k][k] * a[k][k] + b[k][k] * b[k][k];
        for i in k + 1..n {
            // f = m[i][k] / m[k][k]
            let fr = (a[i][k] * a[k][k] + b[i][k] * b[k][k]) / den;
            let fi = (b[i][k] * a[k][k] - a[i][k] * b[k][k]) / den;
            for j in k..n {
                let (pr, pi) = (a[k][j], b[k][j]);
                a[i][j] -= fr * pr - fi * pi;
                b[i][j] -= fr * pi + fi * pr;
            }
            let (pr, pi) = (vr[k], vi[k]);
            vr[i] -= fr * pr - fi * pi;
            vi[i] -= fr * pi + fi * pr;
        }
    }
    let (mut xr, mut xi) = ([0.0; NMAX], [0.0; NMAX]);
    for k in (0..n).rev() {
        let (mut sr, mut si) = (vr[k], vi[k]);
        for j in k + 1..n {
            sr -= a[k][j] * xr[j] - b[k][j] * xi[j];
            si -= a[k][j] * xi[j] + b[k][j] * xr[j];
        }
        let den = a[k][k] * a[k][k] + b[k][k] * b[k][k];
        xr[k] = (sr * a[k][k] + si * b[k][k]) / den;
        xi[k] = (si * a[k][k] - sr * b[k][k]) / den;
    }
    [xr, xi]
}

/// `e^M` of the leading `n x n` block by scaling and squaring with an 18-term Taylor
/// series (`||M/2^s||_inf <= 0.5`: truncation below 1e-20 relative).
fn expm(m: &Mat, n: usize) -> Mat {
    let norm = m[..n]
        .iter()
        .map(|r| r[..n].iter().map(|x| libm::fabs(*x)).sum::<f64>())
        .fold(0.0, f64::max);
    let mut s = 0u32;
    let mut scale = 1.0;
    while norm * scale > 0.5 && s < 64 {
        scale *= 0.5;
        s += 1;
    }
    let mul = |x: &Mat, y: &Mat| {
        let mut z = [[0.0; NMAX]; NMAX];
        for i in 0..n {
            for k in 0..n {
                let xik = x[i][k];
                if xik != 0.0 {
                    for j in 0..n {
                        z[i][j] += xik * y[k][j];
                    }
                }
            }
        }
        z
    };
    let mut a = [[0.0; NMAX]; NMAX];
    let mut sum = [[0.0; NMAX]; NMAX];
    for i in 0..n {
        for j in 0..n {
            a[i][j] = m[i][j] * scale;
        }
        sum[i][i] = 1.0;
    }
    let mut term = sum;
    for k in 1..=18 {
        term = mul(&term, &a);
        for (i, row) in term.iter_mut().enumerate().take(n) {
            for (j, x) in row.iter_mut().enumerate().take(n) {
                *x /= k as f64;
                sum[i][j] += *x;
            }
        }
    }
    for _ in 0..s {
        sum = mul(&sum, &sum);
    }
    sum
}

/// Bilinear transform with step `h` (prewarped): with `W = (I - A h/2)^-1`,
/// `Phi = W (I + A h/2)`, `Gamma = W B h`, `C_d = C W`, `D_d = D + C W B h/2`.
fn tustin(
    a: &[[f64; 2]; 2],
    b: &[f64; 2],
    c: &[f64; 2],
    d: f64,
    h: f64,
) -> ([[f64; 2]; 2], [f64; 2], [f64; 2], f64) {
    let q = h / 2.0;
    let m = [
        [1.0 - a[0][0] * q, -a[0][1] * q],
        [-a[1][0] * q, 1.0 - a[1][1] * q],
    ];
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let w = [
        [m[1][1] / det, -m[0][1] / det],
        [-m[1][0] / det, m[0][0] / det],
    ];
    let p = [
        [1.0 + a[0][0] * q, a[0][1] * q],
        [a[1][0] * q, 1.0 + a[1][1] * q],
    ];
    let mut phi = [[0.0; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            phi[i][j] = w[i][0] * p[0][j] + w[i][1] * p[1][j];
        }
    }
    let wb = [
        w[0][0] * b[0] + w[0][1] * b[1],
        w[1][0] * b[0] + w[1][1] * b[1],
    ];
    let gamma = [wb[0] * h, wb[1] * h];
    let cd = [
        c[0] * w[0][0] + c[1] * w[1][0],
        c[0] * w[0][1] + c[1] * w[1][1],
    ];
    let dd = d + (c[0] * wb[0] + c[1] * wb[1]) * q;
    (phi, gamma, cd, dd)
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;

    fn cmul(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
        (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
    }
    fn cdiv(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
        let n = b.0 * b.0 + b.1 * b.1;
        ((a.0 * b.0 + a.1 * b.1) / n, (a.1 * b.0 - a.0 * b.1) / n)
    }

    #[test]
    fn zoh_step_response_is_exact_for_second_order() {
        let (wn, zeta, dt) = (2.0 * PI * 800.0, 0.05, 1e-5);
        let lin = Linear::<f64, 1>::new(
            1.0,
            [Section::Second {
                wn,
                zeta,
                zero: None,
            }],
            dt,
            Discretisation::Zoh,
        )
        .unwrap();
        let mut s = lin.init(0.0);
        let wd = wn * (1.0 - zeta * zeta).sqrt();
        let phase = zeta.acos();
        let mut worst = 0.0f64;
        for k in 0..5000 {
            let t = k as f64 * dt;
            let want =
                1.0 - (-zeta * wn * t).exp() / (1.0 - zeta * zeta).sqrt() * (wd * t + phase).sin();
            let y = lin.step(&mut s, 1.0);
            worst = worst.max((y - want).abs());
        }
        assert!(worst < 1e-10, "{worst}");
    }

    #[test]
    fn tustin_step_response_is_close_and_keeps_resonance() {
        let (wn, zeta, dt) = (2.0 * PI * 800.0, 0.05, 1e-4);
        let sec = [Section::Second {
            wn,
            zeta,
            zero: None,
        }];
        let lin = Linear::<f64, 1>::new(1.0, sec, dt, Discretisation::Tustin).unwrap();
        // |H(j wn)| = 1/(2 zeta) exactly with prewarping
        let (re, im) = lin.response(800.0, dt);
        let mag = (re * re + im * im).sqrt();
        assert!((mag - 1.0 / (2.0 * zeta)).abs() < 1e-9 * mag, "{mag}");
        // ZOH at this coarse dt does not keep the peak magnitude exactly
        let zoh = Linear::<f64, 1>::new(1.0, sec, dt, Discretisation::Zoh).unwrap();
        let (re, im) = zoh.response(800.0, dt);
        assert!(((re * re + im * im).sqrt() - mag).abs() > 1e-3 * mag);
    }

    #[test]
    fn notch_zero_pair_is_exact_with_tustin() {
        let dt = 1e-4;
        let w = 2.0 * PI * 1200.0;
        let sec = [Section::Second {
            wn: w,
            zeta: 0.7,
            zero: Some((w, 0.0)),
        }];
        let lin = Linear::<f64, 1>::new(1.0, sec, dt, Discretisation::Tustin).unwrap();
        let (re, im) = lin.response(1200.0, dt);
        assert!((re * re + im * im).sqrt() < 1e-9);
    }

    #[test]
    fn rejects_bad_sections() {
        let bad = |s: Section| {
            Linear::<f64, 1>::new(1.0, [s], 1e-4, Discretisation::Zoh)
                .unwrap_err()
                .0
        };
        assert_eq!(
            bad(Section::First { w: -1.0, wz: None }),
            "linear: first-order pole w > 0"
        );
        assert_eq!(
            bad(Section::Second {
                wn: 10.0,
                zeta: 0.0,
                zero: None
            }),
            "linear: damping zeta > 0"
        );
        assert!(Linear::<f64, 1>::new(
            1.0,
            [Section::poles_hz(8000.0, 0.1)],
            1e-4,
            Discretisation::Tustin
        )
        .is_err());
        assert!(Linear::<f64, 1>::new(
            1.0,
            [Section::poles_hz(80.0, 0.1)],
            0.0,
            Discretisation::Zoh
        )
        .is_err());
    }

    #[test]
    fn first_order_with_zero() {
        // (w/wz)(s + wz)/(s + w): DC 1, high-frequency gain w/wz
        let dt = 1e-5;
        let lin = Linear::<f64, 1>::new(
            2.0,
            [Section::First {
                w: 100.0,
                wz: Some(400.0),
            }],
            dt,
            Discretisation::Zoh,
        )
        .unwrap();
        let mut s = lin.init(0.0);
        let y0 = lin.step(&mut s, 1.0);
        assert!((y0 - 2.0 * 0.25).abs() < 1e-12, "{y0}");
        let mut y = y0;
        for _ in 0..200_000 {
            y = lin.step(&mut s, 1.0);
        }
        assert!((y - 2.0).abs() < 1e-6, "{y}");
    }

    /// Continuous response of a unity second-order section.
    fn cont2(wn: f64, zeta: f64, w: f64) -> (f64, f64) {
        cdiv((wn * wn, 0.0), (wn * wn - w * w, 2.0 * zeta * wn * w))
    }

    #[test]
    fn fourth_order_dc_gain_and_frequency_response() {
        let dt = 1e-5;
        let (w1, z1, w2, z2) = (2.0 * PI * 600.0, 0.08, 2.0 * PI * 2500.0, 0.3);
        let secs = [
            Section::Second {
                wn: w1,
                zeta: z1,
                zero: None,
            },
            Section::Second {
                wn: w2,
                zeta: z2,
                zero: None,
            },
        ];
        let lin = Linear::<f64, 2>::new(0.9, secs, dt, Discretisation::Zoh).unwrap();
        // DC: response at 0 Hz and the settled step response.
        let (re, im) = lin.response(0.0, dt);
        assert!((re - 0.9).abs() < 1e-9 && im.abs() < 1e-12, "{re} {im}");
        let mut s = lin.init(0.0);
        let mut y = 0.0;
        for _ in 0..100_000 {
            y = lin.step(&mut s, 2.0);
        }
        assert!((y - 1.8).abs() < 1e-6, "{y}");
        // init() at a DC level is already the steady state
        let mut s = lin.init(2.0);
        assert!((lin.step(&mut s, 2.0) - 1.8).abs() < 1e-9);
        // Frequency response: ZOH equals the continuous one times the hold's
        // sinc(w dt/2) e^(-j w dt/2) up to O((w dt)^2) aliasing terms.
        for &f in &[10.0, 200.0, 600.0, 1500.0] {
            let w = 2.0 * PI * f;
            let hc = cmul(cmul(cont2(w1, z1, w), cont2(w2, z2, w)), (0.9, 0.0));
            let x = w * dt / 2.0;
            let hold = ((x.sin() / x) * x.cos(), -(x.sin() / x) * x.sin());
            let want = cmul(hc, hold);
            let got = lin.response(f, dt);
            let err = ((got.0 - want.0).powi(2) + (got.1 - want.1).powi(2)).sqrt();
            let mag = (want.0 * want.0 + want.1 * want.1).sqrt();
            assert!(err < 2e-3 * mag, "{f} Hz: {got:?} vs {want:?}");
        }
    }
}
