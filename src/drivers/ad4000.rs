//! AD4000-family SAR ADC (AD4000..AD4011, AD4020) in 3-wire CS mode: CNV is both the
//! conversion start and the chip select. A CNV rising edge samples the input and starts a
//! conversion; the interface mode is latched from SDI at that edge (SDI high: CS mode, the
//! one this driver runs; SDI low: daisy-chain mode). CNV stays high for `t_CONV`, then
//! falls and the result is read MSB first. 16-bit parts use 2-byte frames, 18/20-bit parts
//! 3-byte frames, the code left-aligned. Pseudo-differential parts (AD4000/2/6/8/10) deliver
//! straight binary, fully differential ones (AD4001/3/5/7/11/20) two's complement.
//!
//! The configuration register (AD4020 Rev. B, Table 14) holds reserved bits 7:5 that reset
//! to 1 and are written as 1, four mode bits 4:1 and the read-only over-voltage flag in
//! bit 0; its reset value is `0xE1`. A write keeps the reserved bits set and a read-back
//! compares only the mode bits ([`REG_WRITABLE`]).
//!
//! The configuration register is written with the command `0x14` and read with `0x54`,
//! each followed by one data byte, clocked in on SDI as the first bits of a CNV frame (after
//! a CNV rising edge with SDI high and `t_CONV`): outside such a frame the part ignores them.
//! SDI stays at the last bit the bus sent, so every frame here ends with SDI high (all-ones
//! read words, a trailing 0xFF after a register write) and the next CNV edge finds CS mode.
//!
//! With the register's status bit set, six status bits follow the result in every frame
//! (AD4020 Rev. B, "Status Word"): bit 5 the over-voltage clamp flag, bits 4:2 the span
//! compression, high-Z and turbo mode bits as the part holds them, bits 1:0 reserved (not
//! checked here). [`Ad4000::read`] checks bits 5:2 against the configuration on every
//! conversion: an input beyond the span, a part that reset (mode bits back at their reset
//! value) or SDO held low or high fails the read instead of decoding to a plausible code.

use super::{Error, SpiClock};
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use embedded_hal::spi::{Operation, SpiDevice};

/// Register write command.
pub const CMD_WRITE: u8 = 0x14;
/// Register read command.
pub const CMD_READ: u8 = 0x54;
/// Configuration register bits: the reserved bits 7:5 (reset to 1, written as 1), the mode
/// bits 4:1 and the read-only over-voltage flag (bit 0).
pub const REG_RESERVED: u8 = 0b1110_0000;
pub const REG_OV: u8 = 1;
pub const REG_TURBO: u8 = 1 << 1;
pub const REG_HIGHZ: u8 = 1 << 2;
pub const REG_SPAN_COMPRESSION: u8 = 1 << 3;
pub const REG_STATUS_BITS: u8 = 1 << 4;
/// The bits a write sets (the mode bits).
pub const REG_WRITABLE: u8 = REG_TURBO | REG_HIGHZ | REG_SPAN_COMPRESSION | REG_STATUS_BITS;
/// The register's value at power-up.
pub const REG_RESET: u8 = 0xE1;
/// Status word (six bits after the result): the over-voltage flag and the mode bits.
pub const STATUS_OV: u8 = 1 << 5;
pub const STATUS_BITS: u32 = 6;
/// The status bits [`Ad4000::read`] checks (bits 1:0 are reserved).
pub const STATUS_CHECKED: u8 = 0b11_1100;
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
    /// Status bits after every result, checked on every read.
    pub status: bool,
    /// SCK rate the board runs the part at (Hz); the driver asks the bus for at most this
    /// and at most [`SCK_MAX_HZ`].
    pub sck_hz: u32,
}

impl Ad4000Config {
    /// AD4020: 20 bit, two's complement, turbo, status bits, 25 MHz SCK.
    pub const AD4020: Self = Self {
        bits: 20,
        format: CodeFormat::TwosComplement,
        turbo: true,
        high_z: false,
        status: true,
        sck_hz: 25_000_000,
    };

    /// The configuration register value to write: the reset value's reserved bits and
    /// read-only flag as they are, the mode bits as configured.
    pub fn register(&self) -> u8 {
        (REG_RESET & !REG_WRITABLE)
            | (if self.turbo { REG_TURBO } else { 0 })
            | (if self.high_z { REG_HIGHZ } else { 0 })
            | (if self.status { REG_STATUS_BITS } else { 0 })
    }

    /// The status word of a good conversion under this configuration (the bits of
    /// [`STATUS_CHECKED`]): no over-voltage, the mode bits as written.
    pub fn status_word(&self) -> u8 {
        status_of(self.register(), false)
    }

    /// Smallest and largest code.
    pub fn code_range(&self) -> (i32, i32) {
        let full = 1i32 << self.bits.clamp(16, 20);
        match self.format {
            CodeFormat::StraightBinary => (0, full - 1),
            CodeFormat::TwosComplement => (-full / 2, full / 2 - 1),
        }
    }

    /// Bits of a frame: the result and, if enabled, the status word.
    fn frame_bits(&self) -> u32 {
        self.bits.clamp(16, 20) as u32 + if self.status { STATUS_BITS } else { 0 }
    }

    /// Bytes of a conversion frame (2 to 4).
    pub fn frame_bytes(&self) -> usize {
        self.frame_bits().div_ceil(8) as usize
    }
}

/// The status word a part with register `reg` sends (bits 5:2; 1:0 reserved, 0 here).
pub fn status_of(reg: u8, over_voltage: bool) -> u8 {
    (if over_voltage { STATUS_OV } else { 0 })
        | ((reg & (REG_SPAN_COMPRESSION | REG_HIGHZ | REG_TURBO)) << 1)
}

/// All-ones words: a read that holds SDI high (no register command, CS mode at the next
/// CNV edge).
const ONES: [u8; 4] = [0xFF; 4];

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
        // Only the mode bits are the driver's: the reserved bits and the over-voltage flag
        // read whatever the part holds.
        if (read ^ reg) & REG_WRITABLE != 0 {
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
    /// after the start) and the frame is clocked out with SDI held high. With status bits
    /// on, a status word other than [`Ad4000Config::status_word`] is
    /// [`Error::Status`].
    #[inline]
    pub fn read(&mut self) -> Result<i32, Error<SPI::Error, CNV::Error>> {
        self.cnv.set_low().map_err(Error::Pin)?;
        let mut buf = [0u8; 4];
        let n = self.config.frame_bytes();
        let frame = buf.get_mut(..n).unwrap_or(&mut []);
        self.spi
            .transaction(&mut [Operation::Transfer(frame, ONES.get(..n).unwrap_or(&ONES))])
            .map_err(Error::Spi)?;
        if self.config.status {
            let s = status(&self.config, buf);
            if s & STATUS_CHECKED != self.config.status_word() {
                return Err(Error::Status(s));
            }
        }
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

/// The frame as a left-aligned word (bytes past the frame are ignored).
#[inline]
fn word(config: &Ad4000Config, buf: [u8; 4]) -> u32 {
    let n = config.frame_bytes() as u32;
    u32::from_be_bytes(buf) & !(u32::MAX.checked_shr(8 * n).unwrap_or(0))
}

/// Code from a left-aligned MSB-first frame.
#[inline]
pub fn decode(config: &Ad4000Config, buf: [u8; 4]) -> i32 {
    let bits = config.bits.clamp(16, 20) as u32;
    let raw = word(config, buf) >> (32 - bits);
    match config.format {
        CodeFormat::StraightBinary => raw as i32,
        // Sign-extend from `bits`.
        CodeFormat::TwosComplement => ((raw << (32 - bits)) as i32) >> (32 - bits),
    }
}

/// The status word of a frame (0 without status bits).
#[inline]
pub fn status(config: &Ad4000Config, buf: [u8; 4]) -> u8 {
    if !config.status {
        return 0;
    }
    let bits = config.bits.clamp(16, 20) as u32;
    ((word(config, buf) << bits) >> (32 - STATUS_BITS)) as u8
}

/// Left-aligned MSB-first frame of a code and status word (what the chip shifts out; the
/// status word only with status bits on; zeros past the frame).
#[inline]
pub fn encode(config: &Ad4000Config, code: i32, status: u8) -> [u8; 4] {
    let bits = config.bits.clamp(16, 20) as u32;
    let raw = (code as u32) & ((1u32 << bits) - 1);
    let (w, total) = if config.status {
        (
            (raw << STATUS_BITS) | (status as u32 & 0x3F),
            bits + STATUS_BITS,
        )
    } else {
        (raw, bits)
    };
    (w << (32 - total)).to_be_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn register_keeps_the_reserved_bits_of_the_reset_value() {
        let r = Ad4000Config::AD4020.register();
        assert_eq!(r & REG_RESERVED, REG_RESERVED);
        assert_eq!(r & REG_WRITABLE, REG_TURBO | REG_STATUS_BITS);
        assert_eq!(REG_RESET & REG_WRITABLE, 0);
    }

    #[test]
    fn frames_round_trip_in_every_format() {
        for bits in [16u8, 18, 20] {
            for format in [CodeFormat::StraightBinary, CodeFormat::TwosComplement] {
                for st in [false, true] {
                    let c = Ad4000Config {
                        bits,
                        format,
                        turbo: true,
                        high_z: false,
                        status: st,
                        sck_hz: 25_000_000,
                    };
                    let (lo, hi) = c.code_range();
                    for code in [lo, lo + 1, (-1).max(lo), 0, 1, hi / 3, hi - 1, hi] {
                        let f = encode(&c, code, 0b10_0111);
                        assert_eq!(decode(&c, f), code, "{bits} {format:?} {code}");
                        assert_eq!(status(&c, f), if st { 0b10_0111 } else { 0 });
                    }
                }
            }
        }
        // AD4020 full scale negative: 0x80000 left aligned, then the status word: 26 bits.
        let c = Ad4000Config::AD4020;
        assert_eq!(c.frame_bytes(), 4);
        assert_eq!(encode(&c, -(1 << 19), 0), [0x80, 0x00, 0x00, 0x00]);
        assert_eq!(encode(&c, 0, 0b10_0000), [0x00, 0x00, 0x08, 0x00]);
        // Turbo on, status on: the status word of a good conversion shows turbo only.
        assert_eq!(c.status_word(), 0b00_0100);
        // SDO held low or high fails the status check.
        assert_ne!(status(&c, [0; 4]) & STATUS_CHECKED, c.status_word());
        assert_ne!(status(&c, [0xFF; 4]) & STATUS_CHECKED, c.status_word());
    }
}
