//! A stage from an identified model (`piezo sim --stage DIR/fit.json`): the `ss` /
//! `hammerstein-ss` / `lfr` model of `piezo fit` behind the simulator's amplifier and
//! converters (`scheduled-ss`: its model of all records).
//!
//! Scaling (the identified stage rarely has the converters' ranges): the amplifier range
//! `[volts_min, volts_max]` maps linearly onto the model's training input range of each
//! input (`input_range` in fit.json), and the model output `y` (its own unit) becomes
//! `centre_um + um_per_unit * y` with `um_per_unit` such that the full voltage range moves
//! axis `i` by `2 half_span_um` at low frequency (static gain of input `i` to output `i`:
//! the front's major-loop chord slope times the linear block's `G(1)`, plus creep's static
//! gain), signed so the
//! position rises with the voltage (the controllers assume a positive gain). Axis `i`
//! drives input `i` and reads output `i`; the model's other inputs rest at the middle of
//! their range. The model runs at its own sample rate with
//! its input held between samples (zero-order hold) and its output held between its
//! samples. The extensions `piezo diagnose --base` writes (an input delay, creep lags, a
//! drift) run as [`crate::ident::ss::extended::Model::simulate`] runs them, at the model's
//! samples.

use crate::ident::ss::lfr::Lfr;
use crate::ident::ss::model::Modal;
use crate::ident::ss::saved::{Extensions, SsJson};
use anyhow::{Context, Result};
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::path::PathBuf;

/// `[stage.identified]` of a scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IdentifiedCfg {
    /// `fit.json` of `piezo fit --model ss | hammerstein-ss`.
    pub fit_json: PathBuf,
    /// Amplifier voltage range mapped onto the model's training input range (V).
    pub volts_min: f64,
    pub volts_max: f64,
    /// Position at the model's zero output (um).
    pub centre_um: f64,
    /// The largest training output maps to this distance from `centre_um` (um).
    pub half_span_um: f64,
}

/// The running model.
#[derive(Debug, Clone)]
pub struct IdentifiedPlant {
    fronts: Vec<Option<(Cbw<f64>, BwState<f64>)>>,
    modal: Modal,
    /// `lfr` fit.json: the nonlinearity in feedback around `modal`.
    lfr: Option<Lfr>,
    /// Its hysteresis operators' memory.
    lfr_mem: Vec<f64>,
    x: Vec<f64>,
    xn: Vec<f64>,
    /// Model inputs now (model units) and outputs at the last model sample.
    u: Vec<f64>,
    y: Vec<f64>,
    ts: f64,
    /// Time since the last model sample (s).
    since: f64,
    /// Per input: `u = (v - v_mid) * k_in + u_mid`.
    v_mid: f64,
    k_in: Vec<f64>,
    u_mid: Vec<f64>,
    um_per_unit: Vec<f64>,
    centre_um: f64,
    /// Delay, creep and drift of an extended model (empty: none).
    ext: Extensions,
    /// Per input, its last `delay_samples` values (oldest first).
    delay_lines: Vec<VecDeque<f64>>,
    /// Creep lag states, input-major, and their per-sample factors `1 - exp(-ts/tau)`.
    creep_state: Vec<f64>,
    creep_a: Vec<f64>,
    /// Model time since the start (s), for the drift.
    t_model: f64,
}

impl IdentifiedPlant {
    pub fn load(cfg: &IdentifiedCfg, axes: usize) -> Result<Self> {
        let path = &cfg.fit_json;
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("stage.identified: cannot read {}", path.display()))?;
        let saved: SsJson = serde_json::from_str(&text)
            .with_context(|| format!("stage.identified: {} is not a state-space fit.json (piezo fit --model ss | hammerstein-ss)", path.display()))?;
        let model = saved
            .to_model()
            .with_context(|| path.display().to_string())?;
        let lfr = saved.to_lfr().with_context(|| path.display().to_string())?;
        if let Some(r) = lfr.as_ref().and_then(Lfr::large_signal_radius) {
            if r >= 1.0 {
                eprintln!(
                    "warning: {}: the LFR's large-signal loop has spectral radius {r:.4} >= 1: the simulated stage diverges for drives far above the fit's training amplitudes (a fit.json written before 2026-12-01 has no limit on its feedback: fit it again)",
                    path.display()
                );
            }
        }
        let (m, p) = (model.linear.inputs(), model.linear.outputs());
        let ext = saved.extensions.clone();
        ext.check(m, p)
            .with_context(|| path.display().to_string())?;
        anyhow::ensure!(
            axes <= m.min(p),
            "stage.identified: {axes} axes, but the model has {m} inputs and {p} outputs"
        );
        anyhow::ensure!(
            cfg.volts_max > cfg.volts_min && cfg.half_span_um > 0.0 && cfg.centre_um.is_finite(),
            "stage.identified: needs volts_max > volts_min and half_span_um > 0"
        );
        let fronts = model
            .fronts
            .iter()
            .map(|f| match f.def.name {
                "cbw" => {
                    let p = &f.params;
                    let c = Cbw::with_n1(p[0], p[1], p[2], p[3] * p[2])
                        .map_err(|e| anyhow::anyhow!("stage.identified cbw: {e}"))?;
                    let s = c.init(0.0);
                    Ok(Some((c, s)))
                }
                other => anyhow::bail!(
                    "stage.identified: the simulator runs cbw fronts (or none), not `{other}`"
                ),
            })
            .collect::<Result<Vec<_>>>()?;
        let range = |r: &[(f64, f64)], i: usize| r.get(i).copied().filter(|(a, b)| b > a);
        let mut k_in = Vec::new();
        let mut u_mid = Vec::new();
        for i in 0..m {
            let (a, b) = range(&saved.input_range, i).unwrap_or((-1.0, 1.0));
            k_in.push((b - a) / (cfg.volts_max - cfg.volts_min));
            u_mid.push(0.5 * (a + b));
        }
        let y_abs = saved
            .output_range
            .iter()
            .map(|(a, b)| a.abs().max(b.abs()))
            .fold(0.0, f64::max);
        let y_abs = if y_abs > 0.0 { y_abs } else { 1.0 };
        let g1 = model
            .linear
            .response(crate::ident::ss::model::C64::new(1.0, 0.0));
        let um_per_unit = (0..p)
            .map(|i| {
                if i >= m {
                    return cfg.half_span_um / y_abs;
                }
                let half = 0.5 * (cfg.volts_max - cfg.volts_min) * k_in[i];
                // Chord slope of the front's major loop over the input range (1: none).
                let chord = match model.fronts.get(i) {
                    Some(f) => {
                        let tri: Vec<f64> = (0..400)
                            .map(|k| {
                                u_mid[i] + half * (1.0 - ((k % 200) as f64 - 100.0).abs() / 50.0)
                            })
                            .collect();
                        match f.apply(&tri, 1.0) {
                            Ok(v) => (v[300] - v[200]) / (tri[300] - tri[200]),
                            Err(_) => 1.0,
                        }
                    }
                    None => 1.0,
                };
                // Creep's lags (unit static gain each) act on the input beside the model.
                let creep_dc = ext.creep.as_ref().map_or(0.0, |c| {
                    let l = c.tau_s.len();
                    c.c.get(i)
                        .map_or(0.0, |row| row.iter().skip(i * l).take(l).sum())
                });
                let dc = g1[(i, i)].re * chord + creep_dc;
                if dc.is_finite() && dc.abs() * half > 1e-12 {
                    cfg.half_span_um / (dc * half)
                } else {
                    cfg.half_span_um / y_abs
                }
            })
            .collect();
        let n = model.linear.order();
        let mut plant = Self {
            fronts,
            x: vec![0.0; n],
            xn: vec![0.0; n],
            u: u_mid.clone(),
            y: vec![0.0; p],
            ts: 1.0 / saved.sample_rate_hz,
            since: 0.0,
            v_mid: 0.5 * (cfg.volts_min + cfg.volts_max),
            k_in,
            u_mid,
            um_per_unit,
            centre_um: cfg.centre_um,
            modal: model.linear,
            lfr_mem: lfr.as_ref().map_or(Vec::new(), Lfr::rest_memory),
            lfr,
            delay_lines: vec![VecDeque::new(); m],
            creep_state: Vec::new(),
            creep_a: ext.creep.as_ref().map_or(Vec::new(), |c| {
                c.tau_s
                    .iter()
                    .map(|tau| -(-1.0 / (saved.sample_rate_hz * tau)).exp_m1())
                    .collect()
            }),
            ext,
            t_model: 0.0,
        };
        let v0 = vec![cfg.volts_min; axes];
        plant.settle(&v0);
        Ok(plant)
    }

    fn set_inputs(&mut self, volts: &[f64]) {
        for (i, u) in self.u.iter_mut().enumerate() {
            *u = match volts.get(i) {
                Some(v) if v.is_finite() => (v - self.v_mid) * self.k_in[i] + self.u_mid[i],
                _ => self.u_mid[i],
            };
        }
    }

    /// The model's input now: the inputs delayed by the extension's delay.
    fn delayed(&mut self) -> Vec<f64> {
        let d = self.ext.delay_samples;
        if d == 0 {
            return self.u.clone();
        }
        self.u
            .iter()
            .zip(self.delay_lines.iter_mut())
            .map(|(&u, line)| {
                line.push_back(u);
                line.pop_front().unwrap_or(u)
            })
            .collect()
    }

    /// The linear block's input for the model input `ud` (after the fronts).
    fn front_out(&mut self, ud: &[f64], dt: f64) -> Vec<f64> {
        let mut v = ud.to_vec();
        for (vi, f) in v.iter_mut().zip(self.fronts.iter_mut()) {
            if let Some((m, s)) = f {
                *vi = m.step(s, *vi, dt);
            }
        }
        v
    }

    /// Rest for constant amplifier voltages: fronts relaxed there, `x = (I - A)^-1 B v`.
    pub fn settle(&mut self, volts: &[f64]) {
        self.set_inputs(volts);
        for (f, &u) in self.fronts.iter_mut().zip(&self.u) {
            if let Some((m, s)) = f {
                *s = m.init(u);
            }
        }
        // The extensions at rest: the delay lines and the creep lags hold the inputs.
        let d = self.ext.delay_samples;
        for (line, &u) in self.delay_lines.iter_mut().zip(&self.u) {
            *line = std::iter::repeat_n(u, d).collect();
        }
        let lags = self.creep_a.len();
        self.creep_state = self
            .u
            .iter()
            .flat_map(|&u| std::iter::repeat_n(u, lags))
            .collect();
        self.t_model = 0.0;
        let ud = self.u.clone();
        let v = self.front_out(&ud, self.ts);
        let a = self.modal.a();
        let n = a.nrows();
        let ia = nalgebra::DMatrix::<f64>::identity(n, n) - a;
        let bv = &self.modal.b * nalgebra::DVector::from_column_slice(&v);
        let lu = ia.lu();
        if let Some(x) = lu.solve(&bv) {
            self.x = x.iter().copied().collect();
        }
        // With the LFR's feedback: the fixed point `x = (I - A)^-1 (B v + E N(F x + G v))`.
        // Kept only where the iteration contracts; else the linear rest (the model then
        // settles in its first samples).
        if let Some(l) = &self.lfr {
            let x_lin = self.x.clone();
            let mut last = f64::INFINITY;
            for _ in 0..50 {
                let mut rhs: Vec<f64> = bv.iter().copied().collect();
                self.lfr_mem = l.rest_memory();
                l.settle_memory(&self.x, &v, &mut self.lfr_mem);
                l.add_feedback(&self.x, &v, &mut self.lfr_mem, &mut rhs);
                let Some(x) = lu.solve(&nalgebra::DVector::from_vec(rhs)) else {
                    self.x = x_lin;
                    self.lfr_mem = l.rest_memory();
                    break;
                };
                let step: f64 = x.iter().zip(&self.x).map(|(a, b)| (a - b).powi(2)).sum();
                if !step.is_finite() || step > last {
                    self.x = x_lin;
                    self.lfr_mem = l.rest_memory();
                    break;
                }
                last = step;
                self.x = x.iter().copied().collect();
            }
        }
        self.output(&v);
        self.since = 0.0;
    }

    fn output(&mut self, v: &[f64]) {
        for (o, y) in self.y.iter_mut().enumerate() {
            let mut s = 0.0;
            for (i, x) in self.x.iter().enumerate() {
                s += self.modal.c[(o, i)] * x;
            }
            for (j, vj) in v.iter().enumerate() {
                s += self.modal.d[(o, j)] * vj;
            }
            *y = s;
        }
        if let Some(c) = &self.ext.creep {
            for (y, co) in self.y.iter_mut().zip(&c.c) {
                *y += co
                    .iter()
                    .zip(&self.creep_state)
                    .map(|(c, s)| c * s)
                    .sum::<f64>();
            }
        }
        if let Some(rates) = &self.ext.drift_per_s {
            for (y, r) in self.y.iter_mut().zip(rates) {
                *y += r * self.t_model;
            }
        }
    }

    /// The creep lags and the drift's clock after a model sample with input `ud`.
    fn advance_extensions(&mut self, ud: &[f64]) {
        let lags = self.creep_a.len();
        if lags > 0 {
            for (states, &u) in self.creep_state.chunks_mut(lags).zip(ud) {
                for (s, a) in states.iter_mut().zip(&self.creep_a) {
                    *s += a * (u - *s);
                }
            }
        }
        self.t_model += self.ts;
    }

    /// Advances `h` seconds with the amplifier outputs `volts` (one per axis).
    pub fn advance(&mut self, volts: &[f64], h: f64) {
        self.set_inputs(volts);
        self.since += h;
        while self.since >= self.ts {
            self.since -= self.ts;
            let ud = self.delayed();
            let v = self.front_out(&ud, self.ts);
            self.output(&v);
            self.advance_extensions(&ud);
            let mut i = 0;
            for blk in &self.modal.blocks {
                match *blk {
                    crate::ident::ss::model::Block::Real(l) => self.xn[i] = l * self.x[i],
                    crate::ident::ss::model::Block::Pair(s, w) => {
                        self.xn[i] = s * self.x[i] + w * self.x[i + 1];
                        self.xn[i + 1] = -w * self.x[i] + s * self.x[i + 1];
                    }
                }
                i += blk.states();
            }
            for (r, xn) in self.xn.iter_mut().enumerate() {
                for (j, vj) in v.iter().enumerate() {
                    *xn += self.modal.b[(r, j)] * vj;
                }
            }
            if let Some(l) = &self.lfr {
                l.add_feedback(&self.x, &v, &mut self.lfr_mem, &mut self.xn);
            }
            std::mem::swap(&mut self.x, &mut self.xn);
        }
    }

    /// Position of `axis` (um).
    pub fn position_um(&self, axis: usize) -> f64 {
        match (self.y.get(axis), self.um_per_unit.get(axis)) {
            (Some(y), Some(k)) => self.centre_um + k * y,
            _ => f64::NAN,
        }
    }
}

impl super::Stage {
    /// [`Self::advance`] through the identified model: amplifier, model, delay, drift and
    /// noise as for the built-in stage (no force disturbance).
    #[inline(never)]
    pub(super) fn advance_identified(&mut self, dac_volts: &[f64]) {
        let Some(mut plant) = self.identified.take() else {
            return;
        };
        let mut volts = [0.0; 3];
        let n = self.axes.len().min(volts.len());
        for _ in 0..self.substeps {
            for ((v, ax), &u) in volts.iter_mut().zip(self.axes.iter_mut()).zip(dac_volts) {
                *v = ax.amp.step(u);
                ax.v_end = *v;
            }
            plant.advance(&volts[..n], self.h);
            self.advance_time();
            let drift = self.drift_um();
            for (i, (ax, line)) in self.axes.iter_mut().zip(&mut self.delay).enumerate() {
                ax.x = plant.position_um(i);
                ax.v = 0.0;
                let mask = line.len() - 1; // a power of two
                if let Some(p) = line.get_mut(self.delay_pos & mask) {
                    *p = ax.x + drift;
                }
            }
        }
        self.identified = Some(plant);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ident::ss::extended::{Creep, Model};
    use crate::ident::ss::hammerstein::Hammerstein;
    use crate::ident::ss::model::Block;
    use nalgebra::DMatrix;

    /// `saved` as a one-axis stage over 0-10 V (through a file, as `--stage` loads it).
    fn load_one_axis(saved: &SsJson, name: &str) -> IdentifiedPlant {
        let path = std::env::temp_dir().join(format!("piezo-{name}-{}.json", std::process::id()));
        std::fs::write(&path, serde_json::to_string(saved).unwrap()).unwrap();
        let cfg = IdentifiedCfg {
            fit_json: path.clone(),
            volts_min: 0.0,
            volts_max: 10.0,
            centre_um: 0.0,
            half_span_um: 1.0,
        };
        let plant = IdentifiedPlant::load(&cfg, 1).unwrap();
        std::fs::remove_file(&path).ok();
        plant
    }

    /// The simulator's stage runs an extended model's delay, creep and drift as the
    /// model's own simulation does, sample for sample (inputs mapped one to one).
    #[test]
    fn the_stage_runs_the_extensions_as_the_model_simulates_them() {
        let linear = Modal {
            blocks: vec![Block::Real(0.9), Block::Pair(0.95, 0.2)],
            b: DMatrix::from_row_slice(3, 1, &[1.0, 0.5, 0.0]),
            c: DMatrix::from_row_slice(1, 3, &[0.4, 0.1, 0.2]),
            d: DMatrix::from_row_slice(1, 1, &[0.0]),
        };
        let fs = 1000.0;
        let mut base = SsJson::new(
            &Hammerstein {
                fronts: Vec::new(),
                linear,
            },
            fs,
            ("V", "um"),
            serde_json::Value::Null,
        );
        base.input_range = vec![(0.0, 10.0)];
        base.output_range = vec![(-5.0, 5.0)];
        let model = Model {
            delay: 3,
            creep: Some(Creep {
                tau_s: vec![0.01, 0.1],
                c: vec![vec![0.05, 0.02]],
            }),
            drift: Some(vec![0.5]),
            ..Model::of_saved(&base).unwrap()
        };
        let mut plant = load_one_axis(&model.to_saved(&base, serde_json::Value::Null), "ext");
        // The scale counts creep's static gain beside G(1): the 10 V range moves the axis
        // by 2 um at rest.
        let g1 = model
            .linear()
            .response(crate::ident::ss::model::C64::new(1.0, 0.0))[(0, 0)]
            .re
            + 0.05
            + 0.02;
        assert!(
            (plant.um_per_unit[0] - 1.0 / (g1 * 5.0)).abs() < 1e-12,
            "{} against {}",
            plant.um_per_unit[0],
            1.0 / (g1 * 5.0)
        );
        let u: Vec<f64> = (0..300)
            .map(|k| 5.0 + 4.0 * (k as f64 * 0.07).sin())
            .collect();
        let want = model.simulate(std::slice::from_ref(&u), 1.0 / fs).unwrap();
        for (k, &v) in u.iter().enumerate() {
            // Rest at 0 V is the model's rest: the first sample is the model's first.
            plant.advance(&[v], 1.0 / fs);
            assert!(
                (plant.y[0] - want[0][k]).abs() < 1e-9,
                "sample {k}: stage {} model {}",
                plant.y[0],
                want[0][k]
            );
        }
    }

    /// Settled at a constant voltage, an LFR whose feedback follows the running mean square
    /// starts where holding that voltage leaves it: its rest has the mean square of the
    /// held `z` in memory, not zero, so the output does not move while the voltage holds.
    #[test]
    fn an_lfr_with_a_running_mean_square_settles_at_its_rest() {
        use crate::ident::ss::lfr::{Basis, Lfr};
        let lfr = Lfr {
            linear: Modal {
                blocks: vec![Block::Real(0.9), Block::Pair(0.95, 0.2)],
                b: DMatrix::from_row_slice(3, 1, &[1.0, 0.5, 0.0]),
                c: DMatrix::from_row_slice(1, 3, &[0.4, 0.1, 0.2]),
                d: DMatrix::from_row_slice(1, 1, &[0.0]),
            },
            basis: vec![Basis::Rms(50.0)],
            e: DMatrix::from_row_slice(3, 1, &[-0.05, 0.0, 0.0]),
            f: DMatrix::from_row_slice(1, 3, &[1.0, 0.0, 0.0]),
            g: DMatrix::zeros(1, 1),
            z_limit: Vec::new(),
        };
        let fs = 1000.0;
        let mut saved = SsJson::new(
            &Hammerstein {
                fronts: Vec::new(),
                linear: lfr.linear.clone(),
            },
            fs,
            ("V", "um"),
            serde_json::Value::Null,
        )
        .with_lfr(&lfr);
        saved.input_range = vec![(0.0, 10.0)];
        saved.output_range = vec![(-50.0, 50.0)];
        let mut plant = load_one_axis(&saved, "rms");
        plant.settle(&[8.0]);
        let y0 = plant.y[0];
        for k in 0..500 {
            plant.advance(&[8.0], 1.0 / fs);
            assert!(
                (plant.y[0] - y0).abs() < 1e-6 * (1.0 + y0.abs()),
                "sample {k}: {} after a rest at {y0}",
                plant.y[0]
            );
        }
        // The feedback is live there: the linear rest is another point.
        let lin = lfr
            .linear
            .response(crate::ident::ss::model::C64::new(1.0, 0.0))[(0, 0)]
            .re;
        assert!(
            (plant.y[0] - lin * 8.0).abs() > 1e-3,
            "{} vs {}",
            plant.y[0],
            lin * 8.0
        );
    }
}
