//! `piezo score`: the fine-steering-mirror benchmark's official score of a saved model on
//! periodic records (one period of warm-up, every period scored without its first 100
//! samples, RMSE per output, period and record, then the mean), grouped by input level;
//! and what the data allow: the noise floor (the periods' difference) and, from the BLA of
//! a level's records, the noise and nonlinear distortion at the excited lines.
use super::fit_args::Columns;
use crate::ident::saved::Loaded;
use crate::ident::ss::scheduled::{group_by_level, record_level};
use crate::ident::ss::score::{self, period_of};
use crate::record::Quantity;
use anyhow::Result;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// A `fit.json` written by `piezo fit --out DIR` (without it: only the floors).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Periodic record with inputs and outputs (repeat for several; grouped by input level).
    #[arg(long, required = true)]
    pub record: Vec<PathBuf>,
    /// Columns and units of the records.
    #[command(flatten)]
    pub columns: Columns,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> Result<()> {
    let model = args.model.as_deref().map(Loaded::read).transpose()?;
    let recs = args
        .record
        .iter()
        .map(|p| args.columns.read(p, args.json))
        .collect::<Result<Vec<_>>>()?;
    let unit = Quantity::Length.internal();
    let mut per_record = Vec::new();
    let mut levels = Vec::new();
    let mut failed = Vec::new();
    for (path, rec) in args.record.iter().zip(&recs) {
        let n = period_of(rec)?;
        levels.push(record_level(rec, n));
        // A model that fails on one record (an LFR that diverges) leaves the others scored:
        // the record says why, its level has no mean, and the command fails at the end.
        let scored = model.as_ref().map(|m| {
            score::official(rec, |u| {
                let r = crate::record::Record {
                    t: (0..u[0].len()).map(|k| k as f64 * rec.dt()).collect(),
                    u: u.to_vec(),
                    y: Vec::new(),
                    comments: Vec::new(),
                    extra: Vec::new(),
                    unit_note: None,
                };
                m.simulate(&r)
            })
        });
        let (s, error) = match scored {
            Some(Ok(s)) => (Some(s), None),
            Some(Err(e)) => {
                failed.push(format!("{}: {e:#}", path.display()));
                (None, Some(format!("{e:#}")))
            }
            None => (None, None),
        };
        let floor = score::noise_floor(rec);
        if !args.json {
            println!(
                "{}: level {:.4} V RMS, period {n}: {}{}noise floor {}",
                path.display(),
                levels.last().unwrap_or(&0.0),
                error
                    .as_ref()
                    .map_or(String::new(), |e| format!("not scored ({e}), ")),
                s.as_ref().map_or(String::new(), |s| format!(
                    "official RMSE {:.5} {unit} (per period and output {:?}), ",
                    s.mean,
                    s.rmse
                        .iter()
                        .map(|r| r.iter().map(|v| format!("{v:.5}")).collect::<Vec<_>>())
                        .collect::<Vec<_>>()
                )),
                floor.map_or("n/a (one period)".into(), |f| format!("{f:.5} {unit}"))
            );
        }
        per_record.push(serde_json::json!({
            "record": path.display().to_string(),
            "level_v_rms": levels.last(),
            "official": s,
            "error": error,
            "noise_floor": floor,
        }));
    }
    let mut groups = Vec::new();
    for g in group_by_level(&levels) {
        let mean = |f: &dyn Fn(usize) -> Option<f64>| -> Option<f64> {
            let v: Option<Vec<f64>> = g.iter().map(|&i| f(i)).collect();
            v.map(|v| v.iter().sum::<f64>() / v.len().max(1) as f64)
        };
        // No mean over a level with a record the model failed on.
        let official = mean(&|i| per_record[i]["official"]["mean"].as_f64());
        let floor = mean(&|i| per_record[i]["noise_floor"].as_f64());
        let group: Vec<_> = g.iter().map(|&i| recs[i].clone()).collect();
        let bla = super::fit_ss::bla_levels(&group).ok().flatten();
        let level = g.iter().map(|&i| levels[i]).sum::<f64>() / g.len() as f64;
        if !args.json {
            println!(
                "level {level:.4} V RMS ({} records): {}noise floor {}; BLA noise {}, nonlinear distortion {} {unit} RMS per period",
                g.len(),
                match (official, &model) {
                    (Some(o), _) => format!("official RMSE {o:.5} {unit}, "),
                    (None, Some(_)) => "official RMSE n/a (a record not scored), ".into(),
                    (None, None) => String::new(),
                },
                floor.map_or("n/a".into(), |f| format!("{f:.5} {unit}")),
                bla.as_ref().map_or("n/a".into(), |b| format!("{:.5}", b.noise_rms)),
                bla.as_ref()
                    .and_then(|b| b.distortion_rms)
                    .map_or("n/a (needs more records than inputs)".into(), |d| format!("{d:.5}")),
            );
        }
        groups.push(serde_json::json!({
            "level_v_rms": level,
            "records": g.iter().map(|&i| args.record[i].display().to_string()).collect::<Vec<_>>(),
            "official_rmse": official,
            "noise_floor": floor,
            "bla": bla,
        }));
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "unit": unit,
                "records": per_record,
                "levels": groups,
            }))?
        );
    }
    anyhow::ensure!(
        failed.is_empty(),
        "the model could not be scored on {} of {} records (the others are above):\n  {}",
        failed.len(),
        recs.len(),
        failed.join("\n  ")
    );
    Ok(())
}
