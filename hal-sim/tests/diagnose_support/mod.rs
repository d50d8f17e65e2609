//! Records with a hidden cause: a seeded generator draws the cause's size, writes a training
//! and a validation record with different excitations, and the tests check that
//! `diagnose` names the cause and gains on the validation record.
#![allow(dead_code)]

use hal_sim::ident::diagnose::model::{dynamics, effective_input, hysteresis, Shape};
use hal_sim::ident::diagnose::{Cause, Signals};
use hal_sim::numeric::lowpass;

/// The generator's seeded RNG (SplitMix64).
pub use hal_sim::numeric::Rng;

pub const RATE_HZ: f64 = 2000.0;
pub const DURATION_S: f64 = 2.0;

/// A plant: CBW plus the hidden effects, with sizes drawn from the seed.
#[derive(Debug, Clone)]
pub struct Plant {
    pub d: f64,
    pub alpha: f64,
    pub beta: f64,
    pub gamma: f64,
    pub effects: Vec<Cause>,
    pub wn_hz: f64,
    pub zeta: f64,
    pub asym: f64,
    pub creep_gain: f64,
    pub creep_tau_s: f64,
    pub delay_s: f64,
    pub rail_frac: f64,
    pub slew_frac: f64,
    pub coupling: f64,
    pub drift_per_s: f64,
    pub noise: f64,
    pub axes: usize,
}

impl Plant {
    pub fn draw(seed: u64, effects: &[Cause]) -> Self {
        let mut r = Rng::new(seed.wrapping_mul(7919).wrapping_add(13));
        let axes = if effects.contains(&Cause::CrossCoupling) {
            2
        } else {
            1
        };
        let d = r.range(0.12, 0.2);
        // u spans about 100 V: y about d*100 = 12..20 um.
        Self {
            d,
            alpha: d * r.range(0.3, 0.5),
            beta: r.range(0.015, 0.04),
            gamma: r.range(-0.005, 0.012),
            effects: effects.to_vec(),
            wn_hz: r.range(25.0, 80.0),
            zeta: r.range(0.3, 0.8),
            asym: r.range(0.4, 1.0) * r.range(-1.0, 1.0).signum(),
            creep_gain: r.range(0.06, 0.15),
            creep_tau_s: r.range(0.08, 0.6),
            delay_s: r.range(2e-3, 8e-3),
            rail_frac: r.range(0.64, 0.72),
            slew_frac: r.range(0.2, 0.4),
            coupling: r.range(0.05, 0.12) * r.range(-1.0, 1.0).signum(),
            drift_per_s: r.range(0.4, 0.8) * r.range(-1.0, 1.0).signum(),
            noise: r.range(0.01, 0.03),
            axes,
        }
    }

    fn has(&self, c: Cause) -> bool {
        self.effects.contains(&c)
    }

    /// Output of axis `i` for inputs `u` (all axes).
    fn respond(&self, t: &[f64], u: &[Vec<f64>], i: usize, dt: f64, rng: &mut Rng) -> Vec<f64> {
        let shape = Shape {
            beta: self.beta,
            gamma: self.gamma,
            delay_s: if self.has(Cause::Delay) {
                self.delay_s
            } else {
                0.0
            },
            rail_lo_v: f64::NEG_INFINITY,
            rail_hi_v: if self.has(Cause::Saturation) {
                100.0 * self.rail_frac
            } else {
                f64::INFINITY
            },
            // the slew limit is a property of the amplifier, fixed in V/s
            slew_v_per_s: if self.has(Cause::SlewLimit) {
                self.slew_frac * 4000.0
            } else {
                f64::INFINITY
            },
            wn_hz: f64::INFINITY,
            zeta: 1.0,
            play_um: 0.0,
            startup_travel_v: f64::INFINITY,
            rate_ref_v_per_s: f64::INFINITY,
            amp_level_um: 1.0,
            amp_freq_shift: 0.0,
            amp_zeta_scale: 0.0,
        };
        let v = effective_input(&u[i], dt, &shape);
        let g = hysteresis(&v, self.beta, self.gamma);
        let mut y: Vec<f64> = v
            .iter()
            .zip(&g)
            .map(|(v, g)| self.d * v - self.alpha * g)
            .collect();
        if self.has(Cause::Asymmetry) {
            for (y, v) in y.iter_mut().zip(&v) {
                let w = (v - 50.0) / 50.0;
                *y += self.asym * w * w;
            }
        }
        if self.has(Cause::Creep) {
            let c = lowpass(&v, self.creep_tau_s, dt);
            for (y, c) in y.iter_mut().zip(&c) {
                *y += self.creep_gain * self.d * c;
            }
        }
        if self.has(Cause::CrossCoupling) {
            let j = 1 - i;
            for (y, uj) in y.iter_mut().zip(&u[j]) {
                *y += self.coupling * self.d * uj;
            }
        }
        if self.has(Cause::Dynamics) {
            dynamics(&mut y, self.wn_hz, self.zeta, dt);
        }
        if self.has(Cause::Drift) {
            for (y, t) in y.iter_mut().zip(t) {
                *y += self.drift_per_s * t;
            }
        }
        for y in y.iter_mut() {
            *y += self.noise * rng.normal(1.0) + 1.0;
        }
        y
    }

    /// A record under excitation number `which` (train 0, valid 1, ...).
    pub fn record(&self, seed: u64, which: u64) -> Signals {
        self.record_at(seed, which, RATE_HZ, DURATION_S)
    }

    /// A record at another rate and length.
    pub fn record_at(&self, seed: u64, which: u64, rate_hz: f64, duration_s: f64) -> Signals {
        let mut r = Rng::new(seed.wrapping_mul(104_729).wrapping_add(which * 31 + 1));
        let n = (rate_hz * duration_s) as usize;
        let dt = 1.0 / rate_hz;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let u: Vec<Vec<f64>> = (0..self.axes).map(|_| excitation(&t, &mut r)).collect();
        let y = (0..self.axes)
            .map(|i| self.respond(&t, &u, i, dt, &mut r))
            .collect();
        Signals::new(t, u, y).expect("generated record is valid")
    }
}

/// Two sines (0.7..6 Hz) plus held steps with 4 ms ramps, from rest at 0 V, within 0..100 V.
pub fn excitation(t: &[f64], r: &mut Rng) -> Vec<f64> {
    let tau = 2.0 * std::f64::consts::PI;
    let (f1, f2) = (r.range(0.7, 2.0), r.range(2.5, 6.0));
    let (p1, p2) = (r.range(0.0, tau), r.range(0.0, tau));
    let (a1, a2) = (r.range(20.0, 28.0), r.range(5.0, 10.0));
    // Held levels, each 0.15..0.4 s.
    let mut levels = Vec::new();
    let mut at = 0.0;
    while at < t.last().copied().unwrap_or(0.0) + 1.0 {
        levels.push((at, r.range(-12.0, 12.0)));
        at += r.range(0.15, 0.4);
    }
    let ramp = 4e-3;
    let step = |t: f64| {
        let mut v = 0.0;
        let mut prev = 0.0;
        for &(t0, l) in &levels {
            if t < t0 {
                break;
            }
            let f = ((t - t0) / ramp).min(1.0);
            v = prev + f * (l - prev);
            prev = l;
        }
        v
    };
    let fade = 0.2;
    t.iter()
        .map(|&t| {
            let w = (t / fade).min(1.0);
            (50.0 + w * (a1 * (tau * f1 * t + p1).sin() + a2 * (tau * f2 * t + p2).sin() + step(t)))
                .clamp(0.0, 100.0)
        })
        .collect()
}
