//! The axes: the core pipeline plus the names of the selected law and compensator and the
//! parameters they are built from.

use super::converters::{converter_config, Converters};
use super::laws::{ff_with, law_with, validate, FFS, LAWS};
use super::params::Params;
use super::settings::default_of;
use super::target::{c, LoopPipeline, AXES, R, SAFE_VOLTS};
use crate::command::Error;
use crate::feedback::Feedback;
use crate::feedforward::{Feedforward, MultiFeedforward};
use crate::pipeline::{Fault, Mode, OutputLimits, Parts, StuckCode, Wave};
use crate::recorder::Signal;
use crate::Real;
use core::marker::PhantomData;

/// The axes: the core pipeline (sensor scaling, reference, feedforward, feedback, limits,
/// DAC code) over the converters `C`, plus the names of what is selected (the same law and
/// compensator on every axis).
pub struct Loop<C> {
    pub p: LoopPipeline,
    pub sample_hz: R,
    /// Selected law (`open-loop`, `feedforward` or a law of [`LAWS`]) and feedforward.
    pub law: &'static str,
    pub ff: &'static str,
    /// Model, open-loop scaling and gains the law and compensator are built from.
    pub params: Params,
    /// The sensor window's guard band (um, settings `guard`).
    pub guard_um: R,
    /// Identical consecutive ADC codes that are a sensor fault (settings `stuck`, 0: off),
    /// and each axis' detector, on the converter's own codes.
    pub stuck_limit: u32,
    stuck: [StuckCode; AXES],
    converters: PhantomData<C>,
}

// By hand: `derive` would ask `C: Clone` of the converter marker.
impl<C> Clone for Loop<C> {
    fn clone(&self) -> Self {
        Self {
            p: self.p.clone(),
            sample_hz: self.sample_hz,
            law: self.law,
            ff: self.ff,
            params: self.params,
            guard_um: self.guard_um,
            stuck_limit: self.stuck_limit,
            stuck: self.stuck,
            converters: PhantomData,
        }
    }
}

impl<C: Converters> Loop<C> {
    /// Takes `parts` of the replica `from` (where a command was validated and its law or
    /// compensator built, outside the control task's lock) with its names and parameters:
    /// a copy and one bumpless restart ([`crate::pipeline::Pipeline::adopt`]).
    #[inline(never)]
    pub fn adopt(&mut self, from: &Self, parts: Parts) {
        self.p.adopt(&from.p, parts);
        self.law = from.law;
        self.ff = from.ff;
        self.params = from.params;
        if parts.contains(Parts::SENSOR) {
            self.guard_um = from.guard_um;
            self.stuck_limit = from.stuck_limit;
        }
    }

    /// Open loop, holding 0 um, in the safe state's voltage.
    pub fn new(sample_hz: R) -> Self {
        let params = Params::default();
        let ff = MultiFeedforward::PerAxis(core::array::from_fn(|_| {
            Feedforward::Linear(params.linear())
        }));
        let p = LoopPipeline::new(
            converter_config::<C>(sample_hz),
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
            guard_um: c(default_of("guard")),
            stuck_limit: default_of("stuck") as u32,
            stuck: [StuckCode::default(); AXES],
            converters: PhantomData,
        }
    }

    /// One control period: ADC codes in, DAC codes out (the converters' own codes, 0 ..=
    /// [`Converters::DAC_FULL`]), one per axis. No panic, bounded, NaN-safe.
    /// A code that repeats [`Loop::stuck_limit`] times latches the safe state (checked on
    /// the converter's own codes, before the shift drops their noise).
    #[inline(always)]
    pub fn step(&mut self, adc_code: [i32; AXES]) -> [i32; AXES] {
        for (axis, (s, &code)) in self.stuck.iter_mut().zip(&adc_code).enumerate() {
            if s.update(code, self.stuck_limit) {
                self.p.sensor_failed(Fault::SensorStuck { axis });
            }
        }
        let codes = self.p.step(adc_code.map(|c| c >> C::ADC_SHIFT));
        // max/min, not clamp: clamp asserts min <= max (a panic path in the handler).
        #[allow(clippy::manual_clamp)]
        codes.map(|code| code.max(0).min(C::DAC_MAX) << C::DAC_SHIFT)
    }

    /// The DAC write of `axis` failed this period; the converter still holds `held_code`
    /// (its own code): the pipeline takes that as applied and latches the safe state.
    #[inline(always)]
    pub fn dac_write_failed(&mut self, axis: usize, held_code: i32) {
        self.p.dac_write_failed(axis, held_code >> C::DAC_SHIFT);
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
                R::from_i32(adc >> C::ADC_SHIFT),
                R::from_i32(dac >> C::DAC_SHIFT),
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
    pub(super) fn set_params(&mut self, name: &str, v: R) -> Result<(), Error> {
        let mut p = self.params;
        *p.slot(name).ok_or(Error::UnknownParam)? = v;
        self.install(p)
    }

    /// Sets the CBW model `[d, alpha, beta, gamma]` at once (like [`Loop::set_params`]).
    pub(super) fn set_cbw(&mut self, [d, alpha, beta, gamma]: [R; 4]) -> Result<(), Error> {
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
    pub(super) fn install(&mut self, p: Params) -> Result<(), Error> {
        validate(&p, self.sample_hz)?;
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

    /// Sets the sensor window's guard band (um) on every axis, in place.
    pub(super) fn set_guard(&mut self, guard_um: R) -> Result<(), Error> {
        for axis in 0..AXES {
            self.p
                .set_sensor(axis, C::sensor(guard_um.to_f64()))
                .map_err(|_| Error::OutOfRange)?;
        }
        self.guard_um = guard_um;
        Ok(())
    }

    /// Changes the limits of every axis in place (mode, wave, law and compensator keep
    /// running; no pipeline is rebuilt on the serial task's stack). All axes or none.
    pub(super) fn set_limits(&mut self, f: impl Fn(&mut OutputLimits<R>)) -> Result<(), Error> {
        let cfg = self.p.config();
        let new = cfg.axes.map(|a| {
            let mut l = a.limits;
            f(&mut l);
            l
        });
        // Validate all first, so a rejected change leaves every axis as it was.
        for (a, l) in cfg.axes.iter().zip(&new) {
            crate::pipeline::Output::new(l, &a.dac, cfg.sample_hz)
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

/// `law` builds from `p` (out of line: the law is not held in the caller's frame).
#[inline(never)]
fn builds(law: &str, p: &Params, sample_hz: R) -> bool {
    law_with(law, p, sample_hz).is_some()
}
