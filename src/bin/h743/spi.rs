//! embedded-hal 1.0 devices over stm32h7xx-hal's embedded-hal 0.2 SPI and GPIO, with the
//! SCLK divider the drivers set ([`SpiClock`]: RM0433 `SPI_CFG1.MBR`), a delay by core
//! cycles, and the register-level AD5791 bus of the panic path ([`PanicSpi4`]).

use core::convert::Infallible;
use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};
use piezo_core::drivers::SpiClock;
use stm32h7xx_hal::hal as hal02;
use stm32h7xx_hal::nb;
use stm32h7xx_hal::pac;
use stm32h7xx_hal::spi::{Enabled, Spi};

/// Chip select high between two frames, at least (ns): the AD5791's minimum SYNC high time
/// `t6` = 48 ns (data sheet Rev. D, Table 3, IOVCC 1.71 V to 3.3 V).
const CS_HIGH_NS: u32 = 48;

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
    /// The peripheral's kernel clock (Hz) and the divider it runs at (`MBR`, if set here).
    kernel_hz: u32,
    mbr: Option<u8>,
}

impl<BUS, CS: OutputPin> SpiDev<BUS, CS> {
    /// `kernel_hz`: the SPI kernel clock (SPI1: PLL1Q, SPI4: PCLK2), for [`SpiClock`].
    pub fn new(bus: BUS, mut cs: CS, kernel_hz: u32) -> Self {
        cs.set_high().ok();
        Self {
            bus,
            cs,
            kernel_hz,
            mbr: None,
        }
    }
}

/// An SPI peripheral whose SCLK divider can change between transactions: RM0433
/// `SPI_CFG1.MBR` (bits 30:28, kernel clock / 2^(MBR+1)) is writable only with
/// `SPI_CR1.SPE` = 0.
pub trait Divider {
    /// Sets MBR (0 ..= 7): SPE cleared, CFG1 written, SPE set again (SSI stays 1: master
    /// with software slave management, as the HAL sets it up).
    fn set_mbr(&mut self, mbr: u8);
}

macro_rules! divider {
    ($SPI:ident) => {
        impl Divider for Spi<pac::$SPI, Enabled, u8> {
            #[allow(unsafe_code)]
            fn set_mbr(&mut self, mbr: u8) {
                // SAFETY: this bus owns the peripheral and no transaction is in flight
                // between two `SpiDevice` transactions.
                let regs = unsafe { &*pac::$SPI::ptr() };
                regs.cr1
                    .write(|w| w.ssi().slave_not_selected().spe().disabled());
                regs.cfg1.modify(|_, w| w.mbr().bits(mbr & 0b111));
                regs.cr1
                    .write(|w| w.ssi().slave_not_selected().spe().enabled());
            }
        }
    };
}
divider!(SPI1);
divider!(SPI4);

impl<BUS: Divider, CS> SpiClock for SpiDev<BUS, CS> {
    /// The fastest divider (2 ..= 256) at most `max_hz`; 0 if even /256 is faster.
    fn set_sclk_max_hz(&mut self, max_hz: u32) -> u32 {
        let Some(mbr) = (0..8u8).find(|m| self.kernel_hz >> (m + 1) <= max_hz) else {
            return 0;
        };
        if self.mbr != Some(mbr) {
            self.bus.set_mbr(mbr);
            self.mbr = Some(mbr);
        }
        self.kernel_hz >> (mbr + 1)
    }
}

/// `DelayNs` by core cycles at [`crate::SYSCLK_HZ`] (rounded up).
#[derive(Clone, Copy, Debug, Default)]
pub struct CycleDelay;

impl embedded_hal::delay::DelayNs for CycleDelay {
    #[inline]
    fn delay_ns(&mut self, ns: u32) {
        let cycles = (ns as u64 * (crate::SYSCLK_HZ / 1_000_000) as u64).div_ceil(1000);
        cortex_m::asm::delay(cycles.clamp(1, u32::MAX as u64) as u32);
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

/// The AD5791's bus at register level, for the panic and HardFault handlers (the HAL's
/// SPI4 belongs to the control task, out of their reach): SYNC (PE4) raised and held high
/// for `t6` first (a frame the fault interrupted ends there, and the part ignores a frame
/// that is not 24 bits long), SPI4 disabled and enabled again (its FIFOs flushed: whatever
/// was in flight is dropped), SYNC low around the frame, each byte through
/// `SPI_TXDR`/`SPI_RXDR` after `SPI_SR.TXP`/`RXP` with bounded waits, `SPI_CR1.CSTART`
/// (RM0433 SPI registers; `GPIOE_BSRR` for SYNC). It keeps the divider the bus had: 25 MHz,
/// or 6.25 MHz if a read-back was under way, both within the AD5791's write limit.
pub struct PanicSpi4;
/// The AD5791's LDAC (PB3) at register level: taken back from TIM2 CH2 as a GPIO output
/// (`GPIOB_MODER`), then driven through `GPIOB_BSRR`, so the safe code loads even with
/// TIM2 stopped.
pub struct PanicLdac;

#[allow(unsafe_code)]
fn spi4() -> &'static pac::spi1::RegisterBlock {
    // SAFETY: used only on the halt path, with interrupts masked and the control task
    // stopped; the peripheral is re-enabled before use.
    unsafe { &*pac::SPI4::ptr() }
}

#[allow(unsafe_code)]
fn gpioe_bsrr(bits: u32) {
    // SAFETY: a BSRR write sets or resets only the named pins (PE4).
    unsafe { (*pac::GPIOE::ptr()).bsrr.write(|w| w.bits(bits)) }
}

/// PB3 as a push-pull output at `high`, whatever drove it.
#[allow(unsafe_code)]
fn ldac_gpio(high: bool) {
    // SAFETY: halt path only (interrupts masked); BSRR and MODER bits of PB3 alone.
    unsafe {
        let b = &*pac::GPIOB::ptr();
        b.bsrr
            .write(|w| w.bits(if high { 1 << 3 } else { 1 << (3 + 16) }));
        b.moder
            .modify(|r, w| w.bits((r.bits() & !(0b11 << 6)) | (0b01 << 6)));
    }
}

impl ErrorType for PanicSpi4 {
    type Error = SpiError;
}

impl SpiClock for PanicSpi4 {
    /// The divider stays (see above); reported as at most the AD5791's write limit.
    fn set_sclk_max_hz(&mut self, max_hz: u32) -> u32 {
        max_hz.min(25_000_000)
    }
}

impl SpiDevice for PanicSpi4 {
    #[allow(unsafe_code)]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), SpiError> {
        let spi = spi4();
        gpioe_bsrr(1 << 4); // SYNC high: ends an interrupted frame
        embedded_hal::delay::DelayNs::delay_ns(&mut CycleDelay, CS_HIGH_NS);
        spi.cr1
            .write(|w| w.ssi().slave_not_selected().spe().disabled());
        spi.cr1
            .write(|w| w.ssi().slave_not_selected().spe().enabled());
        gpioe_bsrr(1 << (4 + 16)); // SYNC low
        let mut result = Ok(());
        'ops: for op in ops.iter() {
            let Operation::Write(bytes) = op else {
                continue;
            };
            for &b in bytes.iter() {
                if !wait(|| spi.sr.read().txp().bit_is_set()) {
                    result = Err(SpiError::Timeout);
                    break 'ops;
                }
                // SAFETY: an 8-bit access to TXDR pushes one 8-bit frame (DSIZE = 8).
                unsafe { core::ptr::write_volatile(spi.txdr.as_ptr() as *mut u8, b) };
                spi.cr1.modify(|_, w| w.cstart().started());
                if !wait(|| spi.sr.read().rxp().bit_is_set()) {
                    result = Err(SpiError::Timeout);
                    break 'ops;
                }
                // SAFETY: an 8-bit read of RXDR pops one frame.
                let _ = unsafe { core::ptr::read_volatile(spi.rxdr.as_ptr() as *const u8) };
            }
        }
        gpioe_bsrr(1 << 4); // SYNC high
        embedded_hal::delay::DelayNs::delay_ns(&mut CycleDelay, CS_HIGH_NS);
        result
    }
}

/// Polls `ready` at most [`MAX_POLLS`] times.
fn wait(mut ready: impl FnMut() -> bool) -> bool {
    (0..MAX_POLLS).any(|_| ready())
}

impl PinErrorType for PanicLdac {
    type Error = Infallible;
}

impl OutputPin for PanicLdac {
    fn set_low(&mut self) -> Result<(), Infallible> {
        ldac_gpio(false);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        ldac_gpio(true);
        Ok(())
    }
}
