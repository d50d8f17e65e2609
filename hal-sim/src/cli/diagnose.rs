//! `piezo diagnose`: what does the classical Bouc-Wen model miss on this stage?
//!
//! ```text
//! piezo diagnose --train A.csv --valid B.csv [--json] [--predict OUT.csv] [--out DIR]
//! piezo diagnose --train A.csv --split 0.5        # one record: first half fits, second validates
//! piezo diagnose --train A.csv --train B.csv --valid C.csv --valid D.csv   # one model for A and B
//! piezo diagnose --train A.csv --train-window 3.26:6.26 --valid-window 6.26:   # windows of A
//! piezo diagnose --train A.csv --valid B.csv --no-consistency   # skip the swapped run
//! piezo diagnose --base DIR/fit.json --train A.csv --valid B.csv   # from an identified model
//! ```
//!
//! Every run also checks itself on other arrangements of the same data (unless
//! `--no-consistency`): a split record at the other splits of 0.5 / 0.65 / 0.8, time windows
//! at those splits of the whole records, a pair with the records' roles swapped. Causes named
//! in every arrangement are `confident`, the others `uncertain`.
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::fit_args::{Columns, Records, Window};
use crate::ident::diagnose::consistency::{self, Arrangement, SPLITS};
pub use crate::ident::diagnose::report::summary;
use crate::ident::diagnose::{self, report, Diagnosis, Options, Signals};
use crate::report::Report;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Training and validation records (one model fitted on all training records; without
    /// --valid, --split 0.5).
    #[command(flatten)]
    pub records: Records,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Write `t, y_base, y_ext` (suffixed per output for several outputs) on the validation
    /// samples to this CSV (several validation records: a first column `record`, 1-based).
    #[arg(long)]
    pub predict: Option<PathBuf>,
    /// Write plots (loops before/after, residual against the cause's signal) and index.html
    /// (the report with them) into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Skip the consistency check (the same rule run on the other splits of 0.5 / 0.65 / 0.8,
    /// or with the records' roles swapped).
    #[arg(long)]
    pub no_consistency: bool,
    /// Start from this identified model (`piezo fit --model ss | hammerstein-ss |
    /// scheduled-ss | lfr`, its `fit.json`) instead of the classical Bouc-Wen: the causes that
    /// apply to it (structure-nonlinearity, input-hysteresis, creep, drift, delay) are fitted
    /// on --train and scored on --valid by the benchmark's official rule, any number of
    /// inputs and outputs; the records must be periodic (whole periods of a multisine).
    /// With --out, the final model is written as DIR/fit.json (predict, score, sim --stage).
    #[arg(long, value_name = "DIR/fit.json")]
    pub base: Option<PathBuf>,
    /// Columns and units of the records.
    #[command(flatten)]
    pub columns: Columns,
}

fn read(path: &Path, columns: &Columns) -> Result<Signals> {
    let r = columns.read(path, false)?;
    Signals::new(r.t, r.u, r.y).with_context(|| format!("record {}", path.display()))
}

pub fn run(args: Args) -> Result<()> {
    if let Some(base) = &args.base {
        return run_from_base(&args, base);
    }
    let report_start = args.out.as_ref().map(|_| Report::start("piezo diagnose"));
    let load = |p: &PathBuf| read(p, &args.columns);
    let rs = &args.records;
    anyhow::ensure!(!rs.train.is_empty(), "--train is required (see --help)");
    let records = rs.train.iter().map(load).collect::<Result<Vec<_>>>()?;
    let windowed = rs.train_window.is_some() || rs.valid_window.is_some();
    let wholes = records.clone();
    // The arrangement asked for, and the others the consistency check runs.
    let (label, others): (String, Vec<Arrangement>) = if windowed {
        (
            "windows".into(),
            SPLITS
                .iter()
                .map(|&f| Arrangement::split(&wholes, f))
                .collect(),
        )
    } else if rs.valid.is_empty() {
        let f = rs.split.unwrap_or(0.5);
        (format!("split {f}"), consistency::other_splits(&wholes, f))
    } else {
        ("as given".into(), Vec::new())
    };
    let (train, valid, split_note) = if windowed {
        rs.split_at(0, None)?;
        let valid = if rs.valid.is_empty() {
            anyhow::ensure!(
                rs.train_window.is_some() && rs.valid_window.is_some(),
                "without --valid, give both --train-window and --valid-window (the training records then validate too)"
            );
            records.clone()
        } else {
            rs.valid.iter().map(load).collect::<Result<Vec<_>>>()?
        };
        let train = match rs.train_window {
            Some(w) => records
                .iter()
                .map(|r| train_window(r, w))
                .collect::<Result<Vec<_>>>()?,
            None => records,
        };
        let valid = match rs.valid_window {
            Some(w) => valid
                .iter()
                .map(|r| valid_window(r, w))
                .collect::<Result<Vec<_>>>()?,
            None => valid,
        };
        let show = |w: Option<Window>| {
            w.map_or("whole records".to_string(), |w| {
                format!("{}..{} s", w.from_s, w.to_s)
            })
        };
        let note = format!(
            "fit on {} of the training records, scored on {} of the validation records (the model runs through the samples before the window)",
            show(rs.train_window),
            show(rs.valid_window)
        );
        (train, valid, Some(note))
    } else if rs.valid.is_empty() {
        let names: Vec<String> = rs.train.iter().map(|p| p.display().to_string()).collect();
        let h = report::split_records(records, &names, rs.split.unwrap_or(0.5))?;
        (h.train, h.valid, Some(h.note))
    } else {
        rs.split_at(0, None)?;
        let valid = rs.valid.iter().map(load).collect::<Result<Vec<_>>>()?;
        (records, valid, None)
    };
    let opt = Options::default();
    let d = diagnose::diagnose_records(&train, &valid, &opt)?;
    let consistency = if args.no_consistency {
        None
    } else {
        let others = if label == "as given" {
            vec![Arrangement::swapped(&train, &valid)]
        } else {
            others
        };
        Some(consistency::check(&label, &d, &others, &opt)?)
    };
    let mut plots = Vec::new();
    if let Some(dir) = &args.out {
        if valid.len() == 1 {
            plots = diagnose::plots::write(dir, &d, &valid[0])?;
        } else {
            for (k, v) in valid.iter().enumerate() {
                plots.extend(diagnose::plots::write(
                    &dir.join(format!("valid{}", k + 1)),
                    &d,
                    v,
                )?);
            }
        }
    }
    if let Some(path) = &args.predict {
        write_predict(path, &d, &valid)?;
    }
    let files = |ps: &[PathBuf]| {
        ps.iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
    };
    let train_files = files(&rs.train);
    let valid_files = if rs.valid.is_empty() {
        train_files.clone()
    } else {
        files(&rs.valid)
    };
    let mut j = report::json(
        &d,
        split_note.as_deref(),
        &train_files,
        &valid_files,
        &files(&plots),
    );
    if let Some(c) = &consistency {
        j["consistency"] = c.json();
    }
    let mut text = report::summary(&d, split_note.as_deref());
    if let Some(c) = &consistency {
        text += &format!("{}\n", c.text());
    }
    let index = match (&args.out, report_start) {
        (Some(dir), Some(r)) => Some(write_report(r, dir, &text, &j, &plots)?),
        _ => None,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        print!("{text}");
        for p in &plots {
            println!("plot: {}", p.display());
        }
        if let Some(p) = &args.predict {
            println!("predictions: {}", p.display());
        }
        if let Some(i) = index {
            println!("report: {}", i.display());
        }
    }
    Ok(())
}

/// `index.html`: the report as printed, its plots, the causes tried and the models as
/// tables (the `--json` document's).
fn write_report(
    mut r: Report,
    dir: &Path,
    text: &str,
    j: &serde_json::Value,
    plots: &[PathBuf],
) -> Result<PathBuf> {
    let s = r.section("Diagnosis");
    s.pre(text);
    for p in plots {
        if let Ok(rel) = p.strip_prefix(dir) {
            s.plot(rel.to_string_lossy().into_owned());
        }
    }
    r.json("The report in numbers (piezo diagnose --json)", j);
    r.write(dir)
}

/// The samples of `r` inside `w`, the model starting at rest at the first.
fn train_window(r: &Signals, w: Window) -> Result<Signals> {
    let (a, b) = w.samples(&r.t);
    anyhow::ensure!(
        b - a >= 50,
        "--train-window {}..{} s holds {} samples, at least 50 needed",
        w.from_s,
        w.to_s,
        b - a
    );
    Ok(r.slice(a, b))
}

/// `r` up to the end of `w`, scored inside `w` only (the samples before are warm-up).
fn valid_window(r: &Signals, w: Window) -> Result<Signals> {
    let (a, b) = w.samples(&r.t);
    anyhow::ensure!(
        b - a >= 50,
        "--valid-window {}..{} s holds {} samples, at least 50 needed",
        w.from_s,
        w.to_s,
        b - a
    );
    Ok(r.slice(0, b).with_warmup(a))
}

fn write_predict(path: &PathBuf, d: &Diagnosis, valid: &[Signals]) -> Result<()> {
    let several = valid.len() > 1;
    let n_out = valid[0].y.len();
    let suffix = |i: usize| {
        if n_out == 1 {
            String::new()
        } else {
            (i + 1).to_string()
        }
    };
    let mut text = String::from(if several { "record,t" } else { "t" });
    for i in 0..n_out {
        let _ = write!(text, ",y_base{0},y_ext{0}", suffix(i));
    }
    text.push('\n');
    for (r, v) in valid.iter().enumerate() {
        let base = d.base.predict(v);
        let ext = d.extended.predict(v);
        let v = &v.scored();
        for k in 0..v.len() {
            if several {
                let _ = write!(text, "{},", r + 1);
            }
            let _ = write!(text, "{}", v.t[k]);
            for i in 0..n_out {
                let _ = write!(text, ",{},{}", base[i][k], ext[i][k]);
            }
            text.push('\n');
        }
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// `--base`: discovery from an identified state-space model
/// ([`crate::ident::diagnose::from_base`]).
fn run_from_base(args: &Args, base: &Path) -> Result<()> {
    use crate::ident::diagnose::from_base;
    use crate::ident::saved::Loaded;
    let rs = &args.records;
    anyhow::ensure!(
        !rs.train.is_empty() && !rs.valid.is_empty(),
        "--base needs --train and --valid records (periodic: whole periods of a multisine)"
    );
    anyhow::ensure!(
        rs.split.is_none() && rs.train_window.is_none() && rs.valid_window.is_none(),
        "--base scores whole periodic records: --split and the windows do not apply"
    );
    // The kind first: a per-axis fit is refused by name, not by what it lacks.
    let text =
        std::fs::read_to_string(base).with_context(|| format!("cannot read {}", base.display()))?;
    let kind = serde_json::from_str::<serde_json::Value>(&text)
        .ok()
        .and_then(|v| v.get("model").and_then(|m| m.as_str()).map(String::from))
        .unwrap_or_default();
    anyhow::ensure!(
        crate::ident::saved::handles(&kind),
        "{}: model `{kind}`: --base takes a state-space fit.json (piezo fit --model ss | hammerstein-ss | scheduled-ss | lfr); the per-axis hysteresis fits are diagnose's own base already (leave --base out)",
        base.display()
    );
    let Loaded::Ss(saved) = Loaded::parse(&text, &base.display().to_string())? else {
        anyhow::bail!("{}: not a state-space fit.json", base.display());
    };
    let read = |p: &PathBuf| args.columns.read(p, true);
    let train = rs.train.iter().map(read).collect::<Result<Vec<_>>>()?;
    let valid = rs.valid.iter().map(read).collect::<Result<Vec<_>>>()?;
    let names = |ps: &[PathBuf]| {
        ps.iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
    };
    let (train_names, valid_names) = (names(&rs.train), names(&rs.valid));
    let run = from_base::run(
        &saved,
        &base.display().to_string(),
        (&train, &train_names),
        (&valid, &valid_names),
        !args.json,
    )?;
    if let Some(path) = &args.predict {
        write_predict_base(path, &run.base, &run.last, &valid)?;
    }
    let text = run.diagnosis.text(&saved.output_unit);
    let j = &run.json;
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let mut r = Report::start("piezo diagnose --base");
        r.section("Diagnosis from an identified model").pre(&text);
        r.json("The report in numbers (piezo diagnose --base --json)", j);
        let index = r.write(dir)?;
        std::fs::write(dir.join("diagnosis.json"), serde_json::to_string_pretty(j)?)
            .with_context(|| format!("cannot write {}", dir.join("diagnosis.json").display()))?;
        // The final model, for predict, score, sim --stage and another --base.
        let fit = dir.join("fit.json");
        std::fs::write(&fit, serde_json::to_string_pretty(&run.fit)?)
            .with_context(|| format!("cannot write {}", fit.display()))?;
        if !args.json {
            println!("report: {}", index.display());
            println!("extended model: {}", fit.display());
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        print!("{text}");
        if let Some(p) = &args.predict {
            println!("predictions: {}", p.display());
        }
    }
    Ok(())
}

/// `--predict` with `--base`: `record,t,scored,y_base1,y_ext1,...` on every validation
/// record (the official rule's simulation: a period of warm-up first; `scored` 1 on the
/// samples the score reads), so the gains reproduce from the file.
fn write_predict_base(
    path: &Path,
    base: &crate::ident::diagnose::from_base::Model,
    last: &crate::ident::diagnose::from_base::Model,
    valid: &[crate::record::Record],
) -> Result<()> {
    use crate::ident::diagnose::from_base::{predict, scored};
    use crate::ident::ss::score::period_of;
    let outputs = valid.first().map_or(0, |r| r.y.len());
    let mut text = String::from("record,t,scored");
    for o in 1..=outputs {
        let _ = write!(text, ",y_base{o},y_ext{o}");
    }
    text.push('\n');
    for (i, r) in valid.iter().enumerate() {
        let (yb, ye) = (predict(base, r)?, predict(last, r)?);
        let n = period_of(r)?;
        for k in 0..r.len() {
            let _ = write!(
                text,
                "{},{},{}",
                i + 1,
                r.t[k],
                u8::from(scored(r.len(), n, k))
            );
            for o in 0..outputs {
                let _ = write!(text, ",{},{}", yb[o][k], ye[o][k]);
            }
            text.push('\n');
        }
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}
