//! The diagnosis model: classical Bouc-Wen plus optional extensions, one per cause.
//!
//! Per output `i`, driven by its own input `v` (after the input-side extensions):
//! `y = G(s)[d*v - alpha*g(v) + extras] + y0 + drift*t`, where `g` is the CBW hysteresis
//! with unit `alpha` (000 eq. 1-2 with `alpha = 1`; `h = alpha*g` because `dh/du` is
//! homogeneous in `(alpha, h)`), `G(s)` the optional linear dynamics (004 eq. 8, second
//! order, unit DC gain). Everything outside `g`, the input transforms and `G` enters
//! linearly, so the linear coefficients are solved by least squares for every trial of the
//! few nonlinear ones (variable projection): the search space stays 2 to 6 dimensional.

use serde::Serialize;

pub use super::coords::{Coords, PLAY_MAX, PLAY_MIN, TRAVEL_MAX, TRAVEL_MIN};
pub use super::dynamics::{dynamics, dynamics_all};
use super::Signals;
use crate::numeric::solve_spd;

/// A cause the base model may miss; each has one model extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Cause {
    /// Linear dynamics after the hysteresis (004 eq. 8, a Hammerstein structure): a phase
    /// lag that grows with rate. Not the loop rotation of rate-dependent hysteresis: 001
    /// finds that a Hammerstein model cannot reproduce it (re-run in `ident::rate`).
    Dynamics,
    /// Asymmetric loop: output polynomial in the input and input-weighted hysteresis.
    Asymmetry,
    /// First-order creep elements in parallel (time constants 20 ms to 5 s, at most half the record).
    Creep,
    /// Pure input delay.
    Delay,
    /// Amplifier rail: input clipped.
    Saturation,
    /// Amplifier slew-rate limit on the input.
    SlewLimit,
    /// Multi-axis: the other axes' inputs reach this output.
    CrossCoupling,
    /// Slow drift in time: linear plus a settling exponential.
    Drift,
    /// A play (dead zone) at reversals: after the input turns, the output stands still until
    /// the input has moved the play's width back (the micromanipulator's mechanism).
    Backlash,
    /// The slow start after a long rest: the first motion falls short by a fraction that
    /// decays with the input's travel, so it shows in the first cycles only.
    StartupCreep,
    /// Rate-dependent hysteresis: the loop widens and rotates as the input rate grows, which
    /// 001 sec. III finds a Hammerstein model (static hysteresis, then linear dynamics: the
    /// `dynamics` cause) cannot follow at high rates. The CBW output of 000 eq. (1)-(2) is
    /// extended by `rho*(c_h*(-g) + c_v*(v - vbar))`, `rho = r/(r + rate_ref)` with `r` the
    /// input rate `|dv/dt|` and `vbar` the input, both low-passed over [`RATE_TAU_S`]: the
    /// hysteresis grows and the gain about the operating point drops with the rate.
    RateDependence,
    /// A nonlinear position sensor: it reads `x + s2*e^2 + s3*e^3` for the stage's position
    /// `x` (everything else in the model, the structure and drift included),
    /// `e = (x - mid)/half` over the output's range. Unlike `asymmetry` (a polynomial of the
    /// input inside the actuator) it bends the hysteresis loop's two branches by the position
    /// they reach, and acts after creep, dynamics and drift.
    SensorNonlinearity,
    /// The dynamics `G` of `dynamics` (004 eq. 8) with a natural frequency and damping that
    /// move with the structure's oscillation amplitude, as in the fine steering mirror
    /// (hal-sim's `stage.amplitude_dynamics`, `diagnose::dynamics`). It includes the plain
    /// dynamics, so it is searched as their upgrade once they are found, and named only when
    /// it gains over them (it then replaces them).
    AmplitudeDynamics,
}

impl Cause {
    pub const ALL: [Cause; 13] = [
        Cause::Dynamics,
        Cause::Asymmetry,
        Cause::Creep,
        Cause::Delay,
        Cause::Saturation,
        Cause::SlewLimit,
        Cause::CrossCoupling,
        Cause::Drift,
        Cause::Backlash,
        Cause::StartupCreep,
        Cause::RateDependence,
        Cause::SensorNonlinearity,
        Cause::AmplitudeDynamics,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Cause::Dynamics => "dynamics",
            Cause::Asymmetry => "asymmetry",
            Cause::Creep => "creep",
            Cause::Delay => "delay",
            Cause::Saturation => "saturation",
            Cause::SlewLimit => "slew-limit",
            Cause::CrossCoupling => "cross-coupling",
            Cause::Drift => "drift",
            Cause::Backlash => "backlash",
            Cause::StartupCreep => "startup-creep",
            Cause::RateDependence => "rate-dependence",
            Cause::SensorNonlinearity => "sensor-nonlinearity",
            Cause::AmplitudeDynamics => "amplitude-dynamics",
        }
    }

    pub fn from_name(s: &str) -> Option<Cause> {
        Cause::ALL.into_iter().find(|c| c.name() == s)
    }

    fn bit(self) -> u16 {
        1 << (self as u16)
    }
}

/// A set of causes (the extensions a model has).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Causes(u16);

impl Causes {
    pub fn has(self, c: Cause) -> bool {
        self.0 & c.bit() != 0
    }
    pub fn with(self, c: Cause) -> Self {
        Self(self.0 | c.bit())
    }
    pub fn without(self, c: Cause) -> Self {
        Self(self.0 & !c.bit())
    }
    pub fn iter(self) -> impl Iterator<Item = Cause> {
        Cause::ALL.into_iter().filter(move |c| self.has(*c))
    }
    /// `cbw+dynamics+drift`.
    pub fn label(self) -> String {
        let mut s = String::from("cbw");
        for c in self.iter() {
            s.push('+');
            s.push_str(c.name());
        }
        s
    }
}

/// The nonlinear parameters of one output's model, in physical units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Shape {
    /// CBW `beta` (1/V).
    pub beta: f64,
    /// CBW `gamma` (1/V).
    pub gamma: f64,
    /// Input delay (s).
    pub delay_s: f64,
    /// Lower amplifier rail (V).
    pub rail_lo_v: f64,
    /// Upper amplifier rail (V).
    pub rail_hi_v: f64,
    /// Slew-rate limit (V/s).
    pub slew_v_per_s: f64,
    /// Natural frequency of `G` (Hz).
    pub wn_hz: f64,
    /// Damping ratio of `G`.
    pub zeta: f64,
    /// Half the width of the play on the output (its units, um); 0: no play.
    pub play_um: f64,
    /// Input travel (V, summed `|dv|` since the record's start from rest) over which the
    /// start-up deficit decays by `e`.
    pub startup_travel_v: f64,
    /// Input rate at which half the rate dependence acts (V/s); infinite: none.
    pub rate_ref_v_per_s: f64,
    /// Oscillation amplitude at which half the amplitude dependence of `G` acts (output
    /// units).
    pub amp_level_um: f64,
    /// Relative change of `G`'s natural frequency at large amplitude (0: none).
    pub amp_freq_shift: f64,
    /// Relative change of `G`'s damping ratio at large amplitude (0: none).
    pub amp_zeta_scale: f64,
}

/// What the search coordinates are scaled by: the training input of this output.
#[derive(Debug, Clone, Copy)]
pub struct Scales {
    pub u_lo: f64,
    pub u_hi: f64,
    pub rate_max: f64,
    pub dt: f64,
    pub duration_s: f64,
    /// Creep acts on `v - creep_rho * g`: the static displacement's shape, `alpha/d` of the
    /// model the creep was added to (0: on the voltage alone).
    pub creep_rho: f64,
    /// Span of the measured output (the play's width is scaled by it).
    pub y_span: f64,
    /// Middle of the measured output's range (the sensor polynomial's centre).
    pub y_mid: f64,
}

impl Scales {
    pub fn of(t: &[f64], u: &[f64]) -> Self {
        let (lo, hi) = min_max(u);
        let dt = if t.len() > 1 {
            (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
        } else {
            1.0
        };
        let rate_max = u
            .windows(2)
            .map(|w| (w[1] - w[0]).abs() / dt)
            .fold(0.0, f64::max);
        Self {
            u_lo: lo,
            u_hi: hi,
            rate_max: rate_max.max(1e-12),
            dt,
            duration_s: dt * t.len() as f64,
            creep_rho: 0.0,
            y_span: 1.0,
            y_mid: 0.0,
        }
    }
    /// The scales of several records of the same input: the widest range, the fastest rate,
    /// the shortest sample period and the longest record (one record: [`Scales::of`]).
    pub fn of_all(records: &[Signals], input: usize) -> Self {
        let mut all = records.iter().map(|r| Self::of(&r.t, &r.u[input]));
        let first = all.next().unwrap_or_else(|| Self::of(&[], &[]));
        all.fold(first, |a, b| Self {
            u_lo: a.u_lo.min(b.u_lo),
            u_hi: a.u_hi.max(b.u_hi),
            rate_max: a.rate_max.max(b.rate_max),
            dt: a.dt.min(b.dt),
            duration_s: a.duration_s.max(b.duration_s),
            creep_rho: 0.0,
            y_span: 1.0,
            y_mid: 0.0,
        })
    }
    pub fn span(&self) -> f64 {
        (self.u_hi - self.u_lo).max(1e-12)
    }
}

/// Creep time constants: about three per decade, 20 ms to 5 s.
pub const CREEP_TAUS_S: [f64; 8] = [0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0];

/// Time constant of the drift's settling term, in training-record lengths.
pub const DRIFT_TAU_RECORDS: f64 = 3.0;

/// Fixed creep time constants for a record of `duration_s` sampled at `dt`.
pub fn creep_taus(duration_s: f64, dt: f64) -> Vec<f64> {
    CREEP_TAUS_S
        .into_iter()
        .filter(|&tau| tau >= 20.0 * dt && tau <= 0.5 * duration_s)
        .collect()
}

/// One output's model: nonlinear shape and linear coefficients (column order of
/// [`regressors`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutputModel {
    pub shape: Shape,
    /// Coefficient names, in column order.
    pub names: Vec<String>,
    pub coef: Vec<f64>,
}

/// Index of the input that drives output `i`.
pub fn own_input(i: usize, n_inputs: usize) -> usize {
    if i < n_inputs {
        i
    } else {
        0
    }
}

/// A play of half width `half` on `x`, at rest at its first value.
pub fn play(x: &mut [f64], half: f64) {
    let mut p = x.first().copied().unwrap_or(0.0);
    for v in x.iter_mut() {
        p = p.clamp(*v - half, *v + half);
        *v = p;
    }
}

/// `exp(-travel/travel_v)`: the share of the start-up deficit left after the input's travel
/// since the record's first sample (the stage at rest before it).
pub fn startup_decay(v: &[f64], travel_v: f64) -> Vec<f64> {
    let mut travel = 0.0;
    let mut prev = v.first().copied().unwrap_or(0.0);
    v.iter()
        .map(|&x| {
            travel += (x - prev).abs();
            prev = x;
            (-travel / travel_v).exp()
        })
        .collect()
}

/// Time constant over which the rate dependence measures the input rate and the operating
/// point (s); at least two samples.
pub const RATE_TAU_S: f64 = 5e-3;

/// `rho = r/(r + rate_ref)` of the rate dependence, `r` the input rate `|dv/dt|` low-passed
/// over [`RATE_TAU_S`] (0 at rest, towards 1 well above `rate_ref`), and the low-passed input
/// `vbar`.
pub fn rate_weight(v: &[f64], dt: f64, rate_ref: f64) -> (Vec<f64>, Vec<f64>) {
    let tau = RATE_TAU_S.max(2.0 * dt);
    let a = -(-dt / tau).exp_m1();
    let (mut r, mut vbar) = (0.0, v.first().copied().unwrap_or(0.0));
    let mut prev = vbar;
    let mut rho = Vec::with_capacity(v.len());
    let mut bar = Vec::with_capacity(v.len());
    for &x in v {
        r += a * ((x - prev).abs() / dt - r);
        vbar += a * (x - vbar);
        prev = x;
        rho.push(if rate_ref.is_finite() {
            r / (r + rate_ref)
        } else {
            0.0
        });
        bar.push(vbar);
    }
    (rho, bar)
}

/// The sensor polynomial's columns `e^2, e^3`, `e = (x - mid)/half` over the output's range.
pub fn sensor_columns(x: &[f64], s: &Scales) -> [Vec<f64>; 2] {
    let half = (0.5 * s.y_span).max(1e-12);
    let e: Vec<f64> = x.iter().map(|x| (x - s.y_mid) / half).collect();
    [
        e.iter().map(|e| e * e).collect(),
        e.iter().map(|e| e * e * e).collect(),
    ]
}

/// Delay (linear interpolation), slew limit, then rails: the input the actuator sees.
pub fn effective_input(u: &[f64], dt: f64, shape: &Shape) -> Vec<f64> {
    let n = u.len();
    let mut v: Vec<f64> = if shape.delay_s > 0.0 && n > 0 {
        let d = shape.delay_s / dt;
        let whole = d.floor() as usize;
        let frac = d - d.floor();
        (0..n)
            .map(|k| {
                if k < whole + 1 {
                    // before the record: the input rested at its first value
                    let a = k.checked_sub(whole).map_or(u[0], |j| u[j]);
                    return a + frac * (u[0] - a);
                }
                let a = u[k - whole];
                let b = u[k - whole - 1];
                a + frac * (b - a)
            })
            .collect()
    } else {
        u.to_vec()
    };
    if shape.slew_v_per_s.is_finite() {
        let step = shape.slew_v_per_s * dt;
        let mut prev = v.first().copied().unwrap_or(0.0);
        for x in v.iter_mut() {
            prev += (*x - prev).clamp(-step, step);
            *x = prev;
        }
    }
    if shape.rail_lo_v.is_finite() || shape.rail_hi_v.is_finite() {
        for x in v.iter_mut() {
            *x = x.clamp(shape.rail_lo_v, shape.rail_hi_v.max(shape.rail_lo_v));
        }
    }
    v
}

/// CBW hysteresis variable with unit `alpha`, from rest at the first input.
/// (`Cbw::with_n1(0, 1, beta, gamma)`, through its f64 fast path.)
pub fn hysteresis(v: &[f64], beta: f64, gamma: f64) -> Vec<f64> {
    let mut g = Vec::new();
    crate::fast::cbw_unit(v, beta, gamma, &mut g);
    g
}

/// Normalised input `w = (v - mid)/half` for the asymmetry polynomial.
fn normalised(v: &[f64], s: &Scales) -> Vec<f64> {
    let mid = 0.5 * (s.u_hi + s.u_lo);
    let half = 0.5 * s.span();
    v.iter().map(|x| (x - mid) / half).collect()
}

/// The regressor columns of output `i` and their names.
pub fn regressors(
    data: &Signals,
    i: usize,
    causes: Causes,
    shape: &Shape,
    scales: &Scales,
    taus: &[f64],
) -> (Vec<&'static str>, Vec<Vec<f64>>) {
    let dt = data.dt();
    let a = own_input(i, data.u.len());
    let v = effective_input(&data.u[a], dt, shape);
    let g = hysteresis(&v, shape.beta, shape.gamma);
    let mut names = vec!["d", "alpha"];
    let mut cols = Vec::with_capacity(12);
    if causes.has(Cause::Asymmetry) {
        let w = normalised(&v, scales);
        cols.push(w.iter().map(|w| w * w).collect());
        cols.push(w.iter().map(|w| w * w * w).collect());
        cols.push(w.iter().zip(&g).map(|(w, g)| -w * g).collect());
        names.extend(["asym_u2", "asym_u3", "asym_wh"]);
    }
    if causes.has(Cause::Creep) {
        const NAMES: [&str; 8] = [
            "creep_20ms",
            "creep_50ms",
            "creep_100ms",
            "creep_200ms",
            "creep_500ms",
            "creep_1000ms",
            "creep_2000ms",
            "creep_5000ms",
        ];
        // Creep follows the displacement (hysteresis included), not only the voltage.
        let rho = scales.creep_rho;
        let src: Vec<f64> = if rho != 0.0 {
            v.iter().zip(&g).map(|(v, g)| v - rho * g).collect()
        } else {
            v.clone()
        };
        cols.extend(crate::fast::lowpass_many(&src, taus, dt));
        for &tau in taus {
            let k = CREEP_TAUS_S.iter().position(|&t| t == tau).unwrap_or(0);
            names.push(NAMES[k]);
        }
    }
    if causes.has(Cause::StartupCreep) {
        // The static displacement away from the rest position, short by a deficit that
        // decays with the travel: `-s(T) * (d*(v - v0) - alpha*(g - g0))`, both parts free.
        let e = startup_decay(&v, shape.startup_travel_v);
        let (v0, g0) = (
            v.first().copied().unwrap_or(0.0),
            g.first().copied().unwrap_or(0.0),
        );
        cols.push(v.iter().zip(&e).map(|(v, e)| e * (v - v0)).collect());
        cols.push(g.iter().zip(&e).map(|(g, e)| -e * (g - g0)).collect());
        names.extend(["startup_v", "startup_h"]);
    }
    if causes.has(Cause::RateDependence) {
        let (rho, vbar) = rate_weight(&v, dt, shape.rate_ref_v_per_s);
        cols.push(rho.iter().zip(&g).map(|(r, g)| -r * g).collect());
        cols.push(
            rho.iter()
                .zip(v.iter().zip(&vbar))
                .map(|(r, (v, b))| r * (v - b))
                .collect(),
        );
        names.extend(["rate_h", "rate_v"]);
    }
    if causes.has(Cause::CrossCoupling) {
        const NAMES: [&str; 8] = [
            "couple_u1",
            "couple_u2",
            "couple_u3",
            "couple_u4",
            "couple_u5",
            "couple_u6",
            "couple_u7",
            "couple_u8",
        ];
        const H_NAMES: [&str; 8] = [
            "couple_h1",
            "couple_h2",
            "couple_h3",
            "couple_h4",
            "couple_h5",
            "couple_h6",
            "couple_h7",
            "couple_h8",
        ];
        for (j, uj) in data.u.iter().enumerate().take(8) {
            if j == a {
                continue;
            }
            // The other axis' input, and its hysteresis (with this axis' shape): coupling of
            // the other axis' displacement, not only of its voltage.
            let vj = effective_input(uj, dt, shape);
            cols.push(hysteresis(&vj, shape.beta, shape.gamma));
            cols.push(vj);
            names.push(H_NAMES[j]);
            names.push(NAMES[j]);
        }
    }
    let mut all = vec![v, g.into_iter().map(|g| -g).collect::<Vec<_>>()];
    all.extend(cols);
    if causes.has(Cause::Dynamics) {
        let mut cols: Vec<&mut [f64]> = all.iter_mut().map(Vec::as_mut_slice).collect();
        dynamics_all(&mut cols, shape.wn_hz, shape.zeta, dt);
    }
    all.push(vec![1.0; data.t.len()]);
    names.push("y0");
    if causes.has(Cause::Drift) {
        // Linear, plus a slow settling (thermal drift approaches equilibrium): bounded
        // beyond the training record, unlike a polynomial.
        let tau = DRIFT_TAU_RECORDS * scales.duration_s;
        all.push(data.t.clone());
        all.push(data.t.iter().map(|t| -(-t / tau).exp_m1()).collect());
        names.push("drift_per_s");
        names.push("drift_settling");
    }
    (names, all)
}

/// `y = sum coef_k * col_k`.
pub fn combine(cols: &[Vec<f64>], coef: &[f64]) -> Vec<f64> {
    let n = cols.first().map_or(0, Vec::len);
    let mut y = vec![0.0; n];
    for (c, &b) in cols.iter().zip(coef) {
        for (y, x) in y.iter_mut().zip(c) {
            *y += b * x;
        }
    }
    y
}

/// `rmse(combine(cols, coef), y)` to the bit, without the model's output in memory: the
/// searches need only the error, and the sum runs in blocks that stay in L1 (the whole
/// output was written once per column; 9 % of a three-cause diagnose went there).
pub fn combine_rmse(cols: &[Vec<f64>], coef: &[f64], y: &[f64]) -> f64 {
    const BLOCK: usize = 256;
    let n = cols.first().map_or(0, Vec::len).min(y.len());
    let mut buf = [0.0f64; BLOCK];
    let mut s = 0.0;
    let mut lo = 0;
    while lo < n {
        let hi = (lo + BLOCK).min(n);
        let out = &mut buf[..hi - lo];
        out.fill(0.0);
        // Column by column, as `combine` sums: the same rounding per sample.
        for (c, &b) in cols.iter().zip(coef) {
            for (o, x) in out.iter_mut().zip(&c[lo..hi]) {
                *o += b * x;
            }
        }
        for (o, m) in out.iter().zip(&y[lo..hi]) {
            let d = o - m;
            s += d * d;
        }
        lo = hi;
    }
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

/// Least squares `min |X b - y|` by normal equations on scaled columns with a tiny ridge.
pub fn least_squares(cols: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
    least_squares_refs(&refs, y)
}

/// [`least_squares`] on borrowed columns.
pub fn least_squares_refs(cols: &[&[f64]], y: &[f64]) -> Vec<f64> {
    let p = cols.len();
    let (gram, xty) = crate::fast::gram(cols, y);
    let scale: Vec<f64> = (0..p)
        .map(|r| {
            let s = gram[r * p + r].sqrt();
            if s > 0.0 && s.is_finite() {
                1.0 / s
            } else {
                0.0
            }
        })
        .collect();
    let mut a = vec![0.0; p * p];
    let mut b = vec![0.0; p];
    for r in 0..p {
        for c in 0..=r {
            let v = gram[r * p + c] * scale[r] * scale[c];
            a[r * p + c] = v;
            a[c * p + r] = v;
        }
        b[r] = xty[r] * scale[r];
    }
    let mut ridge = 1e-12;
    for _ in 0..8 {
        let mut ar = a.clone();
        for r in 0..p {
            ar[r * p + r] += ridge;
        }
        if let Some(x) = solve_spd(&ar, &b, p) {
            return x.iter().zip(&scale).map(|(x, s)| x * s).collect();
        }
        ridge *= 100.0;
    }
    vec![0.0; p]
}

pub fn min_max(x: &[f64]) -> (f64, f64) {
    x.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numeric::rmse;

    /// The searches' error equals the error of the combined output to the bit, over lengths
    /// that end inside a block and exactly on one.
    #[test]
    fn combine_rmse_is_rmse_of_combine_to_the_bit() {
        for n in [1, 255, 256, 257, 1000, 4096] {
            let cols: Vec<Vec<f64>> = (0..5)
                .map(|c| {
                    (0..n)
                        .map(|k| ((k * (c + 3)) as f64 * 0.37).sin() * (c as f64 + 0.5))
                        .collect()
                })
                .collect();
            let coef = [0.3, -1.7, 2.2e-3, 5.0, -0.01];
            let y: Vec<f64> = (0..n).map(|k| (k as f64 * 0.011).cos()).collect();
            let want = rmse(&combine(&cols, &coef), &y);
            assert_eq!(
                combine_rmse(&cols, &coef, &y).to_bits(),
                want.to_bits(),
                "{n}"
            );
        }
        assert!(combine_rmse(&[], &[], &[1.0]).is_nan());
    }

    #[test]
    fn least_squares_recovers_coefficients() {
        let x1: Vec<f64> = (0..500).map(|k| (k as f64 * 0.1).sin()).collect();
        let x2: Vec<f64> = (0..500).map(|k| k as f64 * 1e3).collect();
        let y: Vec<f64> = x1
            .iter()
            .zip(&x2)
            .map(|(a, b)| 2.0 * a - 3e-4 * b)
            .collect();
        let c = least_squares(&[x1, x2], &y);
        assert!(
            (c[0] - 2.0).abs() < 1e-9 && (c[1] + 3e-4).abs() < 1e-12,
            "{c:?}"
        );
    }

    #[test]
    fn dynamics_has_unit_dc_gain_and_delay_shifts() {
        let mut x = vec![1.0; 10];
        x.extend(vec![2.0; 4000]);
        dynamics(&mut x, 50.0, 0.5, 1e-3);
        assert!((x[x.len() - 1] - 2.0).abs() < 1e-9);
        let u: Vec<f64> = (0..100).map(|k| k as f64).collect();
        let mut shape = Coords {
            causes: Causes::default(),
            scales: Scales::of(&u, &u),
        }
        .shape(&[0.0, 0.0]);
        shape.delay_s = 2.5e-3;
        let v = effective_input(&u, 1e-3, &shape);
        assert!((v[50] - 47.5).abs() < 1e-12, "{}", v[50]);
        assert_eq!(v[0], 0.0);
    }
}
