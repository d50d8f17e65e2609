//! `piezo fit` for the state-space models (`ss`, `hammerstein-ss`, `scheduled-ss`, `lfr`) on
//! records already read: the options as the CLI and the Python package give them, the fit,
//! its checks and the `fit.json` it saves. One path for both callers.

use super::frf::{self, PeriodicSpectra};
use super::lfr::{self, Basis, InputScale, LfrFit, LfrOptions};
use super::saved::SsJson;
use super::{identify, scheduled, score, SsFit, SsOptions};
use crate::fit::models::{self, ModelDef};
use crate::record::{Quantity, Record};
use anyhow::{Context, Result};

/// The options of a state-space fit, parsed ([`FitOptions::parse`]).
#[derive(Debug, Clone)]
pub struct FitOptions {
    /// `ss`, `hammerstein-ss`, `scheduled-ss` or `lfr`.
    pub model: String,
    pub ss: SsOptions,
    /// `lfr`: the linear part from the lowest input level's records (else from all).
    pub lfr_lowest: bool,
    pub lfr: LfrOptions,
    /// The inputs reach the model this many samples late.
    pub input_delay: usize,
}

/// The options as `piezo fit` takes them, as text where the CLI has text.
#[derive(Debug, Clone)]
pub struct FitArgs<'a> {
    pub model: &'a str,
    /// A number 1..=200 or `auto`; `None`: [`lfr::DEFAULT_ORDER`] for `lfr`, else `auto`.
    pub order: Option<&'a str>,
    /// `hammerstein-ss`: the hysteresis per actuator (a registry model, or `none`).
    pub hysteresis: &'a str,
    pub lm_iterations: usize,
    pub joint_iterations: usize,
    pub schedule_tau_s: f64,
    pub lfr_basis: &'a [String],
    /// `all` or `lowest` (`None`: lowest).
    pub lfr_linear: Option<&'a str>,
    pub lfr_channels: &'a str,
    pub lfr_iterations: usize,
    /// Refuse steps whose model diverges at this multiple of the training inputs.
    pub lfr_guard: Option<f64>,
    pub input_delay: usize,
    pub progress: bool,
}

impl FitOptions {
    /// Checks and parses `a`; every refusal names the option.
    pub fn parse(a: &FitArgs) -> Result<Self> {
        let model = a.model;
        anyhow::ensure!(
            crate::saved::handles(model),
            "model `{model}`: expected ss, hammerstein-ss, scheduled-ss or lfr"
        );
        let order = match a.order.unwrap_or(if model == "lfr" {
            lfr::DEFAULT_ORDER
        } else {
            "auto"
        }) {
            "auto" => None,
            s => Some(
                s.parse::<usize>()
                    .ok()
                    .filter(|n| (1..=200).contains(n))
                    .with_context(|| {
                        format!("--order `{s}`: expected a number 1..200 or `auto`")
                    })?,
            ),
        };
        let hysteresis: Option<&'static ModelDef> = match (model, a.hysteresis) {
            ("ss" | "scheduled-ss" | "lfr", _) | (_, "none") => None,
            (_, name) => Some(models::find(name)?),
        };
        let lfr_lowest = match (model, a.lfr_linear) {
            ("lfr", Some("all")) => false,
            ("lfr", None | Some("lowest")) => true,
            ("lfr", Some(o)) => anyhow::bail!("--lfr-linear `{o}`: expected all or lowest"),
            (_, Some(_)) => anyhow::bail!("--lfr-linear applies to --model lfr only"),
            (_, None) => false,
        };
        let lfr = LfrOptions {
            // None given (the Python package's default): the default basis.
            basis: if a.lfr_basis.is_empty() {
                lfr::default_basis()
            } else {
                a.lfr_basis
                    .iter()
                    .map(|b| Basis::parse(b))
                    .collect::<Result<_>>()?
            },
            channels: lfr::Channels::parse(a.lfr_channels)?,
            iterations: a.lfr_iterations,
            guard: match a.lfr_guard {
                Some(g) if !(g.is_finite() && g >= 1.0) => {
                    anyhow::bail!("--lfr-guard {g}: expected a factor >= 1 (e.g. 1.5)")
                }
                g => g,
            },
            progress: a.progress,
            ..Default::default()
        };
        Ok(Self {
            model: model.to_string(),
            ss: SsOptions {
                order,
                hysteresis,
                iterations: a.lm_iterations,
                joint_iterations: a.joint_iterations,
                schedule: (model == "scheduled-ss").then_some(a.schedule_tau_s),
                progress: a.progress,
                ..Default::default()
            },
            lfr_lowest,
            lfr,
            input_delay: a.input_delay,
        })
    }
}

/// What [`fit`] identified: the model to save and what the CLI prints of it.
pub struct Fitted {
    /// The `fit.json` (its `report` without the training files' names).
    pub saved: SsJson,
    pub fit: SsFit,
    pub lfr: Option<LfrFit>,
    /// Where the LFR stays bounded on its training inputs scaled up, from rest.
    pub lfr_scale: Option<InputScale>,
    pub lfr_radius: Option<f64>,
    pub seconds: f64,
}

/// Identifies the model of `opts` on `recs` (their inputs delayed first, as saved; `names`
/// name them in errors).
pub fn fit(recs: Vec<Record>, names: &[String], opts: &FitOptions) -> Result<Fitted> {
    let t0 = std::time::Instant::now();
    let progress = opts.ss.progress;
    let d = opts.input_delay;
    let name = |i: usize| {
        names
            .get(i)
            .cloned()
            .unwrap_or_else(|| format!("training record {}", i + 1))
    };
    let recs = recs
        .into_iter()
        .enumerate()
        .map(|(i, r)| delayed(r, d).with_context(|| name(i)))
        .collect::<Result<Vec<_>>>()?;
    if d > 0 && progress {
        eprintln!("the inputs reach the model {d} sample(s) late (--input-delay {d})");
    }
    let levels = bla_levels(&recs)?;
    if let (Some(l), true) = (&levels, progress) {
        eprintln!(
            "BLA over the training records: noise {:.4e}, nonlinear distortion {} {} RMS per period",
            l.noise_rms,
            l.distortion_rms.map_or("n/a".into(), |d| format!("{d:.4e}")),
            Quantity::Length.internal()
        );
    }
    let lowest = if opts.model == "lfr" && opts.lfr_lowest {
        Some(lowest_level(&recs)?)
    } else {
        None
    };
    let fit = match &lowest {
        Some(low) => {
            if progress {
                eprintln!(
                    "lfr: the linear part from the {} records of the lowest input level",
                    low.len()
                );
            }
            identify(low, &opts.ss)?
        }
        None => identify(&recs, &opts.ss)?,
    };
    let lfr_fit = if opts.model == "lfr" {
        Some(lfr::identify(&fit.model.linear, &recs, &opts.lfr)?)
    } else {
        None
    };
    let lfr_scale = lfr_fit.as_ref().map(|f| {
        let inputs: Vec<&[Vec<f64>]> = recs.iter().map(|r| r.u.as_slice()).collect();
        f.model.bounded_input_scale(&inputs, &lfr::INPUT_SCALES)
    });
    let lfr_radius = lfr_fit.as_ref().and_then(|f| f.model.large_signal_radius());
    let seconds = t0.elapsed().as_secs_f64();
    let report = serde_json::json!({
        "period_samples": fit.period,
        "order_scan": fit.order_scan,
        "modes_to_peak": fit.modes_to_peak,
        "train_rms_linear": fit.linear_rms,
        "train_rms_hammerstein": fit.hammerstein_rms,
        "train_rms_scheduled_bla": fit.scheduled_rms,
        "bla_levels": levels,
        "train_rms_lfr_start": lfr_fit.as_ref().map(|f| f.start_rms),
        "train_rms_lfr": lfr_fit.as_ref().map(|f| f.rms),
        "lfr_iterations": lfr_fit.as_ref().map(|f| f.iterations),
        "lfr_linear_records": lfr_fit
            .as_ref()
            .map(|_| lowest.as_ref().map_or(recs.len(), Vec::len)),
        "lfr_input_scale": lfr_scale,
        "lfr_large_signal_radius": lfr_radius,
        "seconds": seconds,
    });
    let saved = SsJson::new(
        &fit.model,
        fit.fs_hz,
        (Quantity::Voltage.internal(), Quantity::Length.internal()),
        serde_json::Value::Null,
    )
    .with_schedule(fit.schedule.clone());
    let mut saved = match &lfr_fit {
        Some(f) => saved.with_lfr(&f.model),
        None => saved,
    };
    saved.extensions.delay_samples = d;
    let range = |chans: &dyn Fn(&Record) -> &Vec<Vec<f64>>| -> Vec<(f64, f64)> {
        (0..chans(&recs[0]).len())
            .map(|i| {
                recs.iter()
                    .flat_map(|r| chans(r)[i].iter())
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                        (a.min(v), b.max(v))
                    })
            })
            .collect()
    };
    let saved = SsJson {
        report,
        input_range: range(&|r: &Record| &r.u),
        output_range: range(&|r: &Record| &r.y),
        ..saved
    };
    Ok(Fitted {
        saved,
        fit,
        lfr: lfr_fit,
        lfr_scale,
        lfr_radius,
        seconds,
    })
}

/// `rec` with its inputs `d` samples late: shifted within each period of a periodic record
/// (its steady state: what the model's delay gives after a warm-up period), else zeros
/// first, as the saved model simulates from rest ([`super::extended::delay`]).
pub fn delayed(mut rec: Record, d: usize) -> Result<Record> {
    if d == 0 {
        return Ok(rec);
    }
    anyhow::ensure!(
        d < rec.len(),
        "--input-delay {d} is not shorter than the record ({} samples)",
        rec.len()
    );
    // Whole periods only; otherwise the record is one stretch from rest.
    let n = super::score::period_of(&rec)
        .ok()
        .filter(|&n| d < n && rec.len().is_multiple_of(n))
        .unwrap_or(rec.len());
    if n == rec.len() {
        for u in &mut rec.u {
            *u = super::extended::delay(u, d);
        }
        return Ok(rec);
    }
    for u in &mut rec.u {
        let old = u.clone();
        for (k, v) in u.iter_mut().enumerate() {
            let (q, i) = (k / n * n, k % n);
            *v = if i >= d {
                old[k - d]
            } else {
                old[q + n - d + i]
            };
        }
    }
    Ok(rec)
}

/// The records of the lowest input level (grouped as `piezo score` groups them).
pub fn lowest_level(recs: &[Record]) -> Result<Vec<Record>> {
    let levels = recs
        .iter()
        .map(|r| Ok(scheduled::record_level(r, score::period_of(r)?)))
        .collect::<Result<Vec<_>>>()?;
    let groups = scheduled::group_by_level(&levels);
    Ok(groups
        .first()
        .map(|g| g.iter().map(|&i| recs[i].clone()).collect())
        .unwrap_or_default())
}

/// Noise and distortion levels of the BLA of periodic records (`None` otherwise).
pub fn bla_levels(recs: &[Record]) -> Result<Option<frf::Levels>> {
    let periods: Vec<usize> = recs.iter().map(frf::detect_period).collect();
    if periods.iter().zip(recs).any(|(&n, r)| n == r.len())
        || periods.iter().any(|&n| n != periods[0])
    {
        return Ok(None);
    }
    let sp = recs
        .iter()
        .map(|r| PeriodicSpectra::of(r, periods[0]))
        .collect::<Result<Vec<_>>>()?;
    Ok(Some(frf::bla(&sp)?.levels()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(u: Vec<f64>) -> Record {
        let n = u.len();
        Record::new(
            (0..n).map(|k| k as f64 * 1e-3).collect(),
            vec![u],
            vec![vec![0.0; n]],
        )
        .unwrap()
    }

    #[test]
    fn the_input_delay_shifts_within_each_period_or_starts_from_rest() {
        let period: Vec<f64> = (0..512)
            .map(|k| {
                let x = k as f64 * std::f64::consts::TAU / 512.0;
                x.sin() + 0.5 * (3.0 * x + 1.0).cos() + 0.2 * (7.0 * x).sin()
            })
            .collect();
        let u: Vec<f64> = period.iter().chain(&period).copied().collect();
        let d = delayed(record(u.clone()), 3).unwrap();
        for k in 0..u.len() {
            // The periodic steady state, three samples late.
            assert_eq!(d.u[0][k], period[(k + 512 - 3) % 512], "sample {k}");
        }
        // Not periodic: from rest, as the saved model simulates it.
        let ramp: Vec<f64> = (0..300).map(|k| k as f64 + 5.0).collect();
        let d = delayed(record(ramp), 2).unwrap();
        assert_eq!(&d.u[0][..4], &[0.0, 0.0, 5.0, 6.0]);
        assert!(delayed(record(vec![0.0; 300]), 300).is_err());
    }
}
