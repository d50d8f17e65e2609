//! AD4000-family SAR ADC (AD4000..AD4011, AD4020) in 3-wire CS mode: CNV is both the
//! conversion start and the chip select. A CNV rising edge samples the input and starts a
//! conversion; the interface mode is latched from SDI at that edge (SDI high: CS mode, the
//! one this driver runs; SDI low: daisy-chain mode). CNV stays high for `t_CONV`, then
//! falls and the result is read MSB first. 16-bit parts use 2-byte frames, 18/20-bit parts
//! 3-byte frames, the code left-aligned. Pseudo-differential parts (AD4000/2/6/8/10) deliver
//! straight binary, fully differential ones (AD4001/3/5/7/11/20) two's complement.
//!
//! The configuration register is written with the command `0x14` and read with `0x54`,
//! each followed by one data byte, clocked in on SDI as the first bits of a CNV frame (after
//! a CNV rising edge with SDI high and `t_CONV`): outside such a frame the part ignores them.
//! SDI stays at the last bit the bus sent, so every frame here ends with SDI high (all-ones
//! read words, a trailing 0xFF after a register write) and the next CNV edge finds CS mode.

use super::{Error, SpiClock};
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
/// Conversion time, the datasheet maximum (AD4020 data sheet Rev. B, Table 3, `t_CONV`
/// max 320 ns; the AD4000/AD4003 family's is the same): CNV must stay high this long.
pub const T_CONV_NS: u32 = 320;
/// Fastest SCK (AD4020 Rev. B, Table 3: `t_SCK` >= 9.8 ns with VIO above 2.7 V).
pub const SCK_MAX_HZ: u32 = 102_040_816;

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
    /// SCK rate the board runs the part at (Hz); the driver asks the bus for at most this
    /// and at most [`SCK_MAX_HZ`].
    pub sck_hz: u32,
}

impl Ad4000Config {
    /// AD4020: 20 bit, two's complement, turbo, 25 MHz SCK.
    pub const AD4020: Self = Self {
        bits: 20,
        format: CodeFormat::TwosComplement,
        turbo: true,
        high_z: false,
        sck_hz: 25_000_000,
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

/// All-ones words: a read that holds SDI high (no register command, CS mode at the next
/// CNV edge).
const ONES: [u8; 3] = [0xFF; 3];

/// AD4000-family driver: the bus, the CNV pin (a GPIO while configuring; on a board whose
/// timer drives CNV, a no-op pin afterwards) and a delay for `t_CONV`.
#[derive(Debug)]
pub struct Ad4000<SPI, CNV, D> {
    spi: SPI,
    cnv: CNV,
    delay: D,
    config: Ad4000Config,
}

impl<SPI: SpiDevice + SpiClock, CNV: OutputPin, D: DelayNs> Ad4000<SPI, CNV, D> {
    /// Takes the bus, the CNV pin (driven low: idle) and a delay.
    pub fn new(
        spi: SPI,
        mut cnv: CNV,
        delay: D,
        config: Ad4000Config,
    ) -> Result<Self, Error<SPI::Error, CNV::Error>> {
        if !matches!(config.bits, 16 | 18 | 20) {
            return Err(Error::Config("ad4000.bits must be 16, 18 or 20"));
        }
        if config.sck_hz == 0 {
            return Err(Error::Config("ad4000.sck_hz must be above 0"));
        }
        cnv.set_low().map_err(Error::Pin)?;
        Ok(Self {
            spi,
            cnv,
            delay,
            config,
        })
    }

    pub fn config(&self) -> &Ad4000Config {
        &self.config
    }

    /// Writes the configuration register and reads it back, each in a CNV frame of its own
    /// (CNV must be this driver's GPIO here). Leaves CNV low and SDI high.
    pub fn init(&mut self) -> Result<(), Error<SPI::Error, CNV::Error>> {
        let hz = self.config.sck_hz.min(SCK_MAX_HZ);
        if self.spi.set_sclk_max_hz(hz) == 0 {
            return Err(Error::Config("ad4000: the bus cannot run SCK that slow"));
        }
        // SDI high before the first CNV edge: an all-ones read with CNV low (the part shifts
        // out its last result; all-ones SDI is no command).
        self.spi.write(&ONES[..1]).map_err(Error::Spi)?;
        let reg = self.config.register();
        self.frame(&mut [0; 3], &[CMD_WRITE, reg, 0xFF])?;
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

    /// Reads the configuration register (in a CNV frame of its own: CNV must be this
    /// driver's GPIO).
    pub fn read_register(&mut self) -> Result<u8, Error<SPI::Error, CNV::Error>> {
        let mut buf = [0u8; 3];
        self.frame(&mut buf, &[CMD_READ, 0xFF, 0xFF])?;
        Ok(buf[1])
    }

    /// One CNV frame: rising edge (SDI is high: CS mode), `t_CONV`, falling edge, then
    /// `mosi` clocked in and the part's SDO into `miso`.
    fn frame(&mut self, miso: &mut [u8], mosi: &[u8]) -> Result<(), Error<SPI::Error, CNV::Error>> {
        self.cnv.set_high().map_err(Error::Pin)?;
        self.delay.delay_ns(T_CONV_NS);
        self.cnv.set_low().map_err(Error::Pin)?;
        self.spi
            .transaction(&mut [Operation::Transfer(miso, mosi)])
            .map_err(Error::Spi)
    }

    /// CNV rising edge: the input is sampled now and the conversion starts.
    #[inline]
    pub fn start_conversion(&mut self) -> Result<(), Error<SPI::Error, CNV::Error>> {
        self.cnv.set_high().map_err(Error::Pin)
    }

    /// Reads the result of the conversion started last: CNV falls (call it [`T_CONV_NS`]
    /// after the start) and the frame is clocked out with SDI held high.
    #[inline]
    pub fn read(&mut self) -> Result<i32, Error<SPI::Error, CNV::Error>> {
        self.cnv.set_low().map_err(Error::Pin)?;
        let mut buf = [0u8; 3];
        let n = self.config.frame_bytes();
        let frame = buf.get_mut(..n).unwrap_or(&mut []);
        self.spi
            .transaction(&mut [Operation::Transfer(frame, ONES.get(..n).unwrap_or(&ONES))])
            .map_err(Error::Spi)?;
        Ok(decode(&self.config, buf))
    }

    /// Start, wait the conversion time, read.
    #[inline]
    pub fn convert(&mut self) -> Result<i32, Error<SPI::Error, CNV::Error>> {
        self.start_conversion()?;
        self.delay.delay_ns(T_CONV_NS);
        self.read()
    }

    /// Mutable access to the bus (tests, mocks).
    pub fn spi_mut(&mut self) -> &mut SPI {
        &mut self.spi
    }

    pub fn release(self) -> (SPI, CNV, D) {
        (self.spi, self.cnv, self.delay)
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
                    sck_hz: 25_000_000,
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
