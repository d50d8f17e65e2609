//! AD5791-family 20-bit DAC (AD5791; AD5781/AD5780 are the 18-bit parts of the same map).
//!
//! 24-bit frames, MSB first: bit 23 R/W (1 = read), bits 22:20 the register, bits 19:0 the
//! data. A read returns the register in the *next* frame. The DAC register takes effect on
//! a falling LDAC edge (or at the end of the frame while LDAC is held low).
//!
//! At power-on (and after a software reset) the control register holds OPGND = 1 and
//! DACTRI = 1: the DAC is tri-stated and VOUT is clamped to AGND through ~6 kOhm (data sheet
//! Rev. D, p. 19), and the DAC register holds code 0. [`Ad5791::init`] loads the safe code
//! while the output is still clamped, checks it by read-back, and only then clears OPGND
//! and DACTRI, so the first voltage the output drives is the safe one.
//!
//! Timing the driver keeps (AD5791 data sheet Rev. D, Table 3 "Timing Characteristics",
//! IOVCC 1.71 V to 3.3 V column, the slower one at the H743's 3.3 V I/O):
//! * SCLK cycle `t1` >= 40 ns for writes ([`SCLK_MAX_HZ`], 25 MHz),
//! * SCLK cycle `t1` >= 92 ns in read-back ([`SCLK_READBACK_MAX_HZ`], 10.87 MHz),
//! * LDAC low pulse `t10` >= 13 ns ([`LDAC_LOW_NS`]);
//! * SYNC high `t6` >= 48 ns between two frames ([`SYNC_HIGH_NS`]): the bus raises SYNC at
//!   the end of a transaction and lowers it at the start of the next, so the driver waits
//!   `t6` before every frame (the bus cannot know how soon the next one comes).

use super::{Error, SpiClock};
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use embedded_hal::spi::{Operation, SpiDevice};

pub const REG_DAC: u32 = 0b001;
pub const REG_CTRL: u32 = 0b010;
pub const REG_CLEARCODE: u32 = 0b011;
pub const REG_SWCTRL: u32 = 0b100;
/// Read flag (bit 23).
pub const READ: u32 = 1 << 23;
/// Control register bits.
pub const CTRL_RBUF: u32 = 1 << 1;
pub const CTRL_OPGND: u32 = 1 << 2;
pub const CTRL_DACTRI: u32 = 1 << 3;
pub const CTRL_BIN2SC: u32 = 1 << 4;
pub const CTRL_SDODIS: u32 = 1 << 5;
/// Linearity compensation field (bits 9:6); 0 for a span up to 10 V.
pub const CTRL_LINCOMP_SHIFT: u32 = 6;
/// The writable control bits.
pub const CTRL_MASK: u32 = 0x3FE;
/// Software control register bits.
pub const SW_LDAC: u32 = 1 << 0;
pub const SW_CLR: u32 = 1 << 1;
pub const SW_RESET: u32 = 1 << 2;
/// 20-bit data mask.
pub const DATA_MASK: u32 = (1 << 20) - 1;
/// Fastest write SCLK: `t1` >= 40 ns (Table 3, IOVCC 1.71 V to 3.3 V).
pub const SCLK_MAX_HZ: u32 = 25_000_000;
/// Fastest read-back SCLK: `t1` >= 92 ns (Table 3, read-back, IOVCC 1.71 V to 3.3 V).
pub const SCLK_READBACK_MAX_HZ: u32 = 10_869_565;
/// Shortest LDAC low pulse: `t10` >= 13 ns (Table 3, IOVCC 1.71 V to 3.3 V).
pub const LDAC_LOW_NS: u32 = 13;
/// Shortest SYNC high time between frames: `t6` >= 48 ns (Table 3, IOVCC 1.71 V to 3.3 V).
pub const SYNC_HIGH_NS: u32 = 48;

/// The 3 bytes of a write frame.
#[inline]
pub fn write_frame(reg: u32, data: u32) -> [u8; 3] {
    let b = (((reg & 0b111) << 20) | (data & DATA_MASK)).to_be_bytes();
    [b[1], b[2], b[3]]
}

/// How the DAC register is coded (control register bit BIN/2sC).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DacCoding {
    /// `0 ..= 2^20 - 1`, 0 at `V_REFN`.
    OffsetBinary,
    /// `-2^19 ..= 2^19 - 1`, `-2^19` at `V_REFN`.
    TwosComplement,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ad5791Config {
    pub coding: DacCoding,
    /// Internal amplifier buffer off (RBUF = 1): the usual unity-gain setup with an
    /// external reference buffer.
    pub rbuf: bool,
    /// Linearity compensation code (bits 9:6), 0..=15 (0: span up to 10 V, 12: up to 20 V).
    pub lincomp: u8,
    /// SCLK rate of the loop's write frames (Hz); the driver asks the bus for at most this
    /// and at most [`SCLK_MAX_HZ`], and reads back at most at [`SCLK_READBACK_MAX_HZ`].
    pub sclk_hz: u32,
}

impl Ad5791Config {
    /// Offset binary, RBUF, 10 V span.
    pub const DEFAULT: Self = Self {
        coding: DacCoding::OffsetBinary,
        rbuf: true,
        lincomp: 0,
        sclk_hz: 25_000_000,
    };

    /// Control register value with the output still clamped to ground and the DAC
    /// tri-stated (the power-on state of OPGND and DACTRI).
    pub fn control_clamped(&self) -> u32 {
        self.control() | CTRL_OPGND | CTRL_DACTRI
    }

    /// Control register value: output out of ground clamp and tristate.
    pub fn control(&self) -> u32 {
        (if self.rbuf { CTRL_RBUF } else { 0 })
            | (if self.coding == DacCoding::OffsetBinary {
                CTRL_BIN2SC
            } else {
                0
            })
            | (((self.lincomp & 0xF) as u32) << CTRL_LINCOMP_SHIFT)
    }

    /// Smallest and largest code.
    pub fn code_range(&self) -> (i32, i32) {
        match self.coding {
            DacCoding::OffsetBinary => (0, DATA_MASK as i32),
            DacCoding::TwosComplement => (-(1 << 19), (1 << 19) - 1),
        }
    }
}

/// AD5791 driver: the bus, the LDAC pin and a delay for the LDAC pulse.
#[derive(Debug)]
pub struct Ad5791<SPI, LDAC, D> {
    spi: SPI,
    ldac: LDAC,
    delay: D,
    config: Ad5791Config,
}

impl<SPI: SpiDevice + SpiClock, LDAC: OutputPin, D: DelayNs> Ad5791<SPI, LDAC, D> {
    /// Takes the bus, the LDAC pin (driven high: no update) and a delay.
    pub fn new(
        spi: SPI,
        mut ldac: LDAC,
        delay: D,
        config: Ad5791Config,
    ) -> Result<Self, Error<SPI::Error, LDAC::Error>> {
        if config.lincomp > 15 {
            return Err(Error::Config("ad5791.lincomp must be 0..=15"));
        }
        if config.sclk_hz == 0 {
            return Err(Error::Config("ad5791.sclk_hz must be above 0"));
        }
        ldac.set_high().map_err(Error::Pin)?;
        Ok(Self {
            spi,
            ldac,
            delay,
            config,
        })
    }

    pub fn config(&self) -> &Ad5791Config {
        &self.config
    }

    /// Brings the output up at `safe_code`: software reset (output clamped to ground, DAC
    /// tri-stated), coding set with the clamp kept, the safe code written and loaded, the
    /// DAC register read back, then the clamp and tri-state released and the control
    /// register read back. On any error the output is still clamped (or at the safe code).
    pub fn init(&mut self, safe_code: i32) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        self.write_clock()?;
        self.write_register(REG_SWCTRL, SW_RESET)?;
        self.write_register(REG_CTRL, self.config.control_clamped())?;
        self.set_code(safe_code)?;
        let want = self.code_word(safe_code);
        let read = self.read_register(REG_DAC)?;
        if read != want {
            return Err(Error::Verify { wrote: want, read });
        }
        let ctrl = self.config.control();
        self.write_register(REG_CTRL, ctrl)?;
        let read = self.read_register(REG_CTRL)?;
        if read & CTRL_MASK != ctrl {
            return Err(Error::Verify { wrote: ctrl, read });
        }
        Ok(())
    }

    /// The bus at the loop's write rate.
    fn write_clock(&mut self) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        if self
            .spi
            .set_sclk_max_hz(self.config.sclk_hz.min(SCLK_MAX_HZ))
            == 0
        {
            return Err(Error::Config("ad5791: the bus cannot run SCLK that slow"));
        }
        Ok(())
    }

    /// One 24-bit write frame.
    #[inline]
    pub fn write_register(
        &mut self,
        reg: u32,
        data: u32,
    ) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        self.delay.delay_ns(SYNC_HIGH_NS);
        self.spi.write(&write_frame(reg, data)).map_err(Error::Spi)
    }

    /// Reads a register: the read command, then a no-op frame that clocks the data out,
    /// both at the read-back SCLK; the bus returns to the write rate afterwards.
    pub fn read_register(&mut self, reg: u32) -> Result<u32, Error<SPI::Error, LDAC::Error>> {
        let rate = self
            .spi
            .set_sclk_max_hz(self.config.sclk_hz.min(SCLK_READBACK_MAX_HZ));
        if rate == 0 {
            return Err(Error::Config("ad5791: the bus cannot run SCLK that slow"));
        }
        let b = (READ | ((reg & 0b111) << 20)).to_be_bytes();
        let mut out = [0u8; 3];
        self.delay.delay_ns(SYNC_HIGH_NS);
        let read = self.spi.write(&[b[1], b[2], b[3]]).and_then(|()| {
            self.delay.delay_ns(SYNC_HIGH_NS);
            self.spi
                .transaction(&mut [Operation::Transfer(&mut out, &[0, 0, 0])])
        });
        let read = read.map_err(Error::Spi);
        self.write_clock()?;
        read?;
        Ok(u32::from_be_bytes([0, out[0], out[1], out[2]]) & DATA_MASK)
    }

    /// The DAC register as read back (the code the output holds after a load), in the
    /// coding's range.
    pub fn read_code(&mut self) -> Result<i32, Error<SPI::Error, LDAC::Error>> {
        let raw = self.read_register(REG_DAC)?;
        Ok(match self.config.coding {
            DacCoding::OffsetBinary => raw as i32,
            DacCoding::TwosComplement => ((raw << 12) as i32) >> 12,
        })
    }

    /// The 20-bit register word of `code`, clamped into the coding's range.
    #[inline]
    fn code_word(&self, code: i32) -> u32 {
        let (lo, hi) = self.config.code_range();
        code.max(lo).min(hi) as u32 & DATA_MASK
    }

    /// Writes the DAC register (takes effect at the next [`Self::load`]). The code is
    /// clamped into the coding's range.
    #[inline]
    pub fn write_code(&mut self, code: i32) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        self.write_register(REG_DAC, self.code_word(code))
    }

    /// LDAC pulse of at least [`LDAC_LOW_NS`]: the DAC output takes the register value.
    #[inline]
    pub fn load(&mut self) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        self.ldac.set_low().map_err(Error::Pin)?;
        self.delay.delay_ns(LDAC_LOW_NS);
        self.ldac.set_high().map_err(Error::Pin)
    }

    /// Write and load.
    #[inline]
    pub fn set_code(&mut self, code: i32) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        self.write_code(code)?;
        self.load()
    }

    /// Mutable access to the bus (tests, mocks).
    pub fn spi_mut(&mut self) -> &mut SPI {
        &mut self.spi
    }

    pub fn release(self) -> (SPI, LDAC, D) {
        (self.spi, self.ldac, self.delay)
    }
}
