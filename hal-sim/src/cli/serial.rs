//! `piezo serial`: the firmware's command protocol from the command line, over the wire
//! client [`crate::serial`]; one file per subcommand group below.
//!
//! Transport: a serial port (`--port /dev/ttyACM0 [--baud 115200]`) or TCP (`--tcp
//! 127.0.0.1:PORT`, e.g. QEMU `-serial tcp::PORT,server=on,wait=off`).
//!
//! Every command the host builds is a [`Command`] of the core's protocol module, written by
//! [`format_command`](crate::serial::lines::format_command) and parsed back with the
//! firmware's own parser before it is sent.
//!
//! ```text
//! piezo serial --tcp 127.0.0.1:4444 -- "mode ff+pid" "wave sine 5 100 10"
//! piezo serial --port /dev/ttyACM0 wave sine 5um 100Hz --offset 10um
//! piezo serial --tcp 127.0.0.1:4444 wave steps 10um 30um 5 2Hz
//! piezo serial --tcp 127.0.0.1:4444 wave table --freq 10Hz --points 0,20,5,15
//! piezo serial --tcp 127.0.0.1:4444 record --signals ref_um,y_um,u_volts --out rec.csv --svg rec.svg
//! piezo serial --tcp 127.0.0.1:4444 identify --out ident
//! ```
use std::io::{self, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use piezo_core::command::Command;

use crate::serial::link::{connect_tcp, open_serial};
use crate::serial::{Client, Link, SerialError};

pub mod bode;
pub mod identify;
pub mod load_fit;
pub mod params;
pub mod record;
pub mod recording;
pub mod status;
pub mod units;
pub mod wave;

use record::RecordArgs;
use units::{parse_hz, parse_volts, parse_volts_per_s};
use wave::WaveCmd;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Raw lines: piezo serial --tcp 127.0.0.1:4444 -- \"mode ff+pid\" \"wave sine 5 100 10\"\n\
Protocol: one ASCII line per command (max 96 bytes); reply `ok [details]` or `err <code> <message>`; \
`help` lists the commands and parameters."
)]
pub struct Args {
    #[command(flatten)]
    pub conn: Conn,
    #[command(subcommand)]
    pub action: Option<Action>,
    /// Raw command lines (after `--`), sent in order; each reply is printed.
    #[arg(last = true, value_name = "LINE")]
    pub lines: Vec<String>,
}

/// Where the firmware is.
#[derive(clap::Args, Debug, Clone)]
pub struct Conn {
    /// Serial device of the firmware's command port (Nucleo: the ST-LINK VCP, /dev/ttyACM0).
    #[arg(long, global = true, conflicts_with = "tcp")]
    pub port: Option<String>,
    /// Baud rate of --port.
    #[arg(long, global = true, default_value_t = 115_200)]
    pub baud: u32,
    /// TCP address of the serial port (QEMU: -serial tcp::PORT,server=on,wait=off).
    #[arg(long, global = true, value_name = "HOST:PORT")]
    pub tcp: Option<String>,
    /// Longest wait for a reply line, in seconds.
    #[arg(long, global = true, default_value_t = 2.0, value_name = "S")]
    pub timeout_s: f64,
    /// Do not send the `ping` that skips stale output before the first command.
    #[arg(long, global = true)]
    pub no_sync: bool,
    /// Raw lines: go on after a command the firmware refuses (exit status 1 at the end).
    #[arg(long, global = true)]
    pub keep_going: bool,
}

impl Conn {
    /// A TCP link (the QEMU firmware's UART, a fake firmware in tests) with the command
    /// line's defaults and `timeout_s` per reply line.
    pub fn tcp(addr: &str, timeout_s: f64) -> Self {
        Self {
            port: None,
            baud: 115_200,
            tcp: Some(addr.to_string()),
            timeout_s,
            no_sync: false,
            keep_going: false,
        }
    }
}

#[derive(clap::Subcommand, Debug)]
pub enum Action {
    /// Send raw command lines, print every reply.
    Send {
        #[arg(required = true, value_name = "LINE")]
        lines: Vec<String>,
    },
    /// Check the link (`ping`).
    Ping,
    /// List the firmware's commands and parameters (its `help` command).
    Commands,
    /// Select the control mode: open-loop, feedforward or a feedback law; bumpless. The
    /// names are the firmware's own (`piezo_core::firmware::LAWS`, `FFS`).
    Mode {
        #[arg(value_parser = law_names())]
        law: String,
        /// Feedforward compensator to select first.
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(piezo_core::firmware::FFS))]
        ff: Option<String>,
    },
    /// Set the output limits; with no option, print them.
    Limits {
        /// Lowest output voltage (`0`, `0V`).
        #[arg(long, value_parser = parse_volts, allow_hyphen_values = true)]
        u_min: Option<f64>,
        /// Highest output voltage (`120V`).
        #[arg(long, value_parser = parse_volts, allow_hyphen_values = true)]
        u_max: Option<f64>,
        /// Slew limit (`20V/ms`, `20000` = V/s).
        #[arg(long, value_parser = parse_volts_per_s)]
        slew: Option<f64>,
    },
    /// Start a waveform, hold a position or stop (hold where it is).
    #[command(subcommand)]
    Wave(WaveCmd),
    /// Select the axis the 1-axis waves (sine, triangle, square, steps, table, hold) go to
    /// (`axis 1`: y of an XY build); with no number, print it.
    Axis { axis: Option<usize> },
    /// Set parameters by name, values in the settings table's units or with a unit of the
    /// same quantity (`slew=20V/ms`, `notch_hz=2.5kHz`); all are checked against the table
    /// (name, range) before any is sent. Prints the values the firmware took.
    #[command(after_long_help = params::table_help())]
    Set {
        #[arg(required = true, value_name = "NAME=VALUE")]
        assignments: Vec<String>,
    },
    /// Every parameter of the firmware (names from its `help`) with its value; `--save`
    /// also writes the settable ones to a file, `--restore` sets them from one.
    #[command(after_long_help = params::table_help())]
    Params {
        /// Write `name,value,unit` of every settable parameter to FILE (CSV).
        #[arg(long, value_name = "FILE", conflicts_with = "restore")]
        save: Option<PathBuf>,
        /// Set every parameter of FILE (as `--save` writes it): the whole file is checked
        /// against the settings table (known name, unit, range) before anything is sent.
        #[arg(long, value_name = "FILE")]
        restore: Option<PathBuf>,
    },
    /// Send the CBW model of a `piezo fit --model cbw` report to the firmware as one
    /// `cbw <d> <alpha> <beta> <gamma>` line (checked and installed as a whole).
    LoadFit {
        /// The report: `piezo fit --out <dir>` writes `<dir>/fit.json`, `--json` prints it.
        fit: PathBuf,
    },
    /// Link, parameters, timing and recorder state.
    Status,
    /// Timing of the control task (counts: DWT cycles on the H743, SysTick ticks in QEMU).
    Stats {
        /// Reset the counters after reading them.
        #[arg(long)]
        reset: bool,
        /// Clock of the counts, to print microseconds too (H743 400e6, QEMU 25e6).
        #[arg(long, value_parser = parse_hz)]
        clock: Option<f64>,
    },
    /// Capture with the recorder and write CSV (optionally SVG).
    Record(RecordArgs),
    /// Instructions per control step for every mode (QEMU board).
    Bench,
    /// Frequency response (open or closed loop) from the firmware's own excitation and
    /// record: CSV, SVG Bode plot, the resonance and a suggested notch_hz / notch_q.
    Bode(bode::BodeArgs),
    /// Identify the stage and load the model in one command: the tracking error with the
    /// firmware's model, PRBS and sines in open loop, the CBW fit (`piezo fit`'s library),
    /// the diagnosis (`piezo diagnose`'s), the model checked and loaded (`load-fit`), the
    /// tracking error again; `identify: rmse before <a> um, after <b> um`.
    Identify(identify::IdentifyArgs),
}

/// Opens the link of `conn` and syncs (unless --no-sync).
pub fn connect(conn: &Conn) -> Result<Client> {
    if !(conn.timeout_s.is_finite() && conn.timeout_s > 0.0 && conn.timeout_s <= 3600.0) {
        bail!(
            "--timeout-s must be in (0, 3600] seconds, got {}",
            conn.timeout_s
        );
    }
    let timeout = Duration::from_secs_f64(conn.timeout_s);
    let mut client = Client::new(open_link(conn, timeout)?, timeout);
    if !conn.no_sync {
        client.sync().context("no answer to ping")?;
    }
    Ok(client)
}

/// The byte stream of `conn`: its serial port or TCP address.
pub fn open_link(conn: &Conn, timeout: Duration) -> Result<Box<dyn Link>> {
    Ok(match (&conn.port, &conn.tcp) {
        (Some(p), None) => open_serial(p, conn.baud, timeout)?,
        (None, Some(a)) => Box::new(connect_tcp(a, timeout)?),
        _ => bail!("say where the firmware is: --port <device> or --tcp <host:port>"),
    })
}

pub fn run(args: Args) -> Result<()> {
    let action = match (args.action, args.lines.is_empty()) {
        (Some(a), true) => a,
        (None, false) => Action::Send { lines: args.lines },
        (Some(_), false) => bail!("give either a subcommand or raw lines after --, not both"),
        (None, true) => {
            bail!("nothing to send: give a subcommand (see --help) or raw lines after --")
        }
    };
    let mut c = connect(&args.conn)?;
    let out = &mut io::stdout().lock();
    execute(&mut c, action, args.conn.keep_going, out)
}

/// Runs one action on a connected client, printing to `out`.
pub fn execute(
    c: &mut Client,
    action: Action,
    keep_going: bool,
    out: &mut impl Write,
) -> Result<()> {
    match action {
        Action::Send { lines } => {
            let mut failed = 0;
            for l in &lines {
                match c.raw(l) {
                    Ok(r) => {
                        for d in &r.data {
                            writeln!(out, "{d}")?;
                        }
                        writeln!(out, "{}", r.reply_line())?;
                    }
                    Err(e @ SerialError::Firmware { .. }) if keep_going => {
                        writeln!(out, "{}", firmware_line(&e))?;
                        eprintln!("error: {e}");
                        failed += 1;
                    }
                    Err(e) => return Err(e.into()),
                }
            }
            if failed > 0 {
                bail!("{failed} of {} commands failed", lines.len());
            }
        }
        Action::Ping => {
            let t = Instant::now();
            let r = c.send(&Command::Ping)?;
            writeln!(
                out,
                "{} ({:.1} ms round trip)",
                r.reply_line(),
                t.elapsed().as_secs_f64() * 1e3
            )?;
        }
        Action::Commands => writeln!(out, "{}", c.send(&Command::Help)?.reply_line())?,
        Action::Bench => {
            let r = c.send(&Command::Bench)?;
            for d in &r.data {
                writeln!(out, "{d}")?;
            }
            writeln!(out, "{}", r.reply_line())?;
        }
        Action::Mode { law, ff } => {
            if let Some(ff) = ff {
                let r = c.send(&Command::Feedforward(&ff))?;
                writeln!(out, "{}", r.reply_line())?;
            }
            let r = c.send(&Command::Mode(&law))?;
            writeln!(out, "{}", r.reply_line())?;
        }
        Action::Limits { u_min, u_max, slew } => params::limits(c, u_min, u_max, slew, out)?,
        Action::Wave(w) => wave::run(c, w, out)?,
        Action::Axis { axis } => {
            let r = c.send(&Command::Axis(axis))?;
            writeln!(out, "{}", r.reply_line())?;
        }
        Action::Set { assignments } => params::set(c, &assignments, out)?,
        Action::Params { save, restore } => {
            if let Some(f) = restore {
                params::restore(c, &f, out)?;
            }
            params::print_params(c, out)?;
            if let Some(f) = save {
                params::save(c, &f, out)?;
            }
        }
        Action::LoadFit { fit } => load_fit::run(c, &fit, out)?,
        Action::Status => status::status(c, out)?,
        Action::Stats { reset, clock } => status::stats(c, reset, clock, out)?,
        Action::Record(a) => record::run(c, &a, out)?,
        Action::Bode(a) => bode::run(c, &a, out)?,
        Action::Identify(a) => {
            identify::run(c, &a, out)?;
        }
    }
    Ok(())
}

/// The `err ...` line of a firmware error, as the firmware sent it.
fn firmware_line(e: &SerialError) -> String {
    match e {
        SerialError::Firmware { code, message, .. } => match code {
            Some(c) => format!("err {c} {message}"),
            None => format!("err {message}"),
        },
        other => other.to_string(),
    }
}

/// The firmware's modes: its feedback laws and `feedforward` (open loop plus compensator).
fn law_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        piezo_core::firmware::LAWS
            .iter()
            .copied()
            .chain(["feedforward"]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(clap::Parser, Debug)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    #[test]
    fn cli_definition_is_valid_and_parses_units() {
        use clap::{CommandFactory, Parser};
        Cli::command().debug_assert();
        let a = Cli::try_parse_from([
            "serial",
            "--tcp",
            "127.0.0.1:1",
            "wave",
            "sine",
            "5um",
            "0.1kHz",
            "--offset",
            "-2um",
        ])
        .unwrap()
        .args;
        match a.action {
            Some(Action::Wave(WaveCmd::Sine(w))) => {
                assert_eq!((w.amplitude, w.freq, w.offset), (5.0, 100.0, -2.0))
            }
            other => panic!("{other:?}"),
        }
        let a = Cli::try_parse_from(["serial", "--tcp", "h:1", "--", "mode pid", "stats"])
            .unwrap()
            .args;
        assert_eq!(a.lines, vec!["mode pid", "stats"]);
        assert!(a.action.is_none());
        let e = Cli::try_parse_from(["serial", "limits", "--slew", "5 parsecs"]).unwrap_err();
        assert!(e.to_string().contains("unknown unit"), "{e}");
        let a = Cli::try_parse_from(["serial", "wave", "steps", "-1um", "2um", "5", "3Hz"])
            .unwrap()
            .args;
        match a.action {
            Some(Action::Wave(WaveCmd::Steps {
                low,
                high,
                levels,
                freq,
            })) => assert_eq!((low, high, levels, freq), (-1.0, 2.0, 5, 3.0)),
            other => panic!("{other:?}"),
        }
        assert!(Cli::try_parse_from(["serial", "wave", "steps", "1", "2", "65", "3"]).is_err());
        let a = Cli::try_parse_from([
            "serial",
            "wave",
            "table",
            "--freq",
            "10Hz",
            "--points",
            "-1,2um,300nm",
        ])
        .unwrap()
        .args;
        match a.action {
            Some(Action::Wave(WaveCmd::Table(t))) => {
                assert_eq!(
                    (t.freq, t.points, t.file),
                    (10.0, vec![-1.0, 2.0, 0.3], None)
                )
            }
            other => panic!("{other:?}"),
        }
        // One source of points, exactly.
        assert!(Cli::try_parse_from(["serial", "wave", "table", "--freq", "1"]).is_err());
        assert!(Cli::try_parse_from([
            "serial", "wave", "table", "--freq", "1", "--points", "1,2", "--file", "p.csv"
        ])
        .is_err());
    }
}
