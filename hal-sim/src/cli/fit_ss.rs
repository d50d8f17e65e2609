//! `piezo fit --model ss | hammerstein-ss | scheduled-ss | lfr`: one multivariable
//! state-space model (with a hysteresis per actuator, scheduled by the input level, or with
//! a nonlinearity in feedback) for several training records. The fit itself is
//! [`crate::ident::ss::fitting`] (shared with the Python package); here the files and the
//! printout.
use super::fit_args::Args;
pub use crate::ident::saved::handles;
use crate::ident::saved::{score_last_period, Loaded};
pub use crate::ident::ss::fitting::bla_levels;
use crate::ident::ss::fitting::{self, FitArgs, FitOptions};
use crate::ident::ss::lfr;
use crate::record::{Quantity, Record};
use anyhow::{Context, Result};

fn read_all(args: &Args) -> Result<Vec<Record>> {
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
        .map(|p| args.columns.read(p, args.quiet))
        .collect()
}

pub fn run(args: &Args) -> Result<()> {
    let model = args.model.as_deref().unwrap_or("ss");
    let opts = FitOptions::parse(&FitArgs {
        model,
        order: args.order.as_deref(),
        hysteresis: &args.hysteresis,
        lm_iterations: args.lm_iterations,
        joint_iterations: args.joint_iterations,
        schedule_tau_s: args.schedule_tau_s,
        lfr_basis: &args.lfr_basis,
        lfr_linear: args.lfr_linear.as_deref(),
        lfr_channels: &args.lfr_channels,
        lfr_iterations: args.lfr_iterations,
        lfr_guard: args.lfr_guard,
        input_delay: args.input_delay,
        progress: !args.quiet,
    })?;
    let recs = read_all(args)?;
    let n_recs = recs.len();
    let names: Vec<String> = args
        .records
        .train
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let fitting::Fitted {
        mut saved,
        fit,
        lfr: lfr_fit,
        lfr_scale,
        lfr_radius,
        seconds,
    } = fitting::fit(recs, &names, &opts)?;
    if fit.modes_to_peak > crate::ident::ss::MAX_CANCELLATION {
        eprintln!(
            "warning: the order-{} model's modes add up to {:.1e} times the measured response's peak: they cancel (huge gains of opposite effect), so it is no model of the stage; give a lower --order",
            fit.order, fit.modes_to_peak
        );
    }
    saved.report["train"] = serde_json::json!(names);
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
        1 => saved.report["valid"] = valid.remove(0),
        _ => saved.report["valid"] = serde_json::Value::Array(valid),
    }
    println!(
        "{} order {} fitted on {} records in {seconds:.1} s: training RMS output error linear {:.4e}{} {}",
        saved.model,
        fit.order,
        n_recs,
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
    if lfr_fit
        .as_ref()
        .is_some_and(|f| !f.model.z_limit.is_empty())
    {
        match lfr_radius {
            Some(r) if r < 1.0 => println!(
                "  lfr: feedback held beyond {} times each channel's peak |z| on the training records: far out the model is its linear part (spectral radius {r:.4} < 1), bounded for every input",
                lfr::Z_LIMIT_FACTOR
            ),
            _ => eprintln!(
                "warning: the LFR's linear part is not stable (spectral radius {}): the model diverges",
                lfr_radius.map_or("unknown".into(), |r| format!("{r:.4}"))
            ),
        }
    } else if let Some(f) = &lfr_fit {
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
