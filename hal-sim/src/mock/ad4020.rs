//! The AD4000-family ADC mock (AD4020 by default), 3-wire CS mode.
//!
//! Rules enforced (AD4020 data sheet Rev. B; the AD4000 family shares them):
//! * the interface mode is latched from SDI at the CNV rising edge: SDI high selects CS mode
//!   (the one wired here), SDI low daisy-chain mode, in which any frame is refused;
//! * CNV stays high for `t_CONV` max = 320 ns (Table 3) before it falls (a read before the
//!   conversion is done);
//! * no SPI frame while CNV is high (CNV is the chip select in 3-wire mode);
//! * a register command (`0x14` write, `0x54` read) is only taken as the first bits of a
//!   CNV frame (after a rising edge in CS mode): elsewhere, e.g. with CNV low since power-up,
//!   the part ignores it, so the mock refuses it;
//! * SCK period `t_SCK` >= 9.8 ns (Table 3, VIO above 2.7 V);
//! * the configuration register resets to `0xE1` (Table 14): its reserved bits 7:5 read 1
//!   and must be written as 1 (a write with any of them 0 is refused), bits 4:1 are the
//!   mode bits, bit 0 the read-only over-voltage flag;
//! * with the register's status bit set, six status bits follow each result (over-voltage
//!   clamp flag for an input beyond the span, the mode bits as the register holds them).
//!
//! Fault injection ([`MockAdc::set_fault`], [`AdcFault`]): SDO held low or high, an input
//! left floating (the code frozen), a sensor disconnected (the input pulled near a rail).

use super::{BusClock, MockClock, MockPinError, MockSpiError, Violations};
use crate::numeric::Rng;
use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use piezo_core::drivers::ad4000::{self, Ad4000Config, CodeFormat};
use piezo_core::drivers::{wire, SpiClock};
use std::cell::RefCell;
use std::rc::Rc;

/// `t_CONV` max (ns), AD4020 Rev. B Table 3.
const T_CONV_MAX_NS: u64 = 320;
/// Fastest SCK (Hz): `t_SCK` >= 9.8 ns, AD4020 Rev. B Table 3 (VIO above 2.7 V).
const SCK_MAX_HZ: u32 = 102_040_816;

/// Analog imperfections of the position ADC.
#[derive(Debug, Clone, PartialEq)]
pub struct AdcSpec {
    pub config: Ad4000Config,
    /// Reference (V): input span `+-vref` (two's complement) or `0..vref` (straight binary).
    pub vref: f64,
    pub offset_lsb: f64,
    pub gain_error: f64,
    pub noise_lsb: f64,
    /// Actual conversion time (ns), at most the data sheet's 320 ns.
    pub t_conv_ns: u64,
    pub seed: u64,
    /// The bus the part sits on.
    pub bus: BusClock,
}

impl Default for AdcSpec {
    fn default() -> Self {
        Self {
            config: Ad4000Config::AD4020,
            vref: 5.0,
            offset_lsb: 0.0,
            gain_error: 0.0,
            noise_lsb: 0.0,
            t_conv_ns: 290,
            seed: 7,
            bus: BusClock::default(),
        }
    }
}

/// Counters of the ADC mock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AdcStats {
    pub conversions: u64,
    /// Reads before the conversion finished (they return the previous result).
    pub early_reads: u64,
    pub register_writes: u64,
    pub failed_transactions: u64,
}

/// A fault of the position channel ([`MockAdc::set_fault`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdcFault {
    /// SDO held low (a short, a part without supply): every bit clocked out reads 0, so a
    /// two's complement result decodes to 0 (mid-stroke) and the status word to 0.
    StuckLow,
    /// SDO held high: every bit reads 1 (code -1, mid-stroke; status all ones).
    StuckHigh,
    /// The input left floating: the sampling capacitor keeps its charge and every
    /// conversion returns the code of the last conversion before the fault, noise-free,
    /// with a good status word.
    Floating,
    /// The sensor disconnected: its input pulled by the front end's bias network to
    /// [`DISCONNECTED_FRACTION`] of the positive full scale (inside the span: no
    /// over-voltage), converted with the usual noise.
    Disconnected,
}

/// Where a disconnected sensor's input settles, as a fraction of the positive full scale.
pub const DISCONNECTED_FRACTION: f64 = 0.97;

/// What the CNV-low period in progress is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Frame {
    /// No CNV rising edge since power-up: reads shift out the last result, commands are
    /// ignored.
    PowerUp,
    /// After a CNV rising edge with SDI high: CS mode.
    Cs,
    /// After a CNV rising edge with SDI low: daisy-chain mode (not wired here).
    Chain,
}

#[derive(Debug)]
struct AdcChip {
    spec: AdcSpec,
    /// Codes per input volt, gain error included.
    codes_per_volt: f64,
    clock: MockClock,
    rng: Rng,
    /// Code range, for [`Self::quantise`].
    code_lo: i32,
    code_lo_f: f64,
    /// `hi - lo + 0.5`
    code_top_f: f64,
    input_volts: f64,
    reg: u8,
    cnv_high: bool,
    /// SDI (MOSI) level: the last bit sent; low until the bus sends a one.
    sdi_high: bool,
    frame: Frame,
    rise_ns: u64,
    /// Bytes clocked since CNV fell (a command counts only at the start of a CS frame).
    clocked: u32,
    converting: i32,
    ready_at_ns: u64,
    result: i32,
    /// The frames of `converting` and `result` (encoded once per conversion, not per read).
    converting_frame: [u8; 4],
    result_frame: [u8; 4],
    stuck: Option<i32>,
    fault: Option<AdcFault>,
    /// The code a floating input keeps.
    floating_code: i32,
    fail_next: u32,
    stats: AdcStats,
    violations: Violations,
}

impl AdcChip {
    fn codes_per_volt(spec: &AdcSpec) -> f64 {
        let c = &spec.config;
        let full = (1u64 << c.bits) as f64;
        let span = match c.format {
            CodeFormat::TwosComplement => 2.0 * spec.vref,
            CodeFormat::StraightBinary => spec.vref,
        };
        (1.0 + spec.gain_error) / span * full
    }

    #[cold]
    fn violate(&mut self, rule: &'static str, measured: u64) -> MockSpiError {
        let now = self.clock.now_ns();
        MockSpiError::Violation(self.violations.record(rule, now, measured))
    }

    /// The frame a read shifts out: the finished conversion, or the previous result if
    /// the conversion is still running (counted).
    #[inline]
    fn conversion_frame(&mut self) -> [u8; 4] {
        let now = self.clock.now_ns();
        if !self.cnv_high && self.ready_at_ns <= now {
            self.result = self.converting;
            self.result_frame = self.converting_frame;
            // Straight from the conversion (one store-to-load hop less on the loop's chain).
            self.converting_frame
        } else {
            self.stats.early_reads += 1;
            self.result_frame
        }
    }

    /// CNV rising edge: latches the interface mode from SDI, samples the input and starts a
    /// conversion.
    #[inline]
    fn rise(&mut self) {
        let (code, over) = match (self.stuck, self.fault) {
            (Some(c), _) => (c, false),
            (None, Some(AdcFault::Floating)) => (self.floating_code, false),
            (None, Some(AdcFault::Disconnected)) => {
                self.quantise(DISCONNECTED_FRACTION * self.spec.vref)
            }
            _ => self.quantise(self.input_volts),
        };
        self.frame = if self.sdi_high {
            Frame::Cs
        } else {
            Frame::Chain
        };
        self.rise_ns = self.clock.now_ns();
        self.converting = code;
        let reg = self.reg;
        let cfg = Ad4000Config {
            status: reg & ad4000::REG_STATUS_BITS != 0,
            ..self.spec.config
        };
        self.converting_frame = ad4000::encode(&cfg, code, ad4000::status_of(reg, over));
        self.ready_at_ns = self.rise_ns + self.spec.t_conv_ns;
        self.stats.conversions += 1;
    }

    /// The code of `volts` and whether the input is beyond the span (the over-voltage
    /// clamp flag).
    #[inline]
    fn quantise(&mut self, volts: f64) -> (i32, bool) {
        let lo = self.code_lo_f;
        let noise = if self.spec.noise_lsb > 0.0 {
            self.spec.noise_lsb * self.rng.gauss()
        } else {
            0.0
        };
        let x = volts * self.codes_per_volt + self.spec.offset_lsb + noise;
        if x.is_nan() {
            return (self.code_lo, true);
        }
        // Round half up without a libm call: shift to positive, truncate (the shifted value
        // is kept in `0 ..= hi - lo + 0.5`, so truncation is the floor and the code is in
        // range).
        let x = x - lo + 0.5;
        let over = !(0.0..=self.code_top_f).contains(&x);
        let x = x.max(0.0).min(self.code_top_f);
        (x as i32 + self.code_lo, over)
    }

    /// SDO held at one level: every byte clocked out is that level.
    #[inline]
    fn sdo_held(&self) -> Option<u8> {
        match self.fault {
            Some(AdcFault::StuckLow) => Some(0),
            Some(AdcFault::StuckHigh) => Some(0xFF),
            _ => None,
        }
    }

    /// Any SPI transaction: the interface rules, register access or conversion read,
    /// injected failures.
    #[inline(never)]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), MockSpiError> {
        if self.fail_next > 0 {
            self.fail_next -= 1;
            self.stats.failed_transactions += 1;
            return Err(MockSpiError::Injected);
        }
        if self.cnv_high {
            return Err(self.violate(
                "SPI frame while CNV is high (CNV is the 3-wire chip select)",
                0,
            ));
        }
        if self.spec.bus.hz > SCK_MAX_HZ {
            let hz = self.spec.bus.hz as u64;
            return Err(self.violate("SCK above 102 MHz (t_SCK >= 9.8 ns)", hz));
        }
        if self.frame == Frame::Chain {
            // Refused, but the bus still drives MOSI.
            self.sdi_high = wire::last_mosi_high(ops, self.sdi_high);
            return Err(self.violate(
                "frame in daisy-chain mode: SDI was low at the CNV rising edge",
                0,
            ));
        }
        let (mosi, n) = wire::mosi_head::<2>(ops);
        let start = self.frame == Frame::Cs && self.clocked == 0;
        let command = matches!(mosi[0], ad4000::CMD_WRITE | ad4000::CMD_READ) && n > 0;
        if command && !start {
            return Err(self.violate(
                "register access outside a CNV frame (the part ignores it)",
                0,
            ));
        }
        let out: [u8; 4] = match mosi[0] {
            ad4000::CMD_WRITE if command && n >= 2 => {
                if mosi[1] & ad4000::REG_RESERVED != ad4000::REG_RESERVED {
                    return Err(self.violate(
                        "configuration register write with reserved bits 7:5 not 1",
                        mosi[1] as u64,
                    ));
                }
                // Only the mode bits take the write.
                let w = ad4000::REG_WRITABLE;
                self.reg = (self.reg & !w) | (mosi[1] & w);
                self.stats.register_writes += 1;
                [0xFF; 4]
            }
            ad4000::CMD_READ if command => [0xFF, self.reg, 0xFF, 0xFF],
            _ if start => self.conversion_frame(),
            // Power-up (no conversion yet) or past the result: the last result, zeros.
            _ if self.frame == Frame::PowerUp => self.result_frame,
            _ => [0; 4],
        };
        let out = self.sdo_held().map_or(out, |b| [b; 4]);
        self.sdi_high = wire::last_mosi_high(ops, self.sdi_high);
        let clock = &mut self.clock;
        let k = wire::clock_miso(ops, &out, |ns| clock.advance_ns(ns as u64));
        self.clocked = self.clocked.saturating_add(k.max(1) as u32);
        Ok(())
    }
}

/// The AD4000-family mock; clone handles freely.
#[derive(Debug, Clone)]
pub struct MockAdc(Rc<RefCell<AdcChip>>);

impl MockAdc {
    pub fn new(spec: AdcSpec, clock: MockClock) -> Self {
        let rng = Rng::new(spec.seed);
        let (lo, hi) = spec.config.code_range();
        let zero = ad4000::encode(&spec.config, 0, 0);
        Self(Rc::new(RefCell::new(AdcChip {
            codes_per_volt: AdcChip::codes_per_volt(&spec),
            code_lo: lo,
            code_lo_f: lo as f64,
            code_top_f: (hi - lo) as f64 + 0.5,
            converting_frame: zero,
            result_frame: zero,
            spec,
            clock,
            rng,
            input_volts: 0.0,
            fault: None,
            floating_code: 0,
            reg: ad4000::REG_RESET,
            cnv_high: false,
            sdi_high: false,
            frame: Frame::PowerUp,
            rise_ns: 0,
            clocked: 0,
            converting: 0,
            ready_at_ns: 0,
            result: 0,
            stuck: None,
            fail_next: 0,
            stats: AdcStats::default(),
            violations: Violations::default(),
        })))
    }

    /// The SPI device of the chip.
    pub fn spi(&self) -> MockAdcSpi {
        MockAdcSpi(self.0.clone())
    }

    /// The CNV pin.
    pub fn cnv(&self) -> MockCnv {
        MockCnv(self.0.clone())
    }

    /// The analog input (V), sampled at the next CNV rising edge.
    #[inline]
    pub fn set_input_volts(&self, v: f64) {
        self.0.borrow_mut().input_volts = v;
    }

    pub fn stats(&self) -> AdcStats {
        self.0.borrow().stats
    }

    /// The data-sheet rules broken so far.
    pub fn violations(&self) -> super::Violations {
        self.0.borrow().violations
    }

    /// Configuration register as the chip holds it.
    pub fn register(&self) -> u8 {
        self.0.borrow().reg
    }

    /// The bus clock now.
    pub fn bus(&self) -> BusClock {
        self.0.borrow().spec.bus
    }

    /// Fault injection: every conversion returns `code` (or normal again with `None`).
    pub fn set_stuck_code(&self, code: Option<i32>) {
        self.0.borrow_mut().stuck = code;
    }

    /// Fault injection: a fault of the position channel from the next conversion on (or
    /// none again with `None`). A floating input keeps the last conversion's code.
    pub fn set_fault(&self, fault: Option<AdcFault>) {
        let mut chip = self.0.borrow_mut();
        chip.floating_code = chip.result;
        chip.fault = fault;
    }

    /// Fault injection: the next `n` transactions fail.
    pub fn fail_transactions(&self, n: u32) {
        self.0.borrow_mut().fail_next = n;
    }
}

/// SPI side of [`MockAdc`].
#[derive(Debug)]
pub struct MockAdcSpi(Rc<RefCell<AdcChip>>);

impl ErrorType for MockAdcSpi {
    type Error = MockSpiError;
}

impl SpiClock for MockAdcSpi {
    fn set_sclk_max_hz(&mut self, max_hz: u32) -> u32 {
        self.0.borrow_mut().spec.bus.set_max(max_hz)
    }
}

impl SpiDevice for MockAdcSpi {
    #[inline]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), MockSpiError> {
        let mut chip = self.0.borrow_mut();
        // The loop's one read frame (SDI held high, at the start of a CS frame): the
        // conversion result. Inlined into the driver's read; everything else takes the
        // general path, which checks every rule.
        if let [Operation::Transfer(r, w)] = &mut *ops {
            if r.len() == w.len()
                && r.len() <= 4
                && w.iter().all(|b| *b == 0xFF)
                && chip.fail_next == 0
                && chip.fault.is_none()
                && !chip.cnv_high
                && chip.frame == Frame::Cs
                && chip.clocked == 0
                && chip.spec.bus.hz <= SCK_MAX_HZ
            {
                let f = chip.conversion_frame();
                for (d, s) in r.iter_mut().zip(f) {
                    *d = s;
                }
                chip.sdi_high = true;
                chip.clocked = r.len() as u32;
                return Ok(());
            }
        }
        chip.transaction(ops)
    }
}

/// CNV pin of [`MockAdc`]: the rising edge latches the mode, samples the input and starts a
/// conversion; the falling edge (before `t_CONV` is a violation) selects the part.
#[derive(Debug)]
pub struct MockCnv(Rc<RefCell<AdcChip>>);

impl PinErrorType for MockCnv {
    type Error = MockPinError;
}

impl OutputPin for MockCnv {
    #[inline]
    fn set_high(&mut self) -> Result<(), MockPinError> {
        let mut chip = self.0.borrow_mut();
        if !chip.cnv_high {
            chip.rise();
        }
        chip.cnv_high = true;
        Ok(())
    }
    #[inline]
    fn set_low(&mut self) -> Result<(), MockPinError> {
        let mut chip = self.0.borrow_mut();
        if !chip.cnv_high {
            return Ok(());
        }
        chip.cnv_high = false;
        chip.clocked = 0;
        let high_ns = chip.clock.now_ns().saturating_sub(chip.rise_ns);
        if high_ns < T_CONV_MAX_NS {
            let now = chip.clock.now_ns();
            let rule = "CNV fell before t_CONV max = 320 ns (read before the conversion is done)";
            return Err(MockPinError(chip.violations.record(rule, now, high_ns)));
        }
        Ok(())
    }
}
