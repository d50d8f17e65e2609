//! The per-sample control pipeline: ADC code(s) in, DAC code(s) out, one call per sample.
//!
//! It reads like the block diagram:
//! scale + range check ([`Sensor`]) -> reference ([`WaveGen`]) -> feedforward
//! ([`MultiFeedforward`]) -> feedback ([`Feedback`], fed the previously applied voltage) ->
//! range + slew limits ([`Output`]) -> DAC code.
//!
//! Generic over the number type and the axis count `N` (1..=3). Configuration
//! ([`Config`], validated once) is kept apart from the state ([`State`]); allocation-free,
//! panic-free and bounded per sample.
//!
//! Faults (an ADC code outside the sensor window, a non-finite command) latch the safe
//! state: the output slews to `safe_volts` and stays there until [`Pipeline::clear_fault`].

mod adopt;
pub mod excitation;
mod fused;
pub mod output;
pub mod reference;
pub mod sensor;

pub use adopt::Parts;
pub use output::{DacScale, Limited, Output, OutputLimits};
pub use reference::{lissajous, raster, Wave, WaveGen, TABLE_LEN};
pub use sensor::{Sensor, StuckCode};

use crate::feedback::Feedback;
use crate::feedforward::{LinearFf, MultiFeedforward};
use crate::real::Real;
use crate::signals::{LoopSignals, Setpoint};

/// The pipeline the firmware runs: one axis in `f32`.
pub type FirmwarePipeline = Pipeline<f32, 1>;
/// Configuration of [`FirmwarePipeline`].
pub type FirmwareConfig = Config<f32, 1>;
/// The 2-axis (coupled XY scanner) variant of the firmware pipeline.
pub type FirmwarePipeline2 = Pipeline<f32, 2>;

/// A configuration value is unusable; the text names the field and the condition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConfigError {
    /// The axis the field belongs to, if any.
    pub axis: Option<usize>,
    pub what: &'static str,
}

impl ConfigError {
    pub const fn new(what: &'static str) -> Self {
        Self { axis: None, what }
    }
    fn on_axis(self, axis: usize) -> Self {
        Self {
            axis: Some(axis),
            ..self
        }
    }
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.axis {
            Some(a) => write!(f, "pipeline config, axis {a}: {}", self.what),
            None => write!(f, "pipeline config: {}", self.what),
        }
    }
}

impl core::error::Error for ConfigError {}

/// Configuration of one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisConfig<T> {
    pub sensor: Sensor<T>,
    /// The open-loop mode's linear scaling (no hysteresis model).
    pub open_loop: LinearFf<T>,
    pub limits: OutputLimits<T>,
    pub dac: DacScale<T>,
    /// Where the output goes at start-up and on a fault (V, inside the limits).
    pub safe_volts: T,
}

/// Pipeline configuration (validated by [`Pipeline::new`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config<T, const N: usize> {
    /// Loop rate (Hz).
    pub sample_hz: T,
    pub axes: [AxisConfig<T>; N],
}

/// Which path computes the command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Linear scaling of the reference only.
    #[default]
    OpenLoop,
    /// The feedforward compensator alone.
    Feedforward,
    /// Feedforward plus the feedback law.
    ClosedLoop,
}

/// Why the pipeline went to its safe state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// An ADC code outside the sensor's valid window (or a conversion whose frame or status
    /// the driver refused).
    SensorRange { axis: usize },
    /// The ADC code did not change for too many samples ([`StuckCode`]).
    SensorStuck { axis: usize },
    /// The controllers produced NaN or infinity.
    NonFiniteCommand { axis: usize },
    /// The DAC did not take the last code: it still holds an older one.
    DacWrite { axis: usize },
}

/// Event counters (saturating).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    pub samples: u32,
    /// Samples with an ADC code outside the sensor window or a stuck code (any axis).
    pub sensor_faults: u32,
    /// Samples with a non-finite command (any axis).
    pub nonfinite_commands: u32,
    /// Samples where the range or slew limit changed a command (any axis).
    pub saturated_samples: u32,
    /// Failed DAC writes reported by the driver.
    pub dac_faults: u32,
}

/// Signals of the last sample, for recording and telemetry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trace<T, const N: usize> {
    pub setpoint: [Setpoint<T>; N],
    /// Measured position (um); the previous valid value on a sensor fault.
    pub y_um: [T; N],
    pub u_ff: [T; N],
    /// Command before the limits (V).
    pub u_cmd: [T; N],
}

/// Everything that changes from sample to sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct State<T, const N: usize> {
    pub mode: Mode,
    pub fault: Option<Fault>,
    /// Applied voltage (V): what the DAC code stands for.
    pub u_applied: [T; N],
    pub code: [i32; N],
    pub counters: Counters,
    pub trace: Trace<T, N>,
}

fn check_open_loop<T: Real>(ol: &LinearFf<T>) -> Result<(), ConfigError> {
    if ol.is_valid() {
        Ok(())
    } else {
        Err(ConfigError::new(
            "open_loop: um_per_volt must be finite and non-zero, offset_um finite",
        ))
    }
}

fn check_safe_volts<T: Real>(limits: &OutputLimits<T>, safe_volts: T) -> Result<(), ConfigError> {
    if safe_volts >= limits.volts_min && safe_volts <= limits.volts_max {
        Ok(())
    } else {
        Err(ConfigError::new("safe_volts must lie within the limits"))
    }
}

/// The per-sample pipeline of an `N`-axis stage.
#[derive(Debug, Clone)]
pub struct Pipeline<T: Real, const N: usize> {
    config: Config<T, N>,
    output: [Output<T>; N],
    reference: [WaveGen<T>; N],
    feedforward: MultiFeedforward<T, N>,
    feedback: [Feedback<T>; N],
    state: State<T, N>,
    /// [`Pipeline::step`] takes the fused path of `fused.rs` (decided when the mode, the
    /// feedforward or the feedback changes, and once the law primed its observer; a
    /// latched fault clears it, so the step tests one flag).
    fused: bool,
    /// What the generic step settles first (one test per sample while nothing is due).
    pending: Pending,
}

/// Work the generic step does before its sample ([`Pipeline::step_generic`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pending {
    None,
    /// A configuration handed over by [`Pipeline::adopt`] waits for its bumpless restart
    /// (in the control task, not under the command's lock).
    Restart,
    /// The configuration runs the fused step, but the law has not primed its observer
    /// yet: the generic step primes it, the next one takes the fused path once the law is
    /// primed and no fault latched (so the fused step never tests for an unprimed law). The
    /// configuration was decided already: this costs the control interrupt two tests.
    Prime,
    /// The law was handed out for changes ([`Pipeline::feedback_mut`]): the generic step
    /// decides the fused path again, the configuration too.
    Decide,
}

impl<T: Real, const N: usize> Pipeline<T, N> {
    /// Validates `config` and `reference`; starts in [`Mode::OpenLoop`] at `safe_volts`.
    pub fn new(
        config: Config<T, N>,
        reference: [Wave<T>; N],
        feedforward: MultiFeedforward<T, N>,
        feedback: [Feedback<T>; N],
    ) -> Result<Self, ConfigError> {
        if N == 0 || N > 3 {
            return Err(ConfigError::new("axes: 1 to 3 axes are supported"));
        }
        let fs = config.sample_hz;
        if !(fs.is_finite() && fs > T::ZERO) {
            return Err(ConfigError::new("sample_hz must be finite and > 0"));
        }
        let first = config
            .axes
            .first()
            .ok_or(ConfigError::new("axes: 1 to 3 axes are supported"))?;
        let mut output = [Output::new(&first.limits, &first.dac, fs).map_err(|e| e.on_axis(0))?; N];
        let mut gens = [WaveGen::new(Wave::Hold { y_um: T::ZERO }, fs)?; N];
        for (i, a) in config.axes.iter().enumerate() {
            a.sensor.validate().map_err(|e| e.on_axis(i))?;
            check_open_loop(&a.open_loop).map_err(|e| e.on_axis(i))?;
            check_safe_volts(&a.limits, a.safe_volts).map_err(|e| e.on_axis(i))?;
            output[i] = Output::new(&a.limits, &a.dac, fs).map_err(|e| e.on_axis(i))?;
            gens[i] = WaveGen::new(reference[i], fs).map_err(|e| e.on_axis(i))?;
        }
        let reference = gens;
        let mut p = Self {
            config,
            output,
            reference,
            feedforward,
            feedback,
            state: State {
                mode: Mode::OpenLoop,
                fault: None,
                u_applied: [T::ZERO; N],
                code: [0; N],
                counters: Counters::default(),
                trace: Trace {
                    setpoint: [Setpoint::default(); N],
                    y_um: [T::ZERO; N],
                    u_ff: [T::ZERO; N],
                    u_cmd: [T::ZERO; N],
                },
            },
            fused: false,
            pending: Pending::None,
        };
        for i in 0..N {
            let (o, a) = (&p.output[i], &p.config.axes[i]);
            let code = o.code_in_range(a.safe_volts);
            p.state.code[i] = code;
            p.state.u_applied[i] = o.dac.volts(code);
            p.state.trace.u_cmd[i] = a.safe_volts;
            p.state.trace.u_ff[i] = a.safe_volts;
            p.state.trace.setpoint[i] = p.reference[i].current();
        }
        p.decide_fused();
        Ok(p)
    }

    pub fn config(&self) -> &Config<T, N> {
        &self.config
    }
    pub fn state(&self) -> &State<T, N> {
        &self.state
    }
    pub fn output(&self, axis: usize) -> Option<&Output<T>> {
        self.output.get(axis)
    }
    pub fn feedforward(&self) -> &MultiFeedforward<T, N> {
        &self.feedforward
    }
    pub fn feedback(&self) -> &[Feedback<T>; N] {
        &self.feedback
    }
    /// The feedback law of `axis`, to hand a deferred NMPC its plan
    /// ([`crate::feedback::Nmpc::deliver`]; replacing a law is [`Pipeline::set_feedback`]).
    pub fn feedback_mut(&mut self, axis: usize) -> Option<&mut Feedback<T>> {
        // The caller may reset or change the law: the generic step decides again.
        if self.fused || self.pending == Pending::Prime {
            self.fused = false;
            self.pending = Pending::Decide;
        }
        self.feedback.get_mut(axis)
    }
    /// The reference generator of `axis`.
    pub fn reference(&self, axis: usize) -> Option<&WaveGen<T>> {
        self.reference.get(axis)
    }
    /// The configuration runs the fused step (see [`Pipeline::step`]): it allows it and no
    /// fault is latched (a law still to prime its observer runs the generic step until
    /// it did).
    pub fn is_fused(&self) -> bool {
        self.fused
            || self.pending == Pending::Prime
            || (self.pending == Pending::Decide && self.state.fault.is_none() && self.fusable())
    }

    /// Decides the fused path: no restart due, no fault latched, a configuration the fused
    /// step covers and a primed law (an unprimed one: [`Pending::Prime`]). Every change of
    /// one of them decides again (a latched fault only clears the flag).
    fn law_fresh(&self) -> bool {
        matches!(self.feedback.first(), Some(Feedback::Robust(l)) if l.is_fresh())
    }

    fn decide_fused(&mut self) {
        if self.pending == Pending::Restart {
            self.fused = false;
            return;
        }
        let due = self.state.fault.is_none() && self.fusable();
        let fresh = self.law_fresh();
        self.fused = due && !fresh;
        self.pending = if due && fresh {
            Pending::Prime
        } else {
            Pending::None
        };
    }
    /// The DAC codes of the last sample (at start-up: the codes of `safe_volts`).
    pub fn codes(&self) -> [i32; N] {
        self.state.code
    }

    /// Replaces the reference wave of `axis` (its phase restarts).
    pub fn set_wave(&mut self, axis: usize, wave: Wave<T>) -> Result<(), ConfigError> {
        let g = WaveGen::new(wave, self.config.sample_hz).map_err(|e| e.on_axis(axis))?;
        let slot = self
            .reference
            .get_mut(axis)
            .ok_or(ConfigError::new("axis index out of range"))?;
        *slot = g;
        Ok(())
    }

    /// Replaces the feedback law of `axis`; it restarts bumplessly from the applied voltage.
    pub fn set_feedback(&mut self, axis: usize, feedback: Feedback<T>) -> Result<(), ConfigError> {
        let slot = self
            .feedback
            .get_mut(axis)
            .ok_or(ConfigError::new("axis index out of range"))?;
        *slot = feedback;
        self.restart();
        Ok(())
    }

    /// Replaces the feedforward compensator; it restarts at the current setpoints.
    pub fn set_feedforward(&mut self, feedforward: MultiFeedforward<T, N>) {
        self.feedforward = feedforward;
        self.restart();
    }

    /// Replaces the open-loop scaling of `axis` (validated like [`Pipeline::new`]); the
    /// compensator and the law restart bumplessly.
    pub fn set_open_loop(
        &mut self,
        axis: usize,
        open_loop: LinearFf<T>,
    ) -> Result<(), ConfigError> {
        let a = self
            .config
            .axes
            .get_mut(axis)
            .ok_or(ConfigError::new("axis index out of range"))?;
        check_open_loop(&open_loop).map_err(|e| e.on_axis(axis))?;
        a.open_loop = open_loop;
        self.restart();
        Ok(())
    }

    /// Switches mode without a bump: the compensator and the feedback law restart from
    /// the applied voltage, and the slew limit bounds whatever difference remains.
    pub fn set_mode(&mut self, mode: Mode) {
        self.state.mode = mode;
        self.restart();
    }

    /// Replaces the output limits and the safe voltage of `axis` in place (validated like
    /// [`Pipeline::new`]): mode, wave, compensator and law keep running. The caller passes
    /// the safe voltage so that narrowing and widening the range again restores it. A range
    /// that excludes the present code moves the output to its nearest code at the next
    /// sample (the range wins over the slew limit); within it the new slew limit holds.
    pub fn set_limits(
        &mut self,
        axis: usize,
        limits: OutputLimits<T>,
        safe_volts: T,
    ) -> Result<(), ConfigError> {
        let fs = self.config.sample_hz;
        let (Some(a), Some(o)) = (self.config.axes.get_mut(axis), self.output.get_mut(axis)) else {
            return Err(ConfigError::new("axis index out of range"));
        };
        let out = Output::new(&limits, &a.dac, fs).map_err(|e| e.on_axis(axis))?;
        check_safe_volts(&limits, safe_volts).map_err(|e| e.on_axis(axis))?;
        *o = out;
        a.limits = limits;
        a.safe_volts = safe_volts;
        self.clamp_code(axis);
        // The fused step's guard proof covers the output range: decide again (a restart
        // still due keeps the generic path until it ran).
        self.decide_fused();
        Ok(())
    }

    /// The driver reports that the last DAC write of `axis` failed and the converter still
    /// holds `held_code`. The pipeline takes the held code as applied (so the slew limit of
    /// the next sample is measured from what the stage really sees) and latches the safe
    /// state.
    pub fn dac_write_failed(&mut self, axis: usize, held_code: i32) {
        let st = &mut self.state;
        if let (Some(code), Some(u), Some(o)) = (
            st.code.get_mut(axis),
            st.u_applied.get_mut(axis),
            self.output.get(axis),
        ) {
            let (lo, hi) = o.code_range();
            *code = held_code.max(lo).min(hi);
            *u = o.dac.volts(*code);
        }
        st.counters.dac_faults = st.counters.dac_faults.saturating_add(1);
        if st.fault.is_none() {
            st.fault = Some(Fault::DacWrite { axis });
        }
        self.fused = false;
    }

    /// A sensor check outside the pipeline (the stuck-code detector on the converter's own
    /// codes) found `fault`: counted and latched like a code outside the window.
    pub fn sensor_failed(&mut self, fault: Fault) {
        let st = &mut self.state;
        st.counters.sensor_faults = st.counters.sensor_faults.saturating_add(1);
        if st.fault.is_none() {
            st.fault = Some(fault);
        }
        self.fused = false;
    }

    /// Replaces the sensor scaling and window of `axis` (validated like [`Pipeline::new`]).
    pub fn set_sensor(&mut self, axis: usize, sensor: Sensor<T>) -> Result<(), ConfigError> {
        sensor.validate().map_err(|e| e.on_axis(axis))?;
        let a = self
            .config
            .axes
            .get_mut(axis)
            .ok_or(ConfigError::new("axis index out of range"))?;
        a.sensor = sensor;
        // The fused step's guard proof covers the sensor window: decide again.
        self.decide_fused();
        Ok(())
    }

    /// Leaves the safe state (a fault latches it) in the current mode, bumplessly.
    pub fn clear_fault(&mut self) {
        self.state.fault = None;
        self.restart();
    }

    /// The last code stays inside the output range (every step starts from there): a range
    /// that excludes it takes its nearest code now, as the next sample's limit would (the
    /// range wins over the slew limit).
    fn clamp_code(&mut self, axis: usize) {
        if let (Some(code), Some(u), Some(out)) = (
            self.state.code.get_mut(axis),
            self.state.u_applied.get_mut(axis),
            self.output.get(axis),
        ) {
            let (lo, hi) = out.code_range();
            *code = (*code).max(lo).min(hi);
            *u = out.dac.volts(*code);
        }
    }

    // Cold and out of line: the control interrupt enters it once after a fault or a
    // configuration change, so it and the resets it calls stay in flash, leaving ITCM to the
    // per-sample path (build.rs; `.ci/firmware-safety.py` checks the split).
    #[cold]
    #[inline(never)]
    fn restart(&mut self) {
        self.pending = Pending::None;
        let sp: [Setpoint<T>; N] = core::array::from_fn(|i| {
            self.reference
                .get(i)
                .map_or(Setpoint::default(), |g| g.current())
        });
        self.feedforward.reset(&sp);
        let st = &self.state;
        for (i, fb) in self.feedback.iter_mut().enumerate() {
            let u = st.u_applied.get(i).copied().unwrap_or(T::ZERO);
            fb.reset(&LoopSignals {
                setpoint: sp.get(i).copied().unwrap_or_default(),
                y_um: st.trace.y_um.get(i).copied().unwrap_or(T::ZERO),
                u_ff: u,
                u_applied: u,
            });
        }
        self.decide_fused();
    }

    /// The restart due, or the decision after the law primed (cold: once after a change).
    #[cold]
    #[inline(never)]
    fn settle_pending(&mut self) {
        match self.pending {
            Pending::Restart => self.restart(),
            Pending::Prime => {
                if self.state.fault.is_some() {
                    self.pending = Pending::None;
                } else if !self.law_fresh() {
                    self.pending = Pending::None;
                    self.fused = true;
                }
            }
            Pending::Decide => self.decide_fused(),
            Pending::None => {}
        }
    }

    /// One sample: ADC codes in, DAC codes out.
    ///
    /// The firmware's main mode (closed loop, HGO + robust law on IMS-CBW feedforward, one
    /// axis, no fault) runs a fused step (`fused.rs`) with the same arithmetic as
    /// [`Pipeline::step_generic`] and the same results, without the checks that cannot fire
    /// in that configuration; every other case runs the generic step.
    // Not inlined on the target: with the pipeline behind one pointer the step addresses
    // its state in one instruction per access, wherever the caller keeps it (the bench keeps
    // it deep in a large stack frame). On the host inlined: hal-sim's open-loop step 28 -> 12 ns.
    #[cfg_attr(target_os = "none", inline(never))]
    #[cfg_attr(not(target_os = "none"), inline)]
    pub fn step(&mut self, adc: [i32; N]) -> [i32; N] {
        // The flag holds the fault test too (a latched fault clears it).
        if self.fused {
            if let Some(codes) = self.step_fused(adc) {
                return codes;
            }
        }
        // Fixed point (the M3) inlines the generic step: out of line it costs 6-10
        // instructions a step there (the call, a second frame), while the M4F's gains.
        if T::IEEE {
            self.step_generic(adc)
        } else {
            self.step_generic_inline(adc)
        }
    }

    /// The generic step: any mode, feedforward, feedback and axis count.
    /// [`Pipeline::step`] runs it whenever the fused step does not apply; public so tests
    /// can run it as the reference of the fused step.
    // Out of line on the target: inlined, its stack frame and spills were set up and torn
    // down on the fused path too.
    #[cfg_attr(target_os = "none", inline(never))]
    #[cfg_attr(not(target_os = "none"), inline)]
    pub fn step_generic(&mut self, adc: [i32; N]) -> [i32; N] {
        self.step_generic_inline(adc)
    }

    /// [`Pipeline::step_generic`]'s body.
    #[inline(always)]
    fn step_generic_inline(&mut self, adc: [i32; N]) -> [i32; N] {
        if self.pending != Pending::None {
            self.settle_pending();
        }
        let st = &mut self.state;
        st.counters.samples = st.counters.samples.saturating_add(1);

        // Scale and range-check.
        let mut bad_sensor = false;
        for (i, (code, axis)) in adc.iter().zip(&self.config.axes).enumerate() {
            match axis.sensor.position_um(*code) {
                Some(y) => st.trace.y_um[i] = y,
                None => {
                    if !bad_sensor && st.fault.is_none() {
                        st.fault = Some(Fault::SensorRange { axis: i });
                        self.fused = false;
                    }
                    bad_sensor = true;
                }
            }
        }
        if bad_sensor {
            st.counters.sensor_faults = st.counters.sensor_faults.saturating_add(1);
        }

        // Reference.
        let sp: [Setpoint<T>; N] = core::array::from_fn(|i| {
            self.reference
                .get_mut(i)
                .map_or(Setpoint::default(), |g| g.next_setpoint())
        });
        st.trace.setpoint = sp;

        // Feedforward and feedback.
        let mut u = st.u_applied;
        if st.fault.is_none() {
            u = match st.mode {
                Mode::OpenLoop => {
                    core::array::from_fn(|i| match (self.config.axes.get(i), sp.get(i)) {
                        (Some(a), Some(s)) => a.open_loop.compensate(s.y_um),
                        _ => T::ZERO,
                    })
                }
                Mode::Feedforward => self.feedforward.compensate(&sp),
                Mode::ClosedLoop => {
                    let u_ff = self.feedforward.compensate(&sp);
                    st.trace.u_ff = u_ff;
                    let mut u = u_ff;
                    for (i, (u, fb)) in u.iter_mut().zip(self.feedback.iter_mut()).enumerate() {
                        *u = fb.update(&LoopSignals {
                            setpoint: sp[i],
                            y_um: st.trace.y_um[i],
                            u_ff: u_ff[i],
                            u_applied: st.u_applied[i],
                        });
                    }
                    u
                }
            };
            if st.mode != Mode::ClosedLoop {
                st.trace.u_ff = u;
            }
            if let Some(i) = u.iter().position(|u| !u.is_finite()) {
                st.fault = Some(Fault::NonFiniteCommand { axis: i });
                self.fused = false;
                st.counters.nonfinite_commands = st.counters.nonfinite_commands.saturating_add(1);
            }
        }
        if st.fault.is_some() {
            for (u, a) in u.iter_mut().zip(&self.config.axes) {
                *u = a.safe_volts;
            }
        }
        st.trace.u_cmd = u;

        // Limits and conversion.
        let mut saturated = false;
        for (i, (o, u)) in self.output.iter().zip(u).enumerate() {
            let l = o.limit(u, st.code[i]);
            saturated |= l.saturated;
            st.code[i] = l.code;
            st.u_applied[i] = o.dac.volts(l.code);
        }
        if saturated && st.fault.is_none() {
            st.counters.saturated_samples = st.counters.saturated_samples.saturating_add(1);
        }
        st.code
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::feedforward::Feedforward;
    use proptest::prelude::*;

    /// Range `volts_min..volts_max`, slew limit `slew` (V/s).
    fn limits(volts_min: f64, volts_max: f64, slew: f64) -> OutputLimits<f64> {
        OutputLimits {
            volts_min,
            volts_max,
            slew_volts_per_s: slew,
        }
    }

    const FULL: i32 = (1 << 20) - 1;

    pub(crate) fn axis() -> AxisConfig<f64> {
        AxisConfig {
            sensor: Sensor {
                um_per_code: 100.0 / 1_000_000.0,
                offset_um: 0.0,
                code_min: -10,
                code_max: 1_000_010,
            },
            open_loop: LinearFf {
                um_per_volt: 100.0 / 150.0,
                offset_um: 0.0,
            },
            limits: limits(0.0, 150.0, 20_000.0),
            dac: DacScale {
                volts_per_code: 150.0 / FULL as f64,
                volts_at_zero: 0.0,
                code_min: 0,
                code_max: FULL,
            },
            safe_volts: 0.0,
        }
    }

    fn pipeline(um_per_volt_ff: f64, wave: Wave<f64>) -> Pipeline<f64, 1> {
        Pipeline::new(
            Config {
                sample_hz: 100_000.0,
                axes: [axis()],
            },
            [wave],
            MultiFeedforward::PerAxis([Feedforward::Linear(LinearFf {
                um_per_volt: um_per_volt_ff,
                offset_um: 0.0,
            })]),
            [Feedback::OpenLoop],
        )
        .unwrap()
    }

    fn sine() -> Wave<f64> {
        Wave::sine(50.0, 40.0, 100.0)
    }

    #[test]
    fn open_loop_tracks_linear_scaling() {
        let mut p = pipeline(100.0 / 150.0, Wave::Hold { y_um: 30.0 });
        for _ in 0..2000 {
            p.step([300_000]);
        }
        let u = p.state().u_applied[0];
        assert!((u - 45.0).abs() < 1e-3, "{u}");
        // 45 V at 0.2 V/sample: slew-limited for 225 samples.
        let n = p.state().counters.saturated_samples;
        assert!((224..=226).contains(&n), "{n}");
    }

    #[test]
    fn sensor_fault_latches_safe_state_and_counts() {
        let mut p = pipeline(100.0 / 150.0, Wave::Hold { y_um: 30.0 });
        for _ in 0..1000 {
            p.step([300_000]);
        }
        p.step([2_000_000]);
        assert_eq!(p.state().fault, Some(Fault::SensorRange { axis: 0 }));
        for _ in 0..1000 {
            p.step([300_000]);
        }
        assert_eq!(p.state().counters.sensor_faults, 1);
        assert_eq!(p.codes()[0], 0, "slewed to safe_volts = 0");
        p.clear_fault();
        for _ in 0..1000 {
            p.step([300_000]);
        }
        assert!((p.state().u_applied[0] - 45.0).abs() < 1e-3);
    }

    #[test]
    fn nonfinite_command_goes_safe() {
        let mut p = pipeline(0.0, Wave::Hold { y_um: 30.0 });
        p.set_mode(Mode::Feedforward);
        p.step([0]);
        assert_eq!(p.state().fault, Some(Fault::NonFiniteCommand { axis: 0 }));
        assert_eq!(p.codes()[0], 0);
    }

    #[test]
    fn mode_switch_is_bumpless_within_slew() {
        let mut p = pipeline(100.0 / 150.0 * 1.1, sine());
        let step = p.output(0).unwrap().max_step();
        let mut prev = p.codes()[0];
        for k in 0..30_000 {
            if k == 10_000 {
                p.set_mode(Mode::Feedforward);
            }
            if k == 20_000 {
                p.set_mode(Mode::ClosedLoop);
            }
            let c = p.step([500_000])[0];
            assert!((c - prev).abs() <= step);
            prev = c;
        }
    }

    #[test]
    fn set_limits_in_place_keeps_running_and_holds_the_new_limits() {
        let mut p = pipeline(100.0 / 150.0, Wave::Hold { y_um: 60.0 });
        p.set_mode(Mode::Feedforward);
        for _ in 0..1000 {
            p.step([600_000]);
        }
        let bad = limits(10.0, 5.0, 1e4);
        let e = p.set_limits(0, bad, 7.0).unwrap_err();
        assert!(e.what.contains("volts_min"), "{e}");
        assert!(p.set_limits(1, axis().limits, 0.0).is_err());
        let new = limits(20.0, 60.0, 5_000.0);
        let e = p.set_limits(0, new, 0.0).unwrap_err();
        assert!(e.what.contains("safe_volts"), "{e}");
        assert_eq!(
            p.config().axes[0].limits,
            axis().limits,
            "a rejected change keeps the old"
        );
        p.set_limits(0, new, 20.0).unwrap();
        assert_eq!(p.state().mode, Mode::Feedforward);
        assert_eq!(p.config().axes[0].limits, new);
        assert_eq!(p.config().axes[0].safe_volts, 20.0);
        let o = *p.output(0).unwrap();
        let (lo, hi) = o.code_range();
        // 90 V wanted: the range clamps at once to 60 V, then holds it.
        let mut prev = p.step([600_000])[0];
        assert!(prev >= lo && prev <= hi);
        for _ in 0..500 {
            let c = p.step([600_000])[0];
            assert!(c >= lo && c <= hi && (c - prev).abs() <= o.max_step());
            prev = c;
        }
        assert!((p.state().u_applied[0] - 60.0).abs() < 1e-3);
        // Down towards 30 V (hold at 20 um) at the new slew limit: 0.05 V per sample.
        p.set_wave(0, Wave::Hold { y_um: 20.0 }).unwrap();
        let u0 = p.state().u_applied[0];
        p.step([600_000]);
        assert!((u0 - p.state().u_applied[0] - 0.05).abs() < 1e-3);
    }

    #[test]
    fn config_errors_name_the_axis_and_field() {
        let mut a = axis();
        a.safe_volts = 200.0;
        let e = Pipeline::<f64, 2>::new(
            Config {
                sample_hz: 1e5,
                axes: [axis(), a],
            },
            [sine(), sine()],
            MultiFeedforward::PerAxis([
                Feedforward::Linear(axis().open_loop),
                Feedforward::Linear(axis().open_loop),
            ]),
            [Feedback::OpenLoop, Feedback::OpenLoop],
        )
        .unwrap_err();
        assert_eq!(e.axis, Some(1));
        assert!(e.what.contains("safe_volts"));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Whatever the ADC delivers (garbage, out of range), the DAC code stays in the
        /// configured range and moves at most the slew limit per sample, in every mode.
        #[test]
        fn dac_code_stays_in_range_and_slew(
            codes in proptest::collection::vec(prop_oneof![
                any::<i32>(),
                -20i32..1_000_020,
            ], 1..400),
            mode in 0u8..3,
            gain in prop_oneof![Just(0.0), Just(f64::NAN), 0.01f64..10.0],
            clear_every in 0usize..50,
        ) {
            let mut p = pipeline(gain, sine());
            p.set_mode(match mode { 0 => Mode::OpenLoop, 1 => Mode::Feedforward, _ => Mode::ClosedLoop });
            let o = *p.output(0).unwrap();
            let (lo, hi) = o.code_range();
            let mut prev = p.codes()[0];
            for (k, c) in codes.iter().enumerate() {
                if clear_every > 0 && k % clear_every == 0 {
                    p.clear_fault();
                }
                let code = p.step([*c])[0];
                prop_assert!(code >= lo && code <= hi);
                prop_assert!((code - prev).abs() <= o.max_step());
                prop_assert!(p.state().u_applied[0] >= 0.0 && p.state().u_applied[0] <= 150.0);
                prev = code;
            }
        }
    }
}
