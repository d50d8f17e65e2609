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

/// Recorder size: 4 channels x 1024 frames of f32 (16 KiB).
pub const REC_CH: usize = 4;
pub const REC_N: usize = 1024;

/// Converter scaling and output limits of one axis.
#[derive(Clone, Copy, Debug)]
pub struct Io {
    /// Position per ADC code (um/LSB) and position at code 0 (um).
    pub um_per_code: f32,
    pub offset_um: f32,
    /// DAC codes per volt of actuator command, and the largest code.
    pub codes_per_volt: f32,
    pub dac_max: u16,
    /// Actuator range (V) and slew limit (V per sample).
    pub u_min: f32,
    pub u_max: f32,
    pub slew_per_sample: f32,
}

impl Io {
    /// 16-bit ADC over 0..100 um, 12-bit DAC over 0..150 V (amplifier gain 45 V/V at 3.3 V).
    pub const fn on_chip() -> Self {
        Self {
            um_per_code: 100.0 / 65535.0,
            offset_um: 0.0,
            codes_per_volt: 4095.0 / 150.0,
            dac_max: 4095,
            u_min: 0.0,
            u_max: 150.0,
            slew_per_sample: 1.0,
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
    pub amp_um: f32,
    pub offset_um: f32,
    /// Phase in cycles, `[0, 1)`, and its increment per sample.
    pub phase: f32,
    pub dphase: f32,
    /// Angular frequency (rad/s).
    pub w: f32,
    /// Phasor `(cos, sin)` of the phase and its rotation per sample.
    pub cs: (f32, f32),
    pub rot: (f32, f32),
}

impl Wave {
    pub fn hold(y_um: f32) -> Self {
        Self {
            shape: None,
            amp_um: 0.0,
            offset_um: y_um,
            phase: 0.0,
            dphase: 0.0,
            w: 0.0,
            cs: (1.0, 0.0),
            rot: (1.0, 0.0),
        }
    }

    /// A periodic waveform starting at phase 0 (init time: uses libm).
    pub fn periodic(
        shape: Shape,
        amp_um: f32,
        freq_hz: f32,
        offset_um: f32,
        sample_hz: f32,
    ) -> Self {
        let dphase = freq_hz / sample_hz;
        let step = 2.0 * core::f32::consts::PI * dphase;
        Self {
            shape: Some(shape),
            amp_um,
            offset_um,
            phase: 0.0,
            dphase,
            w: 2.0 * core::f32::consts::PI * freq_hz,
            cs: (1.0, 0.0),
            rot: (libm::cosf(step), libm::sinf(step)),
        }
    }

    #[inline]
    pub fn next(&mut self) -> Setpoint<f32> {
        let Some(shape) = self.shape else {
            return Setpoint::hold(self.offset_um);
        };
        self.phase += self.dphase;
        if self.phase >= 1.0 {
            self.phase -= 1.0;
        }
        let (y, dy, ddy) = match shape {
            Shape::Sine => {
                let (c, s) = self.cs;
                let (rc, rs) = self.rot;
                let (c, s) = (c * rc - s * rs, s * rc + c * rs);
                // First-order renormalisation keeps |phasor| = 1 without a sqrt.
                let k = 1.5 - 0.5 * (c * c + s * s);
                self.cs = (c * k, s * k);
                let w = self.w;
                (s * k, w * c * k, -w * w * s * k)
            }
            Shape::Triangle => {
                let p = self.phase;
                let slope = 4.0 * self.w / (2.0 * core::f32::consts::PI);
                if p < 0.25 {
                    (4.0 * p, slope, 0.0)
                } else if p < 0.75 {
                    (2.0 - 4.0 * p, -slope, 0.0)
                } else {
                    (4.0 * p - 4.0, slope, 0.0)
                }
            }
            Shape::Square => (if self.phase < 0.5 { 1.0 } else { -1.0 }, 0.0, 0.0),
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
    pub sample_hz: f32,
    pub wave: Wave,
    pub ff: Feedforward<f32>,
    pub fb: Feedback<f32>,
    /// Last applied command (V).
    pub u_applied: f32,
    /// This period's signals, indexed by [`Signal::index`] (recorder input).
    pub signals: [f32; Signal::COUNT],
}

impl Loop {
    pub fn new(io: Io, sample_hz: f32, fb: Feedback<f32>) -> Self {
        Self {
            io,
            sample_hz,
            wave: Wave::hold(0.0),
            ff: Feedforward::Linear(LinearFf {
                um_per_volt: 0.16,
                offset_um: 0.0,
            }),
            fb,
            u_applied: 0.0,
            signals: [0.0; Signal::COUNT],
        }
    }

    /// One control period: ADC code in, DAC code out. No panic, bounded, NaN-safe.
    #[inline]
    pub fn step(&mut self, adc_code: u32) -> u16 {
        let io = self.io;
        let y_um = adc_code as f32 * io.um_per_code + io.offset_um;
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
            adc_code as f32,
            code as f32,
        ];
        code
    }

    /// Bumpless switch of the feedback law: the new law starts from the applied voltage.
    pub fn set_feedback(&mut self, mut fb: Feedback<f32>) {
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
pub fn dac_code(u: f32, codes_per_volt: f32, max: u16) -> u16 {
    (u * codes_per_volt + 0.5).clamp_to(0.0, max as f32) as u16
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
    pub rec: Recorder<f32, REC_CH, REC_N>,
    pub timing: Timing,
    /// Feedback laws selectable by `mode` (name, constructor).
    pub laws: fn(&str, f32) -> Option<Feedback<f32>>,
}

/// Names of the feedback laws `mode` accepts (the bench iterates over them); they are the
/// laws' own [`Feedback::name`]s.
#[cfg_attr(not(feature = "board-qemu"), allow(dead_code))]
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
pub const STAGE_POLE_PER_S: f32 = 2.0 * core::f32::consts::PI * 500.0;

/// The feedback laws of the core, by name, with gains for [`STAGE_POLE_PER_S`].
pub fn law_by_name(name: &str, sample_hz: f32) -> Option<Feedback<f32>> {
    let dt_s = 1.0 / sample_hz;
    let (ff, base) = match name.strip_prefix("ff+") {
        Some(b) => (true, b),
        None => (false, name),
    };
    let model = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).ok()?;
    let hgo = || {
        Hgo::new(
            ObserverModel::Cbw(model),
            STAGE_POLE_PER_S,
            2e-4,
            hgo::K1 as f32,
            hgo::K2 as f32,
            dt_s,
        )
        .ok()
    };
    let robust = |convergence| {
        Robust::new(
            hgo()?,
            RobustConfig {
                lambda1: 2_000.0,
                lambda2: 2_000.0,
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
            kp: 0.5,
            ki: 2_000.0,
            kd: 0.0,
            tf_s: 1e-4,
            kb: 1.0,
            feedforward: ff,
            dt_s,
        })
        .ok()
        .map(Feedback::Pid),
        "hgo-robust" => robust(Convergence::Exponential),
        "fts" => robust(Convergence::FiniteTime {
            alpha1: 0.8,
            alpha2: 0.8,
            sat_um_per_s: 1e4,
        }),
        "adrc" => Adrc::new(AdrcConfig {
            b: 0.16 * STAGE_POLE_PER_S * STAGE_POLE_PER_S,
            eps_s: 2e-4,
            omega_c: 2_000.0,
            feedforward: ff,
            dt_s,
        })
        .ok()
        .map(Feedback::Adrc),
        "nmpc" => Nmpc::new(
            hgo()?,
            NmpcConfig {
                decimation: 10,
                r: 1e-3,
                iterations: 2,
                u_min: 0.0,
                u_max: 150.0,
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
pub fn ff_by_name(name: &str, sample_hz: f32) -> Option<Feedforward<f32>> {
    let ims = |closure| {
        let model = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).ok()?;
        Ims::new(model, closure, 0.0, 150.0, 1.0 / sample_hz)
            .ok()
            .map(Feedforward::ImsCbw)
    };
    match name {
        "linear" => Some(Feedforward::Linear(LinearFf {
            um_per_volt: 0.16,
            offset_um: 0.0,
        })),
        "ims-cbw" => ims(ImsLoop::Solved),
        "ims-cbw-delayed" => ims(ImsLoop::Delayed),
        _ => None,
    }
}

impl Ctl {
    pub fn new(io: Io, sample_hz: f32) -> Self {
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
                set_param(lp, name, v)?;
                write!(out, "ok {name} {}", get_param(lp, name)?).ok();
            }
            Command::Mode(name) => {
                let fb = (self.laws)(name, lp.sample_hz).ok_or(Error::UnknownMode)?;
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
                lp.wave = Wave::hold(y);
                write!(out, "ok wave hold {y}").ok();
            }
            Command::Wave {
                shape,
                amp_um,
                freq_hz,
                offset_um,
            } => {
                if !(freq_hz < 0.5 * lp.sample_hz) {
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
                    } => (recorder::Trigger::Rising { channel, level }, pre),
                    TriggerCmd::Falling {
                        channel,
                        level,
                        pre,
                    } => (recorder::Trigger::Falling { channel, level }, pre),
                    TriggerCmd::Level {
                        channel,
                        level,
                        pre,
                    } => (recorder::Trigger::Level { channel, level }, pre),
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
    mut frame: impl FnMut(usize) -> Option<[f32; REC_CH]>,
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

fn get_param(lp: &Loop, name: &str) -> Result<f32, Error> {
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

fn set_param(lp: &mut Loop, name: &str, v: f32) -> Result<(), Error> {
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
            check(v > 0.0)?;
            io.slew_per_sample = v;
        }
        "um_per_code" => {
            check(v != 0.0)?;
            io.um_per_code = v;
        }
        "offset_um" => io.offset_um = v,
        "codes_per_volt" => {
            check(v > 0.0)?;
            io.codes_per_volt = v;
        }
        "ff_um_per_volt" => {
            check(v > 0.0)?;
            match &mut lp.ff {
                Feedforward::Linear(l) => l.um_per_volt = v,
                _ => return Err(Error::Busy),
            }
        }
        _ => return Err(Error::UnknownParam),
    }
    Ok(())
}
