//! `piezo serial wave`: start a waveform, load and start a table, hold or stop.
use std::io::Write;
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use piezo_core::command::{Command, Shape, MAX_LEVELS, MAX_LINES};
use piezo_core::pipeline::excitation::{MULTISINE_MAX, PRBS_ORDER_MAX, PRBS_ORDER_MIN};

use crate::serial::lines::table_lines;
use crate::serial::Client;

use super::units::{f32_of, parse_hz, parse_seconds, parse_um};

#[derive(clap::Subcommand, Debug)]
pub enum WaveCmd {
    /// Sine around --offset (`wave sine 5um 100Hz --offset 10um`).
    Sine(WaveArgs),
    /// Triangle around --offset.
    Triangle(WaveArgs),
    /// Square between offset - amplitude and offset + amplitude.
    Square(WaveArgs),
    /// Staircase from LOW up to HIGH in LEVELS levels and back down, once per period
    /// (`wave steps 10um 30um 5 2Hz`; 2 levels is a square wave).
    Steps {
        #[arg(value_parser = parse_um, allow_hyphen_values = true)]
        low: f64,
        #[arg(value_parser = parse_um, allow_hyphen_values = true)]
        high: f64,
        /// Number of levels, 2 to 64.
        #[arg(value_parser = clap::value_parser!(u16).range(2..=MAX_LEVELS as i64))]
        levels: u16,
        #[arg(value_parser = parse_hz)]
        freq: f64,
    },
    /// Periodic spline through 2 to 64 points, one period per 1/--freq (`wave table
    /// --freq 10Hz --points 0,20,5,15` or `--file points.csv`). Loads the firmware's table
    /// (`table clear`, `table add ...`) and starts it (`wave table`).
    Table(TableArgs),
    /// Pseudo-random binary sequence between LOW and HIGH for identifying the linear part:
    /// a maximal LFSR of ORDER bits (2 to 20: 2^ORDER - 1 bits per period) at BIT_RATE
    /// bits/s (below the sample rate) (`wave prbs 10um 12um 12 10kHz`).
    Prbs {
        #[arg(value_parser = parse_um, allow_hyphen_values = true)]
        low: f64,
        #[arg(value_parser = parse_um, allow_hyphen_values = true)]
        high: f64,
        #[arg(value_parser = clap::value_parser!(u8).range(PRBS_ORDER_MIN as i64..=PRBS_ORDER_MAX as i64))]
        order: u8,
        #[arg(value_parser = parse_hz)]
        bit_rate: f64,
        /// Start state of the register (any non-zero pattern; the same seed, the same
        /// sequence).
        #[arg(long, default_value_t = 1)]
        seed: u32,
    },
    /// Linear sine sweep from F0 to F1 over DURATION, repeated, around --offset
    /// (`wave chirp 2um 1Hz 2kHz 10s --offset 50um`).
    Chirp {
        #[arg(value_parser = parse_um)]
        amplitude: f64,
        #[arg(value_parser = parse_hz)]
        f0: f64,
        #[arg(value_parser = parse_hz)]
        f1: f64,
        #[arg(value_parser = parse_seconds)]
        duration: f64,
        #[arg(long, default_value = "0um", value_parser = parse_um, allow_hyphen_values = true)]
        offset: f64,
    },
    /// Multisine: HARMONICS (1 to 32) equal harmonics of F0 (the period is 1/F0), peak
    /// AMPLITUDE around --offset; --seed 0 gives Schroeder's low-crest phases, others
    /// random phases (`wave multisine 2um 10Hz 32 --offset 50um --seed 3`).
    Multisine {
        #[arg(value_parser = parse_um)]
        amplitude: f64,
        #[arg(value_parser = parse_hz)]
        f0: f64,
        #[arg(value_parser = clap::value_parser!(u8).range(1..=MULTISINE_MAX as i64))]
        harmonics: u8,
        #[arg(long, default_value = "0um", value_parser = parse_um, allow_hyphen_values = true)]
        offset: f64,
        #[arg(long, default_value_t = 0)]
        seed: u32,
    },
    /// Hold a position (`wave hold 12.5um`).
    Hold {
        #[arg(value_parser = parse_um, allow_hyphen_values = true)]
        position: f64,
    },
    /// Stop the waveform and hold where it is (every axis).
    Off,
    /// XY raster (2-axis firmware, `--features xy`): x triangle over X_SPAN at LINE_FREQ,
    /// y triangle over Y_SPAN, one y sweep per LINES x periods (`wave raster 20um 20um 16
    /// 50Hz --center 30um,30um`).
    Raster {
        #[arg(value_parser = parse_um)]
        x_span: f64,
        #[arg(value_parser = parse_um)]
        y_span: f64,
        /// x periods per y sweep, 1 to 4096.
        #[arg(value_parser = clap::value_parser!(u16).range(1..=MAX_LINES as i64))]
        lines: u16,
        #[arg(value_parser = parse_hz)]
        line_freq: f64,
        /// Centre `x,y` of the scan (default: half the spans, so it starts at 0).
        #[arg(long, value_delimiter = ',', num_args = 1, value_parser = parse_um, allow_hyphen_values = true)]
        center: Option<Vec<f64>>,
    },
    /// XY Lissajous scan (2-axis firmware): sines of X_AMP at FX and Y_AMP at FY, y --phase
    /// ahead (`wave lissajous 10um 10um 40Hz 30Hz --center 30um,30um`).
    Lissajous {
        #[arg(value_parser = parse_um)]
        x_amp: f64,
        #[arg(value_parser = parse_um)]
        y_amp: f64,
        #[arg(value_parser = parse_hz)]
        fx: f64,
        #[arg(value_parser = parse_hz)]
        fy: f64,
        /// Phase of y ahead of x, degrees (-360 to 360).
        #[arg(long, default_value_t = 90.0, allow_hyphen_values = true)]
        phase: f64,
        /// Centre `x,y` of the scan (default: the amplitudes, so it starts at 0).
        #[arg(long, value_delimiter = ',', num_args = 1, value_parser = parse_um, allow_hyphen_values = true)]
        center: Option<Vec<f64>>,
    },
}

/// `--center x,y` (two positions), or `default`.
fn center_of(center: &Option<Vec<f64>>, default: [f64; 2]) -> Result<[f32; 2]> {
    match center.as_deref() {
        None => Ok(default.map(f32_of)),
        Some(&[x, y]) => Ok([f32_of(x), f32_of(y)]),
        Some(v) => bail!("--center takes two positions x,y, got {}", v.len()),
    }
}

#[derive(clap::Args, Debug)]
pub struct WaveArgs {
    /// Amplitude (`5um`, `500nm`; bare numbers in um).
    #[arg(value_parser = parse_um)]
    pub amplitude: f64,
    /// Frequency (`100Hz`, `1kHz`; bare numbers in Hz).
    #[arg(value_parser = parse_hz)]
    pub freq: f64,
    /// Centre position.
    #[arg(long, default_value = "0um", value_parser = parse_um, allow_hyphen_values = true)]
    pub offset: f64,
}

#[derive(clap::Args, Debug)]
pub struct TableArgs {
    /// Frequency of one pass through the points (`10Hz`).
    #[arg(long, value_parser = parse_hz)]
    pub freq: f64,
    /// Points, comma separated (`0,20,5um,15`; bare numbers in um).
    #[arg(
        long,
        value_delimiter = ',',
        value_parser = parse_um,
        allow_hyphen_values = true,
        required_unless_present = "file"
    )]
    pub points: Vec<f64>,
    /// File of points: numbers separated by commas, spaces or newlines, `#` comments.
    #[arg(long, conflicts_with = "points")]
    pub file: Option<PathBuf>,
}

/// Points (um) from a file: numbers (optionally with a length unit) separated by commas,
/// spaces or newlines; `#` starts a comment.
pub fn read_points(path: &std::path::Path) -> Result<Vec<f64>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let data = line.split('#').next().unwrap_or("");
        for field in data.split(|c: char| c == ',' || c.is_whitespace()) {
            if field.is_empty() {
                continue;
            }
            let v = parse_um(field).map_err(|e| anyhow!("{}:{}: {e}", path.display(), n + 1))?;
            points.push(v);
        }
    }
    Ok(points)
}

/// Sends the waveform `w` (a table: every line built and checked before the first is sent).
pub fn run(c: &mut Client, w: WaveCmd, out: &mut impl Write) -> Result<()> {
    let cmd = match w {
        WaveCmd::Sine(a) => wave(Shape::Sine, a),
        WaveCmd::Triangle(a) => wave(Shape::Triangle, a),
        WaveCmd::Square(a) => wave(Shape::Square, a),
        WaveCmd::Hold { position } => Command::WaveHold(f32_of(position)),
        WaveCmd::Off => Command::WaveOff,
        WaveCmd::Raster {
            x_span,
            y_span,
            lines,
            line_freq,
            center,
        } => Command::WaveRaster {
            span_um: [f32_of(x_span), f32_of(y_span)],
            lines,
            line_hz: f32_of(line_freq),
            center_um: center_of(&center, [x_span / 2.0, y_span / 2.0])?,
        },
        WaveCmd::Lissajous {
            x_amp,
            y_amp,
            fx,
            fy,
            phase,
            center,
        } => Command::WaveLissajous {
            amp_um: [f32_of(x_amp), f32_of(y_amp)],
            freq_hz: [f32_of(fx), f32_of(fy)],
            phase_deg: f32_of(phase),
            center_um: center_of(&center, [x_amp, y_amp])?,
        },
        WaveCmd::Prbs {
            low,
            high,
            order,
            bit_rate,
            seed,
        } => Command::WavePrbs {
            low_um: f32_of(low),
            high_um: f32_of(high),
            order,
            bit_hz: f32_of(bit_rate),
            seed,
        },
        WaveCmd::Chirp {
            amplitude,
            f0,
            f1,
            duration,
            offset,
        } => Command::WaveChirp {
            amp_um: f32_of(amplitude),
            f0_hz: f32_of(f0),
            f1_hz: f32_of(f1),
            duration_s: f32_of(duration),
            offset_um: f32_of(offset),
        },
        WaveCmd::Multisine {
            amplitude,
            f0,
            harmonics,
            offset,
            seed,
        } => Command::WaveMultisine {
            amp_um: f32_of(amplitude),
            f0_hz: f32_of(f0),
            harmonics,
            offset_um: f32_of(offset),
            seed,
        },
        WaveCmd::Steps {
            low,
            high,
            levels,
            freq,
        } => Command::WaveSteps {
            low_um: f32_of(low),
            high_um: f32_of(high),
            levels,
            freq_hz: f32_of(freq),
        },
        WaveCmd::Table(t) => {
            let points = match &t.file {
                Some(f) => read_points(f)?,
                None => t.points.clone(),
            };
            let points: Vec<f32> = points.into_iter().map(f32_of).collect();
            // Every line is built and checked before the first is sent.
            let lines = table_lines(&points)?;
            c.send(&Command::TableClear)?;
            let mut last = None;
            for l in &lines {
                last = Some(c.raw(l)?);
            }
            if let Some(r) = last {
                writeln!(out, "{}", r.reply_line())?;
            }
            Command::WaveTable(f32_of(t.freq))
        }
    };
    let r = c.send(&cmd)?;
    writeln!(out, "{}", r.reply_line())?;
    Ok(())
}

fn wave(shape: Shape, a: WaveArgs) -> Command<'static> {
    Command::Wave {
        shape,
        amp_um: f32_of(a.amplitude),
        freq_hz: f32_of(a.freq),
        offset_um: f32_of(a.offset),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_files_read_with_units_and_errors_name_the_line() {
        let dir = std::env::temp_dir().join(format!("piezo-points-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("points.csv");
        std::fs::write(&f, "# um\n0, 20\n5um 1.5e1\n\n300nm # last\n").unwrap();
        assert_eq!(read_points(&f).unwrap(), vec![0.0, 20.0, 5.0, 15.0, 0.3]);
        std::fs::write(&f, "1\n2,x\n").unwrap();
        let e = read_points(&f).unwrap_err().to_string();
        assert!(e.contains("points.csv:2:") && e.contains("`x`"), "{e}");
    }
}
