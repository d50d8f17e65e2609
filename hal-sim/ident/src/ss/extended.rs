//! A state-space fit with the extensions discovery names (`piezo diagnose --base`): an input
//! delay, a hysteresis ahead of each input, the core (the linear part as identified,
//! scheduled on the input level, or inside an LFR), creep lags added to each output and a
//! drift per output. The one simulation of every `fit.json` of the state-space family
//! ([`Model::of_saved`]); [`Model::to_saved`] writes an extended model back.
use anyhow::Result;

use crate::record::Record;
use crate::ss::hammerstein::Front;
use crate::ss::lfr::Lfr;
use crate::ss::model::Modal;
pub use crate::ss::saved::Creep;
use crate::ss::saved::{Extensions, FrontJson, SsJson};
use crate::ss::scheduled::Schedule;
use crate::ss::score::{period_of, with_warmup};

/// The linear part of the model: as identified, scheduled, or inside an LFR.
#[derive(Debug, Clone)]
pub enum Core {
    Linear(Modal),
    Scheduled(Schedule, Modal),
    Lfr(Lfr),
}

/// The base and the extensions named so far.
#[derive(Debug, Clone)]
pub struct Model {
    /// Input delay (samples).
    pub delay: usize,
    /// Hysteresis ahead of each input (empty: none).
    pub fronts: Vec<Front>,
    pub core: Core,
    pub creep: Option<Creep>,
    /// Drift rate per output (output unit / s), from the first simulated sample.
    pub drift: Option<Vec<f64>>,
}

impl Model {
    /// The base: a `fit.json` of the state-space family.
    pub fn of_saved(s: &SsJson) -> Result<Self> {
        let h = s.to_model()?;
        let core = match (s.to_lfr()?, &s.schedule) {
            (Some(l), _) => Core::Lfr(l),
            (None, Some(sch)) => Core::Scheduled(sch.clone(), h.linear.clone()),
            (None, None) => Core::Linear(h.linear.clone()),
        };
        let e = &s.extensions;
        e.check(s.inputs, s.outputs)?;
        Ok(Self {
            delay: e.delay_samples,
            fronts: h.fronts,
            core,
            creep: e.creep.clone(),
            drift: e.drift_per_s.clone(),
        })
    }

    /// The model as a `fit.json`: `base`'s header (rate, units, ranges) with this model's
    /// parts; its kind is the core's (`lfr`, `scheduled-ss`, `hammerstein-ss` or `ss`).
    pub fn to_saved(&self, base: &SsJson, report: serde_json::Value) -> SsJson {
        let fs = base.sample_rate_hz;
        let linear = self.linear();
        let mut s = SsJson {
            model: if self.fronts.is_empty() {
                "ss"
            } else {
                "hammerstein-ss"
            }
            .into(),
            order: linear.order(),
            hysteresis: self.fronts.iter().map(FrontJson::of).collect(),
            linear: linear.to_json(),
            schedule: None,
            lfr: None,
            modes_hz: linear.modes_hz(fs),
            extensions: Extensions {
                delay_samples: self.delay,
                creep: self.creep.clone(),
                drift_per_s: self.drift.clone(),
            },
            report,
            ..base.clone()
        };
        match &self.core {
            Core::Linear(_) => {}
            Core::Scheduled(sch, _) => s = s.with_schedule(Some(sch.clone())),
            Core::Lfr(l) => s = s.with_lfr(l),
        }
        s
    }

    pub fn inputs(&self) -> usize {
        self.linear().inputs()
    }

    pub fn linear(&self) -> &Modal {
        match &self.core {
            Core::Linear(m) | Core::Scheduled(_, m) => m,
            Core::Lfr(l) => &l.linear,
        }
    }

    /// What the core sees: the inputs delayed, then through the hysteresis.
    fn core_input(&self, u: &[Vec<f64>], dt: f64) -> Result<Vec<Vec<f64>>> {
        let delayed: Vec<Vec<f64>> = u.iter().map(|x| delay(x, self.delay)).collect();
        if self.fronts.is_empty() {
            return Ok(delayed);
        }
        self.fronts
            .iter()
            .zip(&delayed)
            .map(|(f, x)| f.apply(x, dt))
            .collect()
    }

    /// Simulates from rest; `u[j][k]` is input `j` at sample `k`, every `dt` s.
    pub fn simulate(&self, u: &[Vec<f64>], dt: f64) -> Result<Vec<Vec<f64>>> {
        anyhow::ensure!(
            u.len() == self.inputs(),
            "the model has {} inputs, the record {}",
            self.inputs(),
            u.len()
        );
        let v = self.core_input(u, dt)?;
        let mut y = match &self.core {
            Core::Linear(m) => m.simulate(&v)?,
            Core::Scheduled(s, m) => s.simulate(m, &v, dt)?,
            Core::Lfr(l) => l.simulate(&v)?,
        };
        if let Some(c) = &self.creep {
            let regs = creep_regressors(u, self.delay, &c.tau_s, dt);
            for (yo, co) in y.iter_mut().zip(&c.c) {
                for (r, ci) in regs.iter().zip(co) {
                    for (a, b) in yo.iter_mut().zip(r) {
                        *a += ci * b;
                    }
                }
            }
        }
        if let Some(rates) = &self.drift {
            for (yo, rate) in y.iter_mut().zip(rates) {
                for (k, a) in yo.iter_mut().enumerate() {
                    *a += rate * k as f64 * dt;
                }
            }
        }
        Ok(y)
    }

    pub(crate) fn core_records(&self, recs: &[Record]) -> Result<Vec<Record>> {
        recs.iter().map(|r| self.core_record(r)).collect()
    }

    /// The model's record `rec` with the core's input in place of `u` (steady state: the
    /// record's first period ran through first).
    pub(crate) fn core_record(&self, rec: &Record) -> Result<Record> {
        let n = period_of(rec)?;
        let v = self.core_input(&with_warmup(&rec.u, n), rec.dt())?;
        Ok(Record {
            u: v.into_iter().map(|x| x[n..].to_vec()).collect(),
            ..rec.clone()
        })
    }
}

/// `x` delayed by `d` samples (zeros first).
pub fn delay(x: &[f64], d: usize) -> Vec<f64> {
    let d = d.min(x.len());
    std::iter::repeat_n(0.0, d)
        .chain(x[..x.len() - d].iter().copied())
        .collect()
}

/// `lag_l(u_j)` for every input `j` (delayed by `d`) and lag `l`, `j`-major.
pub(crate) fn creep_regressors(u: &[Vec<f64>], d: usize, tau_s: &[f64], dt: f64) -> Vec<Vec<f64>> {
    let mut out = Vec::new();
    for x in u {
        let x = delay(x, d);
        for &tau in tau_s {
            let a = 1.0 - (-dt / tau).exp();
            let mut s = 0.0;
            out.push(
                x.iter()
                    .map(|v| {
                        let now = s;
                        s += a * (v - s);
                        now
                    })
                    .collect(),
            );
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ss::hammerstein::Hammerstein;
    use crate::ss::model::Block;
    use nalgebra::DMatrix;

    /// Two inputs, two outputs: a real pole and a lightly damped pair.
    fn modal() -> Modal {
        Modal {
            blocks: vec![Block::Real(0.9), Block::Pair(0.95, 0.2)],
            b: DMatrix::from_row_slice(3, 2, &[1.0, 0.2, 0.5, 0.0, 0.0, 0.3]),
            c: DMatrix::from_row_slice(2, 3, &[0.4, 0.1, 0.0, 0.0, 0.3, 0.2]),
            d: DMatrix::from_row_slice(2, 2, &[0.0, 0.01, 0.0, 0.0]),
        }
    }

    pub(crate) fn extended() -> (SsJson, Model) {
        let base = SsJson::new(
            &Hammerstein {
                fronts: Vec::new(),
                linear: modal(),
            },
            1000.0,
            ("V", "um"),
            serde_json::Value::Null,
        );
        let model = Model {
            delay: 3,
            creep: Some(Creep {
                tau_s: vec![0.01, 0.1],
                c: vec![vec![0.05, 0.02, 0.0, -0.01], vec![0.0, 0.01, 0.03, 0.0]],
            }),
            drift: Some(vec![0.5, -0.25]),
            ..Model::of_saved(&base).unwrap()
        };
        (base, model)
    }

    #[test]
    fn an_extended_model_saved_and_loaded_simulates_the_same() {
        let (base, model) = extended();
        let saved = model.to_saved(&base, serde_json::json!({"by": "test"}));
        assert_eq!(saved.model, "ss");
        let text = serde_json::to_string(&saved).unwrap();
        let loaded: SsJson = serde_json::from_str(&text).unwrap();
        let u: Vec<Vec<f64>> = (0..2)
            .map(|j| {
                (0..400)
                    .map(|k| ((k * (j + 3)) as f64 * 0.05).sin())
                    .collect()
            })
            .collect();
        let want = model.simulate(&u, 1e-3).unwrap();
        let sim = |s: &SsJson| Model::of_saved(s).unwrap().simulate(&u, 1e-3).unwrap();
        assert_eq!(sim(&loaded), want);
        // Each extension shows: without them the output differs.
        assert_ne!(sim(&base), want);
        // A plain fit.json keeps no extensions section.
        assert!(!serde_json::to_string(&base).unwrap().contains("extensions"));
    }

    #[test]
    fn extensions_of_the_wrong_size_are_refused() {
        let (base, model) = extended();
        let mut saved = model.to_saved(&base, serde_json::Value::Null);
        if let Some(d) = saved.extensions.drift_per_s.as_mut() {
            d.pop();
        }
        let e = format!("{:#}", Model::of_saved(&saved).unwrap_err());
        assert!(e.contains("drift_per_s needs 2 finite rates"), "{e}");
        let mut saved = model.to_saved(&base, serde_json::Value::Null);
        if let Some(c) = saved.extensions.creep.as_mut() {
            c.c[1].push(0.0);
        }
        let e = format!("{:#}", Model::of_saved(&saved).unwrap_err());
        assert!(e.contains("extensions.creep.c"), "{e}");
    }
}
