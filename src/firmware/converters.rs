//! The converter pairs a board can have, and the pipeline's sensor and DAC scalings over
//! the stage that follow from them.

use super::params::Params;
use super::target::{c, AXES, FIXED, R, SAFE_VOLTS};
use crate::drivers::{Ad4000Config, Ad5791Config};
use crate::pipeline::{AxisConfig, Config, DacScale, OutputLimits, Sensor};

/// Span and centre of the SPI ADC's full scale (um): -10..110 um, so the stage at rest
/// (0 um) and at full stroke stays inside the sensor window.
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

/// The H743's on-chip 16-bit ADC (straight binary from 0 um over 0..100 um) and 12-bit
/// DAC.
pub struct OnChip;

impl Converters for OnChip {
    const ADC_BITS: u32 = 16;
    const DAC_BITS: u32 = 12;
    fn sensor() -> Sensor<R> {
        let codes = (65_535 >> Self::ADC_SHIFT) as f64;
        Sensor {
            um_per_code: c(100.0 / codes),
            offset_um: c(0.0),
            code_min: 0,
            code_max: codes as i32,
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
/// 45 V/V at 3.3 V on-chip), slew limit 20 V/ms, safe state 0 V. Every axis alike.
pub fn converter_config<C: Converters>(sample_hz: R) -> Config<R, AXES> {
    Config {
        sample_hz,
        axes: [AxisConfig {
            sensor: C::sensor(),
            open_loop: Params::default().linear(),
            limits: OutputLimits {
                volts_min: c(0.0),
                volts_max: c(150.0),
                slew_volts_per_s: c(20_000.0),
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
