//! `piezo._native`: the identification library (`piezo-ident`) for the `piezo` Python
//! package. Records come in as NumPy arrays (`t`, `u` and `y` channel-major, in s, V and um)
//! with the name the reports give them; the pure-Python wrappers (`python/piezo/`) accept
//! paths and arrays of either orientation and build plain Python objects from what these
//! functions return. Errors are raised as `piezo.errors` exceptions with the CLI's messages.
use std::path::PathBuf;

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use piezo_ident::diagnose::{consistency, diagnose_records, from_base, report, Options, Signals};
use piezo_ident::fit::{models, FitOptions};
use piezo_ident::identify::{self, fit_linear_part, FitInput};
use piezo_ident::optim::Optimizer;
use piezo_ident::record::{Layout, Quantity, Record};
use piezo_ident::saved::{score_last_period, Loaded};
use piezo_ident::ss::fitting::{self, FitArgs, FitOptions as SsFitOptions};
use piezo_ident::ss::frf::detect_period;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A record handed over from Python: `(name, t, u, y)`, `u` and `y` of shape
/// (channels, samples) (`y` may have no rows: an input record).
type RecordIn<'py> = (
    String,
    PyReadonlyArray1<'py, f64>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray2<'py, f64>,
);

/// The exception for an error of the library: `piezo.errors.FileError` (an `OSError`) when
/// a file could not be read or written, else `piezo.errors.InputError` (a `ValueError`);
/// the message is what the `piezo` CLI prints after `error: `.
fn raise(py: Python<'_>, e: anyhow::Error) -> PyErr {
    let io = e.chain().any(|c| c.is::<std::io::Error>());
    let msg = format!("{e:#}");
    let class = if io { "FileError" } else { "InputError" };
    match py
        .import("piezo.errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.call1((msg.clone(),)))
    {
        Ok(obj) => PyErr::from_value(obj),
        Err(_) if io => pyo3::exceptions::PyOSError::new_err(msg),
        Err(_) => pyo3::exceptions::PyValueError::new_err(msg),
    }
}

fn rows(a: &PyReadonlyArray2<'_, f64>) -> Vec<Vec<f64>> {
    a.as_array().outer_iter().map(|r| r.to_vec()).collect()
}

/// Channels as a (channels, samples) array.
fn array2<'py>(
    py: Python<'py>,
    chans: &[Vec<f64>],
    n: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = chans.iter().flatten().copied().collect();
    PyArray1::from_vec(py, flat).reshape([chans.len(), n])
}

/// The record `r` holds (outputs optional for `inputs_only`), checked like a read file.
fn record(r: &RecordIn<'_>, inputs_only: bool) -> anyhow::Result<(String, Record)> {
    let (name, t, u, y) = r;
    let (t, u, y) = (t.as_array().to_vec(), rows(u), rows(y));
    let rec = if inputs_only && y.is_empty() {
        Record::inputs(t, u)
    } else {
        Record::new(t, u, y)
    };
    let rec = rec.map_err(|e| anyhow::anyhow!("record {name}: {e}"))?;
    Ok((name.clone(), rec))
}

fn signals(r: &RecordIn<'_>) -> anyhow::Result<(String, Signals)> {
    let (name, rec) = record(r, false)?;
    let s = Signals::new(rec.t, rec.u, rec.y).map_err(|e| e.context(format!("record {name}")))?;
    Ok((name, s))
}

/// Reads a record of the project's CSV convention (`piezo_ident::record`): time, inputs and
/// outputs in s, V and um; the columns and the units of columns that name none as the CLI's
/// `--t-col`, `--u-col`, `--y-col`, `--input-unit`, `--output-unit`.
#[pyfunction]
#[pyo3(signature = (path, t_col=None, u_col=Vec::new(), y_col=Vec::new(), input_unit="V".to_string(), output_unit="um".to_string(), outputs_optional=false))]
#[allow(clippy::too_many_arguments)]
fn read_record<'py>(
    py: Python<'py>,
    path: PathBuf,
    t_col: Option<String>,
    u_col: Vec<String>,
    y_col: Vec<String>,
    input_unit: String,
    output_unit: String,
    outputs_optional: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let layout = Layout {
        t: t_col,
        u: u_col,
        y: y_col,
        u_unit: input_unit,
        y_unit: output_unit,
        outputs_optional,
    };
    let r = Record::read_with(&path, &layout).map_err(|e| raise(py, e))?;
    let n = r.len();
    let d = PyDict::new(py);
    d.set_item("t", PyArray1::from_vec(py, r.t))?;
    d.set_item("u", array2(py, &r.u, n)?)?;
    d.set_item("y", array2(py, &r.y, n)?)?;
    let extra = PyDict::new(py);
    for (name, c) in r.extra {
        extra.set_item(name, PyArray1::from_vec(py, c))?;
    }
    d.set_item("extra", extra)?;
    d.set_item("comments", r.comments)?;
    d.set_item("unit_note", r.unit_note)?;
    Ok(d)
}

/// The models `fit` knows: `(name, what it is)`, as `piezo fit --list`.
#[pyfunction]
fn models_list() -> Vec<(&'static str, &'static str)> {
    models::MODELS.iter().map(|m| (m.name, m.about)).collect()
}

/// `piezo fit` on records: identifies `model` on `train` (split at `split` when given, or
/// validated on `valid`) and returns the `fit.json` text and the simulated outputs.
#[pyfunction]
#[pyo3(signature = (train, model, valid=None, split=None, valid_periodic=0, linear=0, linear_train=None, optimizer="de".to_string(), generations=300, population=0, seed=1, lm_iterations=60, upsample=20, progress=false))]
#[allow(clippy::too_many_arguments)]
fn fit<'py>(
    py: Python<'py>,
    train: RecordIn<'py>,
    model: String,
    valid: Option<RecordIn<'py>>,
    split: Option<f64>,
    valid_periodic: usize,
    linear: usize,
    linear_train: Option<RecordIn<'py>>,
    optimizer: String,
    generations: usize,
    population: usize,
    seed: u64,
    lm_iterations: usize,
    upsample: usize,
    progress: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let optional = |r: &Option<RecordIn<'py>>| r.as_ref().map(|v| record(v, false)).transpose();
    let inputs = record(&train, false)
        .and_then(|(name, whole)| Ok((name, whole, optional(&valid)?, optional(&linear_train)?)))
        .map_err(|e| raise(py, e))?;
    let started = std::time::Instant::now();
    let run = move || -> anyhow::Result<identify::Fit> {
        let (train_name, whole, valid, linear_train) = inputs;
        anyhow::ensure!(
            !piezo_ident::saved::handles(&model),
            "model `{model}`: the state-space models (ss, hammerstein-ss, scheduled-ss, lfr) are fitted by fit_ss (piezo.fit routes them there)"
        );
        let def = models::find(&model)?;
        anyhow::ensure!(linear <= 2, "--linear {linear}: at most 2 sections");
        let optimizer = match optimizer.as_str() {
            "de" => Optimizer::De,
            "pso" => Optimizer::Pso,
            o => anyhow::bail!("optimizer `{o}`: expected de or pso"),
        };
        let (train, valid, valid_name, valid_from) = match (valid, split) {
            (Some(_), Some(_)) => anyhow::bail!("--split and --valid exclude each other"),
            (Some((name, v)), None) => (whole, Some(v), Some(name), 0),
            (None, Some(f)) => {
                anyhow::ensure!(
                    valid_periodic == 0,
                    "--valid-periodic needs a --valid record of whole periods, not --split"
                );
                let k = identify::split_sample(whole.len(), f)?;
                let s = identify::split(whole, &train_name, k);
                (s.train, Some(s.valid), Some(s.valid_name), s.valid_from)
            }
            (None, None) => (whole, None, None, 0),
        };
        let opts = FitOptions {
            optimizer,
            generations,
            population,
            seed,
            lm_iterations,
            upsample: upsample.max(1),
            linear_sections: linear,
            progress,
            ..Default::default()
        };
        let linear_step = linear_train
            .map(|(name, rec)| {
                fit_linear_part(&rec, linear.max(1), &opts)
                    .map_err(|e| e.context(format!("--linear-train {name}")))
            })
            .transpose()?;
        identify::fit(
            FitInput {
                def,
                train: &train,
                train_name,
                valid: valid.as_ref().zip(valid_name),
                valid_from,
                valid_periodic,
                linear_step,
                input_unit: Quantity::Voltage.internal().into(),
                output_unit: Quantity::Length.internal().into(),
                started,
            },
            &opts,
        )
    };
    let f = py.detach(run).map_err(|e| raise(py, e))?;
    let json = f.report.to_json().map_err(|e| raise(py, e))?;
    let n_train = f.train_sim.first().map_or(0, Vec::len);
    let d = PyDict::new(py);
    d.set_item("fit_json", json)?;
    d.set_item("train_sim", array2(py, &f.train_sim, n_train)?)?;
    for (key, sim) in [
        ("valid_sim", &f.valid_sim),
        ("valid_rest_sim", &f.valid_rest_sim),
    ] {
        match sim {
            Some(s) => d.set_item(key, array2(py, s, s.first().map_or(0, Vec::len))?)?,
            None => d.set_item(key, py.None())?,
        }
    }
    Ok(d)
}

/// `piezo fit --model ss | hammerstein-ss | scheduled-ss | lfr` on records: one
/// multivariable model for all `train` records; returns the `fit.json` text.
#[pyfunction]
#[pyo3(signature = (train, model, order=None, hysteresis="cbw".to_string(), lm_iterations=60, joint_iterations=30, schedule_tau_s=0.15, lfr_basis=None, lfr_linear=None, lfr_channels="outputs:2".to_string(), lfr_iterations=30, lfr_guard=None, input_delay=0, progress=false))]
#[allow(clippy::too_many_arguments)]
fn fit_ss(
    py: Python<'_>,
    train: Vec<RecordIn<'_>>,
    model: String,
    order: Option<String>,
    hysteresis: String,
    lm_iterations: usize,
    joint_iterations: usize,
    schedule_tau_s: f64,
    lfr_basis: Option<Vec<String>>,
    lfr_linear: Option<String>,
    lfr_channels: String,
    lfr_iterations: usize,
    lfr_guard: Option<f64>,
    input_delay: usize,
    progress: bool,
) -> PyResult<String> {
    let (names, recs): (Vec<String>, Vec<Record>) = train
        .iter()
        .map(|r| record(r, false))
        .collect::<anyhow::Result<Vec<_>>>()
        .map_err(|e| raise(py, e))?
        .into_iter()
        .unzip();
    let run = move || -> anyhow::Result<String> {
        let opts = SsFitOptions::parse(&FitArgs {
            model: &model,
            order: order.as_deref(),
            hysteresis: &hysteresis,
            lm_iterations,
            joint_iterations,
            schedule_tau_s,
            lfr_basis: lfr_basis.as_deref().unwrap_or_default(),
            lfr_linear: lfr_linear.as_deref(),
            lfr_channels: &lfr_channels,
            lfr_iterations,
            lfr_guard,
            input_delay,
            progress,
        })?;
        let f = fitting::fit(recs, &names, &opts)?;
        Ok(serde_json::to_string_pretty(&f.saved)?)
    };
    py.detach(run).map_err(|e| raise(py, e))
}

/// `piezo predict`: simulates the saved model (the text of a `fit.json`, or without it the
/// file `name`) from rest on the input record; with measured outputs, their RMSE over the
/// last period.
#[pyfunction]
#[pyo3(signature = (model_json, name, input))]
fn predict<'py>(
    py: Python<'py>,
    model_json: Option<String>,
    name: String,
    input: RecordIn<'py>,
) -> PyResult<Bound<'py, PyDict>> {
    let (_, rec) = record(&input, true).map_err(|e| raise(py, e))?;
    let run = move || -> anyhow::Result<_> {
        let model = match model_json {
            Some(text) => Loaded::parse(&text, &name)?,
            None => Loaded::read(&PathBuf::from(&name))?,
        };
        let sim = model.simulate(&rec)?;
        let score = if rec.y.is_empty() {
            None
        } else {
            anyhow::ensure!(
                rec.y.len() == sim.len(),
                "the record has {} outputs, the model {}",
                rec.y.len(),
                sim.len()
            );
            let (per, mean) = score_last_period(&rec, &sim);
            Some((per, mean, detect_period(&rec)))
        };
        Ok((rec.len(), sim, score))
    };
    let (n, sim, score) = py.detach(run).map_err(|e| raise(py, e))?;
    let d = PyDict::new(py);
    d.set_item("y", array2(py, &sim, n)?)?;
    match score {
        Some((per, mean, period)) => {
            d.set_item("rmse_last_period", per)?;
            d.set_item("rmse_mean", mean)?;
            d.set_item("period_samples", period)?;
        }
        None => {
            d.set_item("rmse_last_period", py.None())?;
            d.set_item("rmse_mean", py.None())?;
            d.set_item("period_samples", py.None())?;
        }
    }
    Ok(d)
}

/// `piezo diagnose`: what the classical Bouc-Wen model misses on these records. Without
/// validation records each training record is split at `split` (0.5 by default). Returns
/// the JSON report (`piezo diagnose --json`) and the summary for a person.
#[pyfunction]
#[pyo3(signature = (train, valid=Vec::new(), split=None, consistency=true))]
fn diagnose<'py>(
    py: Python<'py>,
    train: Vec<RecordIn<'py>>,
    valid: Vec<RecordIn<'py>>,
    split: Option<f64>,
    consistency: bool,
) -> PyResult<(String, String)> {
    let read = |set: &[RecordIn<'py>]| -> anyhow::Result<(Vec<String>, Vec<Signals>)> {
        Ok(set
            .iter()
            .map(signals)
            .collect::<anyhow::Result<Vec<_>>>()?
            .into_iter()
            .unzip())
    };
    if train.is_empty() {
        return Err(raise(
            py,
            anyhow::anyhow!("--train is required (see --help)"),
        ));
    }
    let train = read(&train).map_err(|e| raise(py, e))?;
    let valid = read(&valid).map_err(|e| raise(py, e))?;
    let run = move || -> anyhow::Result<(String, String)> {
        let ((train_names, train), (valid_names, valid)) = (train, valid);
        // The same self-check as `piezo diagnose`: the other splits of a split record, the
        // swapped roles of a pair.
        let (train, valid, note, valid_names, label, others) = if valid.is_empty() {
            let f = split.unwrap_or(0.5);
            let others = consistency::other_splits(&train, f);
            let h = report::split_records(train, &train_names, f)?;
            let label = format!("split {f}");
            (
                h.train,
                h.valid,
                Some(h.note),
                train_names.clone(),
                label,
                others,
            )
        } else {
            anyhow::ensure!(split.is_none(), "--split and --valid exclude each other");
            let others = vec![consistency::Arrangement::swapped(&train, &valid)];
            (
                train,
                valid,
                None,
                valid_names,
                "as given".to_string(),
                others,
            )
        };
        let opt = Options::default();
        let d = diagnose_records(&train, &valid, &opt)?;
        let mut j = report::json(&d, note.as_deref(), &train_names, &valid_names, &[]);
        let mut text = report::summary(&d, note.as_deref());
        if consistency {
            let c = consistency::check(&label, &d, &others, &opt)?;
            j["consistency"] = c.json();
            text.push_str(&c.text());
            text.push('\n');
        }
        Ok((serde_json::to_string_pretty(&j)?, text))
    };
    py.detach(run).map_err(|e| raise(py, e))
}

/// `piezo diagnose --base`: discovery from an identified state-space model (the text of a
/// `fit.json`, or without it the file `name`) on periodic records. Returns the JSON report
/// (`piezo diagnose --base --json`), the text report and the final model's `fit.json`.
#[pyfunction]
#[pyo3(signature = (base_json, name, train, valid))]
fn diagnose_base<'py>(
    py: Python<'py>,
    base_json: Option<String>,
    name: String,
    train: Vec<RecordIn<'py>>,
    valid: Vec<RecordIn<'py>>,
) -> PyResult<(String, String, String)> {
    let read = |set: &[RecordIn<'py>]| -> anyhow::Result<(Vec<String>, Vec<Record>)> {
        Ok(set
            .iter()
            .map(|r| record(r, false))
            .collect::<anyhow::Result<Vec<_>>>()?
            .into_iter()
            .unzip())
    };
    let (train_names, train) = read(&train).map_err(|e| raise(py, e))?;
    let (valid_names, valid) = read(&valid).map_err(|e| raise(py, e))?;
    let run = move || -> anyhow::Result<(String, String, String)> {
        let model = match base_json {
            Some(text) => Loaded::parse(&text, &name)?,
            None => Loaded::read(&PathBuf::from(&name))?,
        };
        let Loaded::Ss(saved) = model else {
            anyhow::bail!(
                "{name}: base= takes a state-space fit.json (piezo fit --model ss | hammerstein-ss | scheduled-ss | lfr); the per-axis hysteresis fits are diagnose's own base already"
            );
        };
        let r = from_base::run(
            &saved,
            &name,
            (&train, &train_names),
            (&valid, &valid_names),
            false,
        )?;
        Ok((
            serde_json::to_string_pretty(&r.json)?,
            r.diagnosis.text(&saved.output_unit),
            serde_json::to_string_pretty(&r.fit)?,
        ))
    };
    py.detach(run).map_err(|e| raise(py, e))
}

#[pymodule]
#[pyo3(name = "_native")]
fn native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read_record, m)?)?;
    m.add_function(wrap_pyfunction!(models_list, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(fit_ss, m)?)?;
    m.add_function(wrap_pyfunction!(predict, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose_base, m)?)?;
    m.add("FORMAT", piezo_ident::FORMAT)?;
    Ok(())
}
