//! `piezo fit`: identify a model of the core from a CSV record.
pub use super::fit_args::Args;
use crate::ident::fit::{models, FitOptions};
pub use crate::ident::identify::{
    fit, fit_linear_part, identify, identify_pairs, split, Fit, FitInput, Identified, Split,
};
pub use crate::ident::saved::{simulate, write_fit_json, ChannelMetrics, Part, Report, FORMAT};
use crate::plot::{write_grid, Plot};
use crate::record::{Quantity, Record};
use crate::report::Report as HtmlReport;
use anyhow::{Context, Result};
use std::path::Path;

fn name_channel(base: char, i: usize, n: usize) -> String {
    if n == 1 {
        base.to_string()
    } else {
        format!("{base}{}", i + 1)
    }
}

pub fn run(args: Args) -> Result<()> {
    if args.list {
        for m in models::MODELS {
            println!("{:<14} {}", m.name, m.about);
        }
        return Ok(());
    }
    let report = args.out.as_ref().map(|_| HtmlReport::start("piezo fit"));
    fit_and_write(&args)?;
    if let (Some(dir), Some(mut report)) = (&args.out, report) {
        // fit.json is the model and its scores, whichever model family wrote it.
        let path = dir.join("fit.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{} is not JSON", path.display()))?;
        report.json("Model (fit.json)", &v);
        let index = report.write(dir)?;
        if !args.json {
            println!("report: {}", index.display());
        }
    }
    Ok(())
}

/// The fit itself: the model family's own path, its files in `--out`.
fn fit_and_write(args: &Args) -> Result<()> {
    let Some(model) = &args.model else {
        anyhow::bail!("--model and --train are required (see --help)");
    };
    args.records.no_windows("piezo fit")?;
    if super::fit_ss::handles(model) {
        return super::fit_ss::run(args);
    }
    anyhow::ensure!(
        args.input_delay == 0,
        "--input-delay applies to the state-space models (ss, hammerstein-ss, scheduled-ss, lfr), not to `{model}`"
    );
    let rs = &args.records;
    let train_path = match rs.train.as_slice() {
        [one] => one,
        [] => anyhow::bail!("--model and --train are required (see --help)"),
        more => anyhow::bail!(
            "model `{model}` takes one --train record, {} given (several: --model ss, hammerstein-ss or scheduled-ss)",
            more.len()
        ),
    };
    let valid_path = match rs.valid.as_slice() {
        [] => None,
        [one] => Some(one),
        more => anyhow::bail!(
            "model `{model}` takes one --valid record, {} given",
            more.len()
        ),
    };
    let def = models::find(model)?;
    anyhow::ensure!(
        args.linear <= 2,
        "--linear {}: at most 2 sections",
        args.linear
    );
    let t0 = std::time::Instant::now();
    let whole = args.columns.read(train_path, args.quiet)?;
    // --split: the model fits the first part and runs on through the rest, scored there.
    let (train, valid, valid_name, valid_from) = match (valid_path, rs.split_at(whole.len(), None)?)
    {
        (Some(v), _) => {
            let rec = args.columns.read(v, args.quiet)?;
            (whole, Some(rec), Some(v.display().to_string()), 0)
        }
        (None, Some(k)) => {
            anyhow::ensure!(
                args.valid_periodic == 0,
                "--valid-periodic needs a --valid record of whole periods, not --split"
            );
            let s = split(whole, &train_path.display().to_string(), k);
            (s.train, Some(s.valid), Some(s.valid_name), s.valid_from)
        }
        (None, None) => (whole, None, None, 0),
    };
    let opts = FitOptions {
        optimizer: args.optimizer,
        generations: args.generations,
        population: args.population,
        seed: args.seed,
        lm_iterations: args.lm_iterations,
        upsample: args.upsample.max(1),
        linear_sections: args.linear,
        progress: !args.quiet,
        ..Default::default()
    };
    // Two-step Hammerstein: linear part from its own record first.
    let linear_step = if let Some(path) = &args.linear_train {
        let rec = args.columns.read(path, args.quiet)?;
        if opts.progress {
            eprintln!("step 1: linear part from {}", path.display());
        }
        Some(
            fit_linear_part(&rec, args.linear.max(1), &opts)
                .with_context(|| format!("--linear-train {}", path.display()))?,
        )
    } else {
        None
    };
    let Fit {
        report,
        train_sim,
        valid_sim,
        valid_rest_sim,
    } = fit(
        FitInput {
            def,
            train: &train,
            train_name: train_path.display().to_string(),
            valid: valid.as_ref().zip(valid_name),
            valid_from,
            valid_periodic: args.valid_periodic,
            linear_step,
            input_unit: Quantity::Voltage.internal().into(),
            output_unit: Quantity::Length.internal().into(),
            started: t0,
        },
        &opts,
    )?;
    if let Some(path) = &args.predict {
        let (rec, sim) = match (&valid, &valid_sim) {
            (Some(v), Some(s)) => (v, s),
            _ => (&train, &train_sim),
        };
        write_prediction(path, rec, sim, valid_rest_sim.as_deref(), def.name)?;
    }
    if let Some(dir) = &args.out {
        write_plots(dir, &train, &train_sim, "train")?;
        if let (Some(v), Some(s)) = (&valid, &valid_sim) {
            write_plots(dir, v, s, "valid")?;
        }
        write_fit_json(dir, &report)?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&report);
    }
    Ok(())
}

fn write_prediction(
    path: &Path,
    rec: &Record,
    sim: &[Vec<f64>],
    from_rest: Option<&[Vec<f64>]>,
    model: &str,
) -> Result<()> {
    let mut comments = vec![format!(
        " piezo fit --model {model}: simulated output y (model), measured output y_meas"
    )];
    if from_rest.is_some() {
        comments.push(
            " y: periodic steady state (--valid-periodic); y_rest: the same input from rest".into(),
        );
    }
    let mut out = Record {
        comments,
        t: rec.t.clone(),
        u: rec.u.clone(),
        y: sim.to_vec(),
        extra: Vec::new(),
        unit_note: rec.unit_note.clone(),
    };
    for (i, y) in rec.y.iter().enumerate() {
        out.extra.push((
            format!("{}_meas", name_channel('y', i, rec.y.len())),
            y.clone(),
        ));
    }
    for (i, y) in from_rest.unwrap_or_default().iter().enumerate() {
        out.extra.push((
            format!("{}_rest", name_channel('y', i, rec.y.len())),
            y.clone(),
        ));
    }
    out.write(path)
}

fn write_plots(dir: &Path, rec: &Record, sim: &[Vec<f64>], what: &str) -> Result<()> {
    for (i, (y, s)) in rec.y.iter().zip(sim).enumerate() {
        let yn = name_channel('y', i, rec.y.len());
        let un = name_channel('u', i.min(rec.u.len() - 1), rec.u.len());
        let u = &rec.u[i.min(rec.u.len() - 1)];
        let e: Vec<f64> = y.iter().zip(s).map(|(a, b)| a - b).collect();
        let plots = [
            Plot::new(
                &format!("{what}: {un} -> {yn} loop"),
                un.as_str(),
                yn.as_str(),
            )
            .line("measured", u, y)
            .line("model", u, s),
            Plot::new(&format!("{what}: {yn} over time"), "t [s]", yn.as_str())
                .line("measured", &rec.t, y)
                .line("model", &rec.t, s),
            Plot::new(
                &format!("{what}: residual {yn} - model"),
                "t [s]",
                &format!("{yn} error"),
            )
            .line("residual", &rec.t, &e),
        ];
        let path = dir.join(format!("{what}_{yn}.svg"));
        write_grid(&path, &plots, 3).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

fn print_report(r: &Report) {
    println!(
        "model {} fitted on {} in {:.1} s",
        r.model, r.train, r.seconds
    );
    if let Some(l) = &r.linear_step {
        println!(
            "step 1 linear part: {:?} (gain {:.6e})",
            l.linear,
            l.values()[0]
        );
    }
    for p in &r.parts {
        let step1 = if r.multibw.is_some() {
            " (003 step 1)"
        } else {
            ""
        };
        println!(
            "{}{step1} u{} -> y{}: sign {:+}, offset {:.6e}",
            p.kind,
            p.input + 1,
            p.output + 1,
            p.fit.sign,
            p.fit.offset
        );
        if let Some(g) = &p.fit.search {
            println!(
                "  global search {:?}: RMSE {:.6e} after {} evaluations ({} iterations, {:.2} s)",
                g.optimizer, g.rmse, g.evals, g.iterations, g.seconds
            );
        }
        for (name, v) in &p.fit.params {
            println!("  {name:<16} {v:.6e}");
        }
        for (k, (f, z)) in p.fit.linear.iter().enumerate() {
            println!("  linear {}: f = {f:.4} Hz, zeta = {z:.4}", k + 1);
        }
    }
    if let Some(m) = &r.multibw {
        println!(
            "multivariable Bouc-Wen (003 eq. 4-7), {} outputs x {} inputs, rows = outputs:",
            m.outputs, m.inputs
        );
        for (name, mat) in [("D", &m.d), ("A", &m.a), ("B", &m.b), ("Gamma", &m.gamma)] {
            for (i, row) in mat.iter().enumerate() {
                let cells: Vec<String> = row.iter().map(|v| format!("{v:>13.5e}")).collect();
                let label = if i == 0 { name } else { "" };
                println!("  {label:<6}{}", cells.join(" "));
            }
        }
        let offs: Vec<String> = m.offset.iter().map(|v| format!("{v:.5e}")).collect();
        println!("  offsets {}", offs.join(" "));
        let list = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.4e}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        println!(
            "  training RMSE after the two steps of 003: {}",
            list(&m.two_step_rmse)
        );
        if !m.joint_rmse.is_empty() {
            println!(
                "  after the joint refinement (not in 003):  {}",
                list(&m.joint_rmse)
            );
        }
        println!("  multivariable IMS (003 eq. 16-19): {}", m.ims);
    }
    let show = |what: &str, ms: &[ChannelMetrics]| {
        for m in ms {
            println!(
                "{what} y{}: RMSE {:.4e}  MPME {:.3} %  RE {:.3} %  max|e| {:.4e}  ({} samples)",
                m.output + 1,
                m.metrics.rmse,
                m.metrics.mpme_pct,
                m.metrics.re_pct,
                m.metrics.max_abs,
                m.metrics.samples
            );
        }
    };
    show("train", &r.train_metrics);
    show("valid", &r.valid_metrics);
    show("valid from rest", &r.valid_from_rest_metrics);
}
