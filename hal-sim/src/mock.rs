//! Mock converters implementing embedded-hal 1.0, behaving like the chips the firmware
//! drives: an AD4000-family position ADC and an AD5791 DAC (register maps, code formats,
//! frame layout), with quantisation, offset and gain error, noise and conversion latency.
//!
//! Each chip is one shared state (`Rc<RefCell<..>>`) seen through several handles: the SPI
//! device, the control pin (CNV or LDAC) and the simulation's analog side. Time comes from a
//! shared [`MockClock`] advanced by [`MockDelay`] and by the simulation loop.

use crate::numeric::Rng;
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{self, ErrorType, Operation, SpiDevice};
use piezo_core::drivers::ad4000::{self, Ad4000Config, CodeFormat};
use piezo_core::drivers::ad5791::{
    CTRL_BIN2SC, CTRL_DACTRI, CTRL_OPGND, DATA_MASK, READ, REG_CLEARCODE, REG_CTRL, REG_DAC,
    REG_SWCTRL, SW_CLR, SW_LDAC, SW_RESET,
};
use std::cell::{Cell, RefCell};
use std::convert::Infallible;
use std::rc::Rc;

/// Simulated time in nanoseconds, shared by the mocks.
#[derive(Debug, Clone, Default)]
pub struct MockClock(Rc<Cell<u64>>);

impl MockClock {
    #[inline]
    pub fn now_ns(&self) -> u64 {
        self.0.get()
    }
    #[inline]
    pub fn advance_ns(&self, ns: u64) {
        self.0.set(self.0.get().saturating_add(ns));
    }
    /// Moves the clock to `ns` if that is later.
    #[inline]
    pub fn set_ns(&self, ns: u64) {
        if ns > self.0.get() {
            self.0.set(ns);
        }
    }
}

/// `DelayNs` that advances the simulated clock instead of waiting.
#[derive(Debug, Clone)]
pub struct MockDelay(pub MockClock);

impl DelayNs for MockDelay {
    #[inline]
    fn delay_ns(&mut self, ns: u32) {
        self.0.advance_ns(ns as u64);
    }
}

/// An injected bus failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MockSpiError;

impl spi::Error for MockSpiError {
    fn kind(&self) -> spi::ErrorKind {
        spi::ErrorKind::Other
    }
}

/// Analog imperfections of the position ADC.
#[derive(Debug, Clone, PartialEq)]
pub struct AdcSpec {
    pub config: Ad4000Config,
    /// Reference (V): input span `+-vref` (two's complement) or `0..vref` (straight binary).
    pub vref: f64,
    pub offset_lsb: f64,
    pub gain_error: f64,
    pub noise_lsb: f64,
    /// Actual conversion time (ns), at most the datasheet's `T_CONV_NS`.
    pub t_conv_ns: u64,
    pub seed: u64,
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
    converting: i32,
    ready_at_ns: u64,
    result: i32,
    /// The frames of `converting` and `result` (encoded once per conversion, not per read).
    converting_frame: [u8; 3],
    result_frame: [u8; 3],
    stuck: Option<i32>,
    fail_next: u32,
    stats: AdcStats,
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

    /// The frame a read shifts out: the finished conversion, or the previous result if
    /// the conversion is still running (counted).
    #[inline]
    fn conversion_frame(&mut self) -> [u8; 3] {
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

    /// CNV rising edge: samples the input and starts a conversion.
    #[inline]
    fn start_conversion(&mut self) {
        let code = match self.stuck {
            Some(c) => c,
            None => self.quantise(self.input_volts),
        };
        self.converting = code;
        self.converting_frame = ad4000::encode(&self.spec.config, code);
        self.ready_at_ns = self.clock.now_ns() + self.spec.t_conv_ns;
        self.stats.conversions += 1;
    }

    #[inline]
    fn quantise(&mut self, volts: f64) -> i32 {
        let lo = self.code_lo_f;
        let noise = if self.spec.noise_lsb > 0.0 {
            self.spec.noise_lsb * self.rng.gauss()
        } else {
            0.0
        };
        let x = volts * self.codes_per_volt + self.spec.offset_lsb + noise;
        if x.is_nan() {
            return self.code_lo;
        }
        // Round half up without a libm call: shift to positive, truncate (the shifted value
        // is kept in `0 ..= hi - lo + 0.5`, so truncation is the floor and the code is in
        // range).
        let x = (x - lo + 0.5).max(0.0).min(self.code_top_f);
        x as i32 + self.code_lo
    }
}

/// The AD4000-family mock; clone handles freely.
#[derive(Debug, Clone)]
pub struct MockAdc(Rc<RefCell<AdcChip>>);

impl MockAdc {
    pub fn new(spec: AdcSpec, clock: MockClock) -> Self {
        let rng = Rng::new(spec.seed);
        let (lo, hi) = spec.config.code_range();
        let zero = ad4000::encode(&spec.config, 0);
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
            reg: 0,
            cnv_high: false,
            converting: 0,
            ready_at_ns: 0,
            result: 0,
            stuck: None,
            fail_next: 0,
            stats: AdcStats::default(),
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

    /// Configuration register as the chip holds it.
    pub fn register(&self) -> u8 {
        self.0.borrow().reg
    }

    /// Fault injection: every conversion returns `code` (or normal again with `None`).
    pub fn set_stuck_code(&self, code: Option<i32>) {
        self.0.borrow_mut().stuck = code;
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

impl SpiDevice for MockAdcSpi {
    #[inline]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), MockSpiError> {
        let mut chip = self.0.borrow_mut();
        // The loop's one read frame (SDI idle high): the conversion result. Inlined into
        // the driver's read; everything else takes the general path.
        if let ([Operation::Read(r)], 0) = (&mut *ops, chip.fail_next) {
            if let Ok(r) = <&mut [u8; 3]>::try_from(&mut **r) {
                *r = chip.conversion_frame();
                return Ok(());
            }
        }
        chip.transaction(ops)
    }
}

impl AdcChip {
    /// Any SPI transaction: register access or conversion read, injected failures.
    #[inline(never)]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), MockSpiError> {
        let chip = self;
        if chip.fail_next > 0 {
            chip.fail_next -= 1;
            chip.stats.failed_transactions += 1;
            return Err(MockSpiError);
        }
        // The first MOSI byte selects a register access; otherwise the frame shifts out
        // the conversion result (SDI idles high).
        let mut mosi = [0xFFu8; 2];
        let mut n = 0;
        for op in ops.iter() {
            let bytes: &[u8] = match op {
                Operation::Write(w) => w,
                Operation::Transfer(_, w) => w,
                Operation::TransferInPlace(b) => b,
                _ => &[],
            };
            for b in bytes {
                if n < 2 {
                    mosi[n] = *b;
                    n += 1;
                }
            }
        }
        let out: [u8; 3] = match mosi[0] {
            ad4000::CMD_WRITE if n >= 2 => {
                // Bit 0 (over-voltage flag) is read-only.
                chip.reg = mosi[1] & !1;
                chip.stats.register_writes += 1;
                [0xFF; 3]
            }
            ad4000::CMD_READ => [0xFF, chip.reg, 0xFF],
            _ => chip.conversion_frame(),
        };
        let mut k = 0;
        for op in ops.iter_mut() {
            match op {
                Operation::Read(r) | Operation::Transfer(r, _) | Operation::TransferInPlace(r) => {
                    for b in r.iter_mut() {
                        *b = out.get(k).copied().unwrap_or(0);
                        k += 1;
                    }
                }
                Operation::Write(w) => k += w.len(),
                Operation::DelayNs(ns) => chip.clock.advance_ns(*ns as u64),
            }
        }
        Ok(())
    }
}

/// CNV pin of [`MockAdc`]: the rising edge samples the input and starts a conversion.
#[derive(Debug)]
pub struct MockCnv(Rc<RefCell<AdcChip>>);

impl PinErrorType for MockCnv {
    type Error = Infallible;
}

impl OutputPin for MockCnv {
    #[inline]
    fn set_high(&mut self) -> Result<(), Infallible> {
        let mut chip = self.0.borrow_mut();
        if !chip.cnv_high {
            chip.start_conversion();
        }
        chip.cnv_high = true;
        Ok(())
    }
    #[inline]
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.0.borrow_mut().cnv_high = false;
        Ok(())
    }
}

/// Analog imperfections of the DAC.
#[derive(Debug, Clone, PartialEq)]
pub struct DacSpec {
    pub vrefp: f64,
    pub vrefn: f64,
    pub offset_lsb: f64,
    pub gain_error: f64,
}

impl Default for DacSpec {
    fn default() -> Self {
        Self {
            vrefp: 10.0,
            vrefn: 0.0,
            offset_lsb: 0.0,
            gain_error: 0.0,
        }
    }
}

/// Counters of the DAC mock.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DacStats {
    pub frames: u64,
    /// Frames that were not 24 bits long (ignored, as the chip does).
    pub bad_frames: u64,
    pub updates: u64,
}

/// Power-on value of the control register: output clamped to ground, tristate.
const CTRL_POWER_ON: u32 = CTRL_OPGND | CTRL_DACTRI;

#[derive(Debug)]
struct DacChip {
    spec: DacSpec,
    /// Volts per code.
    lsb: f64,
    dac: u32,
    ctrl: u32,
    clearcode: u32,
    ldac_low: bool,
    /// DAC register value driving the output.
    active: u32,
    readback: Option<u32>,
    volts: f64,
    stats: DacStats,
}

impl DacChip {
    #[inline]
    fn update_output(&mut self) {
        self.stats.updates += 1;
        self.volts = if self.ctrl & (CTRL_OPGND | CTRL_DACTRI) != 0 {
            0.0
        } else {
            // Offset binary internally; two's complement flips the MSB.
            let d = if self.ctrl & CTRL_BIN2SC != 0 {
                self.active
            } else {
                self.active ^ (1 << 19)
            };
            let (s, lsb) = (&self.spec, self.lsb);
            s.vrefn + (d as f64 * lsb) * (1.0 + s.gain_error) + s.offset_lsb * lsb
        };
    }

    fn reset(&mut self) {
        self.dac = 0;
        self.ctrl = CTRL_POWER_ON;
        self.clearcode = 0;
        self.active = 0;
        self.update_output();
    }

    #[inline]
    fn frame(&mut self, word: u32) {
        let reg = (word >> 20) & 0b111;
        let data = word & DATA_MASK;
        if word & READ != 0 {
            self.readback = Some(match reg {
                REG_DAC => self.dac,
                REG_CTRL => self.ctrl,
                REG_CLEARCODE => self.clearcode,
                _ => 0,
            });
            return;
        }
        match reg {
            REG_DAC => {
                self.dac = data;
                if self.ldac_low {
                    self.active = data;
                    self.update_output();
                }
            }
            REG_CTRL => {
                self.ctrl = data & 0x3FE;
                self.update_output();
            }
            REG_CLEARCODE => self.clearcode = data,
            REG_SWCTRL => {
                if data & SW_RESET != 0 {
                    self.reset();
                } else if data & SW_CLR != 0 {
                    self.active = self.clearcode;
                    self.update_output();
                } else if data & SW_LDAC != 0 {
                    self.active = self.dac;
                    self.update_output();
                }
            }
            _ => {} // 000: no-op
        }
    }
}

/// The AD5791 mock; clone handles freely.
#[derive(Debug, Clone)]
pub struct MockDac(Rc<RefCell<DacChip>>);

impl MockDac {
    pub fn new(spec: DacSpec) -> Self {
        let mut chip = DacChip {
            lsb: (spec.vrefp - spec.vrefn) / DATA_MASK as f64,
            spec,
            dac: 0,
            ctrl: CTRL_POWER_ON,
            clearcode: 0,
            ldac_low: false,
            active: 0,
            readback: None,
            volts: 0.0,
            stats: DacStats::default(),
        };
        chip.reset();
        Self(Rc::new(RefCell::new(chip)))
    }

    pub fn spi(&self) -> MockDacSpi {
        MockDacSpi(self.0.clone())
    }

    pub fn ldac(&self) -> MockLdac {
        MockLdac(self.0.clone())
    }

    /// Output voltage (V).
    #[inline]
    pub fn output_volts(&self) -> f64 {
        self.0.borrow().volts
    }

    /// The DAC register (pending value) and the code driving the output.
    pub fn codes(&self) -> (u32, u32) {
        let c = self.0.borrow();
        (c.dac, c.active)
    }

    pub fn control(&self) -> u32 {
        self.0.borrow().ctrl
    }

    pub fn stats(&self) -> DacStats {
        self.0.borrow().stats
    }
}

/// SPI side of [`MockDac`]: one transaction is one SYNC-low frame.
#[derive(Debug)]
pub struct MockDacSpi(Rc<RefCell<DacChip>>);

impl ErrorType for MockDacSpi {
    type Error = Infallible;
}

impl SpiDevice for MockDacSpi {
    #[inline]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        let mut chip = self.0.borrow_mut();
        // The loop's one write frame, inlined into the driver; the rest: general path.
        if let [Operation::Write([b0, b1, b2])] = ops {
            chip.stats.frames += 1;
            chip.readback = None; // shifted out on MISO, unread
            chip.frame(u32::from_be_bytes([0, *b0, *b1, *b2]));
            return Ok(());
        }
        chip.transaction(ops)
    }
}

impl DacChip {
    /// Any SPI frame (one transaction is one SYNC-low frame).
    #[inline(never)]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Infallible> {
        let chip = self;
        chip.stats.frames += 1;
        let rb = chip.readback.take().unwrap_or(0).to_be_bytes();
        let out = [rb[1], rb[2], rb[3]];
        let mut word: u32 = 0;
        let mut n = 0usize;
        // Shifts one MOSI byte in, returns the MISO byte clocked out at the same time.
        let mut shift = |b: u8, word: &mut u32| {
            *word = (*word << 8) | b as u32;
            let o = out.get(n).copied().unwrap_or(0);
            n += 1;
            o
        };
        for op in ops.iter_mut() {
            match op {
                Operation::Write(w) => w.iter().for_each(|b| {
                    shift(*b, &mut word);
                }),
                Operation::Transfer(r, w) => {
                    let len = r.len().max(w.len());
                    for i in 0..len {
                        let o = shift(w.get(i).copied().unwrap_or(0), &mut word);
                        if let Some(rb) = r.get_mut(i) {
                            *rb = o;
                        }
                    }
                }
                Operation::TransferInPlace(b) => {
                    b.iter_mut().for_each(|x| *x = shift(*x, &mut word))
                }
                Operation::Read(r) => r.iter_mut().for_each(|x| *x = shift(0, &mut word)),
                Operation::DelayNs(_) => {}
            }
        }
        if n == 3 {
            chip.frame(word & 0xFF_FFFF);
        } else {
            chip.stats.bad_frames += 1;
        }
        Ok(())
    }
}

/// LDAC pin of [`MockDac`]: a falling edge loads the DAC register into the output.
#[derive(Debug)]
pub struct MockLdac(Rc<RefCell<DacChip>>);

impl PinErrorType for MockLdac {
    type Error = Infallible;
}

impl OutputPin for MockLdac {
    #[inline]
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0.borrow_mut().ldac_low = false;
        Ok(())
    }
    #[inline]
    fn set_low(&mut self) -> Result<(), Infallible> {
        let mut chip = self.0.borrow_mut();
        if !chip.ldac_low {
            chip.active = chip.dac;
            chip.update_output();
        }
        chip.ldac_low = true;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use piezo_core::drivers::{Ad4000, Ad5791, Ad5791Config, DacCoding};

    #[test]
    fn adc_driver_reads_quantised_codes_after_conversion_time() {
        let clock = MockClock::default();
        let chip = MockAdc::new(AdcSpec::default(), clock.clone());
        let mut adc = Ad4000::new(chip.spi(), chip.cnv(), Ad4000Config::AD4020).unwrap();
        adc.init().unwrap();
        assert_eq!(chip.register(), Ad4000Config::AD4020.register());
        let mut delay = MockDelay(clock.clone());
        let lsb = 10.0 / (1 << 20) as f64;
        for v in [-4.9, -1e-3, 0.0, 2.5, 4.99] {
            chip.set_input_volts(v);
            let code = adc.convert(&mut delay).unwrap();
            assert_eq!(code, (v / lsb).round() as i32, "{v}");
        }
        chip.set_input_volts(7.0);
        assert_eq!(adc.convert(&mut delay).unwrap(), (1 << 19) - 1, "clips");
        // Read without waiting: the previous result, counted.
        chip.set_input_volts(1.0);
        adc.start_conversion().unwrap();
        assert_eq!(adc.read().unwrap(), (1 << 19) - 1);
        assert_eq!(chip.stats().early_reads, 1);
    }

    #[test]
    fn adc_straight_binary_16bit() {
        let clock = MockClock::default();
        let cfg = Ad4000Config {
            bits: 16,
            format: CodeFormat::StraightBinary,
            turbo: false,
            high_z: true,
        };
        let chip = MockAdc::new(
            AdcSpec {
                config: cfg,
                ..AdcSpec::default()
            },
            clock.clone(),
        );
        let mut adc = Ad4000::new(chip.spi(), chip.cnv(), cfg).unwrap();
        adc.init().unwrap();
        chip.set_input_volts(2.5);
        assert_eq!(adc.convert(&mut MockDelay(clock)).unwrap(), 32768);
    }

    #[test]
    fn adc_driver_notices_a_wrong_register() {
        let clock = MockClock::default();
        let chip = MockAdc::new(AdcSpec::default(), clock);
        chip.fail_transactions(1);
        let mut adc = Ad4000::new(chip.spi(), chip.cnv(), Ad4000Config::AD4020).unwrap();
        assert!(adc.init().is_err());
    }

    #[test]
    fn dac_driver_powers_up_writes_and_loads() {
        let chip = MockDac::new(DacSpec::default());
        let mut dac = Ad5791::new(chip.spi(), chip.ldac(), Ad5791Config::DEFAULT).unwrap();
        assert_eq!(chip.output_volts(), 0.0, "clamped to ground at power-up");
        dac.init(0x40000).unwrap();
        assert!((chip.output_volts() - 2.5).abs() < 1e-4);
        dac.write_code(0xFFFFF).unwrap();
        assert!((chip.output_volts() - 2.5).abs() < 1e-4, "waits for LDAC");
        dac.load().unwrap();
        assert!((chip.output_volts() - 10.0).abs() < 1e-9);
        assert_eq!(dac.read_register(REG_DAC).unwrap(), 0xFFFFF);
        assert_eq!(chip.stats().bad_frames, 0);
    }

    #[test]
    fn dac_twos_complement_coding() {
        let chip = MockDac::new(DacSpec {
            vrefp: 10.0,
            vrefn: -10.0,
            ..DacSpec::default()
        });
        let cfg = Ad5791Config {
            coding: DacCoding::TwosComplement,
            rbuf: true,
            lincomp: 12,
        };
        let mut dac = Ad5791::new(chip.spi(), chip.ldac(), cfg).unwrap();
        dac.init(0).unwrap();
        assert!(chip.output_volts().abs() < 1e-4);
        dac.set_code(-(1 << 19)).unwrap();
        assert!((chip.output_volts() + 10.0).abs() < 1e-9);
    }
}
