//! `piezo fit --model ss | hammerstein-ss | scheduled-ss | lfr`: one multivariable
//! state-space model (with a hysteresis per actuator, scheduled by the input level, or with
//! a nonlinearity in feedback) for several training records.
use super::fit_args::Args;
use crate::ident::fit::models;
pub use crate::ident::saved::handles;
use crate::ident::saved::{score_last_period, Loaded};
use crate::ident::ss::frf::{self, PeriodicSpectra};
use crate::ident::ss::lfr::{self, Basis, LfrOptions};
use crate::ident::ss::saved::SsJson;
use crate::ident::ss::{identify, SsOptions};
use crate::record::{Quantity, Record};
use anyhow::{Context, Result};

fn read_all(args: &Args, delay: usize) -> Result<Vec<Record>> {
    let rs = &args.records;
    anyhow::ensure!(
        !rs.train.is_empty(),
        "--train is required (repeat it for several records)"
    );
    anyhow::ensure!(
        rs.split.is_none(),
        "--split: the state-space models validate on --valid records (or on every fourth training record)"
    );
    rs.train
        .iter()
        .map(|p| {
            let r = args.columns.read(p, args.quiet)?;
            delayed(r, delay).with_context(|| p.display().to_string())
        })
        .collect()
}

/// `rec` with its inputs `d` samples late: shifted within each period of a periodic record
/// (its steady state: what the model's delay gives after a warm-up period), else zeros
/// first, as the saved model simulates from rest ([`crate::ident::ss::extended::delay`]).
fn delayed(mut rec: Record, d: usize) -> Result<Record> {
    if d == 0 {
        return Ok(rec);
    }
    anyhow::ensure!(
        d < rec.len(),
        "--input-delay {d} is not shorter than the record ({} samples)",
        rec.len()
    );
    // Whole periods only; otherwise the record is one stretch from rest.
    let n = crate::ident::ss::score::period_of(&rec)
        .ok()
        .filter(|&n| d < n && rec.len().is_multiple_of(n))
        .unwrap_or(rec.len());
    if n == rec.len() {
        for u in &mut rec.u {
            *u = crate::ident::ss::extended::delay(u, d);
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

pub fn run(args: &Args) -> Result<()> {
    let model = args.model.as_deref().unwrap_or("ss");
    let t0 = std::time::Instant::now();
    let delay = args.input_delay;
    let recs = read_all(args, delay)?;
    if delay > 0 && !args.quiet {
        eprintln!("the inputs reach the model {delay} sample(s) late (--input-delay {delay})");
    }
    let order_arg = args
        .order
        .as_deref()
        .unwrap_or(if model == "lfr" { "28" } else { "auto" });
    let order = match order_arg {
        "auto" => None,
        s => Some(
            s.parse::<usize>()
                .ok()
                .filter(|n| (1..=200).contains(n))
                .with_context(|| format!("--order `{s}`: expected a number 1..200 or `auto`"))?,
        ),
    };
    let hysteresis = match (model, args.hysteresis.as_str()) {
        ("ss" | "scheduled-ss" | "lfr", _) | (_, "none") => None,
        (_, name) => Some(models::find(name)?),
    };
    let opts = SsOptions {
        order,
        hysteresis,
        iterations: args.lm_iterations,
        joint_iterations: args.joint_iterations,
        schedule: (model == "scheduled-ss").then_some(args.schedule_tau_s),
        progress: !args.quiet,
        ..Default::default()
    };
    // Nonparametric levels of the training set (periodic records only).
    let levels = bla_levels(&recs)?;
    if let (Some(l), false) = (&levels, args.quiet) {
        eprintln!(
            "BLA over the training records: noise {:.4e}, nonlinear distortion {} {} RMS per period",
            l.noise_rms,
            l.distortion_rms.map_or("n/a".into(), |d| format!("{d:.4e}")),
            Quantity::Length.internal()
        );
    }
    let lowest = match (model, args.lfr_linear.as_deref()) {
        ("lfr", Some("all")) => None,
        ("lfr", None | Some("lowest")) => Some(lowest_level(&recs)?),
        ("lfr", Some(o)) => anyhow::bail!("--lfr-linear `{o}`: expected all or lowest"),
        (_, Some(_)) => anyhow::bail!("--lfr-linear applies to --model lfr only"),
        (_, None) => None,
    };
    let fit = match &lowest {
        Some(low) => {
            if !args.quiet {
                eprintln!(
                    "lfr: the linear part from the {} records of the lowest input level",
                    low.len()
                );
            }
            identify(low, &opts)?
        }
        None => identify(&recs, &opts)?,
    };
    let lfr_fit = if model == "lfr" {
        let lopts = LfrOptions {
            basis: args
                .lfr_basis
                .iter()
                .map(|b| Basis::parse(b))
                .collect::<Result<_>>()?,
            channels: lfr::Channels::parse(&args.lfr_channels)?,
            iterations: args.lfr_iterations,
            progress: !args.quiet,
            ..Default::default()
        };
        Some(lfr::identify(&fit.model.linear, &recs, &lopts)?)
    } else {
        None
    };
    // Where the fitted feedback stays bounded: the training inputs scaled up, from rest.
    let lfr_scale = lfr_fit.as_ref().map(|f| {
        let inputs: Vec<&[Vec<f64>]> = recs.iter().map(|r| r.u.as_slice()).collect();
        f.model.bounded_input_scale(&inputs, &lfr::INPUT_SCALES)
    });
    let lfr_radius = lfr_fit.as_ref().and_then(|f| f.model.large_signal_radius());
    if fit.modes_to_peak > crate::ident::ss::MAX_CANCELLATION {
        eprintln!(
            "warning: the order-{} model's modes add up to {:.1e} times the measured response's peak: they cancel (huge gains of opposite effect), so it is no model of the stage; give a lower --order",
            fit.order, fit.modes_to_peak
        );
    }
    let seconds = t0.elapsed().as_secs_f64();
    let mut report = serde_json::json!({
        "train": args.records.train.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
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
    saved.extensions.delay_samples = delay;
    let loaded = Loaded::Ss(Box::new(saved.clone()));
    let mut valid = Vec::new();
    for v in &args.records.valid {
        let rec = args.columns.read(v, args.quiet)?;
        let sim = loaded.simulate(&rec)?;
        let (per_output, mean) = score_last_period(&rec, &sim);
        println!(
            "valid {}: RMSE over the last period {mean:.4e} {} (per output {})",
            v.display(),
            Quantity::Length.internal(),
            super::predict::list(&per_output)
        );
        valid.push(serde_json::json!({"record": v.display().to_string(), "rmse_last_period": per_output, "mean": mean}));
    }
    // One record: its object (as before several were allowed); several: the list.
    match valid.len() {
        0 => {}
        1 => report["valid"] = valid.remove(0),
        _ => report["valid"] = serde_json::Value::Array(valid),
    }
    println!(
        "{} order {} fitted on {} records in {seconds:.1} s: training RMS output error linear {:.4e}{} {}",
        saved.model,
        fit.order,
        recs.len(),
        fit.linear_rms,
        fit.hammerstein_rms.map_or(String::new(), |h| format!(", hammerstein {h:.4e}")),
        Quantity::Length.internal()
    );
    if let Some(f) = &lfr_fit {
        println!(
            "  lfr ({} iterations): RMS output error on the scored samples (one period warm-up) {:.4e} {}, linear start {:.4e}",
            f.iterations,
            f.rms,
            Quantity::Length.internal(),
            f.start_rms
        );
    }
    if let Some(s) = &lfr_scale {
        let x = |v: f64| format!("{v}x");
        match (s.bounded, s.diverges) {
            (Some(b), None) => println!(
                "  lfr: bounded from rest on the training inputs scaled up to {} (the largest tried)",
                x(b)
            ),
            (b, Some(d)) => {
                println!(
                    "  lfr: bounded from rest on the training inputs scaled by {}, diverges at {}",
                    b.map_or("none of the scales".into(), x),
                    x(d)
                );
                if d <= 1.25 {
                    eprintln!(
                        "warning: the LFR diverges on the training inputs scaled by {}: it is at the edge of stability and may diverge on other records of the same level (inputs the model has not seen); fewer --lfr-iterations or another --lfr-basis",
                        x(d)
                    );
                }
            }
            (None, None) => {}
        }
    }
    if let Some(f) = &lfr_fit {
        match lfr_radius {
            Some(r) if r < 1.0 => println!(
                "  lfr: large-signal loop A + E F (every channel at slope 1) has spectral radius {r:.4} < 1: stable far above the training amplitudes (necessary for bounded responses; amplitudes in between are checked only up to the scale above)"
            ),
            Some(r) => eprintln!(
                "warning: the LFR's large-signal loop A + E F has spectral radius {r:.4} >= 1: far outside its training amplitudes the model diverges (keep `sim --stage` and `predict` inputs near the training amplitudes)"
            ),
            None => println!(
                "  lfr: basis of unbounded slope ({}): no large-signal bound",
                f.model.basis.iter().map(|b| b.name()).collect::<Vec<_>>().join(", ")
            ),
        }
    }
    for (f, p) in &fit.model.fronts.iter().enumerate().collect::<Vec<_>>() {
        println!("  u{} hysteresis {}: {:?}", f + 1, p.def.name, p.params);
    }
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
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let path = dir.join("fit.json");
        std::fs::write(&path, serde_json::to_string_pretty(&saved)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        if !args.quiet {
            eprintln!("wrote {}", path.display());
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&saved)?);
    }
    Ok(())
}

/// The records of the lowest input level (grouped as `piezo score` groups them).
fn lowest_level(recs: &[Record]) -> Result<Vec<Record>> {
    use crate::ident::ss::{scheduled, score};
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
