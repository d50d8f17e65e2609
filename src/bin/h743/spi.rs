//! embedded-hal 1.0 devices over stm32h7xx-hal's embedded-hal 0.2 SPI and GPIO.

use core::convert::Infallible;
use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};
use stm32h7xx_hal::hal as hal02;
use stm32h7xx_hal::nb;

/// Polls of a status flag before a byte exchange is given up (a byte takes ~130 polls
/// at 25 MHz SCK and 400 MHz core clock).
const MAX_POLLS: u32 = 10_000;

/// A failed SPI exchange.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpiError {
    /// The peripheral reported an error (overrun, mode fault, ...).
    Bus,
    /// A status flag did not come within [`MAX_POLLS`] polls.
    Timeout,
}

impl embedded_hal::spi::Error for SpiError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// An embedded-hal 1.0 `SpiDevice`: an embedded-hal 0.2 full-duplex bus plus a chip
/// select held low for the whole transaction.
pub struct SpiDev<BUS, CS> {
    bus: BUS,
    cs: CS,
}

impl<BUS, CS: OutputPin> SpiDev<BUS, CS> {
    pub fn new(bus: BUS, mut cs: CS) -> Self {
        cs.set_high().ok();
        Self { bus, cs }
    }
}

impl<BUS: hal02::spi::FullDuplex<u8>, CS> SpiDev<BUS, CS> {
    /// One byte out, one byte in; bounded.
    #[inline]
    fn exchange(&mut self, out: u8) -> Result<u8, SpiError> {
        poll(|| self.bus.send(out))?;
        poll(|| self.bus.read())
    }
}

#[inline]
fn poll<T, E>(mut f: impl FnMut() -> nb::Result<T, E>) -> Result<T, SpiError> {
    for _ in 0..MAX_POLLS {
        match f() {
            Ok(v) => return Ok(v),
            Err(nb::Error::WouldBlock) => {}
            Err(nb::Error::Other(_)) => return Err(SpiError::Bus),
        }
    }
    Err(SpiError::Timeout)
}

impl<BUS, CS> ErrorType for SpiDev<BUS, CS> {
    type Error = SpiError;
}

impl<BUS: hal02::spi::FullDuplex<u8>, CS: OutputPin> SpiDevice for SpiDev<BUS, CS> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), SpiError> {
        self.cs.set_low().ok();
        let mut result = Ok(());
        for op in ops.iter_mut() {
            result = match op {
                Operation::Read(buf) => buf.iter_mut().try_for_each(|b| {
                    *b = self.exchange(0)?;
                    Ok(())
                }),
                Operation::Write(buf) => buf.iter().try_for_each(|&b| self.exchange(b).map(|_| ())),
                Operation::Transfer(read, write) => {
                    // Words beyond `write` are zeros; words beyond `read` are dropped.
                    let n = read.len().max(write.len());
                    (0..n).try_for_each(|i| {
                        let v = self.exchange(write.get(i).copied().unwrap_or(0))?;
                        if let Some(r) = read.get_mut(i) {
                            *r = v;
                        }
                        Ok(())
                    })
                }
                Operation::TransferInPlace(buf) => buf.iter_mut().try_for_each(|b| {
                    *b = self.exchange(*b)?;
                    Ok(())
                }),
                Operation::DelayNs(ns) => {
                    cortex_m::asm::delay(ns.saturating_mul(crate::SYSCLK_HZ / 1_000_000) / 1000);
                    Ok(())
                }
            };
            if result.is_err() {
                break;
            }
        }
        self.cs.set_high().ok();
        result
    }
}

/// An embedded-hal 0.2 GPIO output as an embedded-hal 1.0 `OutputPin`.
pub struct Gpio<P>(pub P);

impl<P> PinErrorType for Gpio<P> {
    type Error = Infallible;
}

impl<P: hal02::digital::v2::OutputPin> OutputPin for Gpio<P> {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.0.set_low().ok();
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0.set_high().ok();
        Ok(())
    }
}

/// A pin the hardware drives, not the driver: the AD4020's CNV (TIM2 channel 1), and
/// its chip select (CNV doubles as CS in the 3-wire mode). Setting it does nothing.
pub struct HardwarePin;

impl PinErrorType for HardwarePin {
    type Error = Infallible;
}

impl OutputPin for HardwarePin {
    fn set_low(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}
