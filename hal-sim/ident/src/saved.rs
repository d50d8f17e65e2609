//! The saved model: what `piezo fit --out DIR` writes to `DIR/fit.json` (format
//! [`FORMAT`]) and `piezo predict` / `piezo sim --stage` read back, for every model kind.
use crate::fit::resample::Edge;
use crate::fit::{models, Fitted, Metrics};
use crate::multibw::MultiBwFit;
use crate::numeric::rmse;
use crate::record::{Quantity, Record};
use crate::ss::frf::detect_period;
use crate::ss::saved::SsJson;
use anyhow::{Context, Result};
use serde::Serialize;
use serde_json::Value;
use std::path::Path;

pub use super::FORMAT;

/// One identified channel pair.
#[derive(Debug, Serialize)]
pub struct Part {
    /// `direct` (u_i -> y_i), `coupling` (u_j -> y_i, 003 sec. IV.C) or `siso`.
    pub kind: &'static str,
    pub input: usize,
    pub output: usize,
    pub fit: Fitted,
}

/// The fit quality of one output.
#[derive(Debug, Serialize)]
pub struct ChannelMetrics {
    pub output: usize,
    pub metrics: Metrics,
}

/// What `piezo fit` reports.
#[derive(Debug, Serialize)]
pub struct Report {
    /// `piezo-fit/1`: what `piezo predict` reads.
    pub format: &'static str,
    pub model: String,
    /// Sample rate of the training record (dynamic models are simulated at the rate of
    /// the record they are given).
    pub sample_rate_hz: f64,
    pub inputs: usize,
    pub outputs: usize,
    pub input_unit: String,
    pub output_unit: String,
    pub train: String,
    pub valid: Option<String>,
    /// Two-step Hammerstein: the linear part identified first.
    pub linear_step: Option<Fitted>,
    pub parts: Vec<Part>,
    /// `--model cbw` on a multi-axis record: the multivariable Bouc-Wen of 003 (its direct
    /// transfers are also in `parts`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub multibw: Option<MultiBwFit>,
    pub train_metrics: Vec<ChannelMetrics>,
    pub valid_metrics: Vec<ChannelMetrics>,
    /// With `--valid-periodic`: the same validation record simulated from rest, for
    /// comparison (scored over the same samples).
    pub valid_from_rest_metrics: Vec<ChannelMetrics>,
    pub seconds: f64,
}

impl Report {
    /// The text of `fit.json`.
    pub fn to_json(&self) -> Result<String> {
        Ok(serde_json::to_string_pretty(self)?)
    }
}

/// Writes `dir/fit.json` (what `piezo predict` and `piezo serial load-fit` read); its path.
pub fn write_fit_json(dir: &Path, report: &Report) -> Result<std::path::PathBuf> {
    let path = dir.join("fit.json");
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    std::fs::write(&path, report.to_json()?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// True for the model names `piezo fit` fits as state-space models (`crate::cli::fit_ss`).
pub fn handles(model: &str) -> bool {
    matches!(model, "ss" | "hammerstein-ss" | "scheduled-ss" | "lfr")
}

/// Simulates every output of `rec` with the identified parts (summed per output).
pub fn simulate(parts: &[Part], rec: &Record, periodic: usize) -> Result<Vec<Vec<f64>>> {
    let mut out = vec![vec![0.0; rec.len()]; rec.y.len()];
    for p in parts {
        let u = rec.u.get(p.input).with_context(|| {
            format!(
                "the record has {} inputs; the model needs input {}",
                rec.u.len(),
                p.input + 1
            )
        })?;
        let y = if periodic > 0 {
            p.fit.simulate_periodic(u, rec.dt(), periodic)?
        } else {
            p.fit.simulate(u, rec.dt(), Edge::Hold)?
        };
        let dst = out.get_mut(p.output).with_context(|| {
            format!(
                "the record has {} outputs; the model needs output {}",
                rec.y.len(),
                p.output + 1
            )
        })?;
        for (d, v) in dst.iter_mut().zip(y) {
            *d += v;
        }
    }
    Ok(out)
}

/// A saved model of any kind `piezo fit` writes.
#[derive(Debug)]
pub enum Loaded {
    Ss(Box<SsJson>),
    /// The multivariable Bouc-Wen of 003 (`piezo fit --model cbw` on several axes).
    MultiBw(Box<MultiBwFit>),
    /// The per-channel models of the classic fits (cbw, structural-bw, ...).
    Parts {
        parts: Vec<Part>,
        outputs: usize,
    },
}

fn field<'a>(v: &'a Value, key: &str, path: &str) -> Result<&'a Value> {
    v.get(key).with_context(|| format!("{path}: no `{key}`"))
}

fn num(v: &Value, key: &str, path: &str) -> Result<f64> {
    field(v, key, path)?
        .as_f64()
        .with_context(|| format!("{path}: `{key}` is not a number"))
}

/// The models are simulated in V and um (what `crate::record` reads records in): a report
/// in other units (written by hand or by another tool) is refused rather than run off by a
/// factor; one without units (older `piezo fit`) is taken as V and um.
fn check_units(v: &Value, path: &str) -> Result<()> {
    for (key, q) in [
        ("input_unit", Quantity::Voltage),
        ("output_unit", Quantity::Length),
    ] {
        let Some(unit) = v.get(key).filter(|u| !u.is_null()) else {
            continue;
        };
        let unit = unit
            .as_str()
            .with_context(|| format!("{path}: `{key}` is not a unit name"))?;
        let f = q
            .factor(unit.trim())
            .map_err(|e| anyhow::anyhow!("{path}: `{key}`: {e}"))?;
        anyhow::ensure!(
            f == 1.0,
            "{path}: `{key}` is {unit}; models are simulated in {} (refit on a record whose header names its units, which `piezo fit` converts)",
            q.internal()
        );
    }
    Ok(())
}

/// Rebuilds a classic fit part from its JSON (`Part` as `piezo fit` writes it).
fn part(v: &Value, path: &str) -> Result<Part> {
    let fit = field(v, "fit", path)?;
    let name = field(fit, "model", path)?
        .as_str()
        .with_context(|| format!("{path}: `model` is not a name"))?;
    let def = models::find(name)?;
    let params: Vec<f64> = field(fit, "params", path)?
        .as_array()
        .with_context(|| format!("{path}: `params` is not a list"))?
        .iter()
        .map(|p| {
            p.get(1)
                .and_then(Value::as_f64)
                .with_context(|| format!("{path}: a parameter is not [name, value]"))
        })
        .collect::<Result<_>>()?;
    let mut f = Fitted::from_params(
        def,
        &params,
        num(fit, "sign", path)?,
        num(fit, "offset", path)?,
        num(fit, "upsample", path)? as usize,
    )?;
    if let Some(lin) = fit.get("linear").and_then(Value::as_array) {
        f.linear = lin
            .iter()
            .map(|s| {
                match (
                    s.get(0).and_then(Value::as_f64),
                    s.get(1).and_then(Value::as_f64),
                ) {
                    (Some(a), Some(b)) => Ok((a, b)),
                    _ => anyhow::bail!("{path}: a linear section is not [f_hz, zeta]"),
                }
            })
            .collect::<Result<_>>()?;
    }
    let idx = |k: &str| -> Result<usize> {
        field(v, k, path)?
            .as_u64()
            .map(|x| x as usize)
            .with_context(|| format!("{path}: `{k}` is not an index"))
    };
    let kind = match field(v, "kind", path)?.as_str() {
        Some("direct") => "direct",
        Some("coupling") => "coupling",
        _ => "siso",
    };
    Ok(Part {
        kind,
        input: idx("input")?,
        output: idx("output")?,
        fit: f,
    })
}

impl Loaded {
    /// Reads a `fit.json`.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses the text of a `fit.json`; `name` says where it came from in errors.
    ///
    /// ```
    /// use piezo_ident::saved::Loaded;
    /// let err = Loaded::parse(r#"{"model": "cbw", "output_unit": "nm"}"#, "fit.json").unwrap_err();
    /// assert!(format!("{err:#}").contains("`output_unit` is nm; models are simulated in um"));
    /// ```
    pub fn parse(text: &str, name: &str) -> Result<Self> {
        let v: Value = serde_json::from_str(text).with_context(|| format!("{name}: not JSON"))?;
        let p = name.to_string();
        check_units(&v, &p)?;
        let model = field(&v, "model", &p)?.as_str().unwrap_or_default();
        if handles(model) {
            let s: SsJson = serde_json::from_value(v)
                .with_context(|| format!("{p}: not a state-space fit.json"))?;
            s.to_model().with_context(|| p.clone())?;
            return Ok(Self::Ss(Box::new(s)));
        }
        if let Some(m) = v.get("multibw").filter(|m| !m.is_null()) {
            let m: MultiBwFit = serde_json::from_value(m.clone())
                .with_context(|| format!("{p}: `multibw` is not a multivariable Bouc-Wen"))?;
            m.simulate(&vec![vec![0.0; 2]; m.inputs])
                .with_context(|| p.clone())?;
            return Ok(Self::MultiBw(Box::new(m)));
        }
        let parts = field(&v, "parts", &p)?
            .as_array()
            .with_context(|| format!("{p}: `parts` is not a list"))?
            .iter()
            .map(|x| part(x, &p))
            .collect::<Result<Vec<_>>>()?;
        anyhow::ensure!(!parts.is_empty(), "{p}: no model parts");
        let outputs = parts.iter().map(|x| x.output + 1).max().unwrap_or(1);
        Ok(Self::Parts { parts, outputs })
    }

    pub fn inputs(&self) -> usize {
        match self {
            Self::Ss(s) => s.inputs,
            Self::MultiBw(m) => m.inputs,
            Self::Parts { parts, .. } => parts.iter().map(|x| x.input + 1).max().unwrap_or(1),
        }
    }

    pub fn outputs(&self) -> usize {
        match self {
            Self::Ss(s) => s.outputs,
            Self::MultiBw(m) => m.outputs,
            Self::Parts { outputs, .. } => *outputs,
        }
    }

    /// Simulated outputs of `rec`'s inputs from rest.
    pub fn simulate(&self, rec: &Record) -> Result<Vec<Vec<f64>>> {
        anyhow::ensure!(
            rec.u.len() == self.inputs(),
            "the model has {} inputs, the record {} (columns u1..u{})",
            self.inputs(),
            rec.u.len(),
            self.inputs()
        );
        match self {
            Self::Ss(s) => {
                let fs = rec.sample_rate_hz();
                anyhow::ensure!(
                    (fs / s.sample_rate_hz - 1.0).abs() < 1e-3,
                    "the record is sampled at {fs:.6} Hz, the model at {:.6} Hz",
                    s.sample_rate_hz
                );
                crate::ss::extended::Model::of_saved(s)?.simulate(&rec.u, rec.dt())
            }
            Self::MultiBw(m) => m.simulate(&rec.u),
            Self::Parts { parts, outputs } => {
                let shaped = Record {
                    y: vec![vec![0.0; rec.len()]; *outputs],
                    ..rec.clone()
                };
                simulate(parts, &shaped, 0)
            }
        }
    }
}

/// RMSE of each output over the last period (the whole record when not periodic) and
/// their mean: the benchmark's score of one record.
pub fn score_last_period(rec: &Record, sim: &[Vec<f64>]) -> (Vec<f64>, f64) {
    let n = detect_period(rec);
    let start = rec.len() - n;
    let per: Vec<f64> = rec
        .y
        .iter()
        .zip(sim)
        .map(|(y, s)| rmse(&y[start..], &s[start..]))
        .collect();
    let mean = per.iter().sum::<f64>() / per.len().max(1) as f64;
    (per, mean)
}

/// `a, b, c` with 5 significant digits.
pub fn list(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.5e}"))
        .collect::<Vec<_>>()
        .join(", ")
}
