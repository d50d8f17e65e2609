//! AD4000-family SAR ADC (AD4000..AD4011, AD4020): CNV rising edge starts a conversion,
//! the result is read MSB first after `t_CONV`. 16-bit parts use 2-byte frames, 18/20-bit
//! parts 3-byte frames, the code left-aligned. Pseudo-differential parts (AD4000/2/6/8/10)
//! deliver straight binary, fully differential ones (AD4001/3/5/7/11/20) two's complement.
//!
//! The configuration register is written with the command `0x14` and read with `0x54`,
//! each followed by one data byte.

use super::Error;
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use embedded_hal::spi::{Operation, SpiDevice};

/// Register write command.
pub const CMD_WRITE: u8 = 0x14;
/// Register read command.
pub const CMD_READ: u8 = 0x54;
/// Configuration register bits.
pub const REG_TURBO: u8 = 1 << 1;
pub const REG_HIGHZ: u8 = 1 << 2;
pub const REG_SPAN_COMPRESSION: u8 = 1 << 3;
pub const REG_STATUS_BITS: u8 = 1 << 4;
/// Conversion time, worst case over the family (ns).
pub const T_CONV_NS: u32 = 320;

/// How the part codes the result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CodeFormat {
    /// `0 ..= 2^bits - 1` (pseudo-differential parts).
    StraightBinary,
    /// `-2^(bits-1) ..= 2^(bits-1) - 1` (differential parts).
    TwosComplement,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ad4000Config {
    /// 16, 18 or 20.
    pub bits: u8,
    pub format: CodeFormat,
    /// Turbo mode (needed for the full throughput in 3-wire mode).
    pub turbo: bool,
    /// High-Z input mode.
    pub high_z: bool,
}

impl Ad4000Config {
    /// AD4020: 20 bit, two's complement, turbo.
    pub const AD4020: Self = Self {
        bits: 20,
        format: CodeFormat::TwosComplement,
        turbo: true,
        high_z: false,
    };

    /// The configuration register value.
    pub fn register(&self) -> u8 {
        (if self.turbo { REG_TURBO } else { 0 }) | (if self.high_z { REG_HIGHZ } else { 0 })
    }

    /// Smallest and largest code.
    pub fn code_range(&self) -> (i32, i32) {
        let full = 1i32 << self.bits.clamp(16, 20);
        match self.format {
            CodeFormat::StraightBinary => (0, full - 1),
            CodeFormat::TwosComplement => (-full / 2, full / 2 - 1),
        }
    }

    fn frame_bytes(&self) -> usize {
        if self.bits <= 16 {
            2
        } else {
            3
        }
    }
}

/// AD4000-family driver.
#[derive(Debug)]
pub struct Ad4000<SPI, CNV> {
    spi: SPI,
    cnv: CNV,
    config: Ad4000Config,
}

impl<SPI: SpiDevice, CNV: OutputPin> Ad4000<SPI, CNV> {
    /// Takes the bus and the CNV pin (driven low: idle).
    pub fn new(
        spi: SPI,
        mut cnv: CNV,
        config: Ad4000Config,
    ) -> Result<Self, Error<SPI::Error, CNV::Error>> {
        if !matches!(config.bits, 16 | 18 | 20) {
            return Err(Error::Config("ad4000.bits must be 16, 18 or 20"));
        }
        cnv.set_low().map_err(Error::Pin)?;
        Ok(Self { spi, cnv, config })
    }

    pub fn config(&self) -> &Ad4000Config {
        &self.config
    }

    /// Writes the configuration register and reads it back.
    pub fn init(&mut self) -> Result<(), Error<SPI::Error, CNV::Error>> {
        let reg = self.config.register();
        self.spi.write(&[CMD_WRITE, reg]).map_err(Error::Spi)?;
        let read = self.read_register()?;
        // Bit 0 is the read-only over-voltage flag.
        if read & !1 != reg {
            return Err(Error::Verify {
                wrote: reg as u32,
                read: read as u32,
            });
        }
        Ok(())
    }

    /// Reads the configuration register.
    pub fn read_register(&mut self) -> Result<u8, Error<SPI::Error, CNV::Error>> {
        let mut buf = [0u8; 2];
        self.spi
            .transaction(&mut [Operation::Transfer(&mut buf, &[CMD_READ, 0xFF])])
            .map_err(Error::Spi)?;
        Ok(buf[1])
    }

    /// CNV rising edge: the input is sampled now and the conversion starts.
    #[inline]
    pub fn start_conversion(&mut self) -> Result<(), Error<SPI::Error, CNV::Error>> {
        self.cnv.set_high().map_err(Error::Pin)
    }

    /// Reads the result of the conversion started last (call `T_CONV_NS` after the start).
    #[inline]
    pub fn read(&mut self) -> Result<i32, Error<SPI::Error, CNV::Error>> {
        self.cnv.set_low().map_err(Error::Pin)?;
        let mut buf = [0u8; 3];
        let n = self.config.frame_bytes();
        let frame = buf.get_mut(..n).unwrap_or(&mut []);
        self.spi.read(frame).map_err(Error::Spi)?;
        Ok(decode(&self.config, buf))
    }

    /// Start, wait the conversion time, read.
    #[inline]
    pub fn convert(
        &mut self,
        delay: &mut impl DelayNs,
    ) -> Result<i32, Error<SPI::Error, CNV::Error>> {
        self.start_conversion()?;
        delay.delay_ns(T_CONV_NS);
        self.read()
    }

    /// Mutable access to the bus (tests, mocks).
    pub fn spi_mut(&mut self) -> &mut SPI {
        &mut self.spi
    }

    pub fn release(self) -> (SPI, CNV) {
        (self.spi, self.cnv)
    }
}

/// Code from a left-aligned MSB-first frame.
#[inline]
pub fn decode(config: &Ad4000Config, buf: [u8; 3]) -> i32 {
    let bits = config.bits.clamp(16, 20) as u32;
    let raw = if config.frame_bytes() == 2 {
        u32::from_be_bytes([0, 0, buf[0], buf[1]])
    } else {
        u32::from_be_bytes([0, buf[0], buf[1], buf[2]]) >> (24 - bits)
    };
    match config.format {
        CodeFormat::StraightBinary => raw as i32,
        // Sign-extend from `bits`.
        CodeFormat::TwosComplement => ((raw << (32 - bits)) as i32) >> (32 - bits),
    }
}

/// Left-aligned MSB-first frame of a code (what the chip shifts out).
#[inline]
pub fn encode(config: &Ad4000Config, code: i32) -> [u8; 3] {
    let bits = config.bits.clamp(16, 20) as u32;
    let raw = (code as u32) & ((1u32 << bits) - 1);
    if config.frame_bytes() == 2 {
        let b = (raw as u16).to_be_bytes();
        [b[0], b[1], 0]
    } else {
        let b = (raw << (24 - bits)).to_be_bytes();
        [b[1], b[2], b[3]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_in_every_format() {
        for bits in [16u8, 18, 20] {
            for format in [CodeFormat::StraightBinary, CodeFormat::TwosComplement] {
                let c = Ad4000Config {
                    bits,
                    format,
                    turbo: true,
                    high_z: false,
                };
                let (lo, hi) = c.code_range();
                for code in [lo, lo + 1, (-1).max(lo), 0, 1, hi / 3, hi - 1, hi] {
                    assert_eq!(
                        decode(&c, encode(&c, code)),
                        code,
                        "{bits} {format:?} {code}"
                    );
                }
            }
        }
        // AD4020 full scale negative: 0x80000 left aligned.
        assert_eq!(
            encode(&Ad4000Config::AD4020, -(1 << 19)),
            [0x80, 0x00, 0x00]
        );
    }
}
