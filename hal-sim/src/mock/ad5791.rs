//! The AD5791 DAC mock.
//!
//! Rules enforced (AD5791 data sheet Rev. D; Table 3 "Timing Characteristics", IOVCC 1.71 V
//! to 3.3 V column, the slower one, which holds at the H743's 3.3 V I/O):
//! * SCLK cycle `t1` >= 40 ns (25 MHz) for every frame, >= 92 ns (10.87 MHz) for a read-back
//!   (the read command and the frame that clocks the register out);
//! * LDAC low pulse `t10` >= 13 ns;
//! * SYNC high `t6` >= 48 ns between two frames (the mock's frames take no time: the gap
//!   from one frame to the next);
//! * power-on (and software reset): OPGND = 1, DACTRI = 1, the output clamped to AGND through
//!   ~6 kOhm and the DAC register at code 0 (p. 19); the output is driven only once the
//!   control register clears both. Clearing OPGND while DACTRI is set leaves the output
//!   floating, and releasing it while it still holds the power-on code (no load since the
//!   reset) drives an arbitrary level: both are refused, since the amplifier behind it must
//!   see the safe code first.

use super::{BusClock, MockClock, MockPinError, MockSpiError, Violations};
use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use piezo_core::drivers::ad5791::{
    CTRL_BIN2SC, CTRL_DACTRI, CTRL_MASK, CTRL_OPGND, DATA_MASK, READ, REG_CLEARCODE, REG_CTRL,
    REG_DAC, REG_SWCTRL, SW_CLR, SW_LDAC, SW_RESET,
};
use piezo_core::drivers::SpiClock;
use std::cell::RefCell;
use std::rc::Rc;

/// Fastest write SCLK (Hz): `t1` >= 40 ns.
const SCLK_MAX_HZ: u32 = 25_000_000;
/// Fastest read-back SCLK (Hz): `t1` >= 92 ns.
const SCLK_READBACK_MAX_HZ: u32 = 10_869_565;
/// Shortest LDAC low pulse (ns): `t10`.
const LDAC_LOW_MIN_NS: u64 = 13;
/// Shortest SYNC high time between frames (ns): `t6`.
const SYNC_HIGH_MIN_NS: u64 = 48;
/// Power-on value of the control register: output clamped to ground, DAC tri-stated.
const CTRL_POWER_ON: u32 = CTRL_OPGND | CTRL_DACTRI;
/// Output transitions kept for tests (the first ones: power-up and release).
const LOG_LEN: usize = 32;

/// Analog imperfections of the DAC, and its bus.
#[derive(Debug, Clone, PartialEq)]
pub struct DacSpec {
    pub vrefp: f64,
    pub vrefn: f64,
    pub offset_lsb: f64,
    pub gain_error: f64,
    pub bus: BusClock,
}

impl Default for DacSpec {
    fn default() -> Self {
        Self {
            vrefp: 10.0,
            vrefn: 0.0,
            offset_lsb: 0.0,
            gain_error: 0.0,
            bus: BusClock::default(),
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

/// What VOUT does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DacOutput {
    /// Clamped to AGND through ~6 kOhm (OPGND = 1): 0 V.
    Clamped,
    /// DAC tri-stated without the clamp: nothing drives the pin.
    Floating,
    /// Driven at this DAC register code (20 bits as written).
    Driven(u32),
}

#[derive(Debug)]
struct DacChip {
    spec: DacSpec,
    clock: MockClock,
    /// Volts per code.
    lsb: f64,
    dac: u32,
    ctrl: u32,
    clearcode: u32,
    ldac_low: bool,
    ldac_fall_ns: u64,
    /// When SYNC rose at the end of the last frame (`None`: no frame since power-up).
    sync_rise_ns: Option<u64>,
    /// DAC register value driving the output.
    active: u32,
    /// The DAC register was written since the reset, and that write was loaded.
    written: bool,
    loaded: bool,
    readback: Option<u32>,
    output: DacOutput,
    volts: f64,
    log: Vec<(u64, DacOutput)>,
    stats: DacStats,
    violations: Violations,
}

impl DacChip {
    #[cold]
    fn violate(&mut self, rule: &'static str, measured: u64) -> &'static str {
        let now = self.clock.now_ns();
        self.violations.record(rule, now, measured)
    }

    #[inline]
    fn update_output(&mut self) {
        self.stats.updates += 1;
        let output = if self.ctrl & CTRL_OPGND != 0 {
            DacOutput::Clamped
        } else if self.ctrl & CTRL_DACTRI != 0 {
            DacOutput::Floating
        } else {
            DacOutput::Driven(self.active)
        };
        self.volts = match output {
            DacOutput::Clamped | DacOutput::Floating => 0.0,
            DacOutput::Driven(_) => {
                // Offset binary internally; two's complement flips the MSB.
                let d = if self.ctrl & CTRL_BIN2SC != 0 {
                    self.active
                } else {
                    self.active ^ (1 << 19)
                };
                let (s, lsb) = (&self.spec, self.lsb);
                s.vrefn + (d as f64 * lsb) * (1.0 + s.gain_error) + s.offset_lsb * lsb
            }
        };
        // A new code on a driven output is the loop's every sample: no log, no check.
        if core::mem::discriminant(&output) != core::mem::discriminant(&self.output) {
            self.transition(output);
        } else {
            self.output = output;
        }
    }

    /// A change of what VOUT does: logged, and checked when the output is released.
    #[cold]
    fn transition(&mut self, output: DacOutput) {
        let was_driven = matches!(self.output, DacOutput::Driven(_));
        self.output = output;
        if self.log.len() < LOG_LEN {
            self.log.push((self.clock.now_ns(), output));
        }
        match output {
            DacOutput::Floating => {
                self.violate("output floating: OPGND cleared while DACTRI is set", 0);
            }
            DacOutput::Driven(code) if !was_driven && !self.loaded => {
                self.violate(
                    "output released at the power-on code (no DAC register load since reset)",
                    code as u64,
                );
            }
            _ => {}
        }
    }

    fn reset(&mut self) {
        self.dac = 0;
        self.ctrl = CTRL_POWER_ON;
        self.clearcode = 0;
        self.active = 0;
        self.written = false;
        self.loaded = false;
        self.update_output();
    }

    /// The DAC register into the output (LDAC).
    #[inline]
    fn load(&mut self) {
        self.active = self.dac;
        self.loaded = self.written;
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
                self.written = true;
                if self.ldac_low {
                    self.load();
                }
            }
            REG_CTRL => {
                self.ctrl = data & CTRL_MASK;
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
                    self.load();
                }
            }
            _ => {} // 000: no-op
        }
    }

    /// The SCLK rules of one frame (`reading`: a read command or the frame clocking one out).
    #[inline]
    fn check_sclk(&mut self, reading: bool) -> Result<(), MockSpiError> {
        let hz = self.spec.bus.hz;
        if hz > SCLK_MAX_HZ {
            let rule = self.violate("SCLK above 25 MHz (t1 >= 40 ns)", hz as u64);
            return Err(MockSpiError::Violation(rule));
        }
        if reading && hz > SCLK_READBACK_MAX_HZ {
            let rule = self.violate("read-back SCLK above 10.87 MHz (t1 >= 92 ns)", hz as u64);
            return Err(MockSpiError::Violation(rule));
        }
        Ok(())
    }

    /// SYNC falls for a frame: it was high for `t6` at least since the last one (which ends,
    /// SYNC rising, at the same instant: frames take no time here).
    #[inline]
    fn sync_fall(&mut self) -> Result<(), MockSpiError> {
        let now = self.clock.now_ns();
        let last = self.sync_rise_ns.replace(now);
        match last {
            Some(t) if now - t < SYNC_HIGH_MIN_NS => {
                let rule =
                    self.violate("SYNC high shorter than t6 = 48 ns between frames", now - t);
                Err(MockSpiError::Violation(rule))
            }
            _ => Ok(()),
        }
    }

    /// Any SPI frame (one transaction is one SYNC-low frame).
    #[inline(never)]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), MockSpiError> {
        self.sync_fall()?;
        self.stats.frames += 1;
        let pending = self.readback.take();
        let first = ops.iter().find_map(|op| match op {
            Operation::Write(w) => w.first().copied(),
            Operation::Transfer(_, w) => w.first().copied(),
            Operation::TransferInPlace(b) => b.first().copied(),
            Operation::Read(r) => r.first().map(|_| 0),
            Operation::DelayNs(_) => None,
        });
        let read_command = first.is_some_and(|b| b & 0x80 != 0);
        self.check_sclk(pending.is_some() || read_command)?;
        let rb = pending.unwrap_or(0).to_be_bytes();
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
            self.frame(word & 0xFF_FFFF);
        } else {
            self.stats.bad_frames += 1;
        }
        Ok(())
    }
}

/// The AD5791 mock; clone handles freely.
#[derive(Debug, Clone)]
pub struct MockDac(Rc<RefCell<DacChip>>);

impl MockDac {
    pub fn new(spec: DacSpec, clock: MockClock) -> Self {
        let mut chip = DacChip {
            lsb: (spec.vrefp - spec.vrefn) / DATA_MASK as f64,
            spec,
            clock,
            dac: 0,
            ctrl: CTRL_POWER_ON,
            clearcode: 0,
            ldac_low: false,
            ldac_fall_ns: 0,
            sync_rise_ns: None,
            active: 0,
            written: false,
            loaded: false,
            readback: None,
            output: DacOutput::Clamped,
            volts: 0.0,
            log: Vec::new(),
            stats: DacStats::default(),
            violations: Violations::default(),
        };
        chip.reset();
        let t = chip.clock.now_ns();
        chip.log.push((t, DacOutput::Clamped));
        Self(Rc::new(RefCell::new(chip)))
    }

    pub fn spi(&self) -> MockDacSpi {
        MockDacSpi(self.0.clone())
    }

    pub fn ldac(&self) -> MockLdac {
        MockLdac(self.0.clone())
    }

    /// Output voltage (V); 0 while clamped (and while floating, which is a violation).
    #[inline]
    pub fn output_volts(&self) -> f64 {
        self.0.borrow().volts
    }

    /// What VOUT does now.
    pub fn output(&self) -> DacOutput {
        self.0.borrow().output
    }

    /// The first changes of what the output does (time ns, state: clamped, floating, or
    /// driven at the code it was released at), from power-on.
    pub fn output_log(&self) -> Vec<(u64, DacOutput)> {
        self.0.borrow().log.clone()
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

    /// The data-sheet rules broken so far.
    pub fn violations(&self) -> Violations {
        self.0.borrow().violations
    }

    /// The bus clock now.
    pub fn bus(&self) -> BusClock {
        self.0.borrow().spec.bus
    }
}

/// SPI side of [`MockDac`]: one transaction is one SYNC-low frame.
#[derive(Debug)]
pub struct MockDacSpi(Rc<RefCell<DacChip>>);

impl ErrorType for MockDacSpi {
    type Error = MockSpiError;
}

impl SpiClock for MockDacSpi {
    fn set_sclk_max_hz(&mut self, max_hz: u32) -> u32 {
        self.0.borrow_mut().spec.bus.set_max(max_hz)
    }
}

impl SpiDevice for MockDacSpi {
    #[inline]
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), MockSpiError> {
        let mut chip = self.0.borrow_mut();
        // The loop's one write frame, inlined into the driver; the rest: general path.
        if let [Operation::Write([b0, b1, b2])] = ops {
            if chip.readback.is_none() && *b0 & 0x80 == 0 && chip.spec.bus.hz <= SCLK_MAX_HZ {
                chip.sync_fall()?;
                chip.stats.frames += 1;
                chip.frame(u32::from_be_bytes([0, *b0, *b1, *b2]));
                return Ok(());
            }
        }
        chip.transaction(ops)
    }
}

/// LDAC pin of [`MockDac`]: a falling edge loads the DAC register into the output; the low
/// pulse must last `t10`.
#[derive(Debug)]
pub struct MockLdac(Rc<RefCell<DacChip>>);

impl PinErrorType for MockLdac {
    type Error = MockPinError;
}

impl OutputPin for MockLdac {
    #[inline]
    fn set_high(&mut self) -> Result<(), MockPinError> {
        let mut chip = self.0.borrow_mut();
        if !chip.ldac_low {
            return Ok(());
        }
        chip.ldac_low = false;
        let low_ns = chip.clock.now_ns().saturating_sub(chip.ldac_fall_ns);
        if low_ns < LDAC_LOW_MIN_NS {
            let rule = chip.violate("LDAC low pulse shorter than t10 = 13 ns", low_ns);
            return Err(MockPinError(rule));
        }
        Ok(())
    }
    #[inline]
    fn set_low(&mut self) -> Result<(), MockPinError> {
        let mut chip = self.0.borrow_mut();
        if !chip.ldac_low {
            chip.ldac_fall_ns = chip.clock.now_ns();
            chip.load();
        }
        chip.ldac_low = true;
        Ok(())
    }
}
