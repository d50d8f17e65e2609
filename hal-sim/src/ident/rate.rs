//! Seed 001's comparison re-run (issue 19 item 4): BW (001 eq. 2), ABW (eq. 3), PI (eq.
//! 4-5), PPI (eq. 6-7) and DPI (eq. 8-10), each in a Hammerstein structure (the hysteresis,
//! then linear dynamics identified first from a step response, 001 sec. II-C), fitted on a
//! 1 Hz record and validated at 1, 50 and 100 Hz on a stage whose hysteresis depends on the
//! input rate.
//!
//! The stage ([`RateStage`]): a CBW (000 eq. 1-2) whose input gain falls with the input
//! rate, `dv = d g(|du/dt|) du - dh` with `g(r) = 1 / (1 + r / r_c)`, then a second-order
//! linear part. At 50 and 100 Hz the maximum output falls and the loop rotates: 001's
//! "rate-dependent decrease of a maximum output". A Hammerstein model's hysteresis is
//! static (rate-independent) and its linear part is fixed by the step, so it cannot follow
//! that: 001's finding, tested in `hal-sim/tests/seed001.rs`.

use anyhow::{Context, Result};

use super::fit::models::MODELS;
use super::fit::resample::Edge;
use super::fit::{fit_siso, FitOptions};
use crate::numeric::rmse;
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};

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

/// A stage with rate-dependent hysteresis behind second-order dynamics.
#[derive(Debug, Clone, Copy)]
pub struct RateStage {
    pub cbw: Cbw<f64>,
    /// Input rate (V/s) at which the input gain has fallen to half; infinite: no rate
    /// dependence.
    pub rate_c: f64,
    /// Linear part: natural frequency (Hz) and damping ratio.
    pub f_hz: f64,
    pub zeta: f64,
}

impl RateStage {
    /// CBW set 1 of 000 (um/V), half gain at 100 kV/s (at 100 Hz, 0-50 V the input rate
    /// peaks at 15.7 kV/s), a 2 kHz, 0.7-damped linear part.
    pub fn new(rate_dependent: bool) -> Self {
        Self {
            cbw: Cbw::with_n1(0.16, 0.07, 0.02, 0.01).expect("000 set 1 is valid"),
            rate_c: if rate_dependent { 1e5 } else { f64::INFINITY },
            f_hz: 2_000.0,
            zeta: 0.7,
        }
    }

    /// The output (um) for input `u` (V) sampled every `dt` s, from rest.
    pub fn run(&self, u: &[f64], dt: f64) -> Vec<f64> {
        const SUB: usize = 8;
        let h = dt / SUB as f64;
        let w = std::f64::consts::TAU * self.f_hz;
        let mut hs: BwState<f64> = self.cbw.init(u.first().copied().unwrap_or(0.0));
        let mut v = self.cbw.d() * hs.u - hs.h;
        let (mut x, mut dx) = (v, 0.0);
        let mut prev = hs.u;
        u.iter()
            .map(|&uk| {
                let du = uk - prev;
                let g = 1.0 / (1.0 + (du / dt).abs() / self.rate_c);
                for k in 1..=SUB {
                    let ui = prev + du * k as f64 / SUB as f64;
                    let h0 = hs.h;
                    self.cbw.step(&mut hs, ui, h);
                    v += self.cbw.d() * g * du / SUB as f64 - (hs.h - h0);
                    // Semi-implicit Euler of x'' = w^2 (v - x) - 2 zeta w x'.
                    dx += h * (w * w * (v - x) - 2.0 * self.zeta * w * dx);
                    x += h * dx;
                }
                prev = uk;
                x
            })
            .collect()
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
    let y_step = stage.run(&step, dt);
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
            let y = stage.run(&u, dt);
            (u, y, (rate_hz / f).round() as usize)
        })
        .collect();
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
    fn the_stages_peak_falls_with_rate_only_when_rate_dependent() {
        let rate_hz = 20_000.0;
        let peak = |stage: &RateStage, f: f64| {
            let u = sine_0_50(f, 2.0, rate_hz);
            let y = stage.run(&u, 1.0 / rate_hz);
            let per = (rate_hz / f) as usize;
            y[per..].iter().copied().fold(f64::MIN, f64::max)
        };
        let on = RateStage::new(true);
        let (p1, p100) = (peak(&on, 1.0), peak(&on, 100.0));
        assert!(p100 < 0.97 * p1, "peak {p1} at 1 Hz, {p100} at 100 Hz");
        let off = RateStage::new(false);
        let (q1, q100) = (peak(&off, 1.0), peak(&off, 100.0));
        assert!((q100 - q1).abs() < 0.01 * q1, "{q1} vs {q100}");
    }
}
