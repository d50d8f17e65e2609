//! `piezo`: simulate, identify and diagnose piezo stages on the host.
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "piezo",
    version,
    about = "Simulate, identify and diagnose piezoelectric stages"
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Drive every hysteresis model with a decaying sine; write each loop as CSV and SVG.
    Demo(hal_sim::cli::demo::Args),
    /// Run control scenarios on the simulated stage and print tracking metrics.
    Sim(hal_sim::cli::sim::Args),
    /// Identify a model from a measured CSV record.
    Fit(Box<hal_sim::cli::fit::Args>),
    /// Simulate a saved model (`fit.json`) from rest on an input record.
    Predict(hal_sim::cli::predict::Args),
    /// Score a saved model on periodic records by the FSM benchmark's official rule; noise floor and BLA distortion per level.
    Score(hal_sim::cli::score::Args),
    /// Find what the base model gets wrong, name the cause, extend the model, measure the gain.
    Diagnose(hal_sim::cli::diagnose::Args),
    /// Run diagnose on an independent generator's stages with hidden causes; print recall,
    /// false positives and exact-set accuracy.
    DiagnoseBench(hal_sim::cli::diagnose_bench::Args),
    /// Fault campaign over every controller mode.
    Faults(hal_sim::cli::faults::Args),
    /// Talk to the firmware over its serial command port (or QEMU's, over TCP).
    Serial(hal_sim::cli::serial::Args),
    /// Lab console in the browser: scope, settings, mode, wave, Stop, bode, identify.
    Ui(hal_sim::cli::ui::Args),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.cmd {
        Cmd::Demo(a) => hal_sim::cli::demo::run(a),
        Cmd::Sim(a) => hal_sim::cli::sim::run(a),
        Cmd::Fit(a) => hal_sim::cli::fit::run(*a),
        Cmd::Predict(a) => hal_sim::cli::predict::run(a),
        Cmd::Score(a) => hal_sim::cli::score::run(a),
        Cmd::Diagnose(a) => hal_sim::cli::diagnose::run(a),
        Cmd::DiagnoseBench(a) => hal_sim::cli::diagnose_bench::run(a),
        Cmd::Faults(a) => hal_sim::cli::faults::run(a),
        Cmd::Serial(a) => hal_sim::cli::serial::run(a),
        Cmd::Ui(a) => hal_sim::cli::ui::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
