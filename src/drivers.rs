//! Converter drivers generic over embedded-hal 1.0 (`SpiDevice`, `OutputPin`, `DelayNs`):
//! the firmware and hal-sim run the same ones.
//!
//! * [`Ad4000`]: AD4000-family SAR position ADC (16/18/20 bit, straight binary or two's
//!   complement, CNV conversion start).
//! * [`Ad5791`]: AD5791-family 20-bit DAC (control register init, DAC register write, LDAC).

pub mod ad4000;
pub mod ad5791;

pub use ad4000::{Ad4000, Ad4000Config, CodeFormat};
pub use ad5791::{Ad5791, Ad5791Config, DacCoding};

/// The ADC driver the firmware runs (the position ADC).
pub type FirmwareAdc<SPI, CNV> = Ad4000<SPI, CNV>;
/// The DAC driver the firmware runs (the actuator DAC).
pub type FirmwareDac<SPI, LDAC> = Ad5791<SPI, LDAC>;

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
        }
    }
}
