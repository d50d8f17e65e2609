//! `piezo serial identify`: identify the stage the firmware drives and load the model, in
//! one command.
//!
//! 1. **before**: the tracking error of a sine reference (`--ref-amplitude` around
//!    `--ref-offset` at `--ref-hz`) with the firmware's current model, in `mode
//!    feedforward` with `ff ims-cbw`: the position follows the inverse of the model alone,
//!    so the error is the model's error. With a feedback law (`ff+hgo-robust`) the loop
//!    hides most of a wrong model (a CBW 20 % off changes its error by a few hundredths of
//!    a percent of the stroke, README) and the comparison would say little about the fit.
//! 2. **excite** (004 sec. 4.2, two steps): in open loop (`mode open-loop`, `ff linear`,
//!    the voltages through the firmware's `um_per_volt` and `offset_um`) a PRBS around the
//!    middle of the voltage range for the linear part, then sines for the hysteresis: one
//!    capture over the whole range (`--u-low`..`--u-high`) followed by one at half the
//!    amplitude (a minor loop), and a held-back capture at 0.7 of it and twice the
//!    frequency that nothing is fitted on. Captures come back over `rec bin`.
//! 3. **fit**: the CBW with the linear part of step 1 fixed (the library of `piezo fit
//!    --model cbw --linear-train prbs.csv --linear 1`), scored on the held-back capture.
//! 4. **diagnose**: the library of `piezo diagnose` on the sine capture (train) and the
//!    held-back one (valid): what a CBW still misses on this stage (creep, rate dependence,
//!    ...), printed.
//! 5. **load**: the report's CBW through `piezo serial load-fit`'s code path: the
//!    firmware checks it against its conditions (004 eq. 3, IMS invertibility over 0..150
//!    V) and installs it as a whole, or refuses it and keeps its model.
//! 6. **after**: the tracking error of step 1 again, with the new model; the summary line
//!    `identify: rmse before <a> um, after <b> um`.
//!
//! Every capture (`t,u,y` records as `piezo fit` reads them; the tracking captures as
//! `piezo serial record` writes them), `fit.json`, `diagnose.txt` and `identify.svg` go to
//! `--out`. Progress goes to stderr. Waits are bounded by the firmware's own time (control
//! periods in `stats`), with a wall-clock cap only for a firmware that stopped.
//! The firmware is left in `mode feedforward`, `ff ims-cbw`, holding `--ref-offset`, with
//! its recorder's capture length as it was; after an error, in the mode the error found it
//! in, holding `--ref-offset`, no capture armed, the capture length as it was.
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use piezo_core::command::{Command, RecCmd, Shape, TriggerCmd};
use piezo_core::pipeline::excitation::{PRBS_ORDER_MAX, PRBS_ORDER_MIN};
use piezo_core::recorder::Signal;

use crate::cli::fit::{fit, fit_linear_part, write_fit_json, Fit, FitInput};
use crate::ident::diagnose::{self, Signals};
use crate::ident::fit::{models, FitOptions};
use crate::plot::{write_grid, Plot};
use crate::record::Record;
use crate::serial::bulk::read_bin;
use crate::serial::Client;

use super::load_fit;
use super::record::{wait_for_capture, RecordArgs};
use super::recording::Recording;
use super::units::{f32_of, parse_hz, parse_um, parse_volts};

#[derive(clap::Args, Debug, Clone)]
pub struct IdentifyArgs {
    /// Folder for the captures, fit.json, diagnose.txt and identify.svg.
    #[arg(long)]
    pub out: PathBuf,
    /// Tracking reference: sine amplitude (peak).
    #[arg(long, default_value = "6um", value_parser = parse_um)]
    pub ref_amplitude: f64,
    /// Tracking reference: centre (keep it and the amplitude within the stage's stroke).
    #[arg(long, default_value = "12um", value_parser = parse_um, allow_hyphen_values = true)]
    pub ref_offset: f64,
    /// Tracking reference: frequency.
    #[arg(long, default_value = "10Hz", value_parser = parse_hz)]
    pub ref_hz: f64,
    /// Reference periods recorded for each tracking error (after one period of settling).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub ref_periods: u32,
    /// Excitation: lowest voltage of the hysteresis sines.
    #[arg(long, default_value = "10V", value_parser = parse_volts)]
    pub u_low: f64,
    /// Excitation: highest voltage of the hysteresis sines.
    #[arg(long, default_value = "140V", value_parser = parse_volts)]
    pub u_high: f64,
    /// Excitation: frequency of the hysteresis sines (the held-back one runs at twice it).
    #[arg(long, default_value = "10Hz", value_parser = parse_hz)]
    pub sine_hz: f64,
    /// Periods of each hysteresis sine (the first half period settles unrecorded).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub sine_periods: u32,
    /// Excitation: PRBS step (peak to peak) around the middle of --u-low..--u-high.
    #[arg(long, default_value = "20V", value_parser = parse_volts)]
    pub prbs_volts: f64,
    /// Excitation: PRBS bit rate (the stage's lag and the slew limit shape its steps).
    #[arg(long, default_value = "2kHz", value_parser = parse_hz)]
    pub prbs_bit_hz: f64,
    /// Frames of the PRBS capture (at the full control rate).
    #[arg(long, default_value_t = 4096, value_parser = clap::value_parser!(u32).range(256..=200_000))]
    pub prbs_frames: u32,
    /// Frame rate of the sine and tracking captures (the recorder's divider from the
    /// control rate; rounded to a whole divider).
    #[arg(long, default_value = "5kHz", value_parser = parse_hz)]
    pub record_hz: f64,
    /// Global search generations of the fit (`piezo fit --generations`).
    #[arg(long, default_value_t = 300)]
    pub generations: usize,
    /// Skip step 4 (the diagnosis; it takes longest on the host).
    #[arg(long)]
    pub no_diagnose: bool,
    /// Longest wait for progress of a capture, in seconds of the firmware's time.
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    pub wait_s: f64,
    /// Wall-clock cap on any one wait, in seconds (a firmware that stopped running).
    #[arg(long, default_value_t = 600.0, value_name = "S")]
    pub wall_cap_s: f64,
}

/// What identify measured.
#[derive(Debug, Clone)]
pub struct Identified {
    /// Tracking error (um RMS) with the firmware's model before and the identified one after.
    pub rmse_before_um: f64,
    pub rmse_after_um: f64,
    /// The CBW loaded: `d`, `alpha` (um/V), `beta`, `gamma` (1/V).
    pub cbw: [f64; 4],
    /// The model the firmware had before (the same order).
    pub cbw_before: [f64; 4],
    /// Held-back capture: RMSE of the fitted model (um).
    pub held_back_rmse_um: Option<f64>,
    /// The diagnosis' main finding (`none` when the CBW misses nothing it can name).
    pub diagnosis: Option<String>,
}

/// A receiver of [`run`]'s progress lines.
pub type ProgressSink = Box<dyn FnMut(&str)>;

std::thread_local! {
    /// Where the phases' progress goes besides stderr (the console's page).
    static PROGRESS: std::cell::RefCell<Option<ProgressSink>> =
        const { std::cell::RefCell::new(None) };
}

/// Sends the progress lines of [`run`] on this thread also to `sink` (`None`: stderr only).
pub fn progress_to(sink: Option<ProgressSink>) {
    PROGRESS.with(|p| *p.borrow_mut() = sink);
}

fn progress(step: usize, what: &str) {
    let line = format!("identify [{step}/6] {what}");
    eprintln!("{line}");
    PROGRESS.with(|p| {
        if let Some(f) = p.borrow_mut().as_mut() {
            f(&line)
        }
    });
}

/// The firmware's CBW (`cbw_d`, `cbw_alpha`, `cbw_beta`, `cbw_gamma`).
fn firmware_cbw(c: &mut Client) -> Result<[f64; 4]> {
    let mut m = [0.0; 4];
    for (v, name) in m
        .iter_mut()
        .zip(["cbw_d", "cbw_alpha", "cbw_beta", "cbw_gamma"])
    {
        *v = c.get(name)?;
    }
    Ok(m)
}

/// Fails unless the firmware reports no fault (`ok fault none ...`).
fn check_no_fault(c: &mut Client, during: &str) -> Result<()> {
    let r = c.send(&Command::Fault)?;
    if !r.details.starts_with("fault none") {
        bail!(
            "the firmware faulted during {during}: `{}`; it is in its safe state (`piezo \
             serial -- \"fault clear\"` leaves it)",
            r.reply_line()
        );
    }
    Ok(())
}

/// `rec len`: the capture length and the storage (`ok rec len <n> of <capacity>`).
fn rec_len(c: &mut Client, set: Option<usize>) -> Result<(usize, usize)> {
    let r = c.send(&Command::Rec(RecCmd::Length(set)))?;
    let bad = || {
        anyhow!(
            "`{}`: expected `ok rec len <n> of <capacity>`",
            r.reply_line()
        )
    };
    let rest = r.details.strip_prefix("rec len ").ok_or_else(bad)?;
    let (n, cap) = rest.split_once(" of ").ok_or_else(bad)?;
    Ok((
        n.trim().parse().map_err(|_| bad())?,
        cap.trim().parse().map_err(|_| bad())?,
    ))
}

/// Waits until the firmware has run `periods` more control periods (its `stats`); fails
/// when its count stands still for `wall_cap_s` of wall-clock time.
fn run_periods(c: &mut Client, periods: u64, wall_cap_s: f64) -> Result<()> {
    let mut last = c.stats()?.samples;
    let mut ran = 0u64;
    let mut moved = Instant::now();
    while ran < periods {
        std::thread::sleep(Duration::from_millis(5));
        let now = c.stats()?.samples;
        // `stats reset` (by anyone) restarts the count: periods are summed across it.
        let d = u64::from(if now >= last { now - last } else { now });
        if d > 0 {
            moved = Instant::now();
        } else if moved.elapsed().as_secs_f64() > wall_cap_s {
            bail!(
                "the firmware ran no control period for {wall_cap_s} s of wall-clock time \
                 (--wall-cap-s): is its control loop running?"
            );
        }
        ran += d;
        last = now;
    }
    Ok(())
}

/// A capture in progress: what `rec sel`, `rec trig now`, `rec div` and `rec len` set.
struct Capture {
    channels: Vec<String>,
    frames: usize,
    frame_hz: f64,
}

/// Stops any capture, selects `signals`, triggers now every `div` periods for `frames`
/// frames and arms.
fn arm(
    c: &mut Client,
    signals: &[&str],
    div: usize,
    frames: usize,
    sample_hz: f64,
) -> Result<Capture> {
    let sel: Vec<Signal> = signals
        .iter()
        .map(|s| Signal::from_name(s).ok_or_else(|| anyhow!("unknown signal {s}")))
        .collect::<Result<_>>()?;
    c.send(&Command::Rec(RecCmd::Stop))?;
    let channels = c.rec_select(&sel)?;
    c.send(&Command::Rec(RecCmd::Trigger(TriggerCmd::Now)))?;
    c.send(&Command::Rec(RecCmd::Divider(Some(div))))?;
    rec_len(c, Some(frames))?;
    c.send(&Command::Rec(RecCmd::Arm))?;
    Ok(Capture {
        channels,
        frames,
        frame_hz: sample_hz / div as f64,
    })
}

/// Waits for the armed capture and reads it over `rec bin`.
fn finish(
    c: &mut Client,
    cap: Capture,
    a: &IdentifyArgs,
    sample_hz: f64,
    what: &str,
) -> Result<Recording> {
    let wait = RecordArgs {
        signals: cap.channels.clone(),
        xy: false,
        every: 1,
        trigger: "now".into(),
        pre: 0,
        wait_s: a.wait_s,
        wall_cap_s: a.wall_cap_s,
        no_arm: false,
        frames: Some(cap.frames),
        text: false,
        out: PathBuf::new(),
        svg: None,
    };
    let n = wait_for_capture(c, &wait, sample_hz).with_context(|| format!("capture `{what}`"))?;
    if n != cap.frames {
        bail!("capture `{what}`: {n} frames, {} asked", cap.frames);
    }
    let (frames, st) = read_bin(c, 0, n, cap.channels.len())
        .with_context(|| format!("reading capture `{what}` (rec bin)"))?;
    eprintln!(
        "  {what}: {n} frames at {} Hz in {:.2} s over rec bin",
        cap.frame_hz, st.seconds
    );
    Ok(Recording {
        channels: cap.channels,
        sample_hz: cap.frame_hz,
        pre: 0,
        trigger: "now".into(),
        frames,
    })
}

/// The `t,u,y` record of `u_volts -> y_um` (what `piezo fit` reads).
fn fit_record(rec: &Recording, what: &str) -> Result<Record> {
    let (Some(u), Some(y)) = (rec.column("u_volts"), rec.column("y_um")) else {
        bail!("capture `{what}` lacks u_volts or y_um");
    };
    let t = (0..u.len()).map(|i| rec.t_s(i)).collect();
    let mut r = Record::new(t, vec![u], vec![y]).map_err(|e| anyhow!("capture `{what}`: {e}"))?;
    r.comments = vec![format!(
        " piezo serial identify: {what}, applied voltage u [V] -> position y [um]"
    )];
    Ok(r)
}

/// One tracking measurement: `ff ims-cbw`, `mode feedforward`, the reference sine, one
/// period to settle, `--ref-periods` recorded; the tracking error (um RMS).
fn tracking(
    c: &mut Client,
    a: &IdentifyArgs,
    sample_hz: f64,
    div: usize,
    what: &str,
) -> Result<(Recording, f64)> {
    c.send(&Command::Feedforward("ims-cbw"))?;
    c.send(&Command::Mode("feedforward"))?;
    c.send(&Command::Wave {
        shape: Shape::Sine,
        amp_um: f32_of(a.ref_amplitude),
        freq_hz: f32_of(a.ref_hz),
        offset_um: f32_of(a.ref_offset),
    })?;
    let period = (sample_hz / a.ref_hz).round() as u64;
    run_periods(c, period, a.wall_cap_s)?;
    let frames = (period as f64 * f64::from(a.ref_periods) / div as f64).round() as usize;
    let cap = arm(
        c,
        &["ref_um", "y_um", "u_volts", "ff_volts"],
        div,
        frames,
        sample_hz,
    )?;
    let rec = finish(c, cap, a, sample_hz, what)?;
    check_no_fault(c, what)?;
    let rmse = rec
        .tracking_rms()
        .first()
        .map(|(_, e)| *e)
        .ok_or_else(|| anyhow!("capture `{what}` lacks ref_um or y_um"))?;
    Ok((rec, rmse))
}

/// The reference (um) that the open loop turns into `volts` (`ff linear`: `u = (ref -
/// offset_um) / um_per_volt`).
fn um_of_volts(volts: f64, um_per_volt: f64, offset_um: f64) -> f32 {
    f32_of(offset_um + um_per_volt * volts)
}

fn check_args(a: &IdentifyArgs, u_limits: (f64, f64)) -> Result<()> {
    let pos = |v: f64, name: &str| -> Result<()> {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} must be positive, got {v}");
        }
        Ok(())
    };
    pos(a.ref_amplitude, "--ref-amplitude")?;
    pos(a.ref_hz, "--ref-hz")?;
    pos(a.sine_hz, "--sine-hz")?;
    pos(a.prbs_volts, "--prbs-volts")?;
    pos(a.prbs_bit_hz, "--prbs-bit-hz")?;
    pos(a.record_hz, "--record-hz")?;
    pos(a.wait_s, "--wait-s")?;
    pos(a.wall_cap_s, "--wall-cap-s")?;
    let (lo, hi) = u_limits;
    if !(a.u_low >= lo && a.u_high <= hi && a.u_low < a.u_high) {
        bail!(
            "--u-low {} V .. --u-high {} V must be an interval within the firmware's limits \
             u_min {lo} V .. u_max {hi} V",
            a.u_low,
            a.u_high
        );
    }
    let mid = 0.5 * (a.u_low + a.u_high);
    if a.prbs_volts > a.u_high - a.u_low {
        bail!(
            "--prbs-volts {} V is wider than --u-low..--u-high around their middle {mid} V",
            a.prbs_volts
        );
    }
    Ok(())
}

/// `identify`: before, excite, fit, diagnose, load, after; summary on `out`.
pub fn run(c: &mut Client, a: &IdentifyArgs, out: &mut impl Write) -> Result<Identified> {
    let sample_hz = c.get("sample_hz")?;
    if !(sample_hz.is_finite() && sample_hz > 0.0) {
        bail!("the firmware reports sample_hz {sample_hz}");
    }
    check_args(a, (c.get("u_min")?, c.get("u_max")?))?;
    let div = ((sample_hz / a.record_hz).round() as usize).clamp(1, 1000);
    let (len_before, capacity) = rec_len(c, None)?;
    let longest = [
        sample_hz / a.ref_hz * f64::from(a.ref_periods) / div as f64,
        sample_hz / a.sine_hz * (2.0 * f64::from(a.sine_periods) - 0.5) / div as f64,
        f64::from(a.prbs_frames),
    ]
    .into_iter()
    .fold(0.0, f64::max)
    .ceil() as usize;
    if longest > capacity {
        bail!(
            "the longest capture needs {longest} frames, the recorder holds {capacity}: lower \
             --record-hz, --ref-periods, --sine-periods or --prbs-frames"
        );
    }
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let cbw_before = firmware_cbw(c)?;
    check_no_fault(c, "the start (identify needs a running loop)")?;
    let setup = Setup {
        sample_hz,
        div,
        len_before,
        cbw_before,
    };
    let r = phases(c, a, out, &setup);
    if r.is_err() {
        // Best effort, whatever failed: no excitation left running (hold the reference's
        // centre in the current mode), no capture armed, the capture length as it was.
        let _ = c.send(&Command::Rec(RecCmd::Stop));
        let _ = c.send(&Command::WaveHold(f32_of(a.ref_offset)));
        let _ = rec_len(c, Some(len_before));
    }
    r
}

/// What [`run`] found out before the phases.
struct Setup {
    sample_hz: f64,
    /// The recorder's divider of the sine and tracking captures.
    div: usize,
    /// The capture length before identify (restored at the end).
    len_before: usize,
    cbw_before: [f64; 4],
}

/// The six phases of [`run`].
fn phases(
    c: &mut Client,
    a: &IdentifyArgs,
    out: &mut impl Write,
    setup: &Setup,
) -> Result<Identified> {
    let &Setup {
        sample_hz,
        div,
        len_before,
        cbw_before,
    } = setup;
    progress(1, "before: tracking error with the firmware's model");
    let (before_rec, rmse_before) = tracking(c, a, sample_hz, div, "before")?;
    eprintln!("  tracking error {rmse_before:.4} um RMS");
    before_rec.write_csv(&a.out.join("before.csv"))?;

    progress(
        2,
        "excite: PRBS (linear part), then sines (hysteresis), open loop",
    );
    let um_per_volt = c.get("um_per_volt")?;
    let offset_um = c.get("offset_um")?;
    if !(um_per_volt.is_finite() && um_per_volt > 0.0) {
        bail!(
            "the firmware's um_per_volt is {um_per_volt}: the open loop cannot place the voltages"
        );
    }
    let to_um = |v: f64| um_of_volts(v, um_per_volt, offset_um);
    c.send(&Command::Feedforward("linear"))?;
    c.send(&Command::Mode("open-loop"))?;
    let mid = 0.5 * (a.u_low + a.u_high);
    let half = 0.5 * (a.u_high - a.u_low);
    // PRBS: one bit per sample_hz / bit_hz periods, a period at least as long as the capture.
    let prbs_frames = a.prbs_frames as usize;
    let bits = (prbs_frames as f64 * a.prbs_bit_hz / sample_hz).ceil() as usize;
    let mut order = PRBS_ORDER_MIN;
    while (1usize << order) - 1 < bits && order < PRBS_ORDER_MAX {
        order += 1;
    }
    c.send(&Command::WaveHold(to_um(mid)))?;
    run_periods(c, (0.01 * sample_hz) as u64, a.wall_cap_s)?;
    c.send(&Command::WavePrbs {
        low_um: to_um(mid - 0.5 * a.prbs_volts),
        high_um: to_um(mid + 0.5 * a.prbs_volts),
        order,
        bit_hz: f32_of(a.prbs_bit_hz),
        seed: 1,
    })?;
    let cap = arm(
        c,
        &["u_volts", "y_um", "ref_um", "ff_volts"],
        1,
        prbs_frames,
        sample_hz,
    )?;
    let prbs = fit_record(&finish(c, cap, a, sample_hz, "prbs")?, "PRBS")?;
    prbs.write(a.out.join("prbs.csv"))?;
    check_no_fault(c, "the PRBS")?;

    // Sines: the whole range, then half its amplitude (a minor loop), in one capture.
    let sine = |amp: f64, hz: f64| Command::Wave {
        shape: Shape::Sine,
        amp_um: f32_of(amp * um_per_volt),
        freq_hz: f32_of(hz),
        offset_um: to_um(mid),
    };
    let period = (sample_hz / a.sine_hz).round() as u64;
    let each = period * u64::from(a.sine_periods);
    c.send(&sine(half, a.sine_hz))?;
    run_periods(c, period / 2, a.wall_cap_s)?;
    let frames = ((2 * each - period / 2) as f64 / div as f64).round() as usize;
    let cap = arm(
        c,
        &["u_volts", "y_um", "ref_um", "ff_volts"],
        div,
        frames,
        sample_hz,
    )?;
    run_periods(c, each - period / 2, a.wall_cap_s)?;
    c.send(&sine(0.5 * half, a.sine_hz))?;
    let train = fit_record(&finish(c, cap, a, sample_hz, "sines")?, "sines")?;
    train.write(a.out.join("sines.csv"))?;
    check_no_fault(c, "the sines")?;
    // Held back: 0.7 of the range at twice the frequency.
    let held_hz = 2.0 * a.sine_hz;
    c.send(&sine(0.7 * half, held_hz))?;
    let held_period = (sample_hz / held_hz).round() as u64;
    run_periods(c, held_period / 2, a.wall_cap_s)?;
    let frames = ((held_period * u64::from(a.sine_periods)) as f64 / div as f64).round() as usize;
    let cap = arm(
        c,
        &["u_volts", "y_um", "ref_um", "ff_volts"],
        div,
        frames,
        sample_hz,
    )?;
    let held = fit_record(
        &finish(c, cap, a, sample_hz, "held-back")?,
        "held-back sine",
    )?;
    held.write(a.out.join("held_back.csv"))?;
    check_no_fault(c, "the held-back sine")?;
    c.send(&Command::WaveHold(to_um(mid)))?;

    progress(
        3,
        "fit: CBW with the PRBS's linear part fixed (piezo fit's library)",
    );
    let opts = FitOptions {
        generations: a.generations,
        progress: true,
        ..Default::default()
    };
    // The firmware's CBW has no output offset (`y = d u - h` from the sensor's zero): the
    // hysteresis is fitted with the offset held at 0, else the offset absorbs part of the
    // gain and the loop, and the model the firmware gets is not the one that was fitted.
    // The capture starts at the bottom of the sine with the stage's loop state, the model
    // from rest: the first rising half period brings the model's state up to date and is
    // not scored (it sweeps the whole range, which wipes the CBW's memory of where it
    // started).
    let hyst_opts = FitOptions {
        fixed_offset: Some(0.0),
        warmup: ((period / 2) as f64 / div as f64).round() as usize,
        ..opts.clone()
    };
    let cbw_now = |c: &mut Client| {
        firmware_cbw(c)
            .map(|m| format!("{m:?}"))
            .unwrap_or_else(|e| format!("unknown ({e})"))
    };
    let fitted = (|| -> Result<Fit> {
        let t0 = Instant::now();
        let linear = fit_linear_part(&prbs, 1, &opts).context("linear part from the PRBS")?;
        fit(
            FitInput {
                def: models::find("cbw")?,
                train: &train,
                train_name: a.out.join("sines.csv").display().to_string(),
                valid: Some((&held, a.out.join("held_back.csv").display().to_string())),
                valid_from: 0,
                // Whole periods: simulated once before the scored pass (periodic state).
                valid_periodic: 1,
                linear_step: Some(linear),
                input_unit: "V".into(),
                output_unit: "um".into(),
                started: t0,
            },
            &hyst_opts,
        )
    })();
    let fitted = match fitted {
        Ok(f) => f,
        Err(e) => {
            return Err(e.context(format!(
                "the fit failed; nothing was sent: the firmware keeps its model (cbw d, alpha, \
                 beta, gamma = {})",
                cbw_now(c)
            )))
        }
    };
    let report = &fitted.report;
    let fit_json = write_fit_json(&a.out, report)?;
    if let Some(l) = &report.linear_step {
        for (k, (f, z)) in l.linear.iter().enumerate() {
            writeln!(
                out,
                "linear part (PRBS) {}: f = {f:.1} Hz, zeta = {z:.3}",
                k + 1
            )?;
        }
    }
    let held_back_rmse_um = report.valid_metrics.first().map(|m| m.metrics.rmse);
    if let (Some(t), Some(v)) = (report.train_metrics.first(), report.valid_metrics.first()) {
        writeln!(
            out,
            "fit: CBW rmse {:.4} um on the sines (after the warm-up), {:.4} um on the held-back \
             sine (RE {:.3} %)",
            t.metrics.rmse, v.metrics.rmse, v.metrics.re_pct
        )?;
    }

    let diagnosis = if a.no_diagnose {
        None
    } else {
        progress(
            4,
            "diagnose: what the CBW still misses (held-back sine as validation)",
        );
        let sig = |r: &Record| Signals::new(r.t.clone(), r.u.clone(), r.y.clone());
        let held_sig = sig(&held)?.with_warmup(((held_period / 2) as f64 / div as f64) as usize);
        let d = diagnose::diagnose(&sig(&train)?, &held_sig, &diagnose::Options::default())
            .context("diagnose")?;
        let text = crate::cli::diagnose::summary(
            &d,
            Some("train: the sine capture; valid: the held-back sine"),
        );
        std::fs::write(a.out.join("diagnose.txt"), &text)?;
        write!(out, "{text}")?;
        Some(d.cause().to_string())
    };

    progress(
        5,
        "load: the model against the firmware's conditions (load-fit)",
    );
    load_fit::run(c, &fit_json, out).with_context(|| {
        format!(
            "the firmware keeps its previous model (cbw d, alpha, beta, gamma = {})",
            cbw_now(c)
        )
    })?;
    let cbw = firmware_cbw(c)?;

    progress(6, "after: tracking error with the identified model");
    let (after_rec, rmse_after) = tracking(c, a, sample_hz, div, "after")?;
    eprintln!("  tracking error {rmse_after:.4} um RMS");
    after_rec.write_csv(&a.out.join("after.csv"))?;
    c.send(&Command::WaveHold(f32_of(a.ref_offset)))?;
    rec_len(c, Some(len_before))?;
    let svg = a.out.join("identify.svg");
    write_summary_svg(&svg, &before_rec, &after_rec, &train, &fitted, &held)?;
    writeln!(
        out,
        "reference: {} um sine at {} Hz around {} um, mode feedforward, ff ims-cbw",
        a.ref_amplitude, a.ref_hz, a.ref_offset
    )?;
    writeln!(
        out,
        "model: before d {:.5} alpha {:.5} beta {:.5} gamma {:.5}; after d {:.5} alpha {:.5} \
         beta {:.5} gamma {:.5}",
        cbw_before[0], cbw_before[1], cbw_before[2], cbw_before[3], cbw[0], cbw[1], cbw[2], cbw[3]
    )?;
    writeln!(out, "wrote {}", a.out.display())?;
    writeln!(
        out,
        "identify: rmse before {rmse_before:.4} um, after {rmse_after:.4} um"
    )?;
    Ok(Identified {
        rmse_before_um: rmse_before,
        rmse_after_um: rmse_after,
        cbw,
        cbw_before,
        held_back_rmse_um,
        diagnosis,
    })
}

/// Tracking before and after against time, the sine capture's loop measured and fitted,
/// the held-back residual.
fn write_summary_svg(
    path: &Path,
    before: &Recording,
    after: &Recording,
    train: &Record,
    fitted: &Fit,
    held: &Record,
) -> Result<()> {
    let tracking_plot = |rec: &Recording, what: &str| -> Plot {
        let t: Vec<f64> = (0..rec.frames.len()).map(|i| rec.t_s(i) * 1e3).collect();
        let rms = rec.tracking_rms().first().map_or(f64::NAN, |x| x.1);
        let mut p = Plot::new(
            &format!("{what}: tracking error {rms:.3} um RMS"),
            "t [ms]",
            "position [um]",
        );
        for name in ["ref_um", "y_um"] {
            if let Some(v) = rec.column(name) {
                p = p.line(name, &t, &v);
            }
        }
        p
    };
    let mut plots = vec![
        tracking_plot(before, "before (firmware's model)"),
        tracking_plot(after, "after (identified model)"),
        Plot::new("sines: u -> y", "u [V]", "y [um]")
            .line("measured", &train.u[0], &train.y[0])
            .line(
                "fitted CBW + linear part",
                &train.u[0],
                &fitted.train_sim[0],
            ),
    ];
    if let Some(sim) = &fitted.valid_sim {
        let e: Vec<f64> = held.y[0].iter().zip(&sim[0]).map(|(y, s)| y - s).collect();
        plots.push(
            Plot::new("held-back sine: measured - model", "t [s]", "residual [um]")
                .line("residual", &held.t, &e),
        );
    }
    write_grid(path, &plots, 2).with_context(|| format!("writing {}", path.display()))
}
