//! The converter pairs a board can have, and the pipeline's sensor and DAC scalings over
//! the stage that follow from them.

use super::params::Params;
use super::settings::default_of;
use super::target::{c, AXES, FIXED, R, SAFE_VOLTS};
use crate::drivers::{Ad4000Config, Ad5791Config};
use crate::pipeline::{AxisConfig, Config, DacScale, OutputLimits, Sensor};

/// Span and centre of the position ADC's full scale (um), on-chip and SPI: -10..110 um, so
/// the stage at rest (0 um) and at full stroke stays inside the sensor window, and a code at
/// either rail (sensor unplugged, saturated or shorted) is outside it: a sensor fault. The
/// settings table's `guard` (um) narrows the window further at both ends.
pub const SPI_SPAN_UM: f64 = 120.0;
pub const SPI_CENTER_UM: f64 = 50.0;

/// The position ADC's configuration (SPI converters).
pub const ADC_CONFIG: Ad4000Config = Ad4000Config::AD4020;
/// The DAC's configuration (SPI converters).
pub const DAC_CONFIG: Ad5791Config = Ad5791Config::DEFAULT;
/// The firmware's position ADC driver on a board's SPI device and CNV pin: the type
/// hal-sim runs on its mock chip (`hal_sim::sim::SimAdc`).
pub type PositionAdc<SPI, CNV, D> = crate::drivers::FirmwareAdc<SPI, CNV, D>;
/// The firmware's DAC driver on a board's SPI device and LDAC pin (`hal_sim::sim::SimDac`).
pub type ActuatorDac<SPI, LDAC, D> = crate::drivers::FirmwareDac<SPI, LDAC, D>;

/// Bits of a code the pipeline keeps: all of them in f32, at most 15 in Q16.16 (3 nm over
/// 100 um at 15 bits).
const fn keep(bits: u32) -> u32 {
    if FIXED && bits > 15 {
        15
    } else {
        bits
    }
}

/// A board's ADC/DAC pair: code widths and the sensor scaling. Compile-time constants, so
/// the control step's shifts and clamps fold.
pub trait Converters {
    /// Bits of an ADC code and of a DAC code.
    const ADC_BITS: u32;
    const DAC_BITS: u32;
    /// ADC codes are shifted right by this before scaling, DAC codes left after it.
    const ADC_SHIFT: u32 = Self::ADC_BITS - keep(Self::ADC_BITS);
    const DAC_SHIFT: u32 = Self::DAC_BITS - keep(Self::DAC_BITS);
    /// Largest DAC code the pipeline computes (before [`Converters::DAC_SHIFT`]).
    const DAC_MAX: i32 = (1 << keep(Self::DAC_BITS)) - 1;
    /// Largest code of the DAC itself.
    const DAC_FULL: i32 = (1 << Self::DAC_BITS) - 1;
    /// The DAC's own code of 0 V at the stage, as the board is wired (the hardware page of
    /// the book: the on-chip DAC unbuffered from 0 V; the AD5791 offset binary with
    /// V_REFN at AGND). The safe state's code must be this one (checked by a test).
    const ZERO_VOLT_CODE: i32 = 0;
    /// The position sensor over the ADC codes the pipeline sees (shifted), its window
    /// `guard_um` inside the rail codes at each end (rounded down to whole codes; negative
    /// or NaN: none).
    fn sensor(guard_um: f64) -> Sensor<R>;
}

/// Codes in `guard_um` at `um_per_code` (whole codes, rounded down; none for a negative or
/// NaN guard; bounded by `max`).
fn guard_codes(guard_um: f64, um_per_code: f64, max: i32) -> i32 {
    let g = guard_um / um_per_code;
    if g >= 0.0 {
        (g as i32).min(max)
    } else {
        0
    }
}

/// The H743's on-chip 16-bit ADC (straight binary over [`SPI_SPAN_UM`] around
/// [`SPI_CENTER_UM`]; the rail codes are outside the window) and 12-bit DAC.
pub struct OnChip;

impl Converters for OnChip {
    const ADC_BITS: u32 = 16;
    const DAC_BITS: u32 = 12;
    fn sensor(guard_um: f64) -> Sensor<R> {
        let top = 65_535 >> Self::ADC_SHIFT;
        let um_per_code = SPI_SPAN_UM / (top + 1) as f64;
        let g = guard_codes(guard_um, um_per_code, top / 4);
        Sensor {
            um_per_code: c(um_per_code),
            offset_um: c(SPI_CENTER_UM - SPI_SPAN_UM / 2.0),
            code_min: 1 + g,
            code_max: top - 1 - g,
        }
    }
}

/// The external SPI pair through the drivers of [`crate::drivers`] (the ones hal-sim's mock
/// chips run): an AD4020 (20 bit, two's complement over [`SPI_SPAN_UM`] around
/// [`SPI_CENTER_UM`]; a clipped code is out of range) and an AD5791 (20 bit, offset binary).
/// Feature `spi-converters` on the H743; always on the QEMU board, whose simulated stage
/// sits behind the same drivers.
pub struct SpiPair;

impl Converters for SpiPair {
    const ADC_BITS: u32 = 20;
    const DAC_BITS: u32 = 20;
    fn sensor(guard_um: f64) -> Sensor<R> {
        let half = 1i32 << (keep(Self::ADC_BITS) - 1);
        let um_per_code = SPI_SPAN_UM / (2 * half) as f64;
        let g = guard_codes(guard_um, um_per_code, half / 2);
        Sensor {
            um_per_code: c(um_per_code),
            offset_um: c(SPI_CENTER_UM),
            code_min: -half + 1 + g,
            code_max: half - 2 - g,
        }
    }
}

/// The converters over the stage: the sensor of `C`, DAC over 0..150 V (amplifier gain
/// 45 V/V at 3.3 V on-chip), limits from the settings table (0..150 V, 20 V/ms), safe state 0 V. Every axis alike.
pub fn converter_config<C: Converters>(sample_hz: R) -> Config<R, AXES> {
    // 0 V at the configured code, 150 V at the top.
    let zero = (C::ZERO_VOLT_CODE >> C::DAC_SHIFT) as f64;
    let volts_per_code = 150.0 / (C::DAC_MAX as f64 - zero);
    Config {
        sample_hz,
        axes: [AxisConfig {
            sensor: C::sensor(default_of("guard")),
            open_loop: Params::default().linear(),
            limits: OutputLimits {
                volts_min: c(default_of("u_min")),
                volts_max: c(default_of("u_max")),
                slew_volts_per_s: c(default_of("slew")),
            },
            dac: DacScale {
                volts_per_code: c(volts_per_code),
                volts_at_zero: c(0.0 - zero * volts_per_code),
                code_min: 0,
                code_max: C::DAC_MAX,
            },
            safe_volts: c(SAFE_VOLTS),
        }; AXES],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rail codes are sensor faults; the stage at rest and at full stroke is inside the
    /// window, on both converter pairs; the default guard band excludes codes near the
    /// rails as well.
    fn window<C: Converters>(rail_lo: i32, rail_hi: i32) {
        let s = C::sensor(default_of("guard"));
        let near = |um: f64| ((um - s.offset_um as f64) / s.um_per_code as f64).round() as i32;
        assert_eq!(s.position_um(near(108.0)), None, "2 um below the top rail");
        assert_eq!(
            s.position_um(near(-8.0)),
            None,
            "2 um above the bottom rail"
        );
        let s = C::sensor(0.0);
        assert_eq!(s.position_um(rail_lo), None, "low rail must be a fault");
        assert_eq!(s.position_um(rail_hi), None, "high rail must be a fault");
        for um in [0.0, 100.0] {
            let code = ((um - s.offset_um as f64) / s.um_per_code as f64).round() as i32;
            let y = s.position_um(code).expect("inside the window") as f64;
            assert!((y - um).abs() < 0.01, "{um} um read as {y}");
        }
    }

    /// The safe voltage's code, as the pipeline computes it and the boards load at
    /// start-up and on a fault, is the configured code of 0 V on both converter pairs.
    fn zero_volt_code<C: Converters>() {
        use crate::pipeline::Output;
        let cfg = converter_config::<C>(c(1e4));
        let a = &cfg.axes[0];
        let o = Output::new(&a.limits, &a.dac, cfg.sample_hz).unwrap();
        assert_eq!(SAFE_VOLTS, 0.0);
        assert_eq!(
            o.code_in_range(a.safe_volts) << C::DAC_SHIFT,
            C::ZERO_VOLT_CODE
        );
        assert_eq!(a.dac.volts(C::ZERO_VOLT_CODE >> C::DAC_SHIFT), c(0.0));
    }

    #[test]
    fn safe_code_is_the_configured_zero_volt_code() {
        zero_volt_code::<OnChip>();
        zero_volt_code::<SpiPair>();
    }

    #[test]
    fn rails_are_faults_rest_and_stroke_are_not() {
        window::<OnChip>(0, 65_535 >> OnChip::ADC_SHIFT);
        let half = 1 << (SpiPair::ADC_BITS - SpiPair::ADC_SHIFT - 1);
        window::<SpiPair>(-half, half - 1);
    }
}
