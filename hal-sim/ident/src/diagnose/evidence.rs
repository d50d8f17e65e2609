//! Residual signatures: what the residual of the current model correlates with, per cause.
//!
//! Each cause has a few signature signals built from the record and the current model's
//! output; the statistic is the fraction of the residual's variance they explain (R² of a
//! least-squares fit with a constant). Noise alone explains about `p/N` (p signals, N
//! samples), so a real effect stands out even when it is small.

use serde::Serialize;

use super::model::{
    effective_input, hysteresis, least_squares, own_input, play, rate_weight, startup_decay, Cause,
    Shape,
};
use super::Signals;
use crate::numeric::lowpass;

/// The evidence for one cause on one record.
#[derive(Debug, Clone, Serialize)]
pub struct Evidence {
    /// The signal the residual was tested against.
    pub signal: String,
    /// Fraction of the residual variance the signal explains (0..1).
    pub r2: f64,
    /// One sentence for a person.
    pub text: String,
}

/// Central difference scaled by `1/dt`.
pub fn derivative(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|k| {
            let a = x[k.saturating_sub(1)];
            let b = x[(k + 1).min(n - 1)];
            let span = (k + 1).min(n - 1) - k.saturating_sub(1);
            if span == 0 {
                0.0
            } else {
                (b - a) / (span as f64 * dt)
            }
        })
        .collect()
}

/// R² of `r` on `sig` plus a constant.
pub fn explained(r: &[f64], sig: &[Vec<f64>]) -> f64 {
    let n = r.len();
    if n < 3 {
        return 0.0;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    let var: f64 = r.iter().map(|v| (v - mean) * (v - mean)).sum();
    if var.is_nan() || var <= 0.0 {
        return 0.0;
    }
    let mut cols: Vec<Vec<f64>> = sig.to_vec();
    cols.push(vec![1.0; n]);
    let b = least_squares(&cols, r);
    let mut sse = 0.0;
    for k in 0..n {
        let fit: f64 = cols.iter().zip(&b).map(|(c, b)| c[k] * b).sum();
        sse += (r[k] - fit) * (r[k] - fit);
    }
    (1.0 - sse / var).clamp(0.0, 1.0)
}

fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    let c = sab / (saa * sbb).sqrt();
    if c.is_finite() {
        c
    } else {
        0.0
    }
}

fn quantile(x: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    if v.is_empty() {
        return 0.0;
    }
    // The element a sort would put there (total order: the same value), in linear time.
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

fn rms_where(r: &[f64], mask: impl Fn(usize) -> bool) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (k, v) in r.iter().enumerate() {
        if mask(k) {
            s += v * v;
            n += 1;
        }
    }
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

/// The signal a person should plot the residual against for `cause` (x axis label, values).
pub fn signal(
    data: &Signals,
    i: usize,
    cause: Option<Cause>,
    y_model: &[f64],
) -> (String, Vec<f64>) {
    let a = own_input(i, data.u.len());
    let u = &data.u[a];
    let dt = data.dt();
    match cause {
        Some(Cause::Dynamics) | Some(Cause::SlewLimit) | Some(Cause::AmplitudeDynamics) => {
            ("input rate du/dt [V/s]".into(), derivative(u, dt))
        }
        Some(Cause::Delay) => ("model output rate [um/s]".into(), derivative(y_model, dt)),
        Some(Cause::Creep) => (
            "input low-passed (500 ms) minus input [V]".into(),
            lowpass(u, 0.5, dt)
                .iter()
                .zip(u)
                .map(|(l, u)| l - u)
                .collect(),
        ),
        Some(Cause::Drift) => ("time [s]".into(), data.t.clone()),
        Some(Cause::RateDependence) => (
            "input rate |du/dt| [V/s]".into(),
            derivative(u, dt).iter().map(|v| v.abs()).collect(),
        ),
        Some(Cause::SensorNonlinearity) => ("model output [um]".into(), y_model.to_vec()),
        Some(Cause::StartupCreep) => (
            "input travel since the record's start [V]".into(),
            u.iter()
                .scan((u[0], 0.0), |(prev, sum), &x| {
                    *sum += (x - *prev).abs();
                    *prev = x;
                    Some(*sum)
                })
                .collect(),
        ),
        Some(Cause::CrossCoupling) => {
            let j = if a == 0 { 1 } else { 0 };
            match data.u.get(j) {
                Some(uj) => (format!("other axis' input u{} [V]", j + 1), uj.clone()),
                None => ("input u [V]".into(), u.clone()),
            }
        }
        _ => ("input u [V]".into(), u.clone()),
    }
}

/// Evidence for `cause` in residual `r = y - y_model` of output `i` on `data`; `fitted` is
/// the candidate's shape (its fitted slew limit is one of the slew signatures).
pub fn evidence(
    data: &Signals,
    i: usize,
    cause: Cause,
    r: &[f64],
    y_model: &[f64],
    fitted: &Shape,
) -> Evidence {
    let a = own_input(i, data.u.len());
    let s = Sig {
        data,
        i,
        a,
        u: &data.u[a],
        dt: data.dt(),
        n: r.len(),
        r,
        y_model,
        fitted,
    };
    match cause {
        Cause::Dynamics => dynamics(&s),
        Cause::AmplitudeDynamics => amplitude_dynamics(&s),
        Cause::Delay => delay(&s),
        Cause::Creep => creep(&s),
        Cause::Saturation => saturation(&s),
        Cause::SlewLimit => slew_limit(&s),
        Cause::Asymmetry => asymmetry(&s),
        Cause::CrossCoupling => cross_coupling(&s),
        Cause::Backlash => backlash(&s),
        Cause::StartupCreep => startup_creep(&s),
        Cause::RateDependence => rate_dependence(&s),
        Cause::SensorNonlinearity => sensor_nonlinearity(&s),
        Cause::Drift => drift(&s),
    }
}

/// What every signature is built from: output `i` of `data`, driven by input `a` (`u`,
/// sampled every `dt`), its residual `r` (`n` samples) under the model's `y_model`, and the
/// candidate's fitted shape.
#[derive(Clone, Copy)]
struct Sig<'a> {
    data: &'a Signals,
    i: usize,
    a: usize,
    u: &'a Vec<f64>,
    dt: f64,
    n: usize,
    r: &'a [f64],
    y_model: &'a [f64],
    fitted: &'a Shape,
}

fn dynamics(s: &Sig) -> Evidence {
    let Sig {
        u, dt, r, y_model, ..
    } = *s;
    let yd = derivative(y_model, dt);
    let ydd = derivative(&yd, dt);
    let r2 = explained(r, &[yd, ydd]);
    let rate = derivative(u, dt);
    let slow = lowpass(&rate, 1.0 / (2.0 * std::f64::consts::PI * 10.0), dt);
    let fast: Vec<f64> = rate.iter().zip(&slow).map(|(a, b)| a - b).collect();
    let (c_slow, c_fast) = (corr(r, &slow), corr(r, &fast));
    Evidence {
        signal: "input rate by band, model output rate and acceleration".into(),
        r2,
        text: format!(
            "residual follows the input rate (loop rotation): corr {c_slow:+.2} with du/dt below 10 Hz, {c_fast:+.2} above; rate and acceleration of the model output explain {:.0} % of it",
            100.0 * r2
        ),
    }
}

fn amplitude_dynamics(s: &Sig) -> Evidence {
    let Sig {
        dt,
        n,
        r,
        y_model,
        fitted,
        ..
    } = *s;
    // `r` is what the amplitude dependence removes from the plain dynamics (the
    // candidate with it switched off): the ringing's rate and acceleration weighted
    // by the ringing's amplitude (the envelope of the acceleration over `wn^2`).
    let yd = derivative(y_model, dt);
    let ydd = derivative(&yd, dt);
    let w0 = 2.0 * std::f64::consts::PI * fitted.wn_hz;
    let (sig, big) = if w0.is_finite() && w0 > 0.0 {
        let ring: Vec<f64> = ydd.iter().map(|a| a.abs() / (w0 * w0)).collect();
        let env: Vec<f64> = lowpass(&ring, 2.0 / w0, dt)
            .iter()
            .map(|e| 0.5 * std::f64::consts::PI * e)
            .collect();
        let level = fitted.amp_level_um.max(1e-12);
        let rho: Vec<f64> = env.iter().map(|e| e / (e + level)).collect();
        let sig = vec![
            rho.iter().zip(&yd).map(|(r, v)| r * v).collect(),
            rho.iter().zip(&ydd).map(|(r, a)| r * a).collect(),
        ];
        (sig, env)
    } else {
        (Vec::new(), vec![0.0; n])
    };
    let r2 = explained(r, &sig);
    let at = quantile(&big, 0.9);
    let ringing = |k: usize| big[k] > at;
    let (e_big, e_small) = (rms_where(r, ringing), rms_where(r, |k| !ringing(k)));
    Evidence {
        signal: "ringing's rate and acceleration weighted by its amplitude".into(),
        r2,
        text: format!(
            "residual rms {e_big:.3} where the ringing is in its top tenth vs {e_small:.3} elsewhere; a resonance that shifts by {:+.0} % in frequency and {:+.0} % in damping at large amplitude (half at {:.3}) explains {:.0} %",
            100.0 * fitted.amp_freq_shift,
            100.0 * fitted.amp_zeta_scale,
            fitted.amp_level_um,
            100.0 * r2
        ),
    }
}

fn delay(s: &Sig) -> Evidence {
    let Sig { dt, r, y_model, .. } = *s;
    let yd = derivative(y_model, dt);
    let r2 = explained(r, std::slice::from_ref(&yd));
    let var: f64 = yd.iter().map(|v| v * v).sum();
    let lag = if var > 0.0 {
        -r.iter().zip(&yd).map(|(a, b)| a * b).sum::<f64>() / var
    } else {
        0.0
    };
    Evidence {
        signal: "model output rate".into(),
        r2,
        text: format!(
            "residual is proportional to minus the model's rate (a lag of {:.2} ms); explains {:.0} %",
            lag * 1e3,
            100.0 * r2
        ),
    }
}

fn creep(s: &Sig) -> Evidence {
    let Sig { u, dt, r, .. } = *s;
    let sig: Vec<Vec<f64>> = [0.05, 0.5, 2.5]
        .iter()
        .map(|&tau| {
            lowpass(u, tau, dt)
                .iter()
                .zip(u)
                .map(|(l, u)| l - u)
                .collect()
        })
        .collect();
    let r2 = explained(r, &sig);
    Evidence {
        signal: "input low-passed minus input (time since the last input change)".into(),
        r2,
        text: format!(
            "residual relaxes after input changes (time constants 50 ms to 2.5 s explain {:.0} %)",
            100.0 * r2
        ),
    }
}

fn saturation(s: &Sig) -> Evidence {
    let Sig { u, r, .. } = *s;
    let (lo, hi) = (quantile(u, 0.0), quantile(u, 1.0));
    let band = 0.1 * (hi - lo);
    let sig = vec![
        u.iter().map(|v| (v - (hi - band)).max(0.0)).collect(),
        u.iter().map(|v| ((lo + band) - v).max(0.0)).collect(),
    ];
    let r2 = explained(r, &sig);
    let near = |k: usize| u[k] > hi - band || u[k] < lo + band;
    let (e_near, e_mid) = (rms_where(r, near), rms_where(r, |k| !near(k)));
    Evidence {
        signal: "|u| near the rails".into(),
        r2,
        text: format!(
            "residual rms {e_near:.3} where u is within 10 % of its extremes vs {e_mid:.3} elsewhere; explains {:.0} %",
            100.0 * r2
        ),
    }
}

fn slew_limit(s: &Sig) -> Evidence {
    let Sig {
        u, dt, r, fitted, ..
    } = *s;
    let rate = derivative(u, dt);
    let abs: Vec<f64> = rate.iter().map(|v| v.abs()).collect();
    // Limits at quantiles of the rate, and the candidate's fitted limit: the limit
    // may act only on the rare fast steps.
    let fitted_limit = if fitted.slew_v_per_s.is_finite() {
        fitted.slew_v_per_s
    } else {
        quantile(&abs, 0.99)
    };
    let sig: Vec<Vec<f64>> = [0.5, 0.8, 0.95]
        .iter()
        .map(|&q| quantile(&abs, q))
        .chain(std::iter::once(fitted_limit))
        .map(|limit| {
            let limit = limit.max(1e-12);
            let shape = Shape {
                slew_v_per_s: limit,
                ..no_shape()
            };
            effective_input(u, dt, &shape)
                .iter()
                .zip(u)
                .map(|(v, u)| u - v)
                .collect()
        })
        .collect();
    let r2 = explained(r, &sig);
    let fast_at = quantile(&abs, 0.9);
    let fast = |k: usize| abs[k] > fast_at;
    let (e_fast, e_slow) = (rms_where(r, fast), rms_where(r, |k| !fast(k)));
    Evidence {
        signal: "lag of a slew-limited input".into(),
        r2,
        text: format!(
            "residual rms {e_fast:.3} where |du/dt| is in its top 10 % vs {e_slow:.3} elsewhere; a slew-limited input's lag explains {:.0} %",
            100.0 * r2
        ),
    }
}

fn asymmetry(s: &Sig) -> Evidence {
    let Sig { u, r, .. } = *s;
    let (lo, hi) = (quantile(u, 0.0), quantile(u, 1.0));
    let mid = 0.5 * (lo + hi);
    let half = (0.5 * (hi - lo)).max(1e-12);
    let w: Vec<f64> = u.iter().map(|v| (v - mid) / half).collect();
    let sig = vec![
        w.iter().map(|w| w * w).collect(),
        w.iter().map(|w| w * w * w).collect(),
    ];
    let r2 = explained(r, &sig);
    Evidence {
        signal: "u^2, u^3".into(),
        r2,
        text: format!(
            "residual is an even/odd polynomial of the input (asymmetric loop): u^2 and u^3 explain {:.0} %",
            100.0 * r2
        ),
    }
}

fn cross_coupling(s: &Sig) -> Evidence {
    let Sig { data, i, a, r, .. } = *s;
    let sig: Vec<Vec<f64>> = data
        .u
        .iter()
        .enumerate()
        .filter(|(j, _)| *j != a)
        .map(|(_, uj)| uj.clone())
        .collect();
    let r2 = explained(r, &sig);
    let c = sig.first().map_or(0.0, |s| corr(r, s));
    Evidence {
        signal: "other axes' inputs".into(),
        r2,
        text: format!(
            "residual of y{} follows the other axis' input (corr {c:+.2}); explains {:.0} %",
            i + 1,
            100.0 * r2
        ),
    }
}

fn backlash(s: &Sig) -> Evidence {
    let Sig {
        u,
        dt,
        n,
        r,
        y_model,
        fitted,
        ..
    } = *s;
    let (lo, hi) = (quantile(u, 0.0), quantile(u, 1.0));
    let span = (hi - lo).max(1e-12);
    // The lag of a played input behind the input, for play widths around the fitted one.
    // The fitted play (output units) as input volts: the output spans about the input's
    // span times the gain.
    let (y_lo, y_hi) = (quantile(y_model, 0.0), quantile(y_model, 1.0));
    let per_v = ((y_hi - y_lo) / span).max(1e-12);
    let fitted_v = fitted.play_um / per_v;
    let sig: Vec<Vec<f64>> = [0.003 * span, 0.02 * span, fitted_v]
        .iter()
        .filter(|b| **b > 0.0)
        .map(|&b| {
            let mut p = u.clone();
            play(&mut p, b);
            p.iter().zip(u).map(|(p, u)| p - u).collect()
        })
        .collect();
    let r2 = explained(r, &sig);
    let rate = derivative(u, dt);
    // Right after a reversal: within the fitted play's travel of the last turning point.
    let mut turned = vec![false; n];
    let (mut extreme, mut dir) = (u[0], 0.0f64);
    let width = 2.0 * fitted_v.max(0.005 * span);
    for k in 0..n {
        let d = rate[k].signum();
        if d != 0.0 && d != dir {
            dir = d;
            extreme = u[k];
        }
        turned[k] = (u[k] - extreme).abs() < width;
    }
    let (e_turn, e_run) = (rms_where(r, |k| turned[k]), rms_where(r, |k| !turned[k]));
    Evidence {
        signal: "played input minus input (dead zone after reversals)".into(),
        r2,
        text: format!(
            "residual rms {e_turn:.3} within {width:.2} V of a reversal vs {e_run:.3} elsewhere; a play's dead zone explains {:.0} %",
            100.0 * r2
        ),
    }
}

fn startup_creep(s: &Sig) -> Evidence {
    let Sig { u, r, fitted, .. } = *s;
    let (lo, hi) = (quantile(u, 0.0), quantile(u, 1.0));
    let span = (hi - lo).max(1e-12);
    let u0 = u[0];
    let sig: Vec<Vec<f64>> = [0.3 * span, span, fitted.startup_travel_v]
        .iter()
        .filter(|t| t.is_finite() && **t > 0.0)
        .map(|&tv| {
            startup_decay(u, tv)
                .iter()
                .zip(u)
                .map(|(e, u)| e * (u - u0))
                .collect()
        })
        .collect();
    let r2 = explained(r, &sig);
    let early = startup_decay(u, fitted.startup_travel_v.min(1e3 * span));
    let first = |k: usize| early[k] > 0.3;
    let (e_first, e_later) = (rms_where(r, first), rms_where(r, |k| !first(k)));
    Evidence {
        signal: "displacement from rest times a deficit decaying with travel".into(),
        r2,
        text: format!(
            "residual rms {e_first:.3} in the first motion after rest vs {e_later:.3} later; a deficit decaying with the input's travel explains {:.0} %",
            100.0 * r2
        ),
    }
}

fn rate_dependence(s: &Sig) -> Evidence {
    let Sig {
        u, dt, r, fitted, ..
    } = *s;
    let g = hysteresis(u, fitted.beta, fitted.gamma);
    let abs: Vec<f64> = derivative(u, dt).iter().map(|v| v.abs()).collect();
    let moving: Vec<f64> = abs.iter().copied().filter(|v| *v > 0.0).collect();
    // The hysteresis and the operating point's offset weighted by the rate, for the
    // typical moving rate and the fitted reference rate.
    let sig: Vec<Vec<f64>> = [quantile(&moving, 0.5), fitted.rate_ref_v_per_s]
        .iter()
        .filter(|r| r.is_finite() && **r > 0.0)
        .flat_map(|&rr| {
            let (rho, ubar) = rate_weight(u, dt, rr);
            [
                rho.iter().zip(&g).map(|(r, g)| r * g).collect::<Vec<f64>>(),
                rho.iter()
                    .zip(u.iter().zip(&ubar))
                    .map(|(r, (u, b))| r * (u - b))
                    .collect(),
            ]
        })
        .collect();
    let r2 = explained(r, &sig);
    let fast_at = quantile(&abs, 0.75);
    let fast = |k: usize| abs[k] > fast_at;
    let (e_fast, e_slow) = (rms_where(r, fast), rms_where(r, |k| !fast(k)));
    Evidence {
        signal: "hysteresis and operating-point offset weighted by the input rate".into(),
        r2,
        text: format!(
            "residual rms {e_fast:.3} where |du/dt| is in its top quarter vs {e_slow:.3} elsewhere; the loop's widening and rotation with the rate explain {:.0} %",
            100.0 * r2
        ),
    }
}

fn sensor_nonlinearity(s: &Sig) -> Evidence {
    let Sig { r, y_model, .. } = *s;
    let (lo, hi) = (quantile(y_model, 0.0), quantile(y_model, 1.0));
    let mid = 0.5 * (lo + hi);
    let half = (0.5 * (hi - lo)).max(1e-12);
    let e: Vec<f64> = y_model.iter().map(|y| (y - mid) / half).collect();
    let sig = vec![
        e.iter().map(|e| e * e).collect(),
        e.iter().map(|e| e * e * e).collect(),
    ];
    let r2 = explained(r, &sig);
    let ends = |k: usize| e[k].abs() > 0.8;
    let (e_ends, e_mid) = (rms_where(r, ends), rms_where(r, |k| !ends(k)));
    Evidence {
        signal: "position^2, position^3 (the model's output)".into(),
        r2,
        text: format!(
            "residual rms {e_ends:.3} in the outer tenths of the position range vs {e_mid:.3} inside; a polynomial of the position (not of the input) explains {:.0} %",
            100.0 * r2
        ),
    }
}

fn drift(s: &Sig) -> Evidence {
    let Sig { data, n, r, .. } = *s;
    let r2 = explained(r, std::slice::from_ref(&data.t));
    let t_mean = data.t.iter().sum::<f64>() / n.max(1) as f64;
    let r_mean = r.iter().sum::<f64>() / n.max(1) as f64;
    let (mut stt, mut str_) = (0.0, 0.0);
    for (t, v) in data.t.iter().zip(r) {
        stt += (t - t_mean) * (t - t_mean);
        str_ += (t - t_mean) * (v - r_mean);
    }
    let slope = if stt > 0.0 { str_ / stt } else { 0.0 };
    Evidence {
        signal: "time".into(),
        r2,
        text: format!(
            "residual trends in time ({slope:+.4} per s); time explains {:.0} %",
            100.0 * r2
        ),
    }
}

/// A shape with no input-side effect.
pub fn no_shape() -> Shape {
    Shape {
        beta: 1.0,
        gamma: 0.0,
        delay_s: 0.0,
        rail_lo_v: f64::NEG_INFINITY,
        rail_hi_v: f64::INFINITY,
        slew_v_per_s: f64::INFINITY,
        wn_hz: f64::INFINITY,
        zeta: 1.0,
        play_um: 0.0,
        startup_travel_v: f64::INFINITY,
        rate_ref_v_per_s: f64::INFINITY,
        amp_level_um: 1.0,
        amp_freq_shift: 0.0,
        amp_zeta_scale: 0.0,
    }
}

/// Noise rms of a record from second differences (median based, so the signal's own
/// curvature and rare jumps barely count).
pub fn noise_rms(y: &[f64]) -> f64 {
    if y.len() < 5 {
        return 0.0;
    }
    let d2: Vec<f64> = y
        .windows(3)
        .map(|w| (w[0] - 2.0 * w[1] + w[2]).abs())
        .collect();
    // For white noise, second differences have variance 6 sigma^2; median |N(0,1)| = 0.6745.
    quantile(&d2, 0.5) / 0.6745 / 6f64.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn explained_is_one_for_exact_and_small_for_unrelated() {
        let x: Vec<f64> = (0..2000).map(|k| (k as f64 * 0.01).sin()).collect();
        let r: Vec<f64> = x.iter().map(|v| 3.0 * v + 1.0).collect();
        assert!(explained(&r, std::slice::from_ref(&x)) > 0.999_999);
        let mut s = 1u64;
        let noise: Vec<f64> = (0..2000)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        assert!(explained(&noise, &[x]) < 0.01);
    }

    #[test]
    fn noise_estimate_ignores_smooth_signal() {
        let mut s = 7u64;
        let y: Vec<f64> = (0..20000)
            .map(|k| {
                // sum of 12 uniforms: close to Gaussian with unit variance
                let mut g = -6.0;
                for _ in 0..12 {
                    s = s
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    g += (s >> 11) as f64 / (1u64 << 53) as f64;
                }
                10.0 * (k as f64 * 1e-3).sin() + 0.1 * g
            })
            .collect();
        let sigma = noise_rms(&y);
        assert!((sigma - 0.1).abs() < 0.01, "{sigma}");
    }
}
