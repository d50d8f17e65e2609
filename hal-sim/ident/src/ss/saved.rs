//! `fit.json` of the state-space models: everything needed to simulate them.

use super::hammerstein::{Front, Hammerstein};
use super::lfr::{Lfr, LfrJson};
use super::model::{Modal, ModalJson};
use super::scheduled::Schedule;
use crate::fit::models::{self, Scales};
use serde::{Deserialize, Serialize};

/// One actuator's hysteresis in `fit.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FrontJson {
    /// Registry name (`piezo fit --list`).
    pub model: String,
    /// Parameter names and values, in the units of the model (input unit in, input unit out).
    pub params: Vec<(String, f64)>,
}

impl FrontJson {
    pub fn of(f: &Front) -> Self {
        Self {
            model: f.def.name.into(),
            params: param_names(f.def)
                .into_iter()
                .zip(f.params.iter().copied())
                .collect(),
        }
    }
}

/// Additive creep: `y_o += sum_{j,l} c[o][j L + l] lag_l(u_j)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Creep {
    /// Lag time constants (s).
    pub tau_s: Vec<f64>,
    /// `c[o]`, `inputs * tau_s.len()` coefficients per output.
    pub c: Vec<Vec<f64>>,
}

/// What `piezo diagnose --base` added to the identified model (a `piezo fit` model has at
/// most the delay, from `--input-delay`): the inputs delayed, creep lags and a drift added to
/// the outputs ([`crate::ss::extended::Model::simulate`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Extensions {
    /// Input delay (samples at `sample_rate_hz`).
    #[serde(default)]
    pub delay_samples: usize,
    /// Per input, first-order lags of the (delayed) input added to each output.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub creep: Option<Creep>,
    /// Per output, a rate (output unit / s) from the first simulated sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift_per_s: Option<Vec<f64>>,
}

/// A delay longer than this (samples) is refused as a corrupt file.
const MAX_DELAY_SAMPLES: usize = 1 << 20;

impl Extensions {
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// Sizes and values a model with `inputs` and `outputs` can run.
    pub fn check(&self, inputs: usize, outputs: usize) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.delay_samples <= MAX_DELAY_SAMPLES,
            "fit.json: extensions.delay_samples {} is above {MAX_DELAY_SAMPLES}",
            self.delay_samples
        );
        if let Some(c) = &self.creep {
            anyhow::ensure!(
                !c.tau_s.is_empty() && c.tau_s.iter().all(|t| t.is_finite() && *t > 0.0),
                "fit.json: extensions.creep.tau_s must be positive time constants (s)"
            );
            anyhow::ensure!(
                c.c.len() == outputs
                    && c.c.iter().all(|row| {
                        row.len() == inputs * c.tau_s.len() && row.iter().all(|v| v.is_finite())
                    }),
                "fit.json: extensions.creep.c needs {outputs} rows of {} finite coefficients (inputs x lags)",
                inputs * c.tau_s.len()
            );
        }
        if let Some(d) = &self.drift_per_s {
            anyhow::ensure!(
                d.len() == outputs && d.iter().all(|v| v.is_finite()),
                "fit.json: extensions.drift_per_s needs {outputs} finite rates"
            );
        }
        Ok(())
    }
}

/// The saved model.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SsJson {
    /// `piezo-fit/1`.
    pub format: String,
    /// `ss`, `hammerstein-ss`, `scheduled-ss` or `lfr`.
    pub model: String,
    /// The linear block is discrete time at this rate; inputs must be sampled at it.
    pub sample_rate_hz: f64,
    pub inputs: usize,
    pub outputs: usize,
    pub input_unit: String,
    pub output_unit: String,
    pub order: usize,
    /// `v_j = H_j(u_j)` ahead of the linear block (empty: `v = u`).
    pub hysteresis: Vec<FrontJson>,
    /// `x[k+1] = A x + B v`, `y = C x + D v`, `A` block diagonal (see `blocks`).
    pub linear: ModalJson,
    /// `scheduled-ss`: local models per input level, blended by the running input RMS
    /// (`linear` is then the model of all records, used by `piezo sim --stage`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<Schedule>,
    /// `lfr`: the nonlinearity in feedback around `linear` (`x+ = A x + B u + E w`,
    /// `z = F x + G u`, `w = N(z)`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lfr: Option<LfrJson>,
    /// Training range `[min, max]` of each input and output (model units): what
    /// `piezo sim --stage` scales the converters to.
    #[serde(default)]
    pub input_range: Vec<(f64, f64)>,
    #[serde(default)]
    pub output_range: Vec<(f64, f64)>,
    /// Modes of `A` as continuous-time `[f_hz, zeta]`, for reading only.
    #[serde(default)]
    pub modes_hz: Vec<(f64, f64)>,
    /// How the model was identified (report; not needed to simulate).
    #[serde(default)]
    pub report: serde_json::Value,
    /// Extensions `piezo diagnose --base` named, or `piezo fit --input-delay`'s delay.
    #[serde(default, skip_serializing_if = "Extensions::is_empty")]
    pub extensions: Extensions,
}

impl SsJson {
    pub fn new(
        model: &Hammerstein,
        fs_hz: f64,
        units: (&str, &str),
        report: serde_json::Value,
    ) -> Self {
        Self {
            format: crate::FORMAT.into(),
            model: if model.fronts.is_empty() {
                "ss"
            } else {
                "hammerstein-ss"
            }
            .into(),
            sample_rate_hz: fs_hz,
            inputs: model.linear.inputs(),
            outputs: model.linear.outputs(),
            input_unit: units.0.into(),
            output_unit: units.1.into(),
            order: model.linear.order(),
            hysteresis: model.fronts.iter().map(FrontJson::of).collect(),
            linear: model.linear.to_json(),
            schedule: None,
            lfr: None,
            input_range: Vec::new(),
            output_range: Vec::new(),
            modes_hz: model.linear.modes_hz(fs_hz),
            report,
            extensions: Extensions::default(),
        }
    }

    /// With an amplitude schedule (`scheduled-ss`).
    pub fn with_schedule(mut self, schedule: Option<Schedule>) -> Self {
        if schedule.is_some() {
            self.model = "scheduled-ss".into();
        }
        self.schedule = schedule;
        self
    }

    /// With a nonlinearity in feedback (`lfr`).
    pub fn with_lfr(mut self, lfr: &Lfr) -> Self {
        self.model = "lfr".into();
        self.linear = lfr.linear.to_json();
        self.modes_hz = lfr.linear.modes_hz(self.sample_rate_hz);
        self.lfr = Some(lfr.to_json());
        self
    }

    /// The LFR, checked (`None` for the other kinds).
    pub fn to_lfr(&self) -> anyhow::Result<Option<Lfr>> {
        match &self.lfr {
            None => Ok(None),
            Some(j) => Ok(Some(Lfr::from_json(self.to_model()?.linear, j)?)),
        }
    }

    /// The model, checked (with a schedule: the block at its center level).
    pub fn to_model(&self) -> anyhow::Result<Hammerstein> {
        anyhow::ensure!(
            self.sample_rate_hz.is_finite() && self.sample_rate_hz > 0.0,
            "fit.json: sample_rate_hz {} is not positive",
            self.sample_rate_hz
        );
        let linear = Modal::from_json(&self.linear)?;
        anyhow::ensure!(
            linear.inputs() == self.inputs && linear.outputs() == self.outputs,
            "fit.json: the linear block is {} x {}, `inputs`/`outputs` say {} x {}",
            linear.outputs(),
            linear.inputs(),
            self.outputs,
            self.inputs
        );
        anyhow::ensure!(
            self.hysteresis.is_empty() || self.hysteresis.len() == self.inputs,
            "fit.json: {} hysteresis models for {} inputs",
            self.hysteresis.len(),
            self.inputs
        );
        let fronts = self
            .hysteresis
            .iter()
            .map(|f| {
                let def = models::find(&f.model)?;
                let names = param_names(def);
                anyhow::ensure!(
                    names.len() == f.params.len(),
                    "fit.json: `{}` has {} parameters, {} given",
                    f.model,
                    names.len(),
                    f.params.len()
                );
                anyhow::ensure!(
                    f.params.iter().all(|p| p.1.is_finite()),
                    "fit.json: `{}` has a non-finite parameter",
                    f.model
                );
                Ok(Front {
                    def,
                    params: f.params.iter().map(|p| p.1).collect(),
                })
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        anyhow::ensure!(
            self.lfr.is_none() || self.schedule.is_none(),
            "fit.json: an LFR is not combined with a schedule"
        );
        anyhow::ensure!(
            self.lfr.is_some() == (self.model == "lfr"),
            "fit.json: model `{}` {} an `lfr` section",
            self.model,
            if self.lfr.is_some() {
                "with"
            } else {
                "without"
            }
        );
        if let Some(j) = &self.lfr {
            Lfr::from_json(linear.clone(), j)?;
        }
        if let Some(s) = &self.schedule {
            anyhow::ensure!(
                fronts.is_empty(),
                "fit.json: a schedule and hysteresis fronts are not combined"
            );
            s.models(&linear)?;
        }
        Ok(Hammerstein { fronts, linear })
    }
}

fn param_names(def: &models::ModelDef) -> Vec<String> {
    (def.params)(&Scales::of(&[0.0, 1.0], &[0.0, 1.0], 1.0))
        .into_iter()
        .map(|s| s.name)
        .collect()
}
