//! `piezo`: simulate, identify and diagnose piezo stages on the host.
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "piezo",
    version,
    about = "Simulate, identify and diagnose piezoelectric stages"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Drive every hysteresis model with a decaying sine; write each loop as CSV and SVG.
    Demo(hal_sim::cli::demo::Args),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.cmd {
        Cmd::Demo(a) => hal_sim::cli::demo::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
