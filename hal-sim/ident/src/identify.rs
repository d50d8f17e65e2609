//! Identification of a record: the model of `piezo fit` (one SISO fit, a model per
//! input-output pair, or the multivariable Bouc-Wen of 003), scored on the training and the
//! validation record; what `piezo fit`, `piezo serial identify` and the Python package's
//! `piezo.fit` run between reading their records and writing `fit.json` ([`crate::saved`]).
use crate::fit::resample::Edge;
use crate::fit::{fit_siso, metrics, models, FitOptions, Fitted};
use crate::multibw::{self, MultiBwFit};
use crate::record::Record;
use crate::saved::{simulate, ChannelMetrics, Part, Report, FORMAT};
use anyhow::{Context, Result};

/// What [`identify`] found.
#[derive(Debug)]
pub struct Identified {
    pub parts: Vec<Part>,
    /// The multivariable Bouc-Wen of 003; when present it is the model (`parts` then hold
    /// its direct transfers of step 1 for the report).
    pub multibw: Option<MultiBwFit>,
}

/// Simulates every output of `rec` with the identified model (`periodic`: as
/// [`simulate`]).
fn simulate_identified(id: &Identified, rec: &Record, periodic: usize) -> Result<Vec<Vec<f64>>> {
    match &id.multibw {
        Some(m) => m.simulate_periodic(&rec.u, periodic),
        None => simulate(&id.parts, rec, periodic),
    }
}

/// Metrics of every output over the samples from `skip` on (a fit's warm-up is not scored).
fn metrics_after(rec: &Record, sim: &[Vec<f64>], skip: usize) -> Vec<ChannelMetrics> {
    rec.y
        .iter()
        .zip(sim)
        .enumerate()
        .map(|(i, (y, s))| {
            let k = skip.min(y.len()).min(s.len());
            ChannelMetrics {
                output: i,
                metrics: metrics(&y[k..], &s[k..]),
            }
        })
        .collect()
}

/// Identifies `def` on `train`: one SISO fit; for `cbw` on a multi-axis record the
/// multivariable Bouc-Wen of 003 in its two steps (sec. IV: direct transfers, then
/// couplings driven by the direct states `h_j`, eq. 12-13; [`multibw`]); for any other model
/// on a multi-axis record, [`identify_pairs`].
pub fn identify(
    def: &'static models::ModelDef,
    train: &Record,
    opts: &FitOptions,
) -> Result<Identified> {
    let multi = train.u.len() > 1 || train.y.len() > 1;
    if !(multi && def.name == "cbw") {
        return Ok(Identified {
            parts: identify_pairs(def, train, opts)?,
            multibw: None,
        });
    }
    let m = multibw::identify(train, opts)?;
    let parts = m
        .direct
        .iter()
        .enumerate()
        .map(|(j, f)| Part {
            kind: "direct",
            input: j,
            output: j,
            fit: f.clone(),
        })
        .collect();
    Ok(Identified {
        parts,
        multibw: Some(m),
    })
}

/// One SISO fit, or for multi-axis records a model of the class of `def` per input-output
/// pair, each with its own state: direct pairs first, then couplings `u_j -> y_i` fitted on
/// what the direct models leave (kept where they lower the RMSE by more than 1 %), two
/// rounds. This is not 003's coupling structure (there a coupling is driven by the direct
/// state `h_j`, eq. 12); it serves the models that have no multivariable form.
pub fn identify_pairs(
    def: &'static models::ModelDef,
    train: &Record,
    opts: &FitOptions,
) -> Result<Vec<Part>> {
    let (k, n) = (train.u.len(), train.y.len());
    let dt = train.dt();
    if k == 1 && n == 1 {
        let f = fit_siso(def, &train.u[0], &train.y[0], dt, opts)?;
        return Ok(vec![Part {
            kind: "siso",
            input: 0,
            output: 0,
            fit: f,
        }]);
    }
    let sim = |f: &Fitted, j: usize| f.simulate(&train.u[j], dt, Edge::Hold);
    let mut direct: Vec<Option<Fitted>> = (0..n).map(|_| None).collect();
    let mut couplings: Vec<Vec<(usize, Fitted)>> = (0..n).map(|_| Vec::new()).collect();
    // Two rounds: the second refits each direct model on what the couplings of the first
    // leave (a coupled output is not zero while its own input rests).
    for round in 1..=2 {
        for i in 0..n {
            let mut target = train.y[i].clone();
            for (j, f) in &couplings[i] {
                for (t, v) in target.iter_mut().zip(sim(f, *j)?) {
                    *t -= v;
                }
            }
            // Step 1 (003 sec. IV.B): direct hysteresis u_i -> y_i.
            let mut residual = train.y[i].clone();
            if i < k {
                if opts.progress {
                    eprintln!("round {round}, step 1: direct u{} -> y{}", i + 1, i + 1);
                }
                let f = fit_siso(def, &train.u[i], &target, dt, opts)
                    .with_context(|| format!("direct fit u{} -> y{}", i + 1, i + 1))?;
                for (r, v) in residual.iter_mut().zip(sim(&f, i)?) {
                    *r -= v;
                }
                direct[i] = Some(f);
            }
            // Step 2 (003 sec. IV.C): couplings u_j -> y_i on the direct residual.
            couplings[i].clear();
            for j in (0..k).filter(|&j| j != i) {
                if opts.progress {
                    eprintln!("round {round}, step 2: coupling u{} -> y{}", j + 1, i + 1);
                }
                let f = fit_siso(def, &train.u[j], &residual, dt, opts)
                    .with_context(|| format!("coupling fit u{} -> y{}", j + 1, i + 1))?;
                let c = sim(&f, j)?;
                let before = metrics(&residual, &vec![0.0; residual.len()]).rmse;
                if metrics(&residual, &c).rmse < 0.99 * before {
                    for (r, v) in residual.iter_mut().zip(&c) {
                        *r -= v;
                    }
                    couplings[i].push((j, f));
                }
            }
        }
    }
    let mut parts = Vec::new();
    for (i, (d, cs)) in direct.into_iter().zip(couplings).enumerate() {
        if let Some(f) = d {
            parts.push(Part {
                kind: "direct",
                input: i,
                output: i,
                fit: f,
            });
        }
        for (j, f) in cs {
            parts.push(Part {
                kind: "coupling",
                input: j,
                output: i,
                fit: f,
            });
        }
    }
    Ok(parts)
}

/// Step 1 of the two-step Hammerstein identification (004 sec. 4.2): the linear part alone,
/// a gain followed by `sections` second-order sections (unity DC gain), from a record of
/// one input and one output (PRBS or step response); `piezo fit --linear-train`.
pub fn fit_linear_part(rec: &Record, sections: usize, opts: &FitOptions) -> Result<Fitted> {
    anyhow::ensure!(
        rec.u.len() == 1 && rec.y.len() == 1,
        "the linear part needs a record of one input and one output"
    );
    anyhow::ensure!(
        (1..=2).contains(&sections),
        "the linear part has 1 or 2 sections, {sections} asked"
    );
    let step1 = FitOptions {
        linear_sections: sections,
        linear_fixed: None,
        ..opts.clone()
    };
    fit_siso(
        models::find("gain")?,
        &rec.u[0],
        &rec.y[0],
        rec.dt(),
        &step1,
    )
}

/// What a fit starts from.
pub struct FitInput<'a> {
    pub def: &'static models::ModelDef,
    pub train: &'a Record,
    /// Where the training record came from (the report's `train`).
    pub train_name: String,
    /// Validation record and its name: simulated with the identified model, never fitted.
    pub valid: Option<(&'a Record, String)>,
    /// Samples at the start of the validation record that are not scored (`--split`: the
    /// training part the model runs through first).
    pub valid_from: usize,
    /// The validation record is one period of a periodic steady state: simulate this many
    /// periods first (0: from rest).
    pub valid_periodic: usize,
    /// Step 1 of the two-step Hammerstein ([`fit_linear_part`]): its linear part is kept
    /// fixed while `def` is fitted.
    pub linear_step: Option<Fitted>,
    pub input_unit: String,
    pub output_unit: String,
    /// When the work began (the report's `seconds`).
    pub started: std::time::Instant,
}

impl<'a> FitInput<'a> {
    /// A fit of `def` on the whole of `train` (called `name` in the report), in V and um,
    /// without a validation record.
    pub fn train(def: &'static models::ModelDef, train: &'a Record, name: &str) -> Self {
        Self {
            def,
            train,
            train_name: name.into(),
            valid: None,
            valid_from: 0,
            valid_periodic: 0,
            linear_step: None,
            input_unit: crate::record::Quantity::Voltage.internal().into(),
            output_unit: crate::record::Quantity::Length.internal().into(),
            started: std::time::Instant::now(),
        }
    }
}

/// A fit: the report (`fit.json`) and the simulated outputs it was scored on.
pub struct Fit {
    pub report: Report,
    pub train_sim: Vec<Vec<f64>>,
    pub valid_sim: Option<Vec<Vec<f64>>>,
    pub valid_rest_sim: Option<Vec<Vec<f64>>>,
}

/// Identifies `input.def` on the training record and scores it there and on the
/// validation record: what `piezo fit` does between reading its records and writing them
/// out (`piezo serial identify` runs it on what it recorded).
pub fn fit(input: FitInput<'_>, opts: &FitOptions) -> Result<Fit> {
    let FitInput {
        def,
        train,
        train_name,
        valid,
        valid_from,
        valid_periodic,
        linear_step,
        input_unit,
        output_unit,
        started,
    } = input;
    let (valid, valid_name) = match valid {
        Some((v, name)) => (Some(v), Some(name)),
        None => (None, None),
    };
    if let Some(v) = valid {
        anyhow::ensure!(
            v.u.len() >= train.u.len().min(v.u.len()) && v.y.len() == train.y.len(),
            "validation record has {} inputs / {} outputs, training record {} / {}",
            v.u.len(),
            v.y.len(),
            train.u.len(),
            train.y.len()
        );
    }
    let mut opts = opts.clone();
    if let Some(l) = &linear_step {
        opts.linear_fixed = Some(l.linear.clone());
    }
    let id = identify(def, train, &opts)?;
    let train_sim = simulate_identified(&id, train, 0)?;
    let valid_sim = valid
        .map(|v| simulate_identified(&id, v, valid_periodic))
        .transpose()?;
    let valid_rest_sim = match valid {
        Some(v) if valid_periodic > 0 => Some(simulate_identified(&id, v, 0)?),
        _ => None,
    };
    let report = Report {
        format: FORMAT,
        model: def.name.into(),
        sample_rate_hz: train.sample_rate_hz(),
        inputs: train.u.len(),
        outputs: train.y.len(),
        input_unit,
        output_unit,
        train: train_name,
        valid: valid_name,
        linear_step,
        train_metrics: metrics_after(train, &train_sim, opts.warmup),
        valid_metrics: match (valid, &valid_sim) {
            (Some(v), Some(s)) => metrics_after(v, s, valid_from),
            _ => Vec::new(),
        },
        valid_from_rest_metrics: match (valid, &valid_rest_sim) {
            (Some(v), Some(s)) => metrics_after(v, s, valid_from),
            _ => Vec::new(),
        },
        parts: id.parts,
        multibw: id.multibw,
        seconds: started.elapsed().as_secs_f64(),
    };
    Ok(Fit {
        report,
        train_sim,
        valid_sim,
        valid_rest_sim,
    })
}

/// A record split in two for a fit: the model fits the first part and runs on through the
/// rest, which alone is scored (`piezo fit --split`).
#[derive(Debug, Clone)]
pub struct Split {
    /// Samples `0..k`.
    pub train: Record,
    /// The whole record, scored from `valid_from` on.
    pub valid: Record,
    /// The report's `valid`: where the validation samples came from.
    pub valid_name: String,
    pub valid_from: usize,
}

/// Splits `whole` (read from `name`) at sample `k` ([`split_sample`]).
pub fn split(whole: Record, name: &str, k: usize) -> Split {
    let valid_name = format!(
        "{name} (samples {k}..{} after fitting on 0..{k})",
        whole.len()
    );
    Split {
        train: whole.slice(0, k),
        valid: whole,
        valid_name,
        valid_from: k,
    }
}

/// The sample a record of `len` samples is split at for a `fraction` of it (0.1..0.9) to
/// fit and the rest to validate (`--split` of `piezo fit` and `piezo diagnose`).
pub fn split_sample(len: usize, fraction: f64) -> Result<usize> {
    anyhow::ensure!(
        fraction.is_finite() && (0.1..=0.9).contains(&fraction),
        "--split must be within 0.1..0.9, got {fraction}"
    );
    Ok((len as f64 * fraction) as usize)
}
