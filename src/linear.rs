//! Hammerstein linear dynamics (004 eq. 8): a cascade of first- and second-order sections
//! built from continuous poles and zeros, discretised once at construction.
//!
//! Any stable transfer function of modest order with zeros anywhere (left or right half
//! plane: the non-collocated zeros of 004's identified model, eq. 8 with `n = 4`, `m = 2`)
//! is a cascade of sections; [`Linear::from_tf`] factors 004's polynomial form
//! (`sum a_i s^i y = sum b_j s^j v`) into one ([`poly`]).
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
//! Each section has unity DC gain; the cascade's DC gain is `gain`. States are scaled to
//! the section's output (`x1` its pole part at DC gain 1, `x2 = x1'/wn`), so every entry of
//! the discrete matrices is of order one whatever the frequencies (the fixed-point `Real`
//! keeps its digits). The per-sample update is a few multiply-adds per section, no
//! allocation.

// Construction-time dense linear algebra reads clearer with index loops.
#![allow(clippy::needless_range_loop)]

mod matrix;
pub(crate) use matrix::gauss;
pub mod poly;

use crate::hysteresis::{ensure, ParamError};
use crate::real::Real;
use matrix::{csolve, expm, solve, tustin, Mat, NMAX};

/// A continuous section, unity DC gain. Frequencies in rad/s. Zeros may lie anywhere
/// except at `s = 0` (a section keeps unity DC gain); poles must be stable.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Section {
    /// `w/(s + w)`, optionally times `(s + wz)/wz`: a zero at `s = -wz` (`wz < 0`: right
    /// half plane).
    First { w: f64, wz: Option<f64> },
    /// `wn^2/(s^2 + 2 zeta wn s + wn^2)`, optionally times
    /// `(s^2 + 2 zeta_z wz s + wz^2)/wz^2` (a zero pair: notch for `zeta_z` small,
    /// right half plane for `zeta_z < 0`).
    Second {
        wn: f64,
        zeta: f64,
        zero: Option<(f64, f64)>,
    },
    /// `(1 + q1 s + q2 s^2) / (1 + p1 s + p2 s^2)`: any numerator with `q(0) = 1` (two real
    /// zeros of opposite sign included) over stable poles (`p1 > 0`, `p2 >= 0`;
    /// `p2 = 0` is first order and then needs `q2 = 0`).
    Quadratic { q: [f64; 2], p: [f64; 2] },
}

/// A section as normalised polynomials `(1 + q1 s + q2 s^2) / (1 + p1 s + p2 s^2)`.
fn normalised(sec: &Section) -> ([f64; 2], [f64; 2]) {
    match *sec {
        Section::First { w, wz } => ([wz.map_or(0.0, |z| 1.0 / z), 0.0], [1.0 / w, 0.0]),
        Section::Second { wn, zeta, zero } => {
            let q = zero.map_or([0.0; 2], |(wz, zz)| [2.0 * zz / wz, 1.0 / (wz * wz)]);
            (q, [2.0 * zeta / wn, 1.0 / (wn * wn)])
        }
        Section::Quadratic { q, p } => (q, p),
    }
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

    /// Continuous state space `(A, B, C, D)` (2 states, scaled to the output; a
    /// first-order section leaves the second state undriven and decaying) and its prewarp
    /// frequency.
    fn state_space(&self) -> ([[f64; 2]; 2], [f64; 2], [f64; 2], f64, f64) {
        let ([q1, q2], [p1, p2]) = normalised(self);
        if p2 == 0.0 {
            // x' = w (v - x), y = x + q1 x' (q2 = 0 checked).
            let w = 1.0 / p1;
            let w0 = if q1 != 0.0 { libm::fabs(1.0 / q1) } else { w };
            return (
                [[-w, 0.0], [0.0, -w]],
                [w, 0.0],
                [1.0 - q1 * w, 0.0],
                q1 * w,
                w0,
            );
        }
        // x1'' + 2 zeta wn x1' + wn^2 x1 = wn^2 v, x2 = x1'/wn, y = x1 + q1 x1' + q2 x1''.
        let wn = libm::sqrt(1.0 / p2);
        let zw = 0.5 * p1 * wn * wn; // zeta*wn
        let w0 = if q2 != 0.0 {
            libm::sqrt(libm::fabs(1.0 / q2))
        } else {
            wn
        };
        (
            [[0.0, wn], [-wn, -2.0 * zw]],
            [0.0, wn],
            [1.0 - q2 * wn * wn, q1 * wn - 2.0 * q2 * zw * wn],
            q2 * wn * wn,
            w0,
        )
    }

    fn check(&self) -> Result<(), ParamError> {
        match *self {
            Section::First { w, wz } => {
                ensure(w.is_finite() && w > 0.0, "linear: first-order pole w > 0")?;
                ensure(
                    wz.is_none_or(|z| z.is_finite() && z != 0.0),
                    "linear: first-order zero wz finite and != 0",
                )
            }
            Section::Second { wn, zeta, zero } => {
                ensure(
                    wn.is_finite() && wn > 0.0,
                    "linear: natural frequency wn > 0",
                )?;
                ensure(zeta.is_finite() && zeta > 0.0, "linear: damping zeta > 0")?;
                ensure(
                    zero.is_none_or(|(wz, zz)| wz.is_finite() && wz > 0.0 && zz.is_finite()),
                    "linear: zero pair needs wz > 0 and a finite zeta_z",
                )
            }
            Section::Quadratic { q, p } => {
                ensure(
                    q.iter().chain(p.iter()).all(|v| v.is_finite()),
                    "linear: quadratic section coefficients must be finite",
                )?;
                ensure(
                    p[0] > 0.0 && p[1] >= 0.0,
                    "linear: quadratic section poles stable (p1 > 0, p2 >= 0)",
                )?;
                ensure(
                    p[1] > 0.0 || q[1] == 0.0,
                    "linear: a first-order section has at most one zero (q2 = 0)",
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

/// The discrete design of a cascade in f64 (construction time): `x' = Phi x + Gamma v`,
/// `y = gain * (C x + D v)`, `n = 2 * sections` states, and the DC state per unit input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Design {
    pub n: usize,
    pub phi: Mat,
    pub gamma: [f64; NMAX],
    pub c: [f64; NMAX],
    pub d: f64,
    pub gain: f64,
    pub x_dc: [f64; NMAX],
}

/// Discretises `gain` times the cascade of `sections` for sample period `dt` (s).
pub(crate) fn design(
    gain: f64,
    sections: &[Section],
    dt: f64,
    method: Discretisation,
) -> Result<Design, ParamError> {
    ensure(gain.is_finite(), "linear: gain must be finite")?;
    ensure(dt.is_finite() && dt > 0.0, "linear: sample period dt > 0")?;
    ensure(
        (1..=MAX_SECTIONS).contains(&sections.len()),
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
    let n = 2 * sections.len();
    let (a, b, c, d) = compose(&ss[..sections.len()]);
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
            let mut e = expm(&m, n + 1);
            let mut gamma = [0.0; NMAX];
            for i in 0..n {
                gamma[i] = e[i][n];
                e[i][n] = 0.0;
            }
            e[n][n] = 0.0;
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
    match x_dc {
        Some(x_dc) if finite && x_dc.iter().all(|v| v.is_finite()) => Ok(Design {
            n,
            phi,
            gamma,
            c,
            d,
            gain,
            x_dc,
        }),
        _ => Err(ParamError(
            "linear: discretisation failed (frequency too high for dt?)",
        )),
    }
}

impl<T: Real, const S: usize> Linear<T, S> {
    /// Builds the cascade for sample period `dt` (s). `gain` is the DC gain (1 for unity).
    pub fn new(
        gain: f64,
        sections: [Section; S],
        dt: f64,
        method: Discretisation,
    ) -> Result<Self, ParamError> {
        let Design {
            phi,
            gamma,
            c,
            d,
            x_dc,
            ..
        } = design(gain, &sections, dt, method)?;
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

    /// The linear dynamics of 004 eq. (8), `sum_i a_i y^(i) = sum_j b_j v^(j)`, from its
    /// coefficients in ascending order (`b = [b_0..b_m]`, `a = [a_0..a_n]`, `m <= n`),
    /// factored into `S = ceil(n/2)` sections ([`poly::sections`]); zeros anywhere, poles
    /// stable, `a_0, b_0 != 0` (DC gain `b_0/a_0`).
    pub fn from_tf(
        b: &[f64],
        a: &[f64],
        dt: f64,
        method: Discretisation,
    ) -> Result<Self, ParamError> {
        let (gain, secs, count) = poly::sections(b, a)?;
        ensure(
            count == S,
            "linear: the transfer function needs ceil(n/2) sections",
        )?;
        let mut arr = [secs[0]; S];
        arr.copy_from_slice(&secs[..S]);
        Self::new(gain, arr, dt, method)
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

    #[test]
    fn seed_004_model_with_right_half_plane_zeros() {
        // 004 sec. 4.2, eq. (8): n = 4, m = 2, zeros at 49 +- 1151j rad/s.
        let a = [5.421e12, 1.183e10, 1.046e7, 8.753e3, 1.0];
        let b = [5.421e12, -4.002e8, 4.083e6];
        let dt = 1e-4;
        let lin = Linear::<f64, 2>::from_tf(&b, &a, dt, Discretisation::Zoh).unwrap();
        let cont = |w: f64| {
            let ev = |c: &[f64]| {
                c.iter().rev().fold((0.0, 0.0), |acc, &ci| {
                    let m = cmul(acc, (0.0, w));
                    (m.0 + ci, m.1)
                })
            };
            cdiv(ev(&b), ev(&a))
        };
        for f in [0.0, 1.0, 20.0, 100.0, 168.0, 183.2, 300.0, 1000.0] {
            let w = 2.0 * PI * f;
            let x = w * dt / 2.0;
            let hold = if x == 0.0 {
                (1.0, 0.0)
            } else {
                ((x.sin() / x) * x.cos(), -(x.sin() / x) * x.sin())
            };
            let want = cmul(cont(w), hold);
            let got = lin.response(f, dt);
            let err = ((got.0 - want.0).powi(2) + (got.1 - want.1).powi(2)).sqrt();
            let mag = (want.0 * want.0 + want.1 * want.1).sqrt();
            assert!(err < 0.02 * mag + 1e-3, "{f} Hz: {got:?} vs {want:?}");
        }
        // The notch of the zero pair: |G| at 183 Hz is far below its neighbours.
        let mag = |f: f64| {
            let (re, im) = lin.response(f, dt);
            (re * re + im * im).sqrt()
        };
        assert!(
            mag(183.2) < 0.2 * mag(120.0),
            "{} {}",
            mag(183.2),
            mag(120.0)
        );
        // Simulated: the step response equals the continuous one at the sample instants
        // (ZOH is exact for a held step; reference: RK4 on the controllable canonical form
        // of eq. 8 with 1000 steps per sample) and settles at the DC gain b0/a0 = 1.
        let mut x = [0.0f64; 4];
        let f = |x: &[f64; 4]| {
            let mut d = [x[1], x[2], x[3], 1.0];
            for i in 0..4 {
                d[3] -= a[i] * x[i];
            }
            d
        };
        let mut s = lin.init(0.0);
        let mut worst = 0.0f64;
        for _ in 0..300 {
            let y = lin.step(&mut s, 1.0);
            let yc = b[0] * x[0] + b[1] * x[1] + b[2] * x[2];
            worst = worst.max((y - yc).abs());
            let h = dt / 1000.0;
            for _ in 0..1000 {
                let k1 = f(&x);
                let k2 = f(&core::array::from_fn(|i| x[i] + 0.5 * h * k1[i]));
                let k3 = f(&core::array::from_fn(|i| x[i] + 0.5 * h * k2[i]));
                let k4 = f(&core::array::from_fn(|i| x[i] + h * k3[i]));
                for i in 0..4 {
                    x[i] += h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
                }
            }
        }
        assert!(worst < 1e-9, "{worst}");
        let mut y = 0.0;
        for _ in 0..2000 {
            y = lin.step(&mut s, 1.0);
        }
        assert!((y - 1.0).abs() < 1e-6, "{y}");
    }

    #[test]
    fn zeros_anywhere_in_sections() {
        // A right-half-plane real zero: (1 - s/100) * 400/(s + 400), DC 1, and its step
        // response starts the wrong way (non-minimum phase).
        let lin = Linear::<f64, 1>::new(
            1.0,
            [Section::First {
                w: 400.0,
                wz: Some(-100.0),
            }],
            1e-5,
            Discretisation::Zoh,
        )
        .unwrap();
        let mut s = lin.init(0.0);
        let y0 = lin.step(&mut s, 1.0);
        assert!((y0 + 4.0).abs() < 1e-12, "{y0}"); // feedthrough -w/wz
                                                   // Right-half-plane zero pair (zeta_z < 0) keeps |H| of its mirror image.
        let mk = |zz: f64| {
            Linear::<f64, 1>::new(
                1.0,
                [Section::Second {
                    wn: 1000.0,
                    zeta: 0.3,
                    zero: Some((2000.0, zz)),
                }],
                1e-5,
                Discretisation::Tustin,
            )
            .unwrap()
        };
        let (l, r) = (mk(0.2), mk(-0.2));
        for f in [10.0, 200.0, 318.3, 1000.0] {
            let (a, b) = (l.response(f, 1e-5), r.response(f, 1e-5));
            let (ma, mb) = (
                (a.0 * a.0 + a.1 * a.1).sqrt(),
                (b.0 * b.0 + b.1 * b.1).sqrt(),
            );
            assert!((ma - mb).abs() < 1e-9 * ma, "{f}: {ma} {mb}");
        }
        assert!(Linear::<f64, 1>::new(
            1.0,
            [Section::Quadratic {
                q: [0.0, 1e-6],
                p: [1e-3, 0.0]
            }],
            1e-5,
            Discretisation::Zoh
        )
        .is_err());
    }
}
