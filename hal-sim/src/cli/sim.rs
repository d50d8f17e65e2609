//! `piezo sim`: runs scenarios x controllers on the simulated stage and prints tracking
//! metrics; `--json` for machines, `--out DIR` for CSV time series, SVG plots and each run
//! as a `piezo fit` record (`<scenario>_<controller>_record.csv`: `t_s,u_V,y_um`, applied
//! volts and measured position in the convention of `crate::record`; the time series
//! `<scenario>_<controller>.csv` names its units the same way), with `index.html` linking
//! them per scenario (`crate::report`).
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::plot::{write_grid, Plot};
use crate::report::{self, Report, Table};
use crate::scenario::Scenario;
use crate::sim::controllers::{registry, Entry};
use crate::sim::{calibrate, default_scenarios, run_calibrated, Record, RunResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// A built-in scenario name (selects it) or a TOML file (adds it); repeatable.
    /// Without any name every built-in scenario runs.
    #[arg(long = "scenario", value_name = "NAME|FILE")]
    pub scenarios: Vec<String>,
    /// Controller name from the registry; repeatable. Default: all.
    #[arg(long = "controller", value_name = "NAME")]
    pub controllers: Vec<String>,
    /// Reference frequency (Hz) of the built-in periodic scenarios.
    #[arg(long)]
    pub freq_hz: Option<f64>,
    /// Reference amplitude (um, peak) of the built-in periodic scenarios.
    #[arg(long)]
    pub amplitude_um: Option<f64>,
    /// Simulated duration (s) of every scenario.
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Print `{"runs":[...]}` instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Write time series (CSV), plots (SVG) and index.html, the report linking them, here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// List scenarios and controllers, then exit.
    #[arg(long)]
    pub list: bool,
    /// Simulate an identified stage instead of the scenario's: the fit.json of
    /// `piezo fit --model ss | hammerstein-ss --out DIR`. The pipeline's voltage range maps
    /// onto the model's training input range; the model's largest training output onto
    /// 1.25 x the reference amplitude around the reference offset (um).
    #[arg(long, value_name = "FIT_JSON")]
    pub stage: Option<PathBuf>,
}

/// Resolves the scenario arguments: names select built-ins, files add scenarios.
pub fn select_scenarios(args: &Args) -> Result<Vec<Scenario>> {
    if let Some(f) = args.freq_hz {
        if !(f.is_finite() && f > 0.0) {
            bail!("--freq-hz must be finite and > 0, got {f}");
        }
    }
    if let Some(a) = args.amplitude_um {
        if !(a.is_finite() && a >= 0.0) {
            bail!("--amplitude-um must be finite and >= 0, got {a}");
        }
    }
    let builtin = default_scenarios(args.freq_hz, args.amplitude_um);
    let mut named = Vec::new();
    let mut files = Vec::new();
    for s in &args.scenarios {
        let p = Path::new(s);
        if s.ends_with(".toml") || p.is_file() {
            files.push(Scenario::load(p)?);
        } else if let Some(b) = builtin.iter().find(|b| &b.name == s) {
            named.push(b.clone());
        } else {
            let names: Vec<_> = builtin.iter().map(|b| b.name.as_str()).collect();
            bail!(
                "--scenario {s}: no such built-in scenario or file (built-ins: {})",
                names.join(", ")
            );
        }
    }
    let mut out = if named.is_empty() { builtin } else { named };
    out.extend(files);
    if let Some(d) = args.duration_s {
        for s in &mut out {
            s.run.duration_s = d;
            s.run.settle_s = s.run.settle_s.map(|x| x.min(0.5 * d));
        }
    }
    if let Some(path) = &args.stage {
        for s in &mut out {
            s.stage.identified = Some(crate::stage::identified::IdentifiedCfg {
                fit_json: path.clone(),
                volts_min: s.pipeline.volts_min,
                volts_max: s.pipeline.volts_max,
                centre_um: s.reference.offset_um,
                half_span_um: 1.25 * s.reference.amplitude_um,
            });
        }
    }
    for s in &out {
        s.validate()
            .with_context(|| format!("scenario {} with the command-line overrides", s.name))?;
    }
    Ok(out)
}

/// Resolves `--controller` names.
pub fn select_controllers(names: &[String]) -> Result<Vec<Entry>> {
    let all = registry();
    if names.is_empty() {
        return Ok(all);
    }
    names
        .iter()
        .map(|n| {
            crate::sim::controllers::find(n).ok_or_else(|| {
                let known: Vec<_> = all.iter().map(|e| e.name).collect();
                anyhow::anyhow!("--controller {n}: unknown (known: {})", known.join(", "))
            })
        })
        .collect()
}

pub fn run(args: Args) -> Result<()> {
    // Manipulation scenarios (000 Part V, hal_sim::object) are selected by name like the
    // built-ins and run with their own observers and laws; all of them run by default.
    let (manip, rest): (Vec<String>, Vec<String>) = args
        .scenarios
        .iter()
        .cloned()
        .partition(|s| crate::manipulation::SCENARIOS.contains(&s.as_str()));
    let only_manip = !manip.is_empty() && rest.is_empty();
    let run_manip = !manip.is_empty() || (args.scenarios.is_empty() && args.controllers.is_empty());
    let args = Args {
        scenarios: rest,
        ..args
    };
    let scenarios = if only_manip {
        Vec::new()
    } else {
        select_scenarios(&args)?
    };
    let controllers = select_controllers(&args.controllers)?;
    if args.list {
        println!("scenarios:");
        for s in &scenarios {
            println!(
                "  {:<16} {} axis, {:?} {} Hz, {} s",
                s.name, s.stage.axes, s.reference.wave, s.reference.freq_hz, s.run.duration_s
            );
        }
        println!("controllers:");
        for c in &controllers {
            println!("  {:<16} {}", c.name, c.about);
        }
        println!("manipulation scenarios (own observers and laws):");
        for s in crate::manipulation::SCENARIOS {
            println!("  {s}");
        }
        return Ok(());
    }
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let report = args.out.as_ref().map(|_| Report::start("piezo sim"));
    // Calibrate each scenario once, then every (scenario, controller) in parallel.
    let cals: Vec<_> = scenarios.par_iter().map(calibrate).collect::<Result<_>>()?;
    let jobs: Vec<(usize, Entry)> = scenarios
        .iter()
        .enumerate()
        .flat_map(|(i, s)| {
            controllers
                .iter()
                .filter(move |c| s.stage.axes == 1 || c.two_axis.is_some())
                .map(move |c| (i, *c))
        })
        .collect();
    let total: f64 = jobs
        .iter()
        .map(|(i, _)| scenarios[*i].run.duration_s * scenarios[*i].run.loop_hz)
        .sum();
    let verbose = total > 2e7;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<(RunResult, Option<Record>)> = jobs
        .par_iter()
        .map(|(i, c)| {
            let r = run_calibrated(&scenarios[*i], c, &cals[*i], args.out.is_some());
            if verbose {
                let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                eprintln!("[{d}/{}] {} / {}", jobs.len(), scenarios[*i].name, c.name);
            }
            r
        })
        .collect::<Result<_>>()?;
    if let Some(dir) = &args.out {
        for (r, rec) in &results {
            if let Some(rec) = rec {
                write_outputs(dir, r, rec)?;
            }
        }
    }
    let runs: Vec<&RunResult> = results.iter().map(|(r, _)| r).collect();
    let manip_rows = if run_manip {
        crate::manipulation::run_manipulation(&manip, args.out.as_deref())?
    } else {
        Vec::new()
    };
    let all: Vec<Row> = runs
        .iter()
        .map(|r| Row::Tracking(r))
        .chain(manip_rows.iter().map(Row::Manipulation))
        .collect();
    if args.json {
        println!("{}", serde_json::to_string(&Runs { runs: &all })?);
    } else {
        println!(
            "{:<16} {:<22} {:>10} {:>9} {:>11} {:>10} {:>7}",
            "scenario", "controller", "rmse_um", "rmse_%", "max_err_%", "saturated", "faults"
        );
        for r in &runs {
            println!(
                "{:<16} {:<22} {:>10.4} {:>9.3} {:>11.3} {:>10} {:>7}",
                r.scenario,
                r.controller,
                r.rmse_um,
                r.rmse_pct,
                r.max_err_pct,
                r.saturated_samples,
                r.sensor_faults + r.nonfinite_commands
            );
        }
        for m in &manip_rows {
            println!("{}", m.table_line());
        }
    }
    if let Some(dir) = &args.out {
        let path = dir.join("summary.json");
        std::fs::write(&path, serde_json::to_string_pretty(&Runs { runs: &all })?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        if let Some(report) = report {
            let index = write_report(report, dir, &runs, &manip_rows)?;
            if !args.json {
                println!("wrote {}; report {}", dir.display(), index.display());
            }
        }
    }
    Ok(())
}

/// `index.html`: the best controller per scenario, then a section per scenario (its runs'
/// metrics, their files and plots), the manipulation runs, and every other file written.
fn write_report(
    mut report: Report,
    dir: &Path,
    runs: &[&RunResult],
    manip: &[crate::manipulation::ManipRow],
) -> Result<PathBuf> {
    let mut scenarios: Vec<&str> = Vec::new();
    for r in runs {
        if !scenarios.contains(&r.scenario.as_str()) {
            scenarios.push(&r.scenario);
        }
    }
    let mut best = Table::new(&["scenario", "runs", "best controller", "rmse_um", "rmse_%"]);
    for s in &scenarios {
        let of: Vec<&&RunResult> = runs.iter().filter(|r| r.scenario == *s).collect();
        if let Some(b) = of
            .iter()
            .filter(|r| r.rmse_um.is_finite())
            .min_by(|a, b| a.rmse_um.total_cmp(&b.rmse_um))
        {
            best.row(vec![
                (*s).into(),
                of.len().into(),
                b.controller.as_str().into(),
                b.rmse_um.into(),
                b.rmse_pct.into(),
            ]);
        }
    }
    report
        .section("Scenarios")
        .text("The controller with the smallest RMS tracking error per scenario; each scenario's section below has every run, its files and plots.")
        .table(best);
    let many = scenarios.len() > 3;
    for s in &scenarios {
        let mut t = Table::new(&[
            "controller",
            "rmse_um",
            "rmse_%",
            "max_err_%",
            "saturated",
            "faults",
            "files",
        ]);
        let mut plots = Vec::new();
        for r in runs.iter().filter(|r| r.scenario == *s) {
            let stem = format!("{}_{}", r.scenario, r.controller);
            t.row(vec![
                r.controller.as_str().into(),
                r.rmse_um.into(),
                r.rmse_pct.into(),
                r.max_err_pct.into(),
                r.saturated_samples.to_string().into(),
                (r.sensor_faults + r.nonfinite_commands).to_string().into(),
                report::links(
                    dir,
                    &[
                        ("plots", format!("{stem}.svg")),
                        ("time series", format!("{stem}.csv")),
                        ("record", format!("{stem}_record.csv")),
                    ],
                ),
            ]);
            if dir.join(format!("{stem}.svg")).is_file() {
                plots.push(format!("{stem}.svg"));
            }
        }
        let sec = report.section(format!("Scenario {s}"));
        sec.table(t)
            .plots_folded(format!("plots of the {} runs", plots.len()), plots);
        if many {
            sec.folded();
        }
    }
    if !manip.is_empty() {
        let rows: Vec<serde_json::Value> = manip
            .iter()
            .map(serde_json::to_value)
            .collect::<Result<_, _>>()?;
        report
            .section("Manipulation")
            .table(Table::from_objects(&rows));
    }
    report.write(dir)
}

/// The `--json` document: `{"runs":[...]}`, fields in [`RunResult`] order (manipulation rows:
/// the same leading fields, then their own).
#[derive(serde::Serialize)]
struct Runs<'a> {
    runs: &'a [Row<'a>],
}

/// One run in the JSON document, fields in their struct order.
#[derive(serde::Serialize)]
#[serde(untagged)]
enum Row<'a> {
    Tracking(&'a RunResult),
    Manipulation(&'a crate::manipulation::ManipRow),
}

fn write_outputs(dir: &Path, r: &RunResult, rec: &Record) -> Result<()> {
    let stem = format!("{}_{}", r.scenario, r.controller);
    let path = dir.join(format!("{stem}.csv"));
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(&path).with_context(|| format!("cannot write {}", path.display()))?,
    );
    let n_ax = rec.reference.len();
    let mut header = String::from("t_s");
    for i in 0..n_ax {
        header += &format!(",ref{i}_um,pos{i}_um,meas{i}_um,volts{i}_V,err{i}_um");
    }
    writeln!(f, "{header}")?;
    for k in 0..rec.t.len() {
        write!(f, "{:.7}", rec.t[k])?;
        for i in 0..n_ax {
            write!(
                f,
                ",{:.5},{:.5},{:.5},{:.4},{:.5}",
                rec.reference[i][k],
                rec.position[i][k],
                rec.measured[i][k],
                rec.volts[i][k],
                rec.reference[i][k] - rec.position[i][k]
            )?;
        }
        writeln!(f)?;
    }
    f.flush()?;
    // The same run as a `piezo fit` record (t, u = applied volts, y = measured um).
    let path = dir.join(format!("{stem}_record.csv"));
    std::fs::write(&path, rec.fit_record(None)?.to_csv())
        .with_context(|| format!("cannot write {}", path.display()))?;
    let mut plots = Vec::new();
    for i in 0..n_ax {
        let err: Vec<f64> = rec.reference[i]
            .iter()
            .zip(&rec.position[i])
            .map(|(a, b)| a - b)
            .collect();
        let ax = if n_ax > 1 {
            format!(" axis {i}")
        } else {
            String::new()
        };
        plots.push(
            Plot::new(&format!("{stem}{ax}: tracking"), "t [s]", "position [um]")
                .line("reference", &rec.t, &rec.reference[i])
                .line("position", &rec.t, &rec.position[i]),
        );
        plots.push(
            Plot::new(
                &format!("{stem}{ax}: position vs reference"),
                "reference [um]",
                "position [um]",
            )
            .line("position", &rec.reference[i], &rec.position[i])
            .line("ideal", &rec.reference[i], &rec.reference[i]),
        );
        plots.push(
            Plot::new(
                &format!("{stem}{ax}: tracking error"),
                "t [s]",
                "error [um]",
            )
            .line("reference - position", &rec.t, &err),
        );
        plots.push(
            Plot::new(
                &format!("{stem}{ax}: piezo voltage"),
                "t [s]",
                "voltage [V]",
            )
            .line("applied", &rec.t, &rec.volts[i]),
        );
    }
    if n_ax == 2 {
        plots.push(
            Plot::new(&format!("{stem}: scan"), "x [um]", "y [um]")
                .line("reference", &rec.reference[0], &rec.reference[1])
                .line("position", &rec.position[0], &rec.position[1]),
        );
    }
    write_grid(dir.join(format!("{stem}.svg")), &plots, 4)?;
    Ok(())
}
