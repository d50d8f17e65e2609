//! A finished capture of `piezo serial record`: CSV, SVG and summary.
use std::io::Write;
use std::path::Path;

use anyhow::{Context, Result};
use piezo_core::recorder::Signal;

use crate::plot::{write_grid, Plot};

/// The signals of `record --xy`: reference and position of both axes.
pub const XY_SIGNALS: [&str; 4] = ["ref_um", "y_um", "ref1_um", "y1_um"];

/// Unit of a recorder signal (for the CSV header and the plots).
pub fn signal_unit(s: Signal) -> &'static str {
    match s {
        Signal::RefUm
        | Signal::YUm
        | Signal::ErrorUm
        | Signal::RefUm1
        | Signal::YUm1
        | Signal::ErrorUm1 => "um",
        Signal::FfVolts | Signal::UVolts | Signal::FfVolts1 | Signal::UVolts1 => "V",
        Signal::AdcCode | Signal::DacCode | Signal::AdcCode1 | Signal::DacCode1 => "code",
    }
}

/// Unit of a channel named by the firmware (its names end in their unit).
fn name_unit(name: &str) -> &'static str {
    match Signal::from_name(name) {
        Some(s) => signal_unit(s),
        None if name.ends_with("_um") => "um",
        None if name.ends_with("_volts") => "V",
        None => "?",
    }
}

/// A finished capture.
#[derive(Debug, Clone)]
pub struct Recording {
    pub channels: Vec<String>,
    /// Frames per second (the control rate over the recorder's divider).
    pub sample_hz: f64,
    /// Frames before the trigger (time 0 is frame `pre`).
    pub pre: usize,
    pub trigger: String,
    /// Frames, oldest first.
    pub frames: Vec<Vec<f64>>,
}

impl Recording {
    pub fn t_s(&self, i: usize) -> f64 {
        (i as f64 - self.pre as f64) / self.sample_hz
    }

    /// The capture as a record (`crate::record`): header `i,t_s,<signal>...`, whose names
    /// end in their units (`ref_um`, `u_volts`), so `piezo fit` reads `t_s`, `u_volts` and
    /// `y_um` as time, input and output; the `# units:` line repeats them for a reader.
    pub fn write_csv(&self, path: &Path) -> Result<()> {
        let s = self.csv();
        if let Some(dir) = path.parent() {
            if !dir.as_os_str().is_empty() {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
            }
        }
        std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
    }

    /// The text of [`Recording::write_csv`].
    pub fn csv(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# piezo serial record: {} frames at {} Hz, trigger {}, {} frames before it (t_s = 0 at the trigger)",
            self.frames.len(),
            self.sample_hz,
            self.trigger,
            self.pre
        );
        let units: Vec<String> = self
            .channels
            .iter()
            .map(|n| format!("{n} [{}]", name_unit(n)))
            .collect();
        let _ = writeln!(s, "# units: i [frame], t_s [s], {}", units.join(", "));
        let _ = writeln!(s, "i,t_s,{}", self.channels.join(","));
        for (i, f) in self.frames.iter().enumerate() {
            let _ = write!(s, "{i},{:e}", self.t_s(i));
            for v in f {
                let _ = write!(s, ",{v}");
            }
            s.push('\n');
        }
        s
    }

    /// One panel per unit (positions together, voltages together, codes together).
    pub fn write_svg(&self, path: &Path) -> Result<()> {
        let t_ms: Vec<f64> = (0..self.frames.len()).map(|i| self.t_s(i) * 1e3).collect();
        let mut plots = Vec::new();
        let mut seen = Vec::new();
        for u in self.channels.iter().map(|n| name_unit(n)) {
            if seen.contains(&u) {
                continue;
            }
            seen.push(u);
            let mut p = Plot::new(
                &format!("recorder, trigger {}", self.trigger),
                "t [ms]",
                &format!("[{u}]"),
            );
            for (k, name) in self.channels.iter().enumerate() {
                if name_unit(name) == u {
                    let y: Vec<f64> = self
                        .frames
                        .iter()
                        .map(|f| f.get(k).copied().unwrap_or(f64::NAN))
                        .collect();
                    p = p.line(name, &t_ms, &y);
                }
            }
            plots.push(p);
        }
        // Both axes' reference and position: the path in the x-y plane.
        if let [Some(rx), Some(x), Some(ry), Some(y)] = XY_SIGNALS.map(|n| self.column(n)) {
            plots.push(
                Plot::new(
                    &format!("x-y path, trigger {}", self.trigger),
                    "x [um]",
                    "y [um]",
                )
                .line("reference (ref_um, ref1_um)", &rx, &ry)
                .line("measured (y_um, y1_um)", &x, &y),
            );
        }
        write_grid(path, &plots, 1).with_context(|| format!("writing {}", path.display()))
    }

    /// The values of channel `name`, if it was recorded.
    pub fn column(&self, name: &str) -> Option<Vec<f64>> {
        let k = self.channels.iter().position(|c| c == name)?;
        Some(
            self.frames
                .iter()
                .map(|f| f.get(k).copied().unwrap_or(f64::NAN))
                .collect(),
        )
    }

    /// RMS of reference minus position per axis whose pair was recorded (axis, um).
    pub fn tracking_rms(&self) -> Vec<(usize, f64)> {
        [("ref_um", "y_um"), ("ref1_um", "y1_um")]
            .iter()
            .enumerate()
            .filter_map(|(axis, (r, y))| {
                let (r, y) = (self.column(r)?, self.column(y)?);
                let n = r.len().max(1) as f64;
                let e2: f64 = r.iter().zip(&y).map(|(r, y)| (r - y) * (r - y)).sum();
                Some((axis, (e2 / n).sqrt()))
            })
            .collect()
    }

    /// Min/mean/max per channel.
    pub fn summary(&self, out: &mut impl Write) -> Result<()> {
        writeln!(
            out,
            "recorded {} frames at {} Hz ({:.3} ms), trigger {}",
            self.frames.len(),
            self.sample_hz,
            self.frames.len() as f64 / self.sample_hz * 1e3,
            self.trigger
        )?;
        for (k, name) in self.channels.iter().enumerate() {
            let v: Vec<f64> = self
                .frames
                .iter()
                .filter_map(|f| f.get(k).copied())
                .collect();
            let (lo, hi) = v
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
            writeln!(
                out,
                "  {name:<10} min {lo:>12.5} mean {mean:>12.5} max {hi:>12.5} {}",
                name_unit(name)
            )?;
        }
        for (axis, rms) in self.tracking_rms() {
            writeln!(out, "  tracking error axis {axis}: {rms:.5} um RMS")?;
        }
        Ok(())
    }
}
