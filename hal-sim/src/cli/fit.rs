//! `piezo fit`: identify a model of the core from a CSV record.
pub use super::fit_args::Args;
use crate::ident::fit::resample::Edge;
use crate::ident::fit::{fit_siso, metrics, models, FitOptions, Fitted, Metrics};
use crate::ident::multibw::{self, MultiBwFit};
pub use crate::ident::saved::{simulate, Part, FORMAT};
use crate::plot::{write_grid, Plot};
use crate::record::{Quantity, Record};
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::Path;

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

fn name_channel(base: char, i: usize, n: usize) -> String {
    if n == 1 {
        base.to_string()
    } else {
        format!("{base}{}", i + 1)
    }
}

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

/// Writes `dir/fit.json` (what `piezo predict` and `piezo serial load-fit` read); its path.
pub fn write_fit_json(dir: &Path, report: &Report) -> Result<std::path::PathBuf> {
    let path = dir.join("fit.json");
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    std::fs::write(&path, serde_json::to_string_pretty(report)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

pub fn run(args: Args) -> Result<()> {
    if args.list {
        for m in models::MODELS {
            println!("{:<14} {}", m.name, m.about);
        }
        return Ok(());
    }
    let Some(model) = &args.model else {
        anyhow::bail!("--model and --train are required (see --help)");
    };
    args.records.no_windows("piezo fit")?;
    if super::fit_ss::handles(model) {
        return super::fit_ss::run(&args);
    }
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
            let name = format!(
                "{} (samples {k}..{} after fitting on 0..{k})",
                train_path.display(),
                whole.len()
            );
            (whole.slice(0, k), Some(whole), Some(name), k)
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
