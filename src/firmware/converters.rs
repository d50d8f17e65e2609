//! The converter pairs a board can have, and the pipeline's sensor and DAC scalings over
//! the stage that follow from them.

use super::params::Params;
use super::settings::default_of;
use super::target::{c, AXES, FIXED, R, SAFE_VOLTS};
use crate::drivers::{Ad4000Config, Ad5791Config};
use crate::pipeline::{AxisConfig, Config, DacScale, OutputLimits, Sensor};

/// Span and centre of the position ADC's full scale (um), on-chip and SPI: -10..110 um, so
/// the stage at rest (0 um) and at full stroke stays inside the sensor window, and a code at
/// either rail (sensor unplugged, saturated or shorted) is outside it: a sensor fault.
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
    /// The position sensor over the ADC codes the pipeline sees (shifted).
    fn sensor() -> Sensor<R>;
}

/// The H743's on-chip 16-bit ADC (straight binary over [`SPI_SPAN_UM`] around
/// [`SPI_CENTER_UM`]; the rail codes are outside the window) and 12-bit DAC.
pub struct OnChip;

impl Converters for OnChip {
    const ADC_BITS: u32 = 16;
    const DAC_BITS: u32 = 12;
    fn sensor() -> Sensor<R> {
        let top = 65_535 >> Self::ADC_SHIFT;
        Sensor {
            um_per_code: c(SPI_SPAN_UM / (top + 1) as f64),
            offset_um: c(SPI_CENTER_UM - SPI_SPAN_UM / 2.0),
            code_min: 1,
            code_max: top - 1,
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
    fn sensor() -> Sensor<R> {
        let half = 1i32 << (keep(Self::ADC_BITS) - 1);
        Sensor {
            um_per_code: c(SPI_SPAN_UM / (2 * half) as f64),
            offset_um: c(SPI_CENTER_UM),
            code_min: -half + 1,
            code_max: half - 2,
        }
    }
}

/// The converters over the stage: the sensor of `C`, DAC over 0..150 V (amplifier gain
/// 45 V/V at 3.3 V on-chip), limits from the settings table (0..150 V, 20 V/ms), safe state 0 V. Every axis alike.
pub fn converter_config<C: Converters>(sample_hz: R) -> Config<R, AXES> {
    Config {
        sample_hz,
        axes: [AxisConfig {
            sensor: C::sensor(),
            open_loop: Params::default().linear(),
            limits: OutputLimits {
                volts_min: c(default_of("u_min")),
                volts_max: c(default_of("u_max")),
                slew_volts_per_s: c(default_of("slew")),
            },
            dac: DacScale {
                volts_per_code: c(150.0 / C::DAC_MAX as f64),
                volts_at_zero: c(0.0),
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
    /// window, on both converter pairs (issue 15 item 5).
    fn window<C: Converters>(rail_lo: i32, rail_hi: i32) {
        let s = C::sensor();
        assert_eq!(s.position_um(rail_lo), None, "low rail must be a fault");
        assert_eq!(s.position_um(rail_hi), None, "high rail must be a fault");
        for um in [0.0, 100.0] {
            let code = ((um - s.offset_um as f64) / s.um_per_code as f64).round() as i32;
            let y = s.position_um(code).expect("inside the window") as f64;
            assert!((y - um).abs() < 0.01, "{um} um read as {y}");
        }
    }

    #[test]
    fn rails_are_faults_rest_and_stroke_are_not() {
        window::<OnChip>(0, 65_535 >> OnChip::ADC_SHIFT);
        let half = 1 << (SpiPair::ADC_BITS - SpiPair::ADC_SHIFT - 1);
        window::<SpiPair>(-half, half - 1);
    }
}
