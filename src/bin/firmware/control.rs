//! Board-independent part of the firmware: the per-sample step (ADC code in, DAC code out),
//! the recorder hook, the timing statistics and the command executor. The boards call
//! [`Ctl::step`] from their highest-priority task and [`Ctl::execute`] from a low-priority one.

use piezo_core::command::{self, Command, Error, RecCmd, Shape, TriggerCmd};
use piezo_core::drivers::{Ad4000Config, Ad5791Config};
use piezo_core::feedback::{
    hgo, Adrc, AdrcConfig, Convergence, Feedback, Hgo, Nmpc, NmpcConfig, ObserverModel, Pid,
    PidConfig, Robust, RobustConfig,
};
use piezo_core::feedforward::{Feedforward, Ims, ImsLoop, LinearFf, MultiFeedforward};
use piezo_core::hysteresis::Cbw;
use piezo_core::pipeline::{
    lissajous, raster, AxisConfig, Config, DacScale, Mode, OutputLimits, Sensor, Wave, TABLE_LEN,
};
use piezo_core::recorder::{self, Recorder, Signal};
use piezo_core::Real;

/// The number type of the control path: `f32` with an FPU (thumbv7em-none-eabihf), the
/// Q16.16 fixed point of [`piezo_core::fixed`] without one (thumbv7m-none-eabi, Cortex-M3).
/// (A host build, the `same_pipeline` test, takes the f32 variant.)
#[cfg(any(target_abi = "eabihf", not(target_os = "none")))]
pub type R = f32;
#[cfg(not(any(target_abi = "eabihf", not(target_os = "none"))))]
pub type R = piezo_core::fixed::Q16;

/// Axes the firmware drives: 2 with feature `xy` (an XY scanner: raster and Lissajous
/// scans), else 1.
pub const AXES: usize = if cfg!(feature = "xy") { 2 } else { 1 };

/// The pipeline of the control task: [`piezo_core::pipeline::FirmwarePipeline`] (the type
/// hal-sim runs), [`piezo_core::pipeline::FirmwarePipeline2`] with feature `xy`, with an
/// FPU; their Q16.16 twins without one.
#[cfg(all(
    any(target_abi = "eabihf", not(target_os = "none")),
    not(feature = "xy")
))]
pub type LoopPipeline = piezo_core::pipeline::FirmwarePipeline;
#[cfg(all(any(target_abi = "eabihf", not(target_os = "none")), feature = "xy"))]
pub type LoopPipeline = piezo_core::pipeline::FirmwarePipeline2;
#[cfg(not(any(target_abi = "eabihf", not(target_os = "none"))))]
pub type LoopPipeline = piezo_core::pipeline::Pipeline<R, AXES>;

/// A constant of the control path (folded at compile time).
#[inline(always)]
pub fn c(x: f64) -> R {
    R::from_f64(x)
}

/// Recorder size: 4 channels x 1024 frames of R (16 KiB).
pub const REC_CH: usize = 4;
pub const REC_N: usize = 1024;

/// Sample rate of the control loop (Hz). Q16.16 holds values below 32768 only, so the
/// fixed-point build runs at 16 384 Hz (sample period exactly 4 units of 2^-16 s).
#[cfg(any(target_abi = "eabihf", not(target_os = "none")))]
pub const SAMPLE_HZ: u32 = 100_000;
#[cfg(not(any(target_abi = "eabihf", not(target_os = "none"))))]
pub const SAMPLE_HZ: u32 = 16_384;

/// The number type is Q16.16 (no FPU): it holds values below 32768, so codes keep 15 bits.
const FIXED: bool = cfg!(not(any(target_abi = "eabihf", not(target_os = "none"))));

/// The converter pair: the on-chip 16-bit ADC and 12-bit DAC, or the external SPI pair
/// through the drivers of [`piezo_core::drivers`] (the ones hal-sim's mock chips run): an
/// AD4020 (20 bit, two's complement) and an AD5791 (20 bit, offset binary). Feature
/// `spi-converters` on the H743; always on the QEMU board, whose simulated stage sits
/// behind the same drivers.
pub const SPI_CONVERTERS: bool = cfg!(any(feature = "spi-converters", feature = "board-qemu"));

/// The position ADC's configuration (SPI converters).
#[cfg_attr(
    not(any(feature = "spi-converters", feature = "board-qemu")),
    allow(dead_code)
)]
pub const ADC_CONFIG: Ad4000Config = Ad4000Config::AD4020;
/// The DAC's configuration (SPI converters).
#[cfg_attr(
    not(any(feature = "spi-converters", feature = "board-qemu")),
    allow(dead_code)
)]
pub const DAC_CONFIG: Ad5791Config = Ad5791Config::DEFAULT;
/// The firmware's position ADC driver on a board's SPI device and CNV pin: the type
/// hal-sim runs on its mock chip (`hal_sim::sim::SimAdc`).
#[cfg_attr(
    not(any(feature = "spi-converters", feature = "board-qemu")),
    allow(dead_code)
)]
pub type PositionAdc<SPI, CNV> = piezo_core::drivers::FirmwareAdc<SPI, CNV>;
/// The firmware's DAC driver on a board's SPI device and LDAC pin (`hal_sim::sim::SimDac`).
#[cfg_attr(
    not(any(feature = "spi-converters", feature = "board-qemu")),
    allow(dead_code)
)]
pub type ActuatorDac<SPI, LDAC> = piezo_core::drivers::FirmwareDac<SPI, LDAC>;

/// Bits of a converter code.
pub const ADC_BITS: u32 = if SPI_CONVERTERS { 20 } else { 16 };
pub const DAC_BITS: u32 = if SPI_CONVERTERS { 20 } else { 12 };
/// Bits the pipeline sees: all of them in f32, 15 in Q16.16 (3 nm over 100 um at 15 bits).
const ADC_KEEP: u32 = if FIXED { 15 } else { ADC_BITS };
const DAC_KEEP: u32 = if FIXED && DAC_BITS > 15 { 15 } else { DAC_BITS };
/// ADC codes are shifted right by this before scaling, DAC codes left after it.
const ADC_SHIFT: u32 = ADC_BITS - ADC_KEEP;
const DAC_SHIFT: u32 = DAC_BITS - DAC_KEEP;

/// Largest DAC code the pipeline computes (before [`DAC_SHIFT`]).
pub const DAC_MAX: i32 = (1 << DAC_KEEP) - 1;
/// Largest code of the DAC itself.
#[cfg_attr(not(feature = "board-qemu"), allow(dead_code))]
pub const DAC_FULL: i32 = (1 << DAC_BITS) - 1;

/// Span and centre of the SPI ADC's full scale (um): -10..110 um, so the stage at rest
/// (0 um) and at full stroke stays inside the sensor window.
pub const SPI_SPAN_UM: f64 = 120.0;
pub const SPI_CENTER_UM: f64 = 50.0;

/// Safe state of every axis (V): where the output goes at start-up and on a fault.
pub const SAFE_VOLTS: f64 = 0.0;

/// The converters over the stage: ADC over 0..100 um (on-chip straight binary from 0 um;
/// SPI two's complement over [`SPI_SPAN_UM`], a clipped code is out of range), DAC over
/// 0..150 V (amplifier gain 45 V/V at 3.3 V on-chip), slew limit 20 V/ms, safe state 0 V.
/// Every axis alike.
pub fn converter_config(sample_hz: R) -> Config<R, AXES> {
    let sensor = if SPI_CONVERTERS {
        let half = 1i32 << (ADC_KEEP - 1);
        Sensor {
            um_per_code: c(SPI_SPAN_UM / (2 * half) as f64),
            offset_um: c(SPI_CENTER_UM),
            code_min: -half + 1,
            code_max: half - 2,
        }
    } else {
        let codes = (65_535 >> ADC_SHIFT) as f64;
        Sensor {
            um_per_code: c(100.0 / codes),
            offset_um: c(0.0),
            code_min: 0,
            code_max: codes as i32,
        }
    };
    Config {
        sample_hz,
        axes: [AxisConfig {
            sensor,
            open_loop: Params::default().linear(),
            limits: OutputLimits {
                volts_min: c(0.0),
                volts_max: c(150.0),
                slew_volts_per_s: c(20_000.0),
            },
            dac: DacScale {
                volts_per_code: c(150.0 / DAC_MAX as f64),
                volts_at_zero: c(0.0),
                code_min: 0,
                code_max: DAC_MAX,
            },
            safe_volts: c(SAFE_VOLTS),
        }; AXES],
    }
}

/// The axes: the core pipeline (sensor scaling, reference, feedforward, feedback, limits,
/// DAC code) plus the names of what is selected (the same law and compensator on every
/// axis).
pub struct Loop {
    pub p: LoopPipeline,
    pub sample_hz: R,
    /// Selected law (`open-loop`, `feedforward` or a law of [`LAWS`]) and feedforward.
    pub law: &'static str,
    pub ff: &'static str,
    /// Model, open-loop scaling and gains the law and compensator are built from.
    pub params: Params,
}

impl Loop {
    /// Open loop, holding 0 um, in the safe state's voltage.
    pub fn new(sample_hz: R) -> Self {
        let params = Params::default();
        let ff = MultiFeedforward::PerAxis(core::array::from_fn(|_| {
            Feedforward::Linear(params.linear())
        }));
        let p = LoopPipeline::new(
            converter_config(sample_hz),
            [Wave::Hold { y_um: c(0.0) }; AXES],
            ff,
            core::array::from_fn(|_| Feedback::OpenLoop),
        )
        .expect("the converter configuration is valid");
        Self {
            p,
            sample_hz,
            law: "open-loop",
            ff: "linear",
            params,
        }
    }

    /// One control period: ADC codes in, DAC codes out (the converters' own codes, 0 ..=
    /// [`DAC_FULL`]), one per axis. No panic, bounded, NaN-safe.
    #[inline(always)]
    pub fn step(&mut self, adc_code: [i32; AXES]) -> [i32; AXES] {
        let codes = self.p.step(adc_code.map(|c| c >> ADC_SHIFT));
        // max/min, not clamp: clamp asserts min <= max (a panic path in the handler).
        #[allow(clippy::manual_clamp)]
        codes.map(|code| code.max(0).min(DAC_MAX) << DAC_SHIFT)
    }

    /// The DAC write of `axis` failed this period; the converter still holds `held_code`
    /// (its own code): the pipeline takes that as applied and latches the safe state.
    #[inline(always)]
    #[cfg_attr(
        not(any(feature = "spi-converters", feature = "board-qemu")),
        allow(dead_code)
    )]
    pub fn dac_write_failed(&mut self, axis: usize, held_code: i32) {
        self.p.dac_write_failed(axis, held_code >> DAC_SHIFT);
    }

    /// This period's signals, indexed by [`Signal::index`] (recorder input; axis `a` at
    /// `a * Signal::PER_AXIS`, axes the board lacks read 0). Codes as the pipeline sees
    /// them (Q16.16: shifted to 15 bits).
    #[inline(always)]
    pub fn signals(&self, adc_code: [i32; AXES], dac_code: [i32; AXES]) -> [R; Signal::COUNT] {
        let st = self.p.state();
        let mut s = [R::ZERO; Signal::COUNT];
        for (a, chunk) in s.chunks_exact_mut(Signal::PER_AXIS).enumerate().take(AXES) {
            let (Some(sp), Some(&y), Some(&ff), Some(&u), Some(&adc), Some(&dac)) = (
                st.trace.setpoint.get(a),
                st.trace.y_um.get(a),
                st.trace.u_ff.get(a),
                st.u_applied.get(a),
                adc_code.get(a),
                dac_code.get(a),
            ) else {
                continue;
            };
            let r = sp.y_um;
            let v = [
                r,
                y,
                r - y,
                ff,
                u,
                R::from_i32(adc >> ADC_SHIFT),
                R::from_i32(dac >> DAC_SHIFT),
            ];
            for (d, v) in chunk.iter_mut().zip(v) {
                *d = v;
            }
        }
        s
    }

    /// Selects `open-loop`, `feedforward` or a feedback law (bumpless).
    pub fn set_law(&mut self, name: &str) -> Result<(), Error> {
        match name {
            "open-loop" => self.p.set_mode(Mode::OpenLoop),
            "feedforward" => self.p.set_mode(Mode::Feedforward),
            _ => {
                // A known law whose configuration this number type cannot hold (ADRC's
                // gain in Q16.16) is "unsupported", not "unknown".
                let fb = law_with(name, &self.params, self.sample_hz).ok_or(
                    if LAWS.contains(&name) {
                        Error::Unsupported
                    } else {
                        Error::UnknownMode
                    },
                )?;
                self.p.set_feedback(0, fb).map_err(|_| Error::OutOfRange)?;
                for axis in (0..AXES).skip(1) {
                    let fb =
                        law_with(name, &self.params, self.sample_hz).ok_or(Error::UnknownMode)?;
                    self.p
                        .set_feedback(axis, fb)
                        .map_err(|_| Error::OutOfRange)?;
                }
                self.p.set_mode(Mode::ClosedLoop);
            }
        }
        self.law = LAWS
            .iter()
            .chain(["feedforward"].iter())
            .find(|l| **l == name)
            .copied()
            .unwrap_or("?");
        Ok(())
    }

    /// Selects the feedforward compensator (restarts at the current setpoint). Out of line:
    /// its compensators stay out of the frame that [`Loop::install`] holds around
    /// [`Loop::set_law`] (the serial task's stack bound).
    #[inline(never)]
    pub fn set_ff(&mut self, name: &str) -> Result<(), Error> {
        let ff = ff_with(name, &self.params, self.sample_hz).ok_or(Error::UnknownMode)?;
        self.p
            .set_feedforward(MultiFeedforward::PerAxis(core::array::from_fn(|_| {
                ff.clone()
            })));
        self.ff = FFS.iter().find(|f| **f == name).copied().unwrap_or("?");
        Ok(())
    }

    /// Sets parameter `name` of [`Params`] to `v`: validated through the core's
    /// constructors, then the open-loop scaling, the compensator and the selected law are
    /// rebuilt from it and installed bumplessly on every axis. A refused value
    /// ([`Error::OutOfRange`]) changes nothing.
    fn set_params(&mut self, name: &str, v: R) -> Result<(), Error> {
        let mut p = self.params;
        *p.slot(name).ok_or(Error::UnknownParam)? = v;
        self.install(p)
    }

    /// Sets the CBW model `[d, alpha, beta, gamma]` at once (like [`Loop::set_params`]).
    fn set_cbw(&mut self, [d, alpha, beta, gamma]: [R; 4]) -> Result<(), Error> {
        let p = Params {
            cbw_d: d,
            cbw_alpha: alpha,
            cbw_beta: beta,
            cbw_gamma: gamma,
            ..self.params
        };
        self.install(p)
    }

    /// Validates `p` and, when valid, rebuilds and installs everything from it.
    fn install(&mut self, p: Params) -> Result<(), Error> {
        p.validate(self.sample_hz)?;
        // The selected law must build too (validate() covers its parts; checked before
        // anything changes).
        if !matches!(self.law, "open-loop" | "feedforward") && !builds(self.law, &p, self.sample_hz)
        {
            return Err(Error::OutOfRange);
        }
        let old = self.params;
        self.params = p;
        let r = self.reinstall();
        if r.is_err() {
            // Unreachable after validate(); keep the old model running rather than a mix.
            self.params = old;
            let _ = self.reinstall();
        }
        r
    }

    /// Rebuilds the open-loop scaling, the compensator and the selected law from
    /// [`Loop::params`] (bumpless: the pipeline restarts them from the applied voltage).
    #[inline(never)]
    fn reinstall(&mut self) -> Result<(), Error> {
        self.set_open_loop()?;
        self.set_ff(self.ff)?;
        self.set_law(self.law)
    }

    /// The open-loop scaling of [`Loop::params`] on every axis (out of line, like
    /// [`Loop::set_ff`]).
    #[inline(never)]
    fn set_open_loop(&mut self) -> Result<(), Error> {
        for axis in 0..AXES {
            self.p
                .set_open_loop(axis, self.params.linear())
                .map_err(|_| Error::OutOfRange)?;
        }
        Ok(())
    }

    /// Changes the limits of every axis in place (mode, wave, law and compensator keep
    /// running; no pipeline is rebuilt on the serial task's stack). All axes or none.
    fn set_limits(&mut self, f: impl Fn(&mut OutputLimits<R>)) -> Result<(), Error> {
        let cfg = self.p.config();
        let new = cfg.axes.map(|a| {
            let mut l = a.limits;
            f(&mut l);
            l
        });
        // Validate all first, so a rejected change leaves every axis as it was.
        for (a, l) in cfg.axes.iter().zip(&new) {
            piezo_core::pipeline::Output::new(l, &a.dac, cfg.sample_hz)
                .map_err(|_| Error::OutOfRange)?;
        }
        for (axis, l) in new.into_iter().enumerate() {
            // The safe voltage is SAFE_VOLTS, moved into the range while the range excludes it.
            let safe = c(SAFE_VOLTS).clamp_to(l.volts_min, l.volts_max);
            self.p
                .set_limits(axis, l, safe)
                .map_err(|_| Error::OutOfRange)?;
        }
        Ok(())
    }
}

/// Min/max/last of a cycle count, and how many samples there were.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
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
#[derive(Clone, Copy, Debug)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
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

/// Everything the control task owns: the loop, the recorder and the timing; and the point
/// table the executor fills (`table add`) and hands to the reference on `wave table`
/// (the control step never reads it).
pub struct Ctl {
    pub lp: Loop,
    pub rec: Recorder<R, REC_CH, REC_N>,
    pub timing: Timing,
    pub table: PointTable,
    /// The axis the 1-axis waves go to (`axis <n>`).
    pub axis: usize,
}

/// Points of `wave table` as `table add` appends them (um).
pub struct PointTable {
    points: [R; TABLE_LEN],
    len: usize,
}

impl PointTable {
    pub const fn new() -> Self {
        Self {
            points: [R::ZERO; TABLE_LEN],
            len: 0,
        }
    }

    /// The points so far.
    pub fn points(&self) -> &[R] {
        self.points.get(..self.len).unwrap_or(&[])
    }

    /// Appends all of `values` or, if they do not fit, none.
    fn add(&mut self, values: &[f32]) -> Result<(), Error> {
        let free = self.points.get_mut(self.len..).unwrap_or(&mut []);
        if values.len() > free.len() {
            return Err(Error::OutOfRange);
        }
        for (d, v) in free.iter_mut().zip(values) {
            *d = c(*v as f64);
        }
        self.len += values.len();
        Ok(())
    }
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

/// What `set` changes besides the limits: the hysteresis model (the one `piezo fit
/// --model cbw` identifies), the open-loop scaling and the gains (config, apart from the
/// laws' state). [`Params::default`] is the simulated stage: CBW set 1 of the 000 backup
/// slide, first-order linear part with pole [`STAGE_POLE_PER_S`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// CBW (n = 1) of the IMS feedforward and the HGO's observer model: `d`, `alpha` (um/V),
    /// `beta`, `gamma` (1/V).
    pub cbw_d: R,
    pub cbw_alpha: R,
    pub cbw_beta: R,
    pub cbw_gamma: R,
    /// Open-loop scaling (open-loop mode and the `linear` compensator).
    pub um_per_volt: R,
    pub offset_um: R,
    /// HGO `epsilon` (s), 000 eq. (8).
    pub hgo_eps_s: R,
    /// Robust law gains (1/s).
    pub lambda1: R,
    pub lambda2: R,
    /// PID gains: V/um and V/(um s).
    pub pid_kp: R,
    pub pid_ki: R,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            cbw_d: c(0.16),
            cbw_alpha: c(0.07),
            cbw_beta: c(0.02),
            cbw_gamma: c(0.01),
            um_per_volt: c(0.16),
            offset_um: c(0.0),
            hgo_eps_s: c(2e-4),
            lambda1: c(2_000.0),
            lambda2: c(2_000.0),
            pid_kp: c(0.5),
            pid_ki: c(2_000.0),
        }
    }
}

impl Params {
    pub fn model(&self) -> Option<Cbw<R>> {
        Cbw::with_n1(self.cbw_d, self.cbw_alpha, self.cbw_beta, self.cbw_gamma).ok()
    }

    pub fn linear(&self) -> LinearFf<R> {
        LinearFf {
            um_per_volt: self.um_per_volt,
            offset_um: self.offset_um,
        }
    }

    /// The slot of a settable parameter, by its `get`/`set` name.
    fn slot(&mut self, name: &str) -> Option<&mut R> {
        Some(match name {
            "cbw_d" => &mut self.cbw_d,
            "cbw_alpha" => &mut self.cbw_alpha,
            "cbw_beta" => &mut self.cbw_beta,
            "cbw_gamma" => &mut self.cbw_gamma,
            "um_per_volt" => &mut self.um_per_volt,
            "offset_um" => &mut self.offset_um,
            "hgo_eps" => &mut self.hgo_eps_s,
            "lambda1" => &mut self.lambda1,
            "lambda2" => &mut self.lambda2,
            "pid_kp" => &mut self.pid_kp,
            "pid_ki" => &mut self.pid_ki,
            _ => return None,
        })
    }

    /// Every consumer accepts these values: the core's constructors decide (CBW bounds,
    /// IMS invertibility, HGO gains, robust and PID gains, open-loop scaling), so any law
    /// and compensator can be selected afterwards.
    #[inline(never)]
    pub fn validate(&self, sample_hz: R) -> Result<(), Error> {
        let ok = ff_with("ims-cbw", self, sample_hz).is_some()
            && law_with("hgo-robust", self, sample_hz).is_some()
            && law_with("pid", self, sample_hz).is_some()
            && self.linear().is_valid();
        if ok {
            Ok(())
        } else {
            Err(Error::OutOfRange)
        }
    }
}

/// `law` builds from `p` (out of line: the law is not held in the caller's frame).
#[inline(never)]
fn builds(law: &str, p: &Params, sample_hz: R) -> bool {
    law_with(law, p, sample_hz).is_some()
}

/// The feedback laws of the core, by name, with the default [`Params`] (host tests).
#[allow(dead_code)]
pub fn law_by_name(name: &str, sample_hz: R) -> Option<Feedback<R>> {
    law_with(name, &Params::default(), sample_hz)
}

/// The feedback laws of the core, by name, with the model and gains of `p`.
pub fn law_with(name: &str, p: &Params, sample_hz: R) -> Option<Feedback<R>> {
    let dt_s = c(1.0) / sample_hz;
    let (ff, base) = match name.strip_prefix("ff+") {
        Some(b) => (true, b),
        None => (false, name),
    };
    let model = p.model()?;
    let hgo = || {
        Hgo::new(
            ObserverModel::Cbw(model),
            c(STAGE_POLE_PER_S),
            p.hgo_eps_s,
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
                lambda1: p.lambda1,
                lambda2: p.lambda2,
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
            kp: p.pid_kp,
            ki: p.pid_ki,
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
            // Plain ADRC: the ESO estimates the whole linear part.
            a1: c(0.0),
            a2: c(0.0),
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

/// The feedforward compensators, by name, with the default [`Params`] (host tests).
#[allow(dead_code)]
pub fn ff_by_name(name: &str, sample_hz: R) -> Option<Feedforward<R>> {
    ff_with(name, &Params::default(), sample_hz)
}

/// The feedforward compensators, by name: linear scaling, or IMS around the CBW model of
/// `p` (0..150 V).
pub fn ff_with(name: &str, p: &Params, sample_hz: R) -> Option<Feedforward<R>> {
    let ims = |closure| {
        let model = p.model()?;
        Ims::new(model, closure, c(0.0), c(150.0), c(1.0) / sample_hz)
            .ok()
            .map(Feedforward::ImsCbw)
    };
    match name {
        "linear" => Some(Feedforward::Linear(p.linear())),
        "ims-cbw" => ims(ImsLoop::Solved),
        "ims-cbw-delayed" => ims(ImsLoop::Delayed),
        _ => None,
    }
}

impl Ctl {
    pub fn new(sample_hz: R) -> Self {
        Self {
            lp: Loop::new(sample_hz),
            rec: Recorder::new(),
            timing: Timing::new(),
            table: PointTable::new(),
            axis: 0,
        }
    }

    /// Feeds the recorder (only while it captures: the signals cost a few instructions).
    #[inline(always)]
    pub fn record(&mut self, adc_code: [i32; AXES], dac_code: [i32; AXES]) {
        if matches!(
            self.rec.state(),
            recorder::State::Armed | recorder::State::Triggered
        ) {
            let s = self.lp.signals(adc_code, dac_code);
            self.rec.push(&s);
        }
    }

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

    fn try_execute<const N: usize>(
        &mut self,
        cmd: Command<'_>,
        out: &mut command::Reply<N>,
    ) -> Result<(), Error> {
        let lp = &mut self.lp;
        let axis = self.axis;
        match cmd {
            Command::Empty => {}
            Command::Ping => out.push_str("ok pong"),
            Command::Help => {
                out.push_str(
                    "ok ping help get set cbw mode ff wave axis table stats rec fault bench; params:",
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
                out.push_str("ok ");
                out.push_str(name);
                out.push_str(" ");
                push_real(out, get_param(lp, name)?);
            }
            Command::Cbw(v) => {
                let v = v.map(rc);
                lp.set_cbw(v)?;
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
                out.push_str("ok mode ");
                out.push_str(lp.law);
            }
            Command::Feedforward(name) => {
                lp.set_ff(name)?;
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
                out.push_str("ok wave off");
            }
            Command::WaveHold(y) => {
                lp.p.set_wave(axis, Wave::Hold { y_um: c(y as f64) })
                    .map_err(|_| Error::OutOfRange)?;
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
                out.push_str("ok wave steps ");
                push_real(out, lo);
                out.push_str(" ");
                push_real(out, hi);
                out.push_str(" ");
                out.push_u32(levels as u32);
                out.push_str(" ");
                push_real(out, f);
            }
            Command::TableClear => {
                self.table.len = 0;
                out.push_str("ok table 0");
            }
            Command::TableAdd(points) => {
                self.table.add(points.as_slice())?;
                out.push_str("ok table ");
                out.push_usize(self.table.len);
            }
            Command::TableLen => {
                out.push_str("ok table ");
                out.push_usize(self.table.len);
            }
            Command::WaveTable(freq_hz) => {
                let points = self.table.points();
                if points.len() < 2 {
                    return Err(Error::Busy);
                }
                let f = c(freq_hz as f64);
                let wave = Wave::table(points, f).map_err(|_| Error::OutOfRange)?;
                lp.p.set_wave(axis, wave).map_err(|_| Error::OutOfRange)?;
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
                    self.axis = n;
                }
                out.push_str("ok axis ");
                out.push_usize(self.axis);
                out.push_str(" of ");
                out.push_usize(AXES);
            }
            Command::Stats => {
                let t = &self.timing;
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
            }
            Command::StatsReset => {
                self.timing = Timing::new();
                out.push_str("ok");
            }
            Command::Rec(r) => self.rec_command(r, out)?,
            Command::Fault => push_fault(out, &lp.p),
            Command::FaultClear => {
                lp.p.clear_fault();
                push_fault(out, &lp.p);
            }
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
            recorder::ConfigError::BadDivider => Error::OutOfRange,
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

/// A command's number as a control-path value.
fn rc(v: f32) -> R {
    c(v as f64)
}

/// Starts a 2-axis scan on axes 0 and 1 in the same sample (the caller holds the loop);
/// a 1-axis board answers [`Error::Unsupported`]. Both waves are checked before either runs.
fn set_scan(lp: &mut Loop, waves: [Wave<R>; 2]) -> Result<(), Error> {
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
    use piezo_core::pipeline::Fault;
    let st = p.state();
    out.push_str("ok fault ");
    out.push_str(match st.fault {
        None => "none",
        Some(Fault::SensorRange { .. }) => "sensor-range",
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

/// Parameter names of `get`/`set` (`sample_hz` and the converter scalings are read-only;
/// from `cbw_d` on they are the [`Params`]).
pub const PARAMS: [&str; 17] = [
    "u_min",
    "u_max",
    "slew",
    "um_per_code",
    "volts_per_code",
    "sample_hz",
    "cbw_d",
    "cbw_alpha",
    "cbw_beta",
    "cbw_gamma",
    "um_per_volt",
    "offset_um",
    "hgo_eps",
    "lambda1",
    "lambda2",
    "pid_kp",
    "pid_ki",
];

/// Capacity of a command's reply line (`help` lists every parameter).
pub const REPLY_LEN: usize = 256;

fn get_param(lp: &Loop, name: &str) -> Result<R, Error> {
    let cfg = lp.p.config();
    let a = &cfg.axes[0];
    Ok(match name {
        "u_min" => a.limits.volts_min,
        "u_max" => a.limits.volts_max,
        "slew" => a.limits.slew_volts_per_s,
        "um_per_code" => a.sensor.um_per_code,
        "volts_per_code" => a.dac.volts_per_code,
        "sample_hz" => cfg.sample_hz,
        _ => {
            let mut p = lp.params;
            *p.slot(name).ok_or(Error::UnknownParam)?
        }
    })
}

fn set_param(lp: &mut Loop, name: &str, v: R) -> Result<(), Error> {
    let (lo, hi) = {
        let l = &lp.p.config().axes[0].limits;
        (l.volts_min, l.volts_max)
    };
    let check = |ok: bool| if ok { Ok(()) } else { Err(Error::OutOfRange) };
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
        "um_per_code" | "volts_per_code" | "sample_hz" => Err(Error::Busy),
        _ => lp.set_params(name, v),
    }
}
