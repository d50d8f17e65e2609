//! AD5791-family 20-bit DAC (AD5791; AD5781/AD5780 are the 18-bit parts of the same map).
//!
//! 24-bit frames, MSB first: bit 23 R/W (1 = read), bits 22:20 the register, bits 19:0 the
//! data. A read returns the register in the *next* frame. The DAC register takes effect on
//! a falling LDAC edge (or at the end of the frame while LDAC is held low).

use super::Error;
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
/// Software control register bits.
pub const SW_LDAC: u32 = 1 << 0;
pub const SW_CLR: u32 = 1 << 1;
pub const SW_RESET: u32 = 1 << 2;
/// 20-bit data mask.
pub const DATA_MASK: u32 = (1 << 20) - 1;

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
}

impl Ad5791Config {
    /// Offset binary, RBUF, 10 V span.
    pub const DEFAULT: Self = Self {
        coding: DacCoding::OffsetBinary,
        rbuf: true,
        lincomp: 0,
    };

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

/// AD5791 driver.
#[derive(Debug)]
pub struct Ad5791<SPI, LDAC> {
    spi: SPI,
    ldac: LDAC,
    config: Ad5791Config,
}

impl<SPI: SpiDevice, LDAC: OutputPin> Ad5791<SPI, LDAC> {
    /// Takes the bus and the LDAC pin (driven high: no update).
    pub fn new(
        spi: SPI,
        mut ldac: LDAC,
        config: Ad5791Config,
    ) -> Result<Self, Error<SPI::Error, LDAC::Error>> {
        if config.lincomp > 15 {
            return Err(Error::Config("ad5791.lincomp must be 0..=15"));
        }
        ldac.set_high().map_err(Error::Pin)?;
        Ok(Self { spi, ldac, config })
    }

    pub fn config(&self) -> &Ad5791Config {
        &self.config
    }

    /// Loads `initial_code` (the safe output), then releases the output from its power-up
    /// ground clamp by writing the control register, and reads it back.
    pub fn init(&mut self, initial_code: i32) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        self.write_register(REG_SWCTRL, SW_RESET)?;
        let ctrl = self.config.control();
        self.write_register(REG_CTRL, ctrl)?;
        self.write_code(initial_code)?;
        self.load()?;
        let read = self.read_register(REG_CTRL)?;
        if read & 0x3FE != ctrl {
            return Err(Error::Verify { wrote: ctrl, read });
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
        let word = ((reg & 0b111) << 20) | (data & DATA_MASK);
        let b = word.to_be_bytes();
        self.spi.write(&[b[1], b[2], b[3]]).map_err(Error::Spi)
    }

    /// Reads a register: the read command, then a no-op frame that clocks the data out.
    pub fn read_register(&mut self, reg: u32) -> Result<u32, Error<SPI::Error, LDAC::Error>> {
        let b = (READ | ((reg & 0b111) << 20)).to_be_bytes();
        self.spi.write(&[b[1], b[2], b[3]]).map_err(Error::Spi)?;
        let mut out = [0u8; 3];
        self.spi
            .transaction(&mut [Operation::Transfer(&mut out, &[0, 0, 0])])
            .map_err(Error::Spi)?;
        Ok(u32::from_be_bytes([0, out[0], out[1], out[2]]) & DATA_MASK)
    }

    /// Writes the DAC register (takes effect at the next [`Self::load`]). The code is
    /// clamped into the coding's range.
    #[inline]
    pub fn write_code(&mut self, code: i32) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        let (lo, hi) = self.config.code_range();
        self.write_register(REG_DAC, code.max(lo).min(hi) as u32 & DATA_MASK)
    }

    /// LDAC pulse: the DAC output takes the register value.
    #[inline]
    pub fn load(&mut self) -> Result<(), Error<SPI::Error, LDAC::Error>> {
        self.ldac.set_low().map_err(Error::Pin)?;
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

    pub fn release(self) -> (SPI, LDAC) {
        (self.spi, self.ldac)
    }
}
