//! `piezo predict`: simulate a saved `fit.json` from rest on an input record.
pub use crate::ident::saved::{list, score_last_period, Loaded};
use crate::ident::ss::frf::detect_period;
use crate::record::Record;
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// A `fit.json` written by `piezo fit --out DIR`.
    #[arg(long)]
    pub model: PathBuf,
    /// Input record: `t,u1..uk` (output columns, if present, are scored).
    #[arg(long)]
    pub input: PathBuf,
    /// Where to write the simulated output `t,y1..yn`.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Reads a record that may hold inputs only (`t,u1..uk`): then `y` is empty.
pub fn read_inputs(path: &Path) -> Result<Record> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read record {}", path.display()))?;
    let is_y = |c: &str| {
        c == "y"
            || c.strip_prefix('y')
                .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
    };
    let header = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'));
    let has_y = header.is_some_and(|h| h.split(',').map(str::trim).any(is_y));
    if has_y || header.is_none() {
        return Record::read(path);
    }
    // A placeholder output column lets the record parser check everything else.
    let mut seen_header = false;
    let mut padded = String::with_capacity(text.len() + text.len() / 8);
    for line in text.lines() {
        let l = line.trim();
        padded.push_str(line);
        if !l.is_empty() && !l.starts_with('#') {
            padded.push_str(if seen_header { ",0" } else { ",y" });
            seen_header = true;
        }
        padded.push('\n');
    }
    let mut rec =
        Record::parse(&padded).map_err(|e| anyhow::anyhow!("record {}: {e}", path.display()))?;
    rec.y.clear();
    Ok(rec)
}

pub fn run(args: Args) -> Result<()> {
    let model = Loaded::read(&args.model)?;
    let rec = read_inputs(&args.input)?;
    let sim = model.simulate(&rec)?;
    if !rec.y.is_empty() {
        anyhow::ensure!(
            rec.y.len() == sim.len(),
            "the record has {} outputs, the model {}",
            rec.y.len(),
            sim.len()
        );
        let (per, mean) = score_last_period(&rec, &sim);
        println!(
            "RMSE over the last period of {} samples: mean {mean:.5e}, per output {}",
            detect_period(&rec),
            list(&per)
        );
    }
    if let Some(out) = &args.out {
        let r = Record {
            comments: vec![format!(
                " piezo predict --model {}: simulated from rest",
                args.model.display()
            )],
            t: rec.t.clone(),
            u: Vec::new(),
            y: sim,
            extra: Vec::new(),
        };
        r.write(out)?;
    }
    Ok(())
}
