//! Seed 001's comparison re-run (issue 19 item 4): BW (001 eq. 2), ABW (eq. 3), PI (eq.
//! 4-5), PPI (eq. 6-7) and DPI (eq. 8-10), each in a Hammerstein structure (the hysteresis,
//! then linear dynamics identified first from a step response, 001 sec. II-C), fitted on a
//! 1 Hz record and validated at 1, 50 and 100 Hz on a stage whose hysteresis depends on the
//! input rate.
//!
//! The stage ([`RateStage`]) is hal-sim's, with its rate-dependent hysteresis on: at 50 and 100 Hz the loop widens and its
//! gain drops, so the maximum output falls and the loop rotates (001's "rate-dependent
//! decrease of a maximum output"). A Hammerstein model's hysteresis is static and its linear
//! part is fixed by the step, so it cannot follow that: 001's finding, tested in
//! `hal-sim/tests/seed001.rs` against the same stage with the effect off.

use anyhow::{Context, Result};

use super::fit::models::MODELS;
use super::fit::resample::Edge;
use super::fit::{fit_siso, FitOptions};
use crate::numeric::rmse;
use crate::scenario::{RateHysteresis, Scenario};
use crate::stage::Stage;

/// The models of 001's table, with `piezo fit` names.
pub const MODELS_001: [(&str, &str); 5] = [
    ("BW", "cbw-n"),
    ("ABW", "abw-u"),
    ("PI", "pi"),
    ("PPI", "ppi"),
    ("DPI", "dpi"),
];

/// Frequencies of 001's table (Hz).
pub const FREQS_001: [f64; 3] = [1.0, 50.0, 100.0];

/// hal-sim's stage with its rate-dependent hysteresis ([`RateHysteresis`]: the loop widens
/// and the gain about the operating point drops as the input rate grows) on or off; noise,
/// creep, drift and delay off, so the comparison sees the hysteresis and the structure's
/// resonance alone.
#[derive(Debug, Clone)]
pub struct RateStage {
    scenario: Scenario,
}

impl RateStage {
    /// The default stage sampled at `rate_hz`, with the default rate dependence (30 % wider
    /// and 5 % less gain at high rates, half of it at 5 kV/s) when `rate_dependent`.
    pub fn new(rate_dependent: bool, rate_hz: f64) -> Self {
        let mut s = Scenario::default();
        s.run.loop_hz = rate_hz;
        s.stage.noise.enabled = false;
        s.stage.creep.enabled = false;
        s.stage.drift.enabled = false;
        s.stage.delay.enabled = false;
        s.stage.rate_hysteresis = RateHysteresis {
            enabled: rate_dependent,
            ..RateHysteresis::default()
        };
        Self { scenario: s }
    }

    /// The sensor's reading (um) for the piezo voltage `u` (V), one value per sample, from
    /// rest.
    pub fn run(&self, u: &[f64]) -> Result<Vec<f64>> {
        let mut stage = Stage::new(&self.scenario)?;
        let gain = self.scenario.stage.amplifier.gain;
        Ok(u.iter()
            .map(|v| {
                stage.advance(&[v / gain]);
                stage.sensor_um(0)
            })
            .collect())
    }
}

/// 001's excitation: `25 + 25 sin(2 pi f t - pi/2)` V (0-50 V, starting at 0), `periods`
/// periods at `rate_hz` samples per second.
pub fn sine_0_50(f_hz: f64, periods: f64, rate_hz: f64) -> Vec<f64> {
    let n = (periods * rate_hz / f_hz).round() as usize;
    (0..n)
        .map(|k| {
            let t = k as f64 / rate_hz;
            25.0 + 25.0 * (std::f64::consts::TAU * f_hz * t - std::f64::consts::FRAC_PI_2).sin()
        })
        .collect()
}

/// One row of the table: a model's RMSE (um) at each of [`FREQS_001`].
#[derive(Debug, Clone)]
pub struct Row001 {
    pub model: &'static str,
    pub rmse_um: [f64; 3],
}

/// The linear part identified from the step (`(f_hz, zeta)`) and the table.
#[derive(Debug, Clone)]
pub struct Comparison {
    pub linear: Vec<(f64, f64)>,
    pub rows: Vec<Row001>,
}

/// The error a sample range is scored on: 001 scores "from the second half of the first
/// period to the first part of the second period"; here the second period whole.
fn scored(y: &[f64], per_period: usize) -> &[f64] {
    y.get(per_period..2 * per_period).unwrap_or(y)
}

/// Identifies the linear part from a 0 -> 5 V step (001 sec. II-C, 004 sec. 4.2) and fits
/// each model of [`MODELS_001`] on the 1 Hz record with that linear part fixed; then
/// validates each at [`FREQS_001`]. `rate_hz`: samples per second; `generations`: the
/// global search's effort.
pub fn compare(stage: &RateStage, rate_hz: f64, generations: usize) -> Result<Comparison> {
    let dt = 1.0 / rate_hz;
    let n_step = (0.01 * rate_hz) as usize;
    let step: Vec<f64> = (0..n_step)
        .map(|k| if k < n_step / 10 { 0.0 } else { 5.0 })
        .collect();
    let y_step = stage.run(&step)?;
    let def = |name: &str| {
        MODELS
            .iter()
            .find(|m| m.name == name)
            .with_context(|| format!("no model {name}"))
    };
    let opts = FitOptions {
        generations,
        linear_sections: 1,
        ..FitOptions::default()
    };
    let lin = fit_siso(def("gain")?, &step, &y_step, dt, &opts)?.linear;
    // (input, output, samples per period) at each frequency.
    type Record = (Vec<f64>, Vec<f64>, usize);
    let records: Vec<Record> = FREQS_001
        .iter()
        .map(|&f| {
            let u = sine_0_50(f, 2.0, rate_hz);
            let y = stage.run(&u)?;
            Ok((u, y, (rate_hz / f).round() as usize))
        })
        .collect::<Result<_>>()?;
    let mut rows = Vec::new();
    for (label, name) in MODELS_001 {
        let (u1, y1, _) = &records[0];
        let fitted = fit_siso(
            def(name)?,
            u1,
            y1,
            dt,
            &FitOptions {
                generations,
                linear_fixed: Some(lin.clone()),
                ..FitOptions::default()
            },
        )?;
        let mut rmse_um = [0.0; 3];
        for (r, (u, y, per)) in rmse_um.iter_mut().zip(&records) {
            let sim = fitted.simulate(u, dt, Edge::Hold)?;
            *r = rmse(scored(&sim, *per), scored(y, *per));
        }
        rows.push(Row001 {
            model: label,
            rmse_um,
        });
    }
    Ok(Comparison { linear: lin, rows })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stages_loop_changes_with_rate_only_when_rate_dependent() {
        let rate_hz = 10_000.0;
        let peak = |stage: &RateStage, f: f64| {
            let u = sine_0_50(f, 2.0, rate_hz);
            let y = stage.run(&u).unwrap();
            let per = (rate_hz / f) as usize;
            let top = y[per..].iter().copied().fold(f64::MIN, f64::max);
            let bottom = y[per..].iter().copied().fold(f64::MAX, f64::min);
            top - bottom
        };
        let on = RateStage::new(true, rate_hz);
        let (p1, p100) = (peak(&on, 1.0), peak(&on, 100.0));
        assert!(
            (p100 - p1).abs() > 0.02 * p1,
            "span {p1} at 1 Hz, {p100} at 100 Hz"
        );
        let off = RateStage::new(false, rate_hz);
        let (q1, q100) = (peak(&off, 1.0), peak(&off, 100.0));
        assert!((q100 - q1).abs() < 0.02 * q1, "{q1} vs {q100}");
    }
}
