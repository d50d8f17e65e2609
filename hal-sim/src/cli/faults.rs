//! `piezo faults`: the fault campaign over every controller mode.
use anyhow::{bail, Result};

use crate::faults::{Campaign, FaultKind};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Seeds per (fault, controller); each seed draws the fault's time, duration and size.
    #[arg(long, default_value_t = 100)]
    pub seeds: u64,
    /// Loop samples per case (100 kHz).
    #[arg(long, default_value_t = 3000)]
    pub samples: u64,
    /// Controller name (repeatable). Default: every controller of `piezo sim --list`.
    #[arg(long = "controller", value_name = "NAME")]
    pub controllers: Vec<String>,
    /// Fault name (repeatable). Default: all.
    #[arg(long = "fault", value_name = "NAME")]
    pub faults: Vec<String>,
    /// Print `{"cases":..,"unsafe_outputs":..,"max_samples_to_safe":..,"recorder_samples_lost":..,"by_fault":[..]}`.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> Result<()> {
    if args.seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    if args.samples < 500 {
        bail!("--samples must be at least 500, got {}", args.samples);
    }
    let mut faults = Vec::new();
    for f in &args.faults {
        match FaultKind::ALL.iter().find(|k| k.name() == f) {
            Some(k) => faults.push(*k),
            None => bail!(
                "unknown fault '{f}'; one of: {}",
                FaultKind::ALL.map(|k| k.name()).join(", ")
            ),
        }
    }
    let c = Campaign {
        seeds: args.seeds,
        samples: args.samples,
        controllers: args.controllers,
        faults: if faults.is_empty() {
            FaultKind::ALL.to_vec()
        } else {
            faults
        },
    };
    let report = crate::faults::run(&c, &|line| eprintln!("  {line}"))?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{:<24} {:>7} {:>7} {:>10} {:>8} {:>10}",
            "fault", "cases", "unsafe", "detectable", "to safe", "rec. lost"
        );
        for b in &report.by_fault {
            let to_safe = if b.detectable {
                format!("{}", b.max_samples_to_safe)
            } else {
                "-".into()
            };
            println!(
                "{:<24} {:>7} {:>7} {:>10} {:>8} {:>10}",
                b.fault,
                b.cases,
                b.unsafe_outputs,
                if b.detectable { "yes" } else { "no" },
                to_safe,
                b.recorder_samples_lost
            );
        }
        println!(
            "total: {} cases over {} controllers, {} unsafe outputs, safe state within {} samples, {} recorder samples lost",
            report.cases,
            report.controllers.len(),
            report.unsafe_outputs,
            report.max_samples_to_safe,
            report.recorder_samples_lost
        );
    }
    Ok(())
}
