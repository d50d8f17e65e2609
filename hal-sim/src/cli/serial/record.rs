//! `piezo serial record`: select, trigger, arm, wait for the capture (bounded by the
//! firmware's own progress) and read it in chunks.
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Result};
use piezo_core::command::{self, Command, RecCmd, TriggerCmd};
use piezo_core::recorder::Signal;

use crate::serial::bulk::{read_bin, BulkStats};
use crate::serial::lines::checked_line;
use crate::serial::replies::parse_frame;
use crate::serial::{Client, SerialError};

use super::recording::{Recording, XY_SIGNALS};

/// Frames asked for per `rec read` (keeps each reply short on a 115200 Bd port).
pub const READ_CHUNK: usize = 128;

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// Signals, comma separated (ref_um, y_um, error_um, ff_volts, u_volts, adc_code,
    /// dac_code; axis 1 of an XY build: ref1_um, y1_um, error1_um, ff1_volts, u1_volts,
    /// adc1_code, dac1_code); the firmware records 4 channels, unnamed ones keep their
    /// signal.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "ref_um,y_um,u_volts,error_um"
    )]
    pub signals: Vec<String>,
    /// Both axes of an XY build: the signals ref_um,y_um,ref1_um,y1_um (the SVG gets an
    /// x-y panel of reference and measured path).
    #[arg(long, conflicts_with = "signals")]
    pub xy: bool,
    /// Record every N-th control period (1 to 1000): the 1024 frames span N times longer
    /// (`--every 20` at 100 kHz: 205 ms, a whole XY scan).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub every: u32,
    /// `now`, or `rise|fall|level:<signal>:<level>` (level in the signal's unit).
    #[arg(long, default_value = "now")]
    pub trigger: String,
    /// Frames kept before the trigger.
    #[arg(long, default_value_t = 0)]
    pub pre: usize,
    /// Longest wait for the trigger, in seconds of the firmware's own time (control periods
    /// it reports in `stats`, so an emulator running slower than real time gets the same
    /// budget); the capture's own length is added.
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    pub wait_s: f64,
    /// Wall-clock cap on the whole wait, in seconds: only for a firmware that stopped
    /// running or a dead link (the firmware's time above is what bounds a normal wait).
    #[arg(long, default_value_t = 600.0, value_name = "S")]
    pub wall_cap_s: f64,
    /// Read the finished capture without arming a new one (--signals then only names the
    /// columns, in the order the capture was selected).
    #[arg(long)]
    pub no_arm: bool,
    /// Frames per capture (`rec len`: up to the recorder's storage, 32 768 on the H743,
    /// 229 376 on QEMU); without it the firmware's current length (1024 at power-up).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Read with the text `rec read` lines instead of the binary `rec bin` packets.
    #[arg(long)]
    pub text: bool,
    /// CSV file: `i,t_s,<signal>...` in the record convention of `piezo fit` (each signal
    /// name ends in its unit: `t_s`, `u_volts` and `y_um` are the time, input and output
    /// `piezo fit` reads); `#` lines say what was recorded.
    #[arg(long)]
    pub out: PathBuf,
    /// SVG plot of every channel against time.
    #[arg(long)]
    pub svg: Option<PathBuf>,
}

/// Parses `--trigger`: `now` or `rise|fall|level:<signal or channel>:<level>`, with the
/// channel index resolved against the selected `channels`.
pub fn parse_trigger(spec: &str, channels: &[String], pre: usize) -> Result<TriggerCmd> {
    if spec == "now" {
        if pre != 0 {
            bail!("--pre needs an edge trigger (rise|fall|level:<signal>:<level>), not `now`");
        }
        return Ok(TriggerCmd::Now);
    }
    let parts: Vec<&str> = spec.split(':').collect();
    let [kind, ch, level] = parts.as_slice() else {
        bail!("--trigger `{spec}`: use now or rise|fall|level:<signal>:<level>");
    };
    let channel = match channels.iter().position(|n| n == ch) {
        Some(i) => i,
        None => match ch.parse::<usize>() {
            Ok(i) if i < channels.len() => i,
            _ => bail!(
                "--trigger `{spec}`: `{ch}` is not a recorded channel ({})",
                channels.join(", ")
            ),
        },
    };
    let level: f32 = command::parse_f32(level)
        .map_err(|_| anyhow!("--trigger `{spec}`: level `{level}` is not a finite number"))?;
    TriggerCmd::edge(kind, channel, level, pre).ok_or_else(|| {
        anyhow!(
            "--trigger `{spec}`: `{kind}` is not one of {}",
            TriggerCmd::EDGES.join(", ")
        )
    })
}

/// Selects, triggers, arms, waits for the capture and reads it.
pub fn record(c: &mut Client, a: &RecordArgs) -> Result<Recording> {
    record_with_stats(c, a).map(|(r, _)| r)
}

/// [`record`], with what the binary transfer took (`None`: read as text).
pub fn record_with_stats(c: &mut Client, a: &RecordArgs) -> Result<(Recording, Option<BulkStats>)> {
    if !(a.wait_s.is_finite() && a.wait_s > 0.0) {
        bail!("--wait-s must be positive, got {}", a.wait_s);
    }
    if !(a.wall_cap_s.is_finite() && a.wall_cap_s > 0.0) {
        bail!("--wall-cap-s must be positive, got {}", a.wall_cap_s);
    }
    let sample_hz = c.get("sample_hz")?;
    if !(sample_hz.is_finite() && sample_hz > 0.0) {
        bail!("the firmware reports sample_hz {sample_hz}");
    }
    let (channels, trigger, pre) = if a.no_arm {
        let (state, n) = c.rec_status()?;
        if state != "done" || n == 0 {
            bail!("--no-arm: the recorder holds no finished capture (it is {state})");
        }
        let names: Vec<String> = a.signals.iter().map(|s| s.trim().to_string()).collect();
        (names, "unknown (--no-arm)".to_string(), a.pre)
    } else {
        let mut signals = Vec::new();
        let names = if a.xy {
            XY_SIGNALS.map(String::from).to_vec()
        } else {
            a.signals.clone()
        };
        for name in &names {
            let s = Signal::from_name(name.trim()).ok_or_else(|| {
                anyhow!(
                    "--signals: unknown signal `{name}`; one of {}",
                    Signal::ALL.map(|s| s.name()).join(", ")
                )
            })?;
            signals.push(s);
        }
        // A capture left armed (an interrupted session) would refuse the new selection.
        c.send(&Command::Rec(RecCmd::Stop))?;
        let channels = c.rec_select(&signals)?;
        let trig = parse_trigger(&a.trigger, &channels, a.pre)?;
        c.send(&Command::Rec(RecCmd::Trigger(trig)))?;
        c.send(&Command::Rec(RecCmd::Divider(Some(a.every as usize))))?;
        if let Some(n) = a.frames {
            c.send(&Command::Rec(RecCmd::Length(Some(n))))?;
        }
        c.send(&Command::Rec(RecCmd::Arm))?;
        (channels, a.trigger.clone(), a.pre)
    };
    // Frames per second: the control rate over the divider the capture ran with.
    let div = c.rec_divider()?;
    let n = wait_for_capture(c, a, sample_hz)?;
    let sample_hz = sample_hz / div as f64;
    if !a.text && !a.no_arm {
        let (frames, st) = read_bin(c, 0, n, channels.len())?;
        let rec = Recording {
            channels,
            sample_hz,
            pre,
            trigger,
            frames,
        };
        return Ok((rec, Some(st)));
    }
    let mut frames = Vec::with_capacity(n);
    // Values per frame: the selected channels, or what the first frame has (--no-arm).
    let mut width = (!a.no_arm).then_some(channels.len());
    while frames.len() < n {
        let start = frames.len();
        let count = READ_CHUNK.min(n - start);
        let cmd = Command::Rec(RecCmd::Read { start, count });
        let line = checked_line(&cmd)?;
        let r = c.send(&cmd)?;
        let bad = |l: &str, why: String| SerialError::BadReply {
            command: line.clone(),
            line: l.to_string(),
            why,
        };
        if r.data.len() != count {
            return Err(bad(
                &r.reply_line(),
                format!("{} frame lines, asked for {count}", r.data.len()),
            )
            .into());
        }
        if r.details != format!("rec read {count}") {
            return Err(bad(&r.reply_line(), format!("expected `ok rec read {count}`")).into());
        }
        for (k, l) in r.data.iter().enumerate() {
            let (i, v) = parse_frame(l, width).map_err(|why| bad(l, why))?;
            width = Some(v.len());
            if i != start + k {
                return Err(bad(l, format!("frame {i}, expected {}", start + k)).into());
            }
            frames.push(v);
        }
    }
    let mut channels = channels;
    if let Some(first) = frames.first() {
        // --no-arm without enough names: number the rest.
        while channels.len() < first.len() {
            channels.push(format!("ch{}", channels.len()));
        }
    }
    Ok((
        Recording {
            channels,
            sample_hz,
            pre,
            trigger,
            frames,
        },
        None,
    ))
}

/// Waits until the recorder is done; returns its frame count. The wait is bounded by the
/// firmware's progress, counted in the control periods it reports (`stats`, `samples`):
/// `--wait-s` of its time may pass with the capture still armed (no trigger) or with no
/// new frame once triggered. Under an emulator that runs slower than real time the
/// firmware's time runs slower too, so a busy host cannot fail a healthy capture;
/// `--wall-cap-s` only ends a wait on a firmware whose loop stopped or a dead link.
pub(crate) fn wait_for_capture(c: &mut Client, a: &RecordArgs, sample_hz: f64) -> Result<usize> {
    let budget = a.wait_s * sample_hz;
    let wall_deadline = Instant::now() + Duration::from_secs_f64(a.wall_cap_s);
    let mut last = c.stats()?.samples;
    let mut progress = (String::new(), 0);
    // Control periods since the last progress (a state change or a new frame).
    let mut idle = 0.0f64;
    loop {
        let (state, n) = c.rec_status()?;
        if state == "done" {
            return Ok(n);
        }
        if state == "idle" {
            bail!("the recorder went idle without a capture (stopped by someone else?)");
        }
        // `stats reset` (by anyone) restarts the count: periods are summed across it.
        let now = c.stats()?.samples;
        let ran = if now >= last { now - last } else { now } as f64;
        last = now;
        if (state.as_str(), n) != (progress.0.as_str(), progress.1) {
            progress = (state, n);
            idle = 0.0;
            continue;
        }
        idle += ran;
        if idle >= budget {
            bail!(
                "the recorder is still {state} after {} s (trigger `{}` never fired?): \
                 {idle} control periods of the firmware's time without progress ({n} frames)",
                a.wait_s,
                a.trigger,
            );
        }
        if Instant::now() >= wall_deadline {
            bail!(
                "the recorder is still {state} after {} s of wall-clock time (--wall-cap-s) \
                 with {n} frames; the firmware ran {idle} control periods since its last \
                 progress (is its control loop running?)",
                a.wall_cap_s
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// `record`: capture, write the CSV (and SVG), print the summary.
pub fn run(c: &mut Client, a: &RecordArgs, out: &mut impl Write) -> Result<()> {
    let (rec, st) = record_with_stats(c, a)?;
    if let Some(st) = st {
        writeln!(
            out,
            "rec bin: {} frames in {:.3} s ({:.0} frames/s, {:.1} kB/s), {} packets, {} damaged \
             and asked for again, {} requests",
            st.frames,
            st.seconds,
            st.frames_per_s(),
            st.bytes as f64 / st.seconds.max(1e-9) / 1e3,
            st.packets,
            st.damaged,
            st.requests
        )?;
    }
    rec.write_csv(&a.out)?;
    if let Some(svg) = &a.svg {
        rec.write_svg(svg)?;
    }
    rec.summary(out)?;
    writeln!(out, "wrote {}", a.out.display())?;
    if let Some(svg) = &a.svg {
        writeln!(out, "wrote {}", svg.display())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trigger_spec_resolves_channels() {
        let ch: Vec<String> = ["ref_um", "y_um", "u_volts", "error_um"]
            .map(String::from)
            .to_vec();
        assert_eq!(parse_trigger("now", &ch, 0).unwrap(), TriggerCmd::Now);
        assert_eq!(
            parse_trigger("rise:y_um:10.5", &ch, 100).unwrap(),
            TriggerCmd::Rising {
                channel: 1,
                level: 10.5,
                pre: 100
            }
        );
        assert_eq!(
            parse_trigger("fall:2:3", &ch, 0).unwrap(),
            TriggerCmd::Falling {
                channel: 2,
                level: 3.0,
                pre: 0
            }
        );
        assert!(parse_trigger("rise:dac_code:1", &ch, 0).is_err());
        assert!(parse_trigger("rise:y_um:nan", &ch, 0).is_err());
        assert!(parse_trigger("up:y_um:1", &ch, 0).is_err());
        assert!(parse_trigger("now", &ch, 5).is_err());
    }
}
