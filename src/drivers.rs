//! Converter drivers generic over embedded-hal 1.0 (`SpiDevice`, `OutputPin`, `DelayNs`)
//! plus [`SpiClock`]: the firmware and hal-sim run the same ones, and hal-sim's and the QEMU
//! board's mock chips enforce the data sheets' timing on them.
//!
//! * [`Ad4000`]: AD4000-family SAR position ADC (16/18/20 bit, straight binary or two's
//!   complement, CNV conversion start).
//! * [`Ad5791`]: AD5791-family 20-bit DAC (control register init, DAC register write, LDAC).

pub mod ad4000;
pub mod ad5791;
pub mod wire;

pub use ad4000::{Ad4000, Ad4000Config, CodeFormat};
pub use ad5791::{Ad5791, Ad5791Config, DacCoding};

/// The ADC driver the firmware runs (the position ADC).
pub type FirmwareAdc<SPI, CNV, D> = Ad4000<SPI, CNV, D>;
/// The DAC driver the firmware runs (the actuator DAC).
pub type FirmwareDac<SPI, LDAC, D> = Ad5791<SPI, LDAC, D>;

/// An SPI device whose SCLK rate the driver sets between transactions: the converters'
/// limits differ by operation (AD5791: 25 MHz writes, 10.87 MHz read-back), which
/// embedded-hal's `SpiDevice` does not express.
pub trait SpiClock {
    /// Runs the following transactions at the fastest rate the bus has that is at most
    /// `max_hz`; returns that rate, or 0 if the bus cannot go that slow.
    fn set_sclk_max_hz(&mut self, max_hz: u32) -> u32;
}

/// A driver error: the bus, a pin, a register that did not read back, or a bad config.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<S, P> {
    Spi(S),
    Pin(P),
    /// A register read back differently from what was written (chip missing or miswired).
    Verify {
        wrote: u32,
        read: u32,
    },
    /// The driver configuration is not supported; the text names the field.
    Config(&'static str),
    /// A conversion's status bits (AD4000 family) were not what the configuration sets:
    /// the over-voltage clamp flag, or mode bits of a part that reset or a data line held
    /// at one level.
    Status(u8),
}

impl<S: core::fmt::Debug, P: core::fmt::Debug> core::fmt::Display for Error<S, P> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Spi(e) => write!(f, "SPI error: {e:?}"),
            Error::Pin(e) => write!(f, "pin error: {e:?}"),
            Error::Verify { wrote, read } => {
                write!(f, "register read back {read:#x}, wrote {wrote:#x}")
            }
            Error::Config(m) => write!(f, "driver config: {m}"),
            Error::Status(s) => write!(f, "ADC status bits {s:#04x} (over-voltage or mode lost)"),
        }
    }
}
