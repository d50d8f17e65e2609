//! Records with hidden causes, written by hal-sim's simulated actuator ([`crate::stage`]).
//!
//! [`Hidden::draw`] starts from a clean stage (CBW hysteresis with seeded parameters, sensor
//! noise, an ideal amplifier, no creep, resonance, drift, delay or coupling) and switches on
//! the stage effect of every requested cause, with a size drawn from the seed in a range a lab
//! would meet (`u` is the commanded piezo voltage, the stroke about 100 um):
//!
//! | cause | stage effect | size drawn |
//! |---|---|---|
//! | `dynamics` | structural resonance | 80-400 Hz (log-uniform), zeta 0.05-0.3 |
//! | `asymmetry` | static `asym * v^2` term | +-(1.5-4)e-4 um/V^2 (2-5 % of stroke at 110 V) |
//! | `creep` | 1-2 first-order creep elements | gain 1-3 % each, tau 50 ms-1 s (log-uniform) |
//! | `delay` | sensor delay | 1-6 samples |
//! | `saturation` | amplifier upper rail | 85-95 % of the lower of the two records' peak command |
//! | `slew-limit` | amplifier current limit into the piezo capacitance | `I/C` 1-3 kV/s |
//! | `cross-coupling` | 2 axes, displacement coupling | +-(2-6) % each way |
//! | `drift` | thermal drift (linear plus a slow exponential) | +-(1-4) % of the stroke over the record |
//! | `backlash` | a play between actuator and output ([`crate::scenario::Backlash`]) | width 0.8-2.5 um |
//! | `startup-creep` | start-up deficit after a long rest ([`crate::scenario::StartupCreep`]) | depth 4-10 %, travel 40-150 V |
//! | `rate-dependence` | rate-dependent hysteresis ([`crate::scenario::RateHysteresis`]) | loop 10-30 % wider, gain 3-10 % lower at high rates, half at 150-800 V/s, rate over 3-8 ms |
//! | `sensor-nonlinearity` | nonlinear sensor ([`crate::scenario::SensorNonlinearity`]) | `+-(0.5-1.5) % e^2 +-(0.3-1) % e^3` of a 50 um half range |
//! | `amplitude-dynamics` | resonance moving with the oscillation amplitude ([`crate::scenario::AmplitudeDynamics`]) | 60-200 Hz (log-uniform), zeta 0.03-0.1; at large amplitude the frequency 10-30 % lower and the damping 50-200 % higher, half at 0.2-1.0 um |
//!
//! Sensor noise is 5-20 nm RMS. [`Hidden::record`] drives the stage with a seeded
//! excitation, a different draw for each record (`which`: 0 train, 1 valid): two sines
//! (0.7-2 Hz and 2.5-6 Hz) plus held levels with 3-6 ms ramps, ramped in from rest at 0 V,
//! then records the command and the sensor reading, one sample per loop period.

use anyhow::Result;

use super::diagnose::{Cause, Signals};
use crate::numeric::Rng;
use crate::record::Record;
use crate::scenario::Scenario;
use crate::stage::Stage;

/// Record rate and length used by the tests.
pub const RATE_HZ: f64 = 2000.0;
pub const DURATION_S: f64 = 2.0;

/// Nominal stroke (um) the drift is scaled by.
const STROKE_UM: f64 = 100.0;

/// A stage with hidden causes and the excitation seeds of its records.
#[derive(Debug, Clone)]
pub struct Hidden {
    pub seed: u64,
    pub causes: Vec<Cause>,
    pub scenario: Scenario,
    /// The drawn sizes, one phrase per cause (`"delay 3.2 samples (1.60 ms)"`).
    pub sizes: Vec<String>,
    pub rate_hz: f64,
    pub duration_s: f64,
    /// A realistic sensor's imperfections on the reading (none by default).
    pub sensor: Option<SensorRealism>,
}

/// What a real position sensor adds to the reading besides white noise, none of it a cause of
/// the stage's behaviour: mains hum (the fundamental and its third harmonic), 1/f noise and
/// a coarse quantisation.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorRealism {
    /// Mains frequency (50 or 60 Hz).
    pub hum_hz: f64,
    /// Amplitude of the fundamental (um); the third harmonic has a third of it.
    pub hum_um: f64,
    /// RMS of the 1/f noise (um) between [`PINK_LO_HZ`] and [`PINK_HI_HZ`].
    pub pink_um: f64,
    /// Quantisation step of the reading (um).
    pub lsb_um: f64,
}

/// Band of the 1/f noise (Hz).
pub const PINK_LO_HZ: f64 = 0.05;
pub const PINK_HI_HZ: f64 = 500.0;

impl SensorRealism {
    /// Sizes drawn from `seed`: hum 10-30 nm at 50 or 60 Hz, 1/f noise 10-30 nm RMS, a step
    /// of 20-60 nm.
    pub fn draw(seed: u64) -> Self {
        let mut r = Rng::new(seed.wrapping_mul(0x9E37_79B9).wrapping_add(0x5E45));
        Self {
            hum_hz: if r.next_u64().is_multiple_of(2) {
                50.0
            } else {
                60.0
            },
            hum_um: r.range(0.01, 0.03),
            pink_um: r.range(0.01, 0.03),
            lsb_um: r.range(0.02, 0.06),
        }
    }

    /// The reading `y` (sampled at `rate_hz`) with hum, 1/f noise and quantisation; `r`
    /// draws the hum's phase and the noise.
    pub fn apply(&self, y: &mut [f64], rate_hz: f64, r: &mut Rng) {
        let dt = 1.0 / rate_hz;
        let tau = std::f64::consts::TAU;
        let (p1, p3) = (r.range(0.0, tau), r.range(0.0, tau));
        // 1/f: first-order low-passed white noises with equal variance and corners two per
        // decade (their Lorentzians sum to about 1/f between the corners).
        let mut corners = Vec::new();
        let mut f = PINK_LO_HZ;
        while f <= PINK_HI_HZ.min(0.25 * rate_hz) {
            corners.push(f);
            f *= 10f64.sqrt();
        }
        let each = self.pink_um / (corners.len().max(1) as f64).sqrt();
        let poles: Vec<(f64, f64)> = corners
            .iter()
            .map(|fc| {
                let a = (-tau * fc * dt).exp();
                // Stationary variance each^2: innovations of each*sqrt(1 - a^2).
                (a, each * (1.0 - a * a).sqrt())
            })
            .collect();
        let mut state: Vec<f64> = poles.iter().map(|_| each * r.normal(1.0)).collect();
        for (k, y) in y.iter_mut().enumerate() {
            let t = k as f64 * dt;
            let mut pink = 0.0;
            for (x, (a, b)) in state.iter_mut().zip(&poles) {
                *x = a * *x + b * r.normal(1.0);
                pink += *x;
            }
            let hum = self.hum_um
                * ((tau * self.hum_hz * t + p1).sin()
                    + (3.0 * tau * self.hum_hz * t + p3).sin() / 3.0);
            *y = ((*y + hum + pink) / self.lsb_um).round() * self.lsb_um;
        }
    }
}

impl Hidden {
    /// [`Hidden::draw_at`] at [`RATE_HZ`] for [`DURATION_S`].
    pub fn draw(seed: u64, causes: &[Cause]) -> Self {
        Self::draw_at(seed, causes, RATE_HZ, DURATION_S).expect("default rate and length")
    }

    /// Draws the base stage and the size of every cause in `causes` from `seed`.
    pub fn draw_at(seed: u64, causes: &[Cause], rate_hz: f64, duration_s: f64) -> Result<Self> {
        anyhow::ensure!(
            rate_hz.is_finite() && (200.0..=100_000.0).contains(&rate_hz),
            "rate must be within 200 Hz..100 kHz, got {rate_hz}"
        );
        anyhow::ensure!(
            duration_s.is_finite() && (0.5..=600.0).contains(&duration_s),
            "duration must be within 0.5..600 s, got {duration_s}"
        );
        let mut r = Rng::new(seed.wrapping_mul(0x2545_F491).wrapping_add(0xD1A6));
        let mut s = Scenario {
            name: format!("hidden-{seed}"),
            ..Default::default()
        };
        s.run.loop_hz = rate_hz;
        // Fine internal steps: the stage's structure sees its input averaged over one step,
        // a lag of half a step that a fitted delay would pick up.
        s.run.substeps = 32;
        s.run.duration_s = duration_s;
        let has = |c: Cause| causes.contains(&c);
        let st = &mut s.stage;
        st.axes = if has(Cause::CrossCoupling) { 2 } else { 1 };
        st.zero_um = 0.0;
        let h = &mut st.hysteresis;
        h.d = r.range(0.85, 1.0);
        h.alpha = 0.3 * r.range(0.8, 1.2);
        h.beta = 0.012 * r.range(0.8, 1.2);
        h.gamma = 0.004 * r.range(0.5, 1.5);
        h.asym_um_per_v2 = 0.0;
        // An ideal amplifier (its 1.6 us lag is below the noise at these rates).
        st.amplifier.bandwidth_hz = 1e5;
        st.amplifier.current_limit_a = 10.0;
        st.amplifier.rail_min_volts = -20.0;
        st.amplifier.rail_max_volts = 200.0;
        st.creep.enabled = false;
        st.resonance.enabled = false;
        st.drift.enabled = false;
        st.delay.enabled = false;
        st.coupling.enabled = false;
        st.force.enabled = false;
        st.noise.enabled = true;
        st.noise.sigma_um = r.range(0.005, 0.02);
        let mut sizes = Vec::new();
        // Every size is drawn whether used or not, so a cause's size does not depend on the
        // other causes of the case.
        let wn_hz = r.log_uniform(80.0, 400.0);
        let zeta = r.range(0.05, 0.3);
        let asym = r.range(1.5e-4, 4e-4) * r.sign();
        let n_creep = 1 + (r.next_u64() % 2) as usize;
        let creep: Vec<(f64, f64)> = (0..2)
            .map(|_| (r.range(0.01, 0.03), r.log_uniform(0.05, 1.0)))
            .collect();
        let delay_samples = r.range(1.0, 6.0);
        let rail_frac = r.range(0.85, 0.95);
        let slew = r.range(1000.0, 3000.0);
        let coupling = [
            r.range(0.02, 0.06) * r.sign(),
            r.range(0.02, 0.06) * r.sign(),
        ];
        let drift_um = r.range(0.01, 0.04) * STROKE_UM * r.sign();
        let drift_exp = r.range(0.0, 0.6);
        let drift_tau = r.range(2.0, 6.0) * duration_s;
        let play_um = r.range(0.8, 2.5);
        let startup_depth = r.range(0.04, 0.1);
        let startup_travel = r.log_uniform(40.0, 150.0);
        let rate_widen = r.range(0.1, 0.3);
        let rate_drop = r.range(0.03, 0.1);
        let rate_ref = r.log_uniform(150.0, 800.0);
        let rate_tau = r.range(3e-3, 8e-3);
        let sensor_q = r.range(0.005, 0.015) * r.sign();
        let sensor_c = r.range(0.003, 0.01) * r.sign();
        // A lightly damped mode that softens and damps with the drive level, as the fine
        // steering mirror's (drawn after the others: their sizes stay as they were).
        let amp_wn_hz = r.log_uniform(60.0, 200.0);
        let amp_zeta = r.range(0.03, 0.1);
        let amp_level = r.range(0.2, 1.0);
        let amp_shift = -r.range(0.1, 0.3);
        let amp_zeta_scale = r.range(0.5, 2.0);
        let mut hidden = Self {
            seed,
            causes: causes.to_vec(),
            scenario: s,
            sizes: Vec::new(),
            rate_hz,
            duration_s,
            sensor: None,
        };
        let st = &mut hidden.scenario.stage;
        for &c in causes {
            match c {
                Cause::Dynamics => {
                    st.resonance.enabled = true;
                    st.resonance.freq_hz = wn_hz;
                    st.resonance.zeta = zeta;
                    sizes.push(format!("resonance {wn_hz:.0} Hz, zeta {zeta:.2}"));
                }
                Cause::Asymmetry => {
                    st.hysteresis.asym_um_per_v2 = asym;
                    sizes.push(format!("asymmetric term {asym:.2e} um/V^2"));
                }
                Cause::Creep => {
                    st.creep.enabled = true;
                    st.creep.gains = creep[..n_creep].iter().map(|c| c.0).collect();
                    st.creep.taus_s = creep[..n_creep].iter().map(|c| c.1).collect();
                    sizes.push(format!(
                        "creep gains {:?}, taus {:?} s",
                        st.creep.gains, st.creep.taus_s
                    ));
                }
                Cause::Delay => {
                    st.delay.enabled = true;
                    st.delay.seconds = delay_samples / rate_hz;
                    sizes.push(format!(
                        "delay {delay_samples:.1} samples ({:.2} ms)",
                        1e3 * st.delay.seconds
                    ));
                }
                Cause::Saturation => {}
                Cause::SlewLimit => {
                    st.amplifier.current_limit_a = slew * st.amplifier.capacitance_f;
                    sizes.push(format!("slew limit {slew:.0} V/s"));
                }
                Cause::CrossCoupling => {
                    st.coupling.enabled = true;
                    st.coupling.matrix = vec![vec![0.0, coupling[0]], vec![coupling[1], 0.0]];
                    sizes.push(format!(
                        "coupling {:+.3} (y1 <- y2), {:+.3} (y2 <- y1)",
                        coupling[0], coupling[1]
                    ));
                }
                Cause::Backlash => {
                    st.backlash.enabled = true;
                    st.backlash.width_um = play_um;
                    sizes.push(format!("play {play_um:.2} um"));
                }
                Cause::StartupCreep => {
                    st.startup_creep.enabled = true;
                    st.startup_creep.depth = startup_depth;
                    st.startup_creep.travel_v = startup_travel;
                    st.startup_creep.rest_tau_s = 60.0;
                    sizes.push(format!(
                        "start-up deficit {:.1} % decaying over {startup_travel:.0} V of travel",
                        100.0 * startup_depth
                    ));
                }
                Cause::RateDependence => {
                    let rh = &mut st.rate_hysteresis;
                    rh.enabled = true;
                    rh.widen = rate_widen;
                    rh.gain_drop = rate_drop;
                    rh.rate_ref_v_per_s = rate_ref;
                    rh.tau_s = rate_tau;
                    sizes.push(format!(
                        "rate dependence: loop {:.0} % wider and gain {:.1} % lower at high rates, half at {rate_ref:.0} V/s (tau {:.1} ms)",
                        100.0 * rate_widen,
                        100.0 * rate_drop,
                        1e3 * rate_tau
                    ));
                }
                Cause::SensorNonlinearity => {
                    let sn = &mut st.sensor_nonlinearity;
                    sn.enabled = true;
                    sn.center_um = 0.5 * STROKE_UM;
                    sn.half_range_um = 0.5 * STROKE_UM;
                    sn.quadratic = sensor_q;
                    sn.cubic = sensor_c;
                    sizes.push(format!(
                        "sensor error {:+.2} % e^2 {:+.2} % e^3 of the {:.0} um half range",
                        100.0 * sensor_q,
                        100.0 * sensor_c,
                        0.5 * STROKE_UM
                    ));
                }
                Cause::AmplitudeDynamics => {
                    st.resonance.enabled = true;
                    st.resonance.freq_hz = amp_wn_hz;
                    st.resonance.zeta = amp_zeta;
                    let a = &mut st.amplitude_dynamics;
                    a.enabled = true;
                    a.level_um = amp_level;
                    a.freq_shift = amp_shift;
                    a.zeta_scale = amp_zeta_scale;
                    sizes.push(format!(
                        "resonance {amp_wn_hz:.0} Hz, zeta {amp_zeta:.3}, moving by {:+.0} % in frequency and {:+.0} % in damping at large amplitude, half at {amp_level:.2} um",
                        100.0 * amp_shift,
                        100.0 * amp_zeta_scale
                    ));
                }
                Cause::Drift => {
                    // Total drift over the record: a part from a slow exponential, the rest linear.
                    let tail = 1.0 - (-duration_s / drift_tau).exp();
                    st.drift.enabled = true;
                    st.drift.tau_s = drift_tau;
                    st.drift.um = drift_exp * drift_um / tail;
                    st.drift.rate_um_per_s = (1.0 - drift_exp) * drift_um / duration_s;
                    sizes.push(format!(
                        "drift {drift_um:+.2} um over the record ({:.0} % exponential, tau {drift_tau:.1} s)",
                        100.0 * drift_exp
                    ));
                }
            }
        }
        if has(Cause::Saturation) {
            // Below the peak command of both records, so both see the rail.
            let peak = (0..2)
                .flat_map(|w| hidden.command(w))
                .map(|u| u.iter().copied().fold(f64::NEG_INFINITY, f64::max))
                .fold(f64::INFINITY, f64::min);
            let rail = rail_frac * peak;
            hidden.scenario.stage.amplifier.rail_max_volts = rail;
            sizes.push(format!(
                "upper rail {rail:.1} V ({:.0} % of the peak command {peak:.1} V)",
                100.0 * rail_frac
            ));
        }
        if causes.is_empty() {
            sizes.push("none".into());
        }
        hidden.sizes = sizes;
        hidden.scenario.validate()?;
        Ok(hidden)
    }

    /// Number of samples of a record.
    pub fn samples(&self) -> usize {
        (self.rate_hz * self.duration_s).round() as usize
    }

    /// The commanded piezo voltage of record `which`, per axis.
    pub fn command(&self, which: u64) -> Vec<Vec<f64>> {
        let n = self.samples();
        let t: Vec<f64> = (0..n).map(|k| k as f64 / self.rate_hz).collect();
        let mut r = Rng::new(
            self.seed
                .wrapping_mul(104_729)
                .wrapping_add(which.wrapping_mul(31).wrapping_add(1)),
        );
        (0..self.scenario.stage.axes)
            .map(|_| excitation(&t, &mut r))
            .collect()
    }

    /// Record `which` (0: train, 1: valid, others: more excitations): time, the commanded
    /// piezo voltage per axis, the sensor reading per axis.
    pub fn record(&self, which: u64) -> Signals {
        self.record_with(self.command(which), which)
            .expect("the draw's own command fits its stage")
    }

    /// The stage driven by the command `u` (piezo voltage per axis, one value per sample at
    /// the draw's rate) from rest: time, `u` and the sensor reading per axis; `which` seeds
    /// the noise as for [`Hidden::record`].
    pub fn record_with(&self, u: Vec<Vec<f64>>, which: u64) -> Result<Signals> {
        let axes = self.scenario.stage.axes;
        anyhow::ensure!(
            u.len() == axes,
            "the stage has {axes} axes, the command {}",
            u.len()
        );
        let n = u.first().map_or(0, Vec::len);
        anyhow::ensure!(
            u.iter().all(|c| c.len() == n),
            "every axis' command needs the same number of samples"
        );
        let t: Vec<f64> = (0..n).map(|k| k as f64 / self.rate_hz).collect();
        let mut s = self.scenario.clone();
        s.run.seed = self.seed.wrapping_mul(10).wrapping_add(which);
        let mut stage = Stage::new(&s)?;
        let gain = s.stage.amplifier.gain;
        let mut y = vec![Vec::with_capacity(n); axes];
        let mut dac = vec![0.0; axes];
        for k in 0..n {
            for (d, u) in dac.iter_mut().zip(&u) {
                *d = u[k] / gain;
            }
            stage.advance(&dac);
            for (i, y) in y.iter_mut().enumerate() {
                y.push(stage.sensor_um(i));
            }
        }
        if let Some(sensor) = &self.sensor {
            let mut r = Rng::new(s.run.seed.wrapping_mul(0x51_7CC1).wrapping_add(7));
            for y in y.iter_mut() {
                sensor.apply(y, self.rate_hz, &mut r);
            }
        }
        Signals::new(t, u, y)
    }

    /// The same stage read by a realistic sensor ([`SensorRealism::draw`] from the seed).
    pub fn with_realistic_sensor(mut self) -> Self {
        let s = SensorRealism::draw(self.seed);
        self.sizes.push(format!(
            "sensor: hum {:.0} nm at {:.0} Hz, 1/f noise {:.0} nm rms, step {:.0} nm",
            1e3 * s.hum_um,
            s.hum_hz,
            1e3 * s.pink_um,
            1e3 * s.lsb_um
        ));
        self.sensor = Some(s);
        self
    }

    /// Record `which` as a CSV record, its comments naming the hidden causes and sizes.
    pub fn csv_record(&self, which: u64) -> Result<Record> {
        let s = self.record(which);
        let mut r = Record::new(s.t, s.u, s.y)?;
        r.comments = vec![
            format!(
                " hal-sim stage, seed {}, record {which} ({}), {} Hz",
                self.seed,
                if which == 0 { "train" } else { "valid" },
                self.rate_hz
            ),
            format!(
                " hidden: {}",
                if self.causes.is_empty() {
                    "none".into()
                } else {
                    self.causes
                        .iter()
                        .map(|c| c.name())
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            ),
            format!(" sizes: {}", self.sizes.join("; ")),
        ];
        Ok(r)
    }
}

/// Commanded piezo voltage: two sines (0.7-2 Hz, 2.5-6 Hz) plus held levels (0.15-0.4 s
/// each, +-15 V, 3-6 ms ramps) around 60 V, faded in from rest at 0 V over 0.3 s; within
/// 0..150 V.
pub fn excitation(t: &[f64], r: &mut Rng) -> Vec<f64> {
    let tau = 2.0 * std::f64::consts::PI;
    let (f1, f2) = (r.range(0.7, 2.0), r.range(2.5, 6.0));
    let (p1, p2) = (r.range(0.0, tau), r.range(0.0, tau));
    let (a1, a2) = (r.range(25.0, 35.0), r.range(6.0, 12.0));
    let ramp = r.range(3e-3, 6e-3);
    let end = t.last().copied().unwrap_or(0.0);
    let mut levels = Vec::new();
    let mut at = 0.0;
    while at <= end {
        levels.push((at, r.range(-15.0, 15.0)));
        at += r.range(0.15, 0.4);
    }
    let mut k = 0;
    let (mut prev, mut level) = (0.0, 0.0);
    let fade = 0.3;
    t.iter()
        .map(|&t| {
            while k < levels.len() && levels[k].0 <= t {
                prev = level;
                level = levels[k].1;
                k += 1;
            }
            let t0 = if k > 0 { levels[k - 1].0 } else { 0.0 };
            let step = prev + ((t - t0) / ramp).min(1.0) * (level - prev);
            let w = (t / fade).min(1.0);
            // From rest: the centre ramps in with the rest.
            let v = w * (60.0 + a1 * (tau * f1 * t + p1).sin() + a2 * (tau * f2 * t + p2).sin())
                + w * step;
            v.clamp(0.0, 150.0)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_differ_and_effects_show() {
        let h = Hidden::draw(1, &[]);
        let (a, b) = (h.record(0), h.record(1));
        assert_eq!(a.len(), 4000);
        assert_ne!(a.u, b.u, "train and valid need different excitations");
        let (lo, hi) = super::super::diagnose::model::min_max(&a.y[0]);
        assert!((60.0..130.0).contains(&(hi - lo)), "stroke {}", hi - lo);
        // A rail below the peak flattens the top of the output.
        let s = Hidden::draw(1, &[Cause::Saturation]);
        let ys = s.record(0);
        let rail = s.scenario.stage.amplifier.rail_max_volts;
        let peak = a.u[0].iter().copied().fold(0.0, f64::max);
        assert!(rail < peak, "{rail} {peak}");
        let (_, hs) = super::super::diagnose::model::min_max(&ys.y[0]);
        assert!(hs < hi - 1.0, "clipped top {hs} vs {hi}");
        assert!(s.sizes[0].contains("rail"));
        // Cross-coupling makes two axes.
        let c = Hidden::draw(2, &[Cause::CrossCoupling]);
        let rc = c.record(0);
        assert_eq!((rc.u.len(), rc.y.len()), (2, 2));
        assert!(Hidden::draw_at(1, &[], 1e9, 1.0).is_err());
    }
}
