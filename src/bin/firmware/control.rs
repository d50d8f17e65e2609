//! Board-independent part of the firmware: the per-sample step (ADC code in, DAC code out)
//! and the timing statistics. The boards call [`Loop::step`] from their highest-priority task.

use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};
use piezo_core::Real;

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

/// Stand-in control step until the core pipeline is wired: sine reference, CBW inverse
/// multiplicative feedforward (`u = (y_ref + h) / d`, 003 eq. 14), range and slew limits.
pub struct Loop {
    pub io: Io,
    pub model: Cbw<f32>,
    pub state: BwState<f32>,
    /// Reference: offset + amplitude * sin(phase), phase advanced per sample.
    pub ref_offset_um: f32,
    pub ref_amp_um: f32,
    pub ref_phase: f32,
    pub ref_dphase: f32,
    /// Last applied command (V) and last measured position (um).
    pub u_applied: f32,
    pub y_um: f32,
    pub y_ref_um: f32,
}

impl Loop {
    pub fn new(io: Io, sample_hz: f32) -> Self {
        // 000 backup slide, parameter set 1 (init time only, not the control path).
        let model = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).expect("CBW parameter set 1 is valid");
        Self {
            io,
            model,
            state: model.init(0.0),
            ref_offset_um: 10.0,
            ref_amp_um: 5.0,
            ref_phase: 0.0,
            ref_dphase: 2.0 * f32::PI * 10.0 / sample_hz,
            u_applied: 0.0,
            y_um: 0.0,
            y_ref_um: 0.0,
        }
    }

    /// One control period: ADC code in, DAC code out. No panic, bounded, NaN-safe.
    #[inline]
    pub fn step(&mut self, adc_code: u32) -> u16 {
        let io = &self.io;
        self.y_um = adc_code as f32 * io.um_per_code + io.offset_um;
        self.ref_phase += self.ref_dphase;
        if self.ref_phase > f32::PI {
            self.ref_phase -= 2.0 * f32::PI;
        }
        self.y_ref_um = self.ref_offset_um + self.ref_amp_um * self.ref_phase.sin();
        let u = (self.y_ref_um + self.state.h) / self.model.d();
        let lo = (self.u_applied - io.slew_per_sample).max(io.u_min);
        let hi = (self.u_applied + io.slew_per_sample).min(io.u_max);
        let u = u.clamp_to(lo, hi);
        self.model.step(&mut self.state, u, 0.0);
        self.u_applied = u;
        dac_code(u, io.codes_per_volt, io.dac_max)
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
    /// The whole interrupt handler (converter access, step, bookkeeping).
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
