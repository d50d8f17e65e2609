//! The command executor: one parsed command against the control state, its reply line
//! written without `core::fmt`.

use super::control_loop::Loop;
use super::converters::Converters;
use super::ctl::{Ctl, PointTable};
use super::target::{c, LoopPipeline, AXES, R, REC_CH, REPLY_LEN};
use super::timing::{NmpcCounts, Timing};
use crate::command::{self, Command, Error, RecCmd, Shape, TriggerCmd};
use crate::pipeline::{lissajous, raster, Parts, Wave};
use crate::recorder::{self, Signal};
use crate::Real;

impl<C: Converters> Ctl<C> {
    /// Runs one command, writing its reply line (without newline) into `out`.
    /// `rec read` is not handled here (the caller streams frames under short locks).
    /// Replies are written by [`command::Reply`]'s own number writers, not `core::fmt`:
    /// no indirect calls, so the serial handler has a static stack bound.
    pub fn execute<const N: usize>(&mut self, cmd: Command<'_>, out: &mut command::Reply<N>) {
        if let Err(e) = self.try_execute(cmd, out) {
            out.clear();
            out.push_error(e);
        }
    }

    /// Parses and runs one command line on this control state (no replica, no port): its
    /// reply, or the parser's error as a reply. What host tests and tools ask with.
    pub fn answer(&mut self, line: &str) -> command::Reply<REPLY_LEN> {
        let mut r = command::Reply::new();
        match command::parse(line.as_bytes()) {
            Ok(cmd) => self.execute(cmd, &mut r),
            Err(e) => r.push_error(e),
        }
        r
    }

    fn try_execute<const N: usize>(
        &mut self,
        cmd: Command<'_>,
        out: &mut command::Reply<N>,
    ) -> Result<(), Error> {
        match cmd {
            Command::Stats => push_stats(out, &self.timing, self.nmpc_counts()),
            Command::StatsReset => {
                self.timing = Timing::new();
                out.push_str("ok");
            }
            Command::Rec(r) => self.rec_command(r, out)?,
            cmd => {
                run(&mut self.lp, &mut self.table, &mut self.axis, cmd, out)?;
            }
        }
        Ok(())
    }
}

/// A command on the loop `lp` (the live one, or the command task's replica), the point table
/// and the selected axis; returns the parts of the pipeline it changed. The timing and the
/// recorder commands are the control state's ([`Ctl::execute`]).
pub(super) fn run<C: Converters, const N: usize>(
    lp: &mut Loop<C>,
    table: &mut PointTable,
    selected: &mut usize,
    cmd: Command<'_>,
    out: &mut command::Reply<N>,
) -> Result<Parts, Error> {
    let axis = *selected;
    let mut parts = Parts::NONE;
    match cmd {
        Command::Empty => {}
        Command::Ping => out.push_str("ok pong"),
        Command::Help => {
            out.push_str(
                    "ok ping help get set cbw mode ff wave axis table stats rec fault bench selftest; params:",
                );
            for p in PARAMS {
                out.push_str(" ");
                out.push_str(p);
            }
        }
        Command::Get(name) => {
            let v = get_param(lp, name)?;
            out.push_str("ok ");
            out.push_str(name);
            out.push_str(" ");
            push_real(out, v);
        }
        Command::Set(name, v) => {
            set_param(lp, name, c(v as f64))?;
            parts = if matches!(name, "u_min" | "u_max" | "slew") {
                Parts::LIMITS
            } else if matches!(name, "guard" | "stuck") {
                Parts::SENSOR
            } else {
                Parts::MODEL
            };
            out.push_str("ok ");
            out.push_str(name);
            out.push_str(" ");
            push_real(out, get_param(lp, name)?);
        }
        Command::Cbw(v) => {
            let v = v.map(rc);
            lp.set_cbw(v)?;
            parts = Parts::MODEL;
            out.push_str("ok cbw");
            for v in [
                lp.params.cbw_d,
                lp.params.cbw_alpha,
                lp.params.cbw_beta,
                lp.params.cbw_gamma,
            ] {
                out.push_str(" ");
                push_real(out, v);
            }
        }
        Command::Mode(name) => {
            lp.set_law(name)?;
            parts = Parts::FEEDBACK.union(Parts::MODE);
            out.push_str("ok mode ");
            out.push_str(lp.law);
        }
        Command::Feedforward(name) => {
            lp.set_ff(name)?;
            parts = Parts::FEEDFORWARD;
            out.push_str("ok ff ");
            out.push_str(lp.ff);
        }
        Command::WaveOff => {
            // Every axis holds where its reference is now.
            let sp = lp.p.state().trace.setpoint;
            for (a, s) in sp.iter().enumerate() {
                lp.p.set_wave(a, Wave::Hold { y_um: s.y_um })
                    .map_err(|_| Error::OutOfRange)?;
            }
            parts = Parts::WAVES;
            out.push_str("ok wave off");
        }
        Command::WaveHold(y) => {
            lp.p.set_wave(axis, Wave::Hold { y_um: c(y as f64) })
                .map_err(|_| Error::OutOfRange)?;
            parts = Parts::wave(axis);
            out.push_str("ok wave hold ");
            out.push_f32(y);
        }
        Command::Wave {
            shape,
            amp_um,
            freq_hz,
            offset_um,
        } => {
            let (a, f, o) = (c(amp_um as f64), c(freq_hz as f64), c(offset_um as f64));
            let wave = match shape {
                Shape::Sine => Wave::Sine {
                    offset_um: o,
                    amplitude_um: a,
                    freq_hz: f,
                    phase_turns: c(0.0),
                },
                Shape::Triangle => Wave::Triangle {
                    offset_um: o,
                    amplitude_um: a,
                    freq_hz: f,
                    phase_turns: c(0.0),
                },
                Shape::Square => Wave::Steps {
                    low_um: o - a,
                    high_um: o + a,
                    levels: 2,
                    freq_hz: f,
                },
            };
            lp.p.set_wave(axis, wave).map_err(|_| Error::OutOfRange)?;
            parts = Parts::wave(axis);
            out.push_str("ok wave ");
            out.push_str(shape.name());
            for v in [a, f, o] {
                out.push_str(" ");
                push_real(out, v);
            }
        }
        Command::WaveSteps {
            low_um,
            high_um,
            levels,
            freq_hz,
        } => {
            let (lo, hi, f) = (c(low_um as f64), c(high_um as f64), c(freq_hz as f64));
            lp.p.set_wave(
                axis,
                Wave::Steps {
                    low_um: lo,
                    high_um: hi,
                    levels,
                    freq_hz: f,
                },
            )
            .map_err(|_| Error::OutOfRange)?;
            parts = Parts::wave(axis);
            out.push_str("ok wave steps ");
            push_real(out, lo);
            out.push_str(" ");
            push_real(out, hi);
            out.push_str(" ");
            out.push_u32(levels as u32);
            out.push_str(" ");
            push_real(out, f);
        }
        Command::WavePrbs {
            low_um,
            high_um,
            order,
            bit_hz,
            seed,
        } => {
            let (lo, hi, f) = (c(low_um as f64), c(high_um as f64), c(bit_hz as f64));
            let wave = Wave::Prbs {
                low_um: lo,
                high_um: hi,
                order,
                bit_hz: f,
                seed,
            };
            lp.p.set_wave(axis, wave).map_err(|_| Error::OutOfRange)?;
            parts = Parts::wave(axis);
            out.push_str("ok wave prbs ");
            for v in [lo, hi] {
                push_real(out, v);
                out.push_str(" ");
            }
            out.push_u32(order as u32);
            out.push_str(" ");
            push_real(out, f);
            out.push_str(" ");
            out.push_u32(seed);
            // Bits per period.
            out.push_str(" ");
            out.push_u32((1u32 << order) - 1);
        }
        Command::WaveChirp {
            amp_um,
            f0_hz,
            f1_hz,
            duration_s,
            offset_um,
        } => {
            let v = [amp_um, f0_hz, f1_hz, duration_s, offset_um].map(|v| c(v as f64));
            let wave = Wave::chirp(v[4], v[0], v[1], v[2], v[3]).map_err(|_| Error::OutOfRange)?;
            lp.p.set_wave(axis, wave).map_err(|_| Error::OutOfRange)?;
            parts = Parts::wave(axis);
            out.push_str("ok wave chirp");
            for x in v {
                out.push_str(" ");
                push_real(out, x);
            }
        }
        Command::WaveMultisine {
            amp_um,
            f0_hz,
            harmonics,
            offset_um,
            seed,
        } => {
            let (a, f, o) = (c(amp_um as f64), c(f0_hz as f64), c(offset_um as f64));
            let wave = Wave::multisine(o, a, f, harmonics, seed).map_err(|_| Error::OutOfRange)?;
            lp.p.set_wave(axis, wave).map_err(|_| Error::OutOfRange)?;
            parts = Parts::wave(axis);
            out.push_str("ok wave multisine ");
            push_real(out, a);
            out.push_str(" ");
            push_real(out, f);
            out.push_str(" ");
            out.push_u32(harmonics as u32);
            out.push_str(" ");
            push_real(out, o);
            out.push_str(" ");
            out.push_u32(seed);
        }
        Command::TableClear => {
            table.len = 0;
            out.push_str("ok table 0");
        }
        Command::TableAdd(points) => {
            table.add(points.as_slice())?;
            out.push_str("ok table ");
            out.push_usize(table.len);
        }
        Command::TableLen => {
            out.push_str("ok table ");
            out.push_usize(table.len);
        }
        Command::WaveTable(freq_hz) => {
            let points = table.points();
            if points.len() < 2 {
                return Err(Error::Busy);
            }
            let f = c(freq_hz as f64);
            let wave = Wave::table(points, f).map_err(|_| Error::OutOfRange)?;
            lp.p.set_wave(axis, wave).map_err(|_| Error::OutOfRange)?;
            parts = Parts::wave(axis);
            out.push_str("ok wave table ");
            push_real(out, f);
            out.push_str(" ");
            out.push_usize(points.len());
        }
        Command::WaveRaster {
            span_um,
            lines,
            line_hz,
            center_um,
        } => {
            let (half, center) = (span_um.map(|s| c(s as f64 * 0.5)), center_um.map(rc));
            let line_hz = c(line_hz as f64);
            // One y sweep per `lines` x periods: y runs at line_hz / (2 lines).
            let frame_hz = line_hz / R::from_i32(2 * lines as i32);
            set_scan(lp, raster(center, half, line_hz, frame_hz))?;
            parts = Parts::wave(0).union(Parts::wave(1));
            out.push_str("ok wave raster ");
            push_real(out, half[0] + half[0]);
            out.push_str(" ");
            push_real(out, half[1] + half[1]);
            out.push_str(" ");
            out.push_u32(lines as u32);
            out.push_str(" ");
            push_real(out, line_hz);
            for v in center {
                out.push_str(" ");
                push_real(out, v);
            }
        }
        Command::WaveLissajous {
            amp_um,
            freq_hz,
            phase_deg,
            center_um,
        } => {
            let (amp, f, center) = (amp_um.map(rc), freq_hz.map(rc), center_um.map(rc));
            // The core's lissajous(), with y `phase_deg` ahead of x instead of 90 deg.
            let mut waves = lissajous(center, amp, f);
            if let [_, Wave::Sine { phase_turns, .. }] = &mut waves {
                *phase_turns = c(phase_deg as f64 / 360.0);
            }
            set_scan(lp, waves)?;
            parts = Parts::wave(0).union(Parts::wave(1));
            out.push_str("ok wave lissajous");
            for v in amp.into_iter().chain(f) {
                out.push_str(" ");
                push_real(out, v);
            }
            out.push_str(" ");
            out.push_f32(phase_deg);
            for v in center {
                out.push_str(" ");
                push_real(out, v);
            }
        }
        Command::Axis(n) => {
            if let Some(n) = n {
                if n >= AXES {
                    return Err(Error::OutOfRange);
                }
                *selected = n;
            }
            out.push_str("ok axis ");
            out.push_usize(*selected);
            out.push_str(" of ");
            out.push_usize(AXES);
        }
        Command::Stats | Command::StatsReset | Command::Rec(_) => return Err(Error::Unsupported),
        Command::Fault => push_fault(out, &lp.p),
        Command::FaultClear => {
            lp.p.clear_fault();
            parts = Parts::CLEAR_FAULT;
            push_fault(out, &lp.p);
        }
        Command::Defaults => {
            lp.default_settings()?;
            parts = Parts::MODEL.union(Parts::LIMITS).union(Parts::SENSOR);
            out.push_str("ok defaults");
        }
        // The board's own: the command line runs them (see `Port`).
        Command::Bench | Command::Selftest | Command::Save | Command::Load => {
            return Err(Error::Unsupported)
        }
    }
    Ok(parts)
}

impl<C: Converters> Ctl<C> {
    fn rec_command<const N: usize>(
        &mut self,
        r: RecCmd<'_>,
        out: &mut command::Reply<N>,
    ) -> Result<(), Error> {
        let cfg = |e: recorder::ConfigError| match e {
            recorder::ConfigError::NoSuchChannel => Error::UnknownSignal,
            recorder::ConfigError::PreTooLong => Error::OutOfRange,
            recorder::ConfigError::Busy => Error::Busy,
            recorder::ConfigError::BadDivider => Error::OutOfRange,
            recorder::ConfigError::BadLength => Error::OutOfRange,
        };
        match r {
            RecCmd::Select(names) => {
                if names.len() > REC_CH {
                    return Err(Error::TooManyArguments);
                }
                let mut sel = *self.rec.channels();
                for (slot, name) in sel.iter_mut().zip(names.iter()) {
                    *slot = Signal::from_name(name).ok_or(Error::UnknownSignal)?;
                    if slot.axis() >= AXES {
                        return Err(Error::Unsupported);
                    }
                }
                self.rec.select(&sel).map_err(cfg)?;
                out.push_str("ok rec sel");
                for s in self.rec.channels() {
                    out.push_str(" ");
                    out.push_str(s.name());
                }
            }
            RecCmd::Trigger(t) => {
                let (trigger, pre) = match t {
                    TriggerCmd::Now => (recorder::Trigger::Now, 0),
                    TriggerCmd::Rising {
                        channel,
                        level,
                        pre,
                    } => (
                        recorder::Trigger::Rising {
                            channel,
                            level: c(level as f64),
                        },
                        pre,
                    ),
                    TriggerCmd::Falling {
                        channel,
                        level,
                        pre,
                    } => (
                        recorder::Trigger::Falling {
                            channel,
                            level: c(level as f64),
                        },
                        pre,
                    ),
                    TriggerCmd::Level {
                        channel,
                        level,
                        pre,
                    } => (
                        recorder::Trigger::Level {
                            channel,
                            level: c(level as f64),
                        },
                        pre,
                    ),
                };
                self.rec.set_trigger(trigger, pre).map_err(cfg)?;
                out.push_str("ok");
            }
            RecCmd::Arm => {
                self.rec.arm();
                out.push_str("ok");
            }
            RecCmd::Stop => {
                self.rec.stop();
                out.push_str("ok");
            }
            RecCmd::Status => {
                out.push_str("ok rec ");
                out.push_str(self.rec.state().name());
                out.push_str(" ");
                out.push_usize(self.rec.progress());
            }
            RecCmd::Divider(n) => {
                if let Some(n) = n {
                    let n = u32::try_from(n).unwrap_or(u32::MAX);
                    self.rec.set_divider(n).map_err(cfg)?;
                }
                out.push_str("ok rec div ");
                out.push_u32(self.rec.divider());
            }
            RecCmd::Length(n) => {
                if let Some(n) = n {
                    self.rec.set_capture_len(n).map_err(cfg)?;
                }
                out.push_str("ok rec len ");
                out.push_usize(self.rec.capture_len());
                out.push_str(" of ");
                out.push_usize(self.rec.capacity());
            }
            RecCmd::Read { .. } | RecCmd::Bin { .. } => return Err(Error::Unsupported),
        }
        Ok(())
    }
}

/// `stats`: the control task's timing, then `lost` (samples lost entirely), `late` (the
/// longest start after the period's trigger, `-` on a board whose counter does not tell) and,
/// while an NMPC law runs, its solver's `nmpc_jobs` and `nmpc_missed` (boundaries whose plan
/// came too late) since the mode was selected (`stats reset` leaves those).
pub fn push_stats<const N: usize>(
    out: &mut command::Reply<N>,
    t: &Timing,
    nmpc: Option<NmpcCounts>,
) {
    out.push_str("ok step");
    for v in [t.step.min, t.step.max, t.step.last] {
        out.push_str(" ");
        out.push_u32(v);
    }
    out.push_str(" isr");
    for v in [t.isr.min, t.isr.max, t.isr.last] {
        out.push_str(" ");
        out.push_u32(v);
    }
    out.push_str(" samples ");
    out.push_u32(t.isr.count);
    out.push_str(" overruns ");
    out.push_u32(t.overruns);
    out.push_str(" lost ");
    out.push_u32(t.lost);
    out.push_str(" late ");
    if t.delay.count == 0 {
        out.push_str("-");
    } else {
        out.push_u32(t.delay.max);
    }
    if let Some(n) = nmpc {
        out.push_str(" nmpc_jobs ");
        out.push_u32(n.jobs);
        out.push_str(" nmpc_missed ");
        out.push_u32(n.missed);
    }
}

/// Streams `rec read <start> <count>`: `frame(i)` fetches frame `i` (under a short lock;
/// `None` past the capture ends the stream), `line` sends one line.
pub fn stream_frames(
    start: usize,
    count: usize,
    mut frame: impl FnMut(usize) -> Option<[R; REC_CH]>,
    mut line: impl FnMut(&str),
) {
    let mut sent = 0;
    for i in start..start.saturating_add(count) {
        let Some(f) = frame(i) else {
            break;
        };
        let mut r = command::Reply::<96>::new();
        r.push_usize(i);
        for v in f {
            r.push_str(" ");
            push_real(&mut r, v);
        }
        line(r.as_str());
        sent += 1;
    }
    let mut r = command::Reply::<48>::new();
    if sent == 0 && count > 0 {
        r.push_error(Error::Busy);
    } else {
        r.push_str("ok rec read ");
        r.push_usize(sent);
    }
    line(r.as_str());
}

/// Streams `rec bin <start> <count>` ([`crate::bulk`]): `available` is the capture's
/// frames in place ([`crate::recorder::Recorder::readable`]: from the trigger on, while it
/// fills); the reply line `ok rec bin <frames> <packets>` (err 12 when
/// nothing is available), then the packets, each of up to
/// [`crate::bulk::FRAMES_PER_PACKET`] frames fetched by `frame(i)` (one short lock each),
/// all sent to `port`. Bounded by `count`; a frame gone meanwhile (the recorder re-armed)
/// ends the stream early (the host finds the packets missing and asks again).
pub fn stream_bin(
    start: usize,
    count: usize,
    available: usize,
    mut frame: impl FnMut(usize) -> Option<[R; REC_CH]>,
    port: &mut impl super::Port,
) {
    use crate::bulk::{encode, FRAMES_PER_PACKET, MAX_FRAMED};
    let n = count.min(available.saturating_sub(start));
    let mut r = command::Reply::<48>::new();
    if n == 0 && count > 0 {
        r.push_error(Error::Busy);
        port.send(r.as_str());
        return;
    }
    let packets = n.div_ceil(FRAMES_PER_PACKET);
    r.push_str("ok rec bin ");
    r.push_usize(n);
    r.push_str(" ");
    r.push_usize(packets);
    port.send(r.as_str());
    let mut buf = [[0.0f32; REC_CH]; FRAMES_PER_PACKET];
    let mut out = [0u8; MAX_FRAMED];
    for p in 0..packets {
        let first = start + p * FRAMES_PER_PACKET;
        let k = FRAMES_PER_PACKET.min(start + n - first);
        for (j, slot) in buf.iter_mut().take(k).enumerate() {
            let Some(f) = frame(first + j) else {
                return;
            };
            *slot = f.map(|v| v.to_f64() as f32);
        }
        let frames = buf.get(..k).unwrap_or(&[]);
        if let Some(len) = encode(first as u32, frames, &mut out) {
            port.send_bytes(out.get(..len).unwrap_or(&[]));
        }
    }
}

/// A command's number as a control-path value.
fn rc(v: f32) -> R {
    c(v as f64)
}

/// Starts a 2-axis scan on axes 0 and 1 in the same sample (the caller holds the loop);
/// a 1-axis board answers [`Error::Unsupported`]. Both waves are checked before either runs.
fn set_scan<C: Converters>(lp: &mut Loop<C>, waves: [Wave<R>; 2]) -> Result<(), Error> {
    if AXES < 2 {
        return Err(Error::Unsupported);
    }
    let fs = lp.p.config().sample_hz;
    for w in &waves {
        w.validate(fs).map_err(|_| Error::OutOfRange)?;
    }
    for (axis, w) in waves.into_iter().enumerate() {
        lp.p.set_wave(axis, w).map_err(|_| Error::OutOfRange)?;
    }
    Ok(())
}

/// `ok fault <state> sensor <n> nonfinite <n> dac <n>`: the latched fault and the counters.
fn push_fault<const N: usize>(out: &mut command::Reply<N>, p: &LoopPipeline) {
    use crate::pipeline::Fault;
    let st = p.state();
    out.push_str("ok fault ");
    out.push_str(match st.fault {
        None => "none",
        Some(Fault::SensorRange { .. }) => "sensor-range",
        Some(Fault::SensorStuck { .. }) => "sensor-stuck",
        Some(Fault::NonFiniteCommand { .. }) => "non-finite",
        Some(Fault::DacWrite { .. }) => "dac-write",
    });
    let c = &st.counters;
    for (name, n) in [
        (" sensor ", c.sensor_faults),
        (" nonfinite ", c.nonfinite_commands),
        (" dac ", c.dac_faults),
    ] {
        out.push_str(name);
        out.push_u32(n);
    }
}

/// A value of the control path as text (Q16.16 through f32: 24 significant bits).
pub fn push_real<const N: usize>(out: &mut command::Reply<N>, v: R) {
    out.push_f32(v.to_f64() as f32);
}

use super::settings::{setting, Access};
pub use super::settings::{PARAMS, READ_ONLY};

pub(super) fn get_param<C: Converters>(lp: &Loop<C>, name: &str) -> Result<R, Error> {
    let cfg = lp.p.config();
    let a = &cfg.axes[0];
    Ok(match name {
        "u_min" => a.limits.volts_min,
        "u_max" => a.limits.volts_max,
        "slew" => a.limits.slew_volts_per_s,
        "um_per_code" => a.sensor.um_per_code,
        "volts_per_code" => a.dac.volts_per_code,
        "sample_hz" => cfg.sample_hz,
        "guard" => lp.guard_um,
        "stuck" => R::from_i32(lp.stuck_limit.min(i32::MAX as u32) as i32),
        _ => {
            let mut p = lp.params;
            *p.slot(name).ok_or(Error::UnknownParam)?
        }
    })
}

fn set_param<C: Converters>(lp: &mut Loop<C>, name: &str, v: R) -> Result<(), Error> {
    let (lo, hi) = {
        let l = &lp.p.config().axes[0].limits;
        (l.volts_min, l.volts_max)
    };
    let check = |ok: bool| if ok { Ok(()) } else { Err(Error::OutOfRange) };
    if let Some(s) = setting(name) {
        if s.access != Access::ReadOnly {
            check(s.accepts(v.to_f64()))?;
        }
    }
    match name {
        "u_min" => {
            check(v >= c(0.0) && v < hi)?;
            lp.set_limits(|l| l.volts_min = v)
        }
        "u_max" => {
            check(v > lo && v <= c(150.0))?;
            lp.set_limits(|l| l.volts_max = v)
        }
        "slew" => {
            check(v > c(0.0))?;
            lp.set_limits(|l| l.slew_volts_per_s = v)
        }
        "guard" => lp.set_guard(v),
        "stuck" => {
            // Whole samples only.
            let n = v.to_f64();
            check(n == (n as u32) as f64)?;
            lp.stuck_limit = n as u32;
            Ok(())
        }
        _ if READ_ONLY.contains(&name) => Err(Error::Busy),
        _ => lp.set_params(name, v),
    }
}
