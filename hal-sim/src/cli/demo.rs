//! `piezo demo`: every hysteresis model driven by a decaying sine; each loop as CSV and SVG.
use anyhow::{Context, Result};
use piezo_core::hysteresis::{Cbw, Hysteresis};
use std::io::Write;
use std::path::PathBuf;

use crate::plot::{write_grid, Plot};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output folder for the CSV files and plots.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Sample rate (Hz).
    #[arg(long, default_value_t = 10_000.0)]
    pub rate_hz: f64,
}

/// A decaying sine from 0: `u(t) = amp * e^(-t/tau) * sin(2 pi f t)`, 1 Hz, 6 s.
pub fn decaying_sine(amp: f64, rate_hz: f64) -> (Vec<f64>, Vec<f64>) {
    let n = (6.0 * rate_hz) as usize;
    let t: Vec<f64> = (0..n).map(|k| k as f64 / rate_hz).collect();
    let u = t
        .iter()
        .map(|t| amp * (-t / 2.5).exp() * (2.0 * std::f64::consts::PI * t).sin())
        .collect();
    (t, u)
}

/// Runs `model` over `u` from rest and returns its output.
pub fn run_model<M: Hysteresis<f64>>(model: &M, u: &[f64], dt: f64) -> Vec<f64> {
    let mut s = model.init(0.0);
    u.iter().map(|&u| model.step(&mut s, u, dt)).collect()
}

pub fn run(args: Args) -> Result<()> {
    anyhow::ensure!(
        args.rate_hz.is_finite() && args.rate_hz >= 10.0,
        "--rate-hz must be at least 10 Hz, got {}",
        args.rate_hz
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let dt = 1.0 / args.rate_hz;
    let (t, u) = decaying_sine(100.0, args.rate_hz);
    let cbw = Cbw::with_n1(0.16, 0.07, 0.02, 0.01)?;
    let models: Vec<(&str, Vec<f64>)> = vec![("cbw", run_model(&cbw, &u, dt))];
    let mut plots = Vec::new();
    for (name, y) in &models {
        let path = args.out.join(format!("{name}.csv"));
        let mut f = std::io::BufWriter::new(
            std::fs::File::create(&path)
                .with_context(|| format!("cannot write {}", path.display()))?,
        );
        writeln!(f, "t,u,y")?;
        for k in 0..t.len() {
            writeln!(f, "{},{},{}", t[k], u[k], y[k])?;
        }
        plots.push(Plot::new(name, "u [V]", "y [um]").line(name, &u, y));
        println!("{name}: {}", path.display());
    }
    let svg = args.out.join("loops.svg");
    write_grid(&svg, &plots, 3)?;
    println!("plot: {}", svg.display());
    Ok(())
}
