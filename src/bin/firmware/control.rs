//! Board-independent part of the firmware: the per-sample step (ADC code in, DAC code out),
//! the recorder hook, the timing statistics and the command executor. The boards call
//! [`Ctl::step`] from their highest-priority task and [`Ctl::execute`] from a low-priority one.

use core::fmt::Write;
use piezo_core::command::{self, Command, Error, RecCmd, Shape, TriggerCmd};
use piezo_core::feedback::{
    hgo, Adrc, AdrcConfig, Convergence, Feedback, Hgo, Nmpc, NmpcConfig, ObserverModel, Pid,
    PidConfig, Robust, RobustConfig,
};
use piezo_core::feedforward::{Feedforward, Ims, ImsLoop, LinearFf};
use piezo_core::hysteresis::Cbw;
use piezo_core::recorder::{self, Recorder, Signal};
use piezo_core::signals::{LoopSignals, Setpoint};
use piezo_core::Real;

/// The number type of the control path: `f32` with an FPU (thumbv7em-none-eabihf), the
/// Q16.16 fixed point of [`piezo_core::fixed`] without one (thumbv7m-none-eabi, Cortex-M3).
#[cfg(target_abi = "eabihf")]
pub type R = f32;
#[cfg(not(target_abi = "eabihf"))]
pub type R = piezo_core::fixed::Q16;

/// A constant of the control path (folded at compile time).
#[inline(always)]
pub fn c(x: f64) -> R {
    R::from_f64(x)
}

/// What the control path needs beyond [`Real`]: converter codes and printing.
pub trait Sample: Real + core::fmt::Display {
    /// `code * um_per_code` without leaving the type's range (codes up to 2^16).
    fn from_code(code: u32, per_code: Self) -> Self;
    /// Rounded, saturated to `0..=max` (NaN and -inf give 0).
    fn to_code(self, max: u16) -> u16;
    /// A code as a signal value (Q16.16 saturates above 32767).
    fn code_value(code: u32) -> Self;
}

impl Sample for f32 {
    #[inline(always)]
    fn from_code(code: u32, per_code: Self) -> Self {
        code as f32 * per_code
    }
    #[inline(always)]
    fn to_code(self, max: u16) -> u16 {
        (self + 0.5).clamp_to(0.0, max as f32) as u16
    }
    #[inline(always)]
    fn code_value(code: u32) -> Self {
        code as f32
    }
}

impl Sample for piezo_core::fixed::Q16 {
    #[inline(always)]
    fn from_code(code: u32, per_code: Self) -> Self {
        // An integer times a Q16.16 value is already Q16.16.
        let v = code as i64 * per_code.raw() as i64;
        Self::from_raw(v.clamp(i32::MIN as i64 + 1, i32::MAX as i64 - 1) as i32)
    }
    #[inline(always)]
    fn to_code(self, max: u16) -> u16 {
        if !self.is_finite() {
            return if self.raw() > 0 { max } else { 0 };
        }
        let v = (self.raw() as i64 + (1 << 15)) >> 16;
        v.clamp(0, max as i64) as u16
    }
    #[inline(always)]
    fn code_value(code: u32) -> Self {
        Self::from_usize(code as usize)
    }
}

/// Recorder size: 4 channels x 1024 frames of R (16 KiB).
pub const REC_CH: usize = 4;
pub const REC_N: usize = 1024;

/// Converter scaling and output limits of one axis.
#[derive(Clone, Copy, Debug)]
pub struct Io {
    /// Position per ADC code (um/LSB) and position at code 0 (um).
    pub um_per_code: R,
    pub offset_um: R,
    /// DAC codes per volt of actuator command, and the largest code.
    pub codes_per_volt: R,
    pub dac_max: u16,
    /// Actuator range (V) and slew limit (V per sample).
    pub u_min: R,
    pub u_max: R,
    pub slew_per_sample: R,
}

impl Io {
    /// 16-bit ADC over 0..100 um, 12-bit DAC over 0..150 V (amplifier gain 45 V/V at c(3.3) V).
    pub fn on_chip() -> Self {
        Self {
            um_per_code: c(100.0 / 65535.0),
            offset_um: c(0.0),
            codes_per_volt: c(4095.0 / 150.0),
            dac_max: 4095,
            u_min: c(0.0),
            u_max: c(150.0),
            slew_per_sample: c(1.0),
        }
    }
}

/// Reference generator (stand-in until the core pipeline's generator is wired).
///
/// The sine is a rotating phasor (one complex multiply per sample, renormalised): `sinf` and
/// `cosf` of libm compute in f64, which the single-precision FPU of the M4F/M7 emulates in
/// software (thousands of instructions per sample).
#[derive(Clone, Copy, Debug)]
pub struct Wave {
    pub shape: Option<Shape>,
    pub amp_um: R,
    pub offset_um: R,
    /// Phase in cycles, `[0, 1)`, and its increment per sample.
    pub phase: R,
    pub dphase: R,
    /// Angular frequency (rad/s).
    pub w: R,
    /// Phasor `(cos, sin)` of the phase and its rotation per sample.
    pub cs: (R, R),
    pub rot: (R, R),
}

impl Wave {
    pub fn hold(y_um: R) -> Self {
        Self {
            shape: None,
            amp_um: c(0.0),
            offset_um: y_um,
            phase: c(0.0),
            dphase: c(0.0),
            w: c(0.0),
            cs: (c(1.0), c(0.0)),
            rot: (c(1.0), c(0.0)),
        }
    }

    /// A periodic waveform starting at phase 0 (init time: uses libm).
    pub fn periodic(shape: Shape, amp_um: R, freq_hz: R, offset_um: R, sample_hz: R) -> Self {
        let dphase = freq_hz / sample_hz;
        let step = c(2.0) * R::PI * dphase;
        Self {
            shape: Some(shape),
            amp_um,
            offset_um,
            phase: c(0.0),
            dphase,
            w: c(2.0) * R::PI * freq_hz,
            cs: (c(1.0), c(0.0)),
            rot: (step.cos(), step.sin()),
        }
    }

    #[inline]
    pub fn next(&mut self) -> Setpoint<R> {
        let Some(shape) = self.shape else {
            return Setpoint::hold(self.offset_um);
        };
        self.phase += self.dphase;
        if self.phase >= c(1.0) {
            self.phase -= c(1.0);
        }
        let (y, dy, ddy) = match shape {
            Shape::Sine => {
                let (c0, s0) = self.cs;
                let (rc, rs) = self.rot;
                let (co, si) = (c0 * rc - s0 * rs, s0 * rc + c0 * rs);
                // First-order renormalisation keeps |phasor| = 1 without a sqrt.
                let k = c(1.5) - c(0.5) * (co * co + si * si);
                let (co, si) = (co * k, si * k);
                self.cs = (co, si);
                let w = self.w;
                (si, w * co, -w * w * si)
            }
            Shape::Triangle => {
                let p = self.phase;
                let slope = c(4.0) * self.w / (c(2.0) * R::PI);
                if p < c(0.25) {
                    (c(4.0) * p, slope, c(0.0))
                } else if p < c(0.75) {
                    (c(2.0) - c(4.0) * p, -slope, c(0.0))
                } else {
                    (c(4.0) * p - c(4.0), slope, c(0.0))
                }
            }
            Shape::Square => (
                if self.phase < c(0.5) { c(1.0) } else { -c(1.0) },
                c(0.0),
                c(0.0),
            ),
        };
        Setpoint {
            y_um: self.offset_um + self.amp_um * y,
            dy: self.amp_um * dy,
            ddy: self.amp_um * ddy,
        }
    }
}

/// One axis: reference, feedforward, feedback, limits, converter scaling.
pub struct Loop {
    pub io: Io,
    pub sample_hz: R,
    pub wave: Wave,
    pub ff: Feedforward<R>,
    pub fb: Feedback<R>,
    /// Last applied command (V).
    pub u_applied: R,
    /// This period's signals, indexed by [`Signal::index`] (recorder input).
    pub signals: [R; Signal::COUNT],
}

impl Loop {
    pub fn new(io: Io, sample_hz: R, fb: Feedback<R>) -> Self {
        Self {
            io,
            sample_hz,
            wave: Wave::hold(c(0.0)),
            ff: Feedforward::Linear(LinearFf {
                um_per_volt: c(0.16),
                offset_um: c(0.0),
            }),
            fb,
            u_applied: c(0.0),
            signals: [c(0.0); Signal::COUNT],
        }
    }

    /// One control period: ADC code in, DAC code out. No panic, bounded, NaN-safe.
    #[inline]
    pub fn step(&mut self, adc_code: u32) -> u16 {
        let io = self.io;
        let y_um = R::from_code(adc_code, io.um_per_code) + io.offset_um;
        let setpoint = self.wave.next();
        let u_ff = self.ff.compensate(&setpoint);
        let u = self.fb.update(&LoopSignals {
            setpoint,
            y_um,
            u_ff,
            u_applied: self.u_applied,
        });
        let lo = (self.u_applied - io.slew_per_sample).max(io.u_min);
        let hi = (self.u_applied + io.slew_per_sample).min(io.u_max);
        let u = u.clamp_to(lo, hi);
        self.u_applied = u;
        let code = dac_code(u, io.codes_per_volt, io.dac_max);
        self.signals = [
            setpoint.y_um,
            y_um,
            setpoint.y_um - y_um,
            u_ff,
            u,
            R::code_value(adc_code),
            R::code_value(code as u32),
        ];
        code
    }

    /// Bumpless switch of the feedback law: the new law starts from the applied voltage.
    pub fn set_feedback(&mut self, mut fb: Feedback<R>) {
        let io = LoopSignals {
            setpoint: Setpoint::hold(self.signals[Signal::RefUm.index()]),
            y_um: self.signals[Signal::YUm.index()],
            u_ff: self.signals[Signal::FfVolts.index()],
            u_applied: self.u_applied,
        };
        fb.reset(&io);
        self.fb = fb;
    }
}

/// Volts to a DAC code, saturating (NaN -> 0).
#[inline(always)]
pub fn dac_code(u: R, codes_per_volt: R, max: u16) -> u16 {
    (u * codes_per_volt).to_code(max)
}

/// Min/max/last of a cycle count, and how many samples there were.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct CycleStats {
    pub min: u32,
    pub max: u32,
    pub last: u32,
    pub count: u32,
}

impl CycleStats {
    pub const fn new() -> Self {
        Self {
            min: u32::MAX,
            max: 0,
            last: 0,
            count: 0,
        }
    }
    #[inline(always)]
    pub fn record(&mut self, cycles: u32) {
        self.last = cycles;
        self.min = self.min.min(cycles);
        self.max = self.max.max(cycles);
        self.count = self.count.wrapping_add(1);
    }
}

/// Timing of the control task, reported every second and reset by command.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct Timing {
    /// The pipeline step alone.
    pub step: CycleStats,
    /// The whole interrupt handler (converter access, step, recorder, bookkeeping).
    pub isr: CycleStats,
    /// Samples whose processing missed the deadline (the next sample was due or lost).
    pub overruns: u32,
}

impl Timing {
    pub const fn new() -> Self {
        Self {
            step: CycleStats::new(),
            isr: CycleStats::new(),
            overruns: 0,
        }
    }
}

/// Everything the control task owns: the loop, the recorder and the timing.
pub struct Ctl {
    pub lp: Loop,
    pub rec: Recorder<R, REC_CH, REC_N>,
    pub timing: Timing,
    /// Feedback laws selectable by `mode` (name, constructor).
    pub laws: fn(&str, R) -> Option<Feedback<R>>,
}

/// Names of the feedback laws `mode` accepts (the bench iterates over them); they are the
/// laws' own [`Feedback::name`]s.
pub const LAWS: [&str; 11] = [
    "open-loop",
    "pid",
    "ff+pid",
    "hgo-robust",
    "ff+hgo-robust",
    "fts",
    "ff+fts",
    "adrc",
    "ff+adrc",
    "nmpc",
    "ff+nmpc",
];

/// Stage the laws are tuned for: CBW set 1 of the 000 backup slide, first-order linear part
/// with pole [`STAGE_POLE_PER_S`], range 0..150 V.
pub const STAGE_POLE_PER_S: f64 = 2.0 * core::f64::consts::PI * 500.0;

/// The feedback laws of the core, by name, with gains for [`STAGE_POLE_PER_S`].
pub fn law_by_name(name: &str, sample_hz: R) -> Option<Feedback<R>> {
    let dt_s = c(1.0) / sample_hz;
    let (ff, base) = match name.strip_prefix("ff+") {
        Some(b) => (true, b),
        None => (false, name),
    };
    let model = Cbw::with_n1(c(0.16), c(0.07), c(0.02), c(0.01)).ok()?;
    let hgo = || {
        Hgo::new(
            ObserverModel::Cbw(model),
            c(STAGE_POLE_PER_S),
            c(2e-4),
            c(hgo::K1),
            c(hgo::K2),
            dt_s,
        )
        .ok()
    };
    let robust = |convergence| {
        Robust::new(
            hgo()?,
            RobustConfig {
                lambda1: c(2_000.0),
                lambda2: c(2_000.0),
                feedforward: ff,
                convergence,
            },
        )
        .ok()
        .map(Feedback::Robust)
    };
    match base {
        "open-loop" if !ff => Some(Feedback::OpenLoop),
        "pid" => Pid::new(PidConfig {
            kp: c(0.5),
            ki: c(2_000.0),
            kd: c(0.0),
            tf_s: c(1e-4),
            kb: c(1.0),
            feedforward: ff,
            dt_s,
        })
        .ok()
        .map(Feedback::Pid),
        "hgo-robust" => robust(Convergence::Exponential),
        "fts" => robust(Convergence::FiniteTime {
            alpha1: c(0.8),
            alpha2: c(0.8),
            sat_um_per_s: c(1e4),
        }),
        "adrc" => Adrc::new(AdrcConfig {
            b: c(0.16 * STAGE_POLE_PER_S * STAGE_POLE_PER_S),
            eps_s: c(2e-4),
            omega_c: c(2_000.0),
            feedforward: ff,
            dt_s,
        })
        .ok()
        .map(Feedback::Adrc),
        "nmpc" => Nmpc::new(
            hgo()?,
            NmpcConfig {
                decimation: 10,
                r: c(1e-3),
                iterations: 2,
                u_min: c(0.0),
                u_max: c(150.0),
                feedforward: ff,
            },
        )
        .ok()
        .map(Feedback::Nmpc),
        _ => None,
    }
}

/// Names of the feedforward compensators `ff` accepts.
#[cfg_attr(not(feature = "board-qemu"), allow(dead_code))]
pub const FFS: [&str; 3] = ["linear", "ims-cbw", "ims-cbw-delayed"];

/// The feedforward compensators, by name: linear scaling, or IMS around the CBW model of
/// 000 backup slide set 1 (0..150 V).
pub fn ff_by_name(name: &str, sample_hz: R) -> Option<Feedforward<R>> {
    let ims = |closure| {
        let model = Cbw::with_n1(c(0.16), c(0.07), c(0.02), c(0.01)).ok()?;
        Ims::new(model, closure, c(0.0), c(150.0), c(1.0) / sample_hz)
            .ok()
            .map(Feedforward::ImsCbw)
    };
    match name {
        "linear" => Some(Feedforward::Linear(LinearFf {
            um_per_volt: c(0.16),
            offset_um: c(0.0),
        })),
        "ims-cbw" => ims(ImsLoop::Solved),
        "ims-cbw-delayed" => ims(ImsLoop::Delayed),
        _ => None,
    }
}

impl Ctl {
    pub fn new(io: Io, sample_hz: R) -> Self {
        Self {
            lp: Loop::new(io, sample_hz, Feedback::OpenLoop),
            rec: Recorder::new(),
            timing: Timing::new(),
            laws: law_by_name,
        }
    }

    /// Runs one command, writing its reply line (without newline) into `out`.
    /// `rec read` is not handled here (the caller streams frames under short locks).
    pub fn execute<const N: usize>(&mut self, cmd: Command<'_>, out: &mut command::Reply<N>) {
        if let Err(e) = self.try_execute(cmd, out) {
            out.clear();
            write!(out, "{e}").ok();
        }
    }

    fn try_execute<const N: usize>(
        &mut self,
        cmd: Command<'_>,
        out: &mut command::Reply<N>,
    ) -> Result<(), Error> {
        let lp = &mut self.lp;
        match cmd {
            Command::Empty => {}
            Command::Ping => {
                write!(out, "ok pong").ok();
            }
            Command::Help => {
                write!(
                    out,
                    "ok ping help get set mode ff wave stats rec bench; params:"
                )
                .ok();
                for p in PARAMS {
                    write!(out, " {p}").ok();
                }
            }
            Command::Get(name) => {
                let v = get_param(lp, name)?;
                write!(out, "ok {name} {v}").ok();
            }
            Command::Set(name, v) => {
                set_param(lp, name, c(v as f64))?;
                write!(out, "ok {name} {}", get_param(lp, name)?).ok();
            }
            Command::Mode(name) => {
                // A known law whose configuration this number type cannot hold (ADRC's gain
                // in Q16.16) is "unsupported", not "unknown".
                let fb = (self.laws)(name, lp.sample_hz).ok_or(if LAWS.contains(&name) {
                    Error::Unsupported
                } else {
                    Error::UnknownMode
                })?;
                lp.set_feedback(fb);
                write!(out, "ok mode {}", lp.fb.name()).ok();
            }
            Command::Feedforward(name) => {
                lp.ff = ff_by_name(name, lp.sample_hz).ok_or(Error::UnknownMode)?;
                lp.ff
                    .reset(&Setpoint::hold(lp.signals[Signal::RefUm.index()]));
                write!(out, "ok ff {}", lp.ff.name()).ok();
            }
            Command::WaveOff => {
                lp.wave = Wave::hold(lp.signals[Signal::RefUm.index()]);
                write!(out, "ok wave off").ok();
            }
            Command::WaveHold(y) => {
                lp.wave = Wave::hold(c(y as f64));
                write!(out, "ok wave hold {y}").ok();
            }
            Command::Wave {
                shape,
                amp_um,
                freq_hz,
                offset_um,
            } => {
                let (amp_um, freq_hz, offset_um) =
                    (c(amp_um as f64), c(freq_hz as f64), c(offset_um as f64));
                if !(freq_hz < c(0.5) * lp.sample_hz) {
                    return Err(Error::OutOfRange);
                }
                lp.wave = Wave::periodic(shape, amp_um, freq_hz, offset_um, lp.sample_hz);
                write!(
                    out,
                    "ok wave {} {amp_um} {freq_hz} {offset_um}",
                    shape.name()
                )
                .ok();
            }
            Command::Stats => {
                let t = &self.timing;
                write!(
                    out,
                    "ok step {} {} {} isr {} {} {} samples {} overruns {}",
                    t.step.min,
                    t.step.max,
                    t.step.last,
                    t.isr.min,
                    t.isr.max,
                    t.isr.last,
                    t.isr.count,
                    t.overruns
                )
                .ok();
            }
            Command::StatsReset => {
                self.timing = Timing::new();
                write!(out, "ok").ok();
            }
            Command::Rec(r) => self.rec_command(r, out)?,
            Command::Bench => return Err(Error::Unsupported),
        }
        Ok(())
    }

    fn rec_command<const N: usize>(
        &mut self,
        r: RecCmd<'_>,
        out: &mut command::Reply<N>,
    ) -> Result<(), Error> {
        let cfg = |e: recorder::ConfigError| match e {
            recorder::ConfigError::NoSuchChannel => Error::UnknownSignal,
            recorder::ConfigError::PreTooLong => Error::OutOfRange,
            recorder::ConfigError::Busy => Error::Busy,
        };
        match r {
            RecCmd::Select(names) => {
                if names.len() > REC_CH {
                    return Err(Error::TooManyArguments);
                }
                let mut sel = *self.rec.channels();
                for (slot, name) in sel.iter_mut().zip(names.iter()) {
                    *slot = Signal::from_name(name).ok_or(Error::UnknownSignal)?;
                }
                self.rec.select(&sel).map_err(cfg)?;
                write!(out, "ok rec sel").ok();
                for s in self.rec.channels() {
                    write!(out, " {}", s.name()).ok();
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
                write!(out, "ok").ok();
            }
            RecCmd::Arm => {
                self.rec.arm();
                write!(out, "ok").ok();
            }
            RecCmd::Stop => {
                self.rec.stop();
                write!(out, "ok").ok();
            }
            RecCmd::Status => {
                write!(out, "ok rec {} {}", self.rec.state().name(), self.rec.len()).ok();
            }
            RecCmd::Read { .. } => return Err(Error::Unsupported),
        }
        Ok(())
    }
}

/// Streams `rec read <start> <count>`: `frame(i)` fetches frame `i` (under a short lock),
/// `line` sends one line. Bounded by the recorder length.
pub fn stream_frames(
    start: usize,
    count: usize,
    mut frame: impl FnMut(usize) -> Option<[R; REC_CH]>,
    mut line: impl FnMut(&str),
) {
    let mut sent = 0;
    for i in start..start.saturating_add(count).min(REC_N) {
        let Some(f) = frame(i) else {
            break;
        };
        let mut r = command::Reply::<96>::new();
        write!(r, "{i}").ok();
        for v in f {
            write!(r, " {v}").ok();
        }
        line(r.as_str());
        sent += 1;
    }
    let mut r = command::Reply::<32>::new();
    if sent == 0 && count > 0 {
        write!(r, "{}", Error::Busy).ok();
    } else {
        write!(r, "ok rec read {sent}").ok();
    }
    line(r.as_str());
}

/// Parameter names of `get`/`set`.
pub const PARAMS: [&str; 7] = [
    "u_min",
    "u_max",
    "slew",
    "um_per_code",
    "offset_um",
    "codes_per_volt",
    "ff_um_per_volt",
];

fn get_param(lp: &Loop, name: &str) -> Result<R, Error> {
    let io = &lp.io;
    Ok(match name {
        "u_min" => io.u_min,
        "u_max" => io.u_max,
        "slew" => io.slew_per_sample,
        "um_per_code" => io.um_per_code,
        "offset_um" => io.offset_um,
        "codes_per_volt" => io.codes_per_volt,
        "ff_um_per_volt" => match &lp.ff {
            Feedforward::Linear(l) => l.um_per_volt,
            _ => return Err(Error::Busy),
        },
        _ => return Err(Error::UnknownParam),
    })
}

fn set_param(lp: &mut Loop, name: &str, v: R) -> Result<(), Error> {
    let io = &mut lp.io;
    let check = |ok: bool| if ok { Ok(()) } else { Err(Error::OutOfRange) };
    match name {
        "u_min" => {
            check(v < io.u_max)?;
            io.u_min = v;
        }
        "u_max" => {
            check(v > io.u_min)?;
            io.u_max = v;
        }
        "slew" => {
            check(v > c(0.0))?;
            io.slew_per_sample = v;
        }
        "um_per_code" => {
            check(v != c(0.0))?;
            io.um_per_code = v;
        }
        "offset_um" => io.offset_um = v,
        "codes_per_volt" => {
            check(v > c(0.0))?;
            io.codes_per_volt = v;
        }
        "ff_um_per_volt" => {
            check(v > c(0.0))?;
            match &mut lp.ff {
                Feedforward::Linear(l) => l.um_per_volt = v,
                _ => return Err(Error::Busy),
            }
        }
        _ => return Err(Error::UnknownParam),
    }
    Ok(())
}
