//! An independent record generator: simulated stages with known hidden causes, to check
//! `piezo diagnose` on data it was not tuned to (`piezo diagnose-bench`).
//!
//! Written from this specification alone, not from diagnose's model code nor from hal-sim's
//! own simulated stage (`stage`, `sim`, `ident::generate`): its own integration, its own
//! parameterisation of every cause, wider parameter ranges and other excitations. That is
//! why it does not reuse the core's CBW: a shared model would share its mistakes.
//!
//! # The stage (every axis)
//!
//! Command (V, `0..u_max`, `u_max` 100 or 150 V) held by the DAC over each sample period
//! -> amplifier (first-order lag, time constant 10-25 % of the sample period, so it settles
//! within the period; optional rail and slew limit) -> classical Bouc-Wen (000 eq. (1)-(2):
//! `v = d u - h`, `dh/dt = a du/dt - b |du/dt| h - g du/dt |h|`) with the input-side causes
//! -> coupling to the other axis -> creep -> play -> second-order structural mode ->
//! drift -> sensor (delay, nonlinearity, offset, white and 1/f noise, mains hum,
//! quantisation), read at the end of each sample period.
//!
//! Integration: the amplifier is solved exactly over each sub-step (at least 4 per sample,
//! at most 20 us), so the input is a straight line within a sub-step; all other states
//! advance by classical RK4 along it.
//!
//! | part | range |
//! |---|---|
//! | piezo coefficient `d` | 0.3-1.5 um/V |
//! | CBW shape | `(b + g) u_max` 2-10 (log-uniform), `b/(b + g)` 0.55-0.9; `a` set so the loop over a full-range cycle is 5-25 % of the stroke wide (redrawn if `a > 0.85 d`) |
//! | background structural mode | `max(300 Hz, 8x the drive's top frequency)`-5 kHz (log-uniform), zeta 0.3-0.7 |
//! | sample rate | 2, 5, 10 or 20 kHz (one per case) |
//! | record length | 5-40 s, log-uniform, at most 100 000 samples (train and valid drawn apart) |
//! | sensor | range `-0.1..1.1` of the stroke, 14-18 bits, offset +-10 um |
//! | noise | white 2-20 nm rms; 1/f (0.1 Hz-1 kHz) 1-10 nm rms; mains hum 50 or 60 Hz in half the cases, 5-30 nm with 0-50 % third harmonic |
//!
//! Nuisances (background mode, amplifier lag, 1/f noise, hum, quantisation, offset) are
//! never causes.
//!
//! # The causes (names as `piezo diagnose` reports them)
//!
//! | cause | physics | size drawn |
//! |---|---|---|
//! | `dynamics` | a low structural mode replaces the background one | 50-800 Hz (log-uniform), zeta 0.02-0.2 |
//! | `asymmetry` | the CBW's centre line bows (quadratic in the input, 0 at both ends of the range) | bow +-(1.5-4) % of the stroke at mid-range |
//! | `creep` | logarithmic creep: one first-order element per decade at 0.02, 0.2, 2, 20 s driven by the displacement | 1-3 % of the displacement per decade |
//! | `delay` | sensor delay, fractional | 1-6 sample periods |
//! | `saturation` | the amplifier's upper rail | 75-92 % of the lower of the two records' peak commands |
//! | `slew-limit` | the amplifier's slew rate | 30-70 % of the lower of the two records' 95th-percentile command rates |
//! | `cross-coupling` | two axes; each axis' displacement gains a share of the other's (before creep and structure) | +-(3-10) % each way |
//! | `drift` | warm-up drift `lin t + amp (1 - exp(-t/tau))`, same physics in both records (sizes within +-20 %) | 1-4 % of the stroke over the training record, `tau` 0.2-1x its length, either sign |
//! | `backlash` | a play between actuator and structure | 1-4 % of the stroke wide |
//! | `startup-creep` | the first motion after rest falls short: displacement times `1 - depth exp(-travel/travel_v)`, `travel` the amplifier output's path since the start | depth 5-15 %, `travel_v` 0.3-1.5 `u_max` |
//! | `rate-dependence` | CBW `a` times `1 + widen rho` and the response to the input's excursion about its 20-100 ms mean reduced by `gain_drop rho`, `rho = r/(r + r_half)`, `r` the input rate low-passed over 2-10 ms | widen 20-50 %, gain drop 3-10 %, `r_half` 0.3-1x the drive's median rate |
//! | `sensor-nonlinearity` | capacitive-gauge bow: the reading gains the chord-free part of `e/(1 - kappa e)`, `e` the position over the sensor range | `kappa` +-(0.1-0.4), peak +-(0.5-2) % of the stroke |
//! | `amplitude-dynamics` | a low mode whose stiffness softens and damping grows with the deflection `e`: `1 - soften rho`, `1 + damp_up rho`, `rho = e^2/(e^2 + half^2)` | 60-400 Hz, zeta 0.02-0.1, soften 0.2-0.5, damp_up 0.5-2, `half` 0.3-1x the linear mode's 95th-percentile deflection |
//!
//! `dynamics` and `amplitude-dynamics` are never drawn together (the latter is the
//! former's upgrade). A case has 0-3 causes (equally likely), drawn without repetition.
//! Two-axis cases: every `cross-coupling` case and a fifth of the others (then each cause
//! acts on both axes, sizes drawn per axis).
//!
//! # Excitations
//!
//! Sines (0.5-100 Hz), sines whose amplitude decays or grows exponentially (1-60 Hz),
//! triangles (0.5-40 Hz), band-limited noise (2-100 Hz) and multisines (4-10 lines between
//! 0.5 and 100 Hz), each from rest at 0 V with a 0.25 s fade-in. The training and validation
//! records of an axis use two different kinds.
//!
//! # Clearly present
//!
//! Each drawn cause must change the noise-free reading, after removing the best
//! offset-plus-gain of the input (what the base model absorbs), by an RMS of at least
//! `max(6 sigma, 0.2 % of the reading's span)` on both records (`sigma` the white, 1/f
//! and quantisation noise together). A case whose causes miss it is drawn again (sizes,
//! plant and excitation; the causes stay); after [`ATTEMPTS`] the best draw is kept and
//! flagged (`presence_ok: false`).
pub mod excitation;
pub mod plant;

use serde::Serialize;

use crate::numeric::Rng;
use crate::record::Record;
pub use excitation::Excitation;
pub use plant::{Axis, Mode, Plant};
use plant::{Drift, Hum, RateDep, SensorNl, Startup};

/// Draws of a case before the best one is kept unchecked.
pub const ATTEMPTS: usize = 12;

/// Largest record (samples per channel).
pub const MAX_SAMPLES: usize = 100_000;

/// The catalogue's causes, by the names `piezo diagnose` reports.
pub const CAUSES: [&str; 13] = [
    "dynamics",
    "asymmetry",
    "creep",
    "delay",
    "saturation",
    "slew-limit",
    "cross-coupling",
    "drift",
    "backlash",
    "startup-creep",
    "rate-dependence",
    "sensor-nonlinearity",
    "amplitude-dynamics",
];

/// One drawn case: the plant, the two records and the truth.
#[derive(Clone, Debug, Serialize)]
pub struct Case {
    pub index: usize,
    pub seed: u64,
    /// The hidden causes, names from [`CAUSES`], sorted.
    pub causes: Vec<&'static str>,
    pub fs_hz: f64,
    pub plant: Plant,
    /// Per axis.
    pub train_excitation: Vec<Excitation>,
    pub valid_excitation: Vec<Excitation>,
    /// Per cause: the smallest ratio of its effect to the presence threshold over the
    /// records and axes (>= 1: clearly present).
    pub presence: Vec<(&'static str, f64)>,
    pub presence_ok: bool,
    pub attempts: usize,
    #[serde(skip)]
    pub train: Record,
    #[serde(skip)]
    pub valid: Record,
}

/// The seed of case `index` in the table of seed `seed` (cases do not depend on each other).
pub fn case_seed(seed: u64, index: usize) -> u64 {
    let mut r = Rng::new(seed ^ (index as u64).wrapping_mul(0xA24B_AED4_963E_E407));
    r.next_u64()
}

/// Case `index` of the table drawn from `seed`.
pub fn draw_case(seed: u64, index: usize) -> Case {
    draw_case_capped(seed, index, MAX_SAMPLES)
}

/// [`draw_case`] with records cut to `max_samples` (the same draws otherwise; for quick
/// tests).
pub fn draw_case_capped(seed: u64, index: usize, max_samples: usize) -> Case {
    let cs = case_seed(seed, index);
    let mut rng = Rng::new(cs);
    let causes = draw_causes(&mut rng);
    let two_axes = causes.contains(&"cross-coupling") || rng.uniform() < 0.2;
    let mut best: Option<Case> = None;
    for attempt in 1..=ATTEMPTS {
        let case = draw_once(&mut rng, index, cs, &causes, two_axes, attempt, max_samples);
        let worst = case
            .presence
            .iter()
            .map(|p| p.1)
            .fold(f64::INFINITY, f64::min);
        if case.presence_ok {
            return case;
        }
        let better = best
            .as_ref()
            .is_none_or(|b| worst > b.presence.iter().map(|p| p.1).fold(f64::INFINITY, f64::min));
        if better {
            best = Some(case);
        }
    }
    best.expect("at least one attempt")
}

fn draw_causes(rng: &mut Rng) -> Vec<&'static str> {
    let k = rng.below(4);
    let mut out: Vec<&'static str> = Vec::new();
    while out.len() < k {
        let c = CAUSES[rng.below(CAUSES.len())];
        let clash = (c == "dynamics" && out.contains(&"amplitude-dynamics"))
            || (c == "amplitude-dynamics" && out.contains(&"dynamics"));
        if !out.contains(&c) && !clash {
            out.push(c);
        }
    }
    out.sort();
    out
}

/// Record length drawn for `fs`.
fn draw_len(rng: &mut Rng, fs: f64, max_samples: usize) -> usize {
    let t = rng.log_uniform(5.0, 40.0);
    ((t * fs) as usize).min(MAX_SAMPLES).min(max_samples)
}

/// A clean axis (no cause) for the given drives.
fn draw_axis(rng: &mut Rng, u_max: f64, fs: f64, top_hz: f64) -> Axis {
    let d = rng.range(0.3, 1.5);
    let hysteresis = rng.range(0.05, 0.25);
    let (b, g, a, stroke) = loop {
        let k = rng.log_uniform(2.0, 10.0) / u_max;
        let share = rng.range(0.55, 0.9);
        let (b, g) = (share * k, (1.0 - share) * k);
        let (w1, top1) = plant::cbw_unit_loop(b, g, u_max);
        // width(a) = a w1, stroke(a) = d u_max - a top1; solve width = H stroke.
        let a = hysteresis * d * u_max / (w1 + hysteresis * top1);
        if a <= 0.85 * d {
            break (b, g, a, d * u_max - a * top1);
        }
    };
    let f_lo = (8.0 * top_hz).clamp(300.0, 4000.0);
    let fast = Mode::linear(rng.log_uniform(f_lo, 5000.0), rng.range(0.3, 0.7));
    let ts = 1.0 / fs;
    Axis {
        u_max_v: u_max,
        d_um_per_v: d,
        a,
        b_per_v: b,
        g_per_v: g,
        hysteresis,
        stroke_um: stroke,
        mode: fast,
        fast,
        bow_um: 0.0,
        creep_per_decade: 0.0,
        delay_s: 0.0,
        rail_v: None,
        slew_v_per_s: None,
        drift: None,
        play_um: 0.0,
        startup: None,
        rate: None,
        sensor_nl: None,
        tau_amp_s: rng.range(0.10, 0.25) * ts,
        offset_um: rng.range(-10.0, 10.0),
        sensor_lo_um: -0.1 * stroke,
        sensor_hi_um: 1.1 * stroke,
        bits: 14 + rng.below(5) as u32,
        white_um: rng.log_uniform(0.002, 0.02),
        pink_um: rng.log_uniform(0.001, 0.01),
        hum: (rng.uniform() < 0.5).then(|| Hum {
            f_hz: if rng.uniform() < 0.5 { 50.0 } else { 60.0 },
            amp_um: rng.range(0.005, 0.03),
            third: rng.range(0.0, 0.5),
            phase: rng.range(0.0, std::f64::consts::TAU),
        }),
    }
}

/// 95th percentile of `|x|`.
fn p95_abs(x: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = x.map(f64::abs).collect();
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() as f64 * 0.95) as usize).min(v.len() - 1);
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

fn rates(cmd: &[f64], fs: f64) -> impl Iterator<Item = f64> + '_ {
    cmd.windows(2).map(move |w| (w[1] - w[0]) * fs)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Switches `cause` on for axis `i` with a drawn size. `cmds`: the axis' training and
/// validation commands. Needs the plant for `amplitude-dynamics` (its deflection scale).
fn apply(
    rng: &mut Rng,
    plant: &mut Plant,
    i: usize,
    cause: &str,
    cmds: [&[f64]; 2],
    fs: f64,
    train_s: f64,
) {
    if cause == "cross-coupling" {
        plant.coupling[i] = rng.sign() * rng.range(0.03, 0.10);
        return;
    }
    if cause == "amplitude-dynamics" {
        let mode = Mode::linear(rng.log_uniform(60.0, 400.0), rng.range(0.02, 0.1));
        plant.axes[i].mode = mode;
        // The linear mode's deflection on the training drive sets the scale.
        let lin = plant.simulate_deflection(i, cmds[0], fs);
        plant.axes[i].mode = Mode {
            soften: rng.range(0.2, 0.5),
            damp_up: rng.range(0.5, 2.0),
            half_um: rng.range(0.3, 1.0) * lin.max(1e-3),
            ..mode
        };
        return;
    }
    let ax = &mut plant.axes[i];
    let stroke = ax.stroke_um;
    match cause {
        "dynamics" => ax.mode = Mode::linear(rng.log_uniform(50.0, 800.0), rng.range(0.02, 0.2)),
        "asymmetry" => ax.bow_um = rng.sign() * rng.range(0.015, 0.04) * stroke,
        "creep" => ax.creep_per_decade = rng.range(0.01, 0.03),
        "delay" => ax.delay_s = rng.log_uniform(1.0, 6.0) / fs,
        "saturation" => {
            let peak = cmds.iter().map(|c| c.iter().fold(0.0f64, |a, &b| a.max(b)));
            let low = peak.fold(f64::INFINITY, f64::min);
            ax.rail_v = Some(rng.range(0.75, 0.92) * low);
        }
        "slew-limit" => {
            let r = cmds
                .iter()
                .map(|c| p95_abs(rates(c, fs)))
                .fold(f64::INFINITY, f64::min);
            ax.slew_v_per_s = Some(rng.range(0.3, 0.7) * r);
        }
        "drift" => {
            let total = rng.sign() * rng.range(0.01, 0.04) * stroke;
            let lin = rng.uniform();
            let tau = rng.range(0.2, 1.0) * train_s;
            let exp_norm = 1.0 - (-train_s / tau).exp();
            ax.drift = Some(Drift {
                lin_um_per_s: lin * total / train_s,
                amp_um: (1.0 - lin) * total / exp_norm,
                tau_s: tau,
            });
        }
        "backlash" => ax.play_um = rng.range(0.01, 0.04) * stroke,
        "startup-creep" => {
            ax.startup = Some(Startup {
                depth: rng.range(0.05, 0.15),
                travel_v: rng.range(0.3, 1.5) * ax.u_max_v,
            })
        }
        "rate-dependence" => {
            let med = median(
                cmds.iter()
                    .map(|c| median(rates(c, fs).map(f64::abs).collect()))
                    .collect(),
            );
            ax.rate = Some(RateDep {
                widen: rng.range(0.2, 0.5),
                gain_drop: rng.range(0.03, 0.1),
                r_half_v_per_s: rng.range(0.3, 1.0) * med.max(1.0),
                tau_r_s: rng.range(0.002, 0.01),
                tau_u_s: rng.range(0.02, 0.1),
            });
        }
        "sensor-nonlinearity" => {
            ax.sensor_nl = Some(SensorNl {
                kappa: rng.sign() * rng.range(0.1, 0.4),
                bow_um: rng.sign() * rng.range(0.005, 0.02) * stroke,
            })
        }
        other => unreachable!("unknown cause {other}"),
    }
}

impl Plant {
    /// The 95th percentile of the structure's deflection on axis `i` for drive `cmd`
    /// (noise-free, single-axis run of that axis, against the same axis with its
    /// background mode).
    fn simulate_deflection(&self, i: usize, cmd: &[f64], fs: f64) -> f64 {
        let mut ax = self.axes[i].clone();
        // Against the background mode (as good as static below it, and stable at the
        // integration's step).
        let static_ax = Axis {
            mode: ax.fast,
            ..ax.clone()
        };
        ax.delay_s = 0.0;
        let one = |a: Axis| {
            Plant {
                axes: vec![a],
                coupling: [0.0; 2],
            }
            .simulate(&[cmd.to_vec()], fs)
            .remove(0)
        };
        let (y, y0) = (one(ax), one(static_ax));
        p95_abs(y.iter().zip(&y0).map(|(a, b)| a - b))
    }

    /// A copy with `cause` switched off (for `amplitude-dynamics`: its mode made linear,
    /// so the check asks for the amplitude dependence itself).
    pub fn without(&self, cause: &str) -> Plant {
        let mut p = self.clone();
        for ax in p.axes.iter_mut() {
            match cause {
                // (a mode with amplitude dependence is `amplitude-dynamics`' own)
                "dynamics" if ax.mode.soften == 0.0 && ax.mode.damp_up == 0.0 => ax.mode = ax.fast,
                "asymmetry" => ax.bow_um = 0.0,
                "creep" => ax.creep_per_decade = 0.0,
                "delay" => ax.delay_s = 0.0,
                "saturation" => ax.rail_v = None,
                "slew-limit" => ax.slew_v_per_s = None,
                "drift" => ax.drift = None,
                "backlash" => ax.play_um = 0.0,
                "startup-creep" => ax.startup = None,
                "rate-dependence" => ax.rate = None,
                "sensor-nonlinearity" => ax.sensor_nl = None,
                "amplitude-dynamics" => ax.mode = Mode::linear(ax.mode.f_hz, ax.mode.zeta),
                _ => {}
            }
        }
        if cause == "cross-coupling" {
            p.coupling = [0.0; 2];
        }
        p
    }
}

/// RMS of `d` after removing its least-squares fit on `[1, u]`.
fn rms_beyond_gain(d: &[f64], u: &[f64]) -> f64 {
    let n = d.len() as f64;
    let (mu, md) = (u.iter().sum::<f64>() / n, d.iter().sum::<f64>() / n);
    let (mut suu, mut sud) = (0.0, 0.0);
    for (a, b) in u.iter().zip(d) {
        suu += (a - mu) * (a - mu);
        sud += (a - mu) * (b - md);
    }
    let k = if suu > 0.0 { sud / suu } else { 0.0 };
    let ss: f64 = u
        .iter()
        .zip(d)
        .map(|(a, b)| {
            let r = b - md - k * (a - mu);
            r * r
        })
        .sum();
    (ss / n).sqrt()
}

fn draw_once(
    rng: &mut Rng,
    index: usize,
    seed: u64,
    causes: &[&'static str],
    two_axes: bool,
    attempts: usize,
    max_samples: usize,
) -> Case {
    let na = if two_axes { 2 } else { 1 };
    let fs = [2000.0, 5000.0, 10_000.0, 20_000.0][rng.below(4)];
    let u_max = if rng.uniform() < 0.5 { 100.0 } else { 150.0 };
    let (n_train, n_valid) = (
        draw_len(rng, fs, max_samples),
        draw_len(rng, fs, max_samples),
    );
    let mut train_ex = Vec::new();
    let mut valid_ex = Vec::new();
    for _ in 0..na {
        let kt = rng.below(excitation::KINDS);
        let kv = (kt + 1 + rng.below(excitation::KINDS - 1)) % excitation::KINDS;
        train_ex.push(Excitation::draw(kt, rng));
        valid_ex.push(Excitation::draw(kv, rng));
    }
    let tc: Vec<Vec<f64>> = train_ex
        .iter()
        .map(|e| e.command(fs, n_train, u_max))
        .collect();
    let vc: Vec<Vec<f64>> = valid_ex
        .iter()
        .map(|e| e.command(fs, n_valid, u_max))
        .collect();
    let axes = (0..na)
        .map(|i| {
            let top = train_ex[i].top_hz().max(valid_ex[i].top_hz());
            draw_axis(rng, u_max, fs, top)
        })
        .collect();
    let mut plant = Plant {
        axes,
        coupling: [0.0; 2],
    };
    let train_s = n_train as f64 / fs;
    for c in causes {
        for i in 0..na {
            apply(rng, &mut plant, i, c, [&tc[i], &vc[i]], fs, train_s);
        }
    }
    // Drift is one process: the validation record's sizes within +-20 % of the training's.
    let valid_plant = {
        let mut p = plant.clone();
        for ax in p.axes.iter_mut() {
            if let Some(d) = ax.drift.as_mut() {
                d.lin_um_per_s *= rng.range(0.8, 1.2);
                d.amp_um *= rng.range(0.8, 1.2);
            }
        }
        p
    };
    let noise_seeds = (rng.next_u64(), rng.next_u64());
    let clean_t = plant.simulate(&tc, fs);
    let clean_v = valid_plant.simulate(&vc, fs);
    let mut presence = Vec::new();
    for c in causes {
        let mut worst = f64::INFINITY;
        for (p, cmd, clean) in [(&plant, &tc, &clean_t), (&valid_plant, &vc, &clean_v)] {
            let off = p.without(c).simulate(cmd, fs);
            // Cross-coupling shows on either axis; the others on every axis.
            let ratios = (0..na).map(|i| {
                let ax = &p.axes[i];
                let lsb = (ax.sensor_hi_um - ax.sensor_lo_um) / (1u64 << ax.bits) as f64;
                let sigma = (ax.white_um.powi(2) + ax.pink_um.powi(2) + lsb * lsb / 12.0).sqrt();
                let (lo, hi) = clean[i]
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
                let thr = (6.0 * sigma).max(0.002 * (hi - lo));
                let d: Vec<f64> = clean[i].iter().zip(&off[i]).map(|(a, b)| a - b).collect();
                rms_beyond_gain(&d, &cmd[i]) / thr
            });
            let r = if *c == "cross-coupling" {
                ratios.fold(0.0, f64::max)
            } else {
                ratios.fold(f64::INFINITY, f64::min)
            };
            worst = worst.min(r);
        }
        presence.push((*c, worst));
    }
    let presence_ok = presence.iter().all(|p| p.1 >= 1.0);
    let record = |p: &Plant, cmd: &[Vec<f64>], clean: &[Vec<f64>], ns: u64, what: &str| {
        let y = p.add_noise(clean, fs, ns);
        let n = cmd[0].len();
        let t = (0..n).map(|k| k as f64 / fs).collect();
        let mut r = Record::new(t, cmd.to_vec(), y).expect("generated records are well-formed");
        r.comments = vec![format!(
            " independent generator, case {index} (seed {seed}), {what} record; the truth is in answer.json"
        )];
        r
    };
    Case {
        index,
        seed,
        causes: causes.to_vec(),
        fs_hz: fs,
        train: record(&plant, &tc, &clean_t, noise_seeds.0, "training"),
        valid: record(&valid_plant, &vc, &clean_v, noise_seeds.1, "validation"),
        plant,
        train_excitation: train_ex,
        valid_excitation: valid_ex,
        presence,
        presence_ok,
        attempts,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cases_are_reproducible_and_independent_of_each_other() {
        let a = draw_case_capped(3, 5, 3000);
        let b = draw_case_capped(3, 5, 3000);
        assert_eq!(a.causes, b.causes);
        assert_eq!(a.train, b.train);
        assert_eq!(a.valid, b.valid);
        assert_ne!(draw_case_capped(3, 6, 3000).train, a.train);
        // Training and validation drives differ in kind.
        for (t, v) in a.train_excitation.iter().zip(&a.valid_excitation) {
            let kind = |e: &Excitation| serde_json::to_value(e).unwrap()["kind"].clone();
            assert!(kind(t) != kind(v) || matches!(t, Excitation::SweptAmplitude { .. }));
        }
    }

    #[test]
    fn cause_counts_cover_zero_to_three_and_never_both_dynamics() {
        let mut counts = [0; 4];
        for i in 0..400 {
            let mut rng = Rng::new(case_seed(1, i));
            let c = draw_causes(&mut rng);
            counts[c.len()] += 1;
            assert!(!(c.contains(&"dynamics") && c.contains(&"amplitude-dynamics")));
        }
        assert!(counts.iter().all(|&n| n > 70), "{counts:?}");
    }

    /// The presence measure: what an offset and a gain of the input explain is not an effect.
    #[test]
    fn presence_measure_ignores_offset_and_gain() {
        let d: Vec<f64> = vec![0.0; 100];
        let u: Vec<f64> = (0..100).map(|k| k as f64).collect();
        assert_eq!(rms_beyond_gain(&d, &u), 0.0);
        let lin: Vec<f64> = u.iter().map(|x| 3.0 + 0.5 * x).collect();
        assert!(rms_beyond_gain(&lin, &u) < 1e-9);
        let sq: Vec<f64> = u.iter().map(|x| x * x).collect();
        assert!(rms_beyond_gain(&sq, &u) > 100.0);
    }

    /// A cause switched off leaves the reading as it was.
    #[test]
    fn without_a_cause_its_effect_is_gone() {
        let case = draw_case_capped(2, 1, 3000);
        let cmd = &case.train.u;
        let base = case.plant.simulate(cmd, case.fs_hz);
        for c in CAUSES {
            let off = case.plant.without(c).simulate(cmd, case.fs_hz);
            let same = off == base;
            assert_eq!(same, !case.causes.contains(&c), "{c} in {:?}", case.causes);
        }
    }
}
