//! `piezo predict`: simulate a saved `fit.json` from rest on an input record.
use super::fit_args::Columns;
pub use crate::ident::saved::{list, score_last_period, Loaded};
use crate::ident::ss::frf::detect_period;
use crate::record::Record;
use anyhow::Result;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// A `fit.json` written by `piezo fit --out DIR`.
    #[arg(long)]
    pub model: PathBuf,
    /// Input record: `t_s,u1_V..uk_V` (output columns, if present, are scored).
    #[arg(long)]
    pub input: PathBuf,
    /// Columns and units of the input record.
    #[command(flatten)]
    pub columns: Columns,
    /// Where to write the simulated output `t_s,y1_um..yn_um` (without units when the
    /// input record stated none).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    let model = Loaded::read(&args.model)?;
    let rec = args.columns.read_inputs(&args.input, false)?;
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
            unit_note: rec.unit_note.clone(),
        };
        r.write(out)?;
    }
    Ok(())
}
