//! No_std mock converter chips for the QEMU board, for the firmware's own drivers: an AD4020
//! whose CNV edge samples the stage and an AD5791 whose LDAC edge sets the stage's voltage,
//! as strict as hal-sim's models (`hal-sim/src/mock`, same rules, same data-sheet numbers):
//!
//! * AD4020 (data sheet Rev. B): the interface mode latched from SDI at the CNV rising edge
//!   (SDI low: daisy-chain mode, every frame refused); CNV high for `t_CONV` max 320 ns
//!   before it falls; no frame while CNV is high; a register command only as the first bits
//!   of a CNV frame; SCK <= 102 MHz (`t_SCK` >= 9.8 ns); the configuration register resets
//!   to `0xE1`, its reserved bits 7:5 read 1 and a write must keep them 1; with its status
//!   bit set, six status bits follow each result (over-voltage flag, the mode bits).
//!   Fault injection ([`set_fault`]): SDO held low or high, the input floating (the code
//!   frozen), the sensor disconnected (the input pulled to 97 % of the positive full scale).
//! * AD5791 (data sheet Rev. D, Table 3, IOVCC 1.71 V to 3.3 V): SCLK <= 25 MHz, <= 10.87 MHz
//!   in read-back; LDAC low >= 13 ns; SYNC high >= 48 ns (`t6`) between frames; power-on clamp (OPGND, DACTRI) until the control
//!   register clears both; a floating output or a release at the power-on code is refused.
//!
//! A broken rule returns an error to the driver and is counted ([`violations`]); the board
//! prints the count and the first rule in its `done` line and in `selftest`, and CI requires
//! 0. Time comes from the CMSDK APB timer 1 (25 MHz, 40 ns per tick; QEMU `-icount shift=0`
//! makes it virtual time): a check passes only if the time *surely* elapsed (ticks seen - 1,
//! times 40 ns) is long enough, and [`TimerDelay`] waits the same way.
//!
//! State lives in atomics, one chip of each kind per axis (the const parameter `A`), so the
//! pins and the bus of a chip are separate handles like on a board.

use core::sync::atomic::{AtomicBool, AtomicI32, AtomicU32, AtomicU8, Ordering::Relaxed};
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{self, ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{self, ErrorType, Operation, SpiDevice};
use piezo_core::drivers::{ad4000, ad5791, wire, SpiClock};
use piezo_core::firmware::{ActuatorDac, PositionAdc, ADC_CONFIG, DAC_CONFIG};

/// Axes of mock chips (the xy build uses both).
const CHIPS: usize = 2;

/// The SPI the board's mock buses run: 25 MHz at reset, at most 50 MHz (as the H743's SPI1
/// and SPI4 with a 100 MHz kernel clock).
pub const BUS_RESET_HZ: u32 = 25_000_000;
pub const BUS_MAX_HZ: u32 = 50_000_000;

/// AD4020: `t_CONV` max (ns) and the fastest SCK (Hz), Rev. B Table 3.
const T_CONV_MAX_NS: u32 = 320;
const ADC_SCK_MAX_HZ: u32 = 102_040_816;
/// AD5791: fastest write and read-back SCLK (Hz), shortest LDAC pulse (ns), Rev. D Table 3.
const DAC_SCLK_MAX_HZ: u32 = 25_000_000;
const DAC_SCLK_READBACK_MAX_HZ: u32 = 10_869_565;
const LDAC_LOW_MIN_NS: u32 = 13;
const SYNC_HIGH_MIN_NS: u32 = 48;

/// CMSDK APB timer 1 of the mps2 machines, free-running down from `u32::MAX` at 25 MHz.
pub mod clock {
    const BASE: usize = 0x4000_1000;
    const CTRL: usize = BASE;
    const VALUE: usize = BASE + 0x4;
    const RELOAD: usize = BASE + 0x8;
    pub const NS_PER_TICK: u32 = 40;

    #[allow(unsafe_code)]
    fn write(addr: usize, v: u32) {
        // SAFETY: a CMSDK timer register of the mps2 memory map; only this module uses
        // timer 1.
        unsafe { core::ptr::write_volatile(addr as *mut u32, v) }
    }

    /// Starts the timer (first thing at boot: every chip check reads it).
    pub fn start() {
        write(RELOAD, u32::MAX);
        write(VALUE, u32::MAX);
        write(CTRL, 1);
    }

    #[allow(unsafe_code)]
    #[inline]
    pub fn now() -> u32 {
        // SAFETY: as above, a read of the counter.
        unsafe { core::ptr::read_volatile(VALUE as *const u32) }
    }

    /// Time surely elapsed since the reading `t0` (ns): `k` ticks seen means more than
    /// `(k - 1) * 40` ns.
    #[inline]
    pub fn elapsed_min_ns(t0: u32) -> u32 {
        t0.wrapping_sub(now())
            .saturating_sub(1)
            .saturating_mul(NS_PER_TICK)
    }
}

/// `DelayNs` on [`clock`]: returns once `ns` have surely elapsed (bounded: the poll count
/// covers the wait many times over at one instruction per ns).
#[derive(Clone, Copy, Debug, Default)]
pub struct TimerDelay;

impl DelayNs for TimerDelay {
    #[inline]
    fn delay_ns(&mut self, ns: u32) {
        let t0 = clock::now();
        for _ in 0..ns.saturating_add(2 * clock::NS_PER_TICK) {
            if clock::elapsed_min_ns(t0) >= ns {
                break;
            }
        }
    }
}

/// The rules, for [`violations`] (index + 1 is stored).
const RULES: [&str; 12] = [
    "AD4020: SPI frame while CNV is high",
    "AD4020: SCK above 102 MHz",
    "AD4020: frame in daisy-chain mode (SDI low at the CNV rising edge)",
    "AD4020: register access outside a CNV frame",
    "AD4020: CNV fell before t_CONV max = 320 ns",
    "AD5791: SCLK above 25 MHz",
    "AD5791: read-back SCLK above 10.87 MHz",
    "AD5791: LDAC low pulse shorter than 13 ns",
    "AD5791: output floating (OPGND cleared while DACTRI is set)",
    "AD5791: output released at the power-on code",
    "AD4020: configuration write with reserved bits 7:5 not 1",
    "AD5791: SYNC high shorter than t6 = 48 ns between frames",
];
static VIOLATIONS: AtomicU32 = AtomicU32::new(0);
static FIRST: AtomicU8 = AtomicU8::new(0);

/// A broken data-sheet rule (the mock's error).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Violation(pub &'static str);

impl spi::Error for Violation {
    fn kind(&self) -> spi::ErrorKind {
        spi::ErrorKind::Other
    }
}
impl digital::Error for Violation {
    fn kind(&self) -> digital::ErrorKind {
        digital::ErrorKind::Other
    }
}

#[cold]
fn violate(rule: usize) -> Violation {
    VIOLATIONS.fetch_add(1, Relaxed);
    let _ = FIRST.compare_exchange(0, rule as u8 + 1, Relaxed, Relaxed);
    Violation(RULES.get(rule).copied().unwrap_or("?"))
}

/// Broken rules so far, and the first.
pub fn violations() -> (u32, &'static str) {
    let first = FIRST.load(Relaxed) as usize;
    let rule = first
        .checked_sub(1)
        .and_then(|i| RULES.get(i).copied())
        .unwrap_or("none");
    (VIOLATIONS.load(Relaxed), rule)
}

/// The amplifier enable line (off at reset; the control period drives it from the
/// pipeline's safe state, the panic handler turns it off).
pub static AMP_ON: AtomicBool = AtomicBool::new(false);

/// The code axis `a`'s ADC input corresponds to now (the stage writes it every sample).
static INPUT: [AtomicI32; CHIPS] = [const { AtomicI32::new(0) }; CHIPS];

/// Faults of the position channel ([`set_fault`]).
pub const FAULT_NONE: u8 = 0;
/// SDO held low: every bit reads 0 (code 0 is mid-stroke; the status word 0).
pub const FAULT_STUCK_LOW: u8 = 1;
/// SDO held high: every bit reads 1 (code -1, mid-stroke; status all ones).
pub const FAULT_STUCK_HIGH: u8 = 2;
/// The input floating: every conversion returns the code sampled before the fault.
pub const FAULT_FLOATING: u8 = 3;
/// The sensor disconnected: the input at 97 % of the positive full scale (plus the stage's
/// noise), inside the span (no over-voltage flag).
pub const FAULT_DISCONNECTED: u8 = 4;
static FAULT: [AtomicU8; CHIPS] = [const { AtomicU8::new(FAULT_NONE) }; CHIPS];

/// Injects `fault` (a `FAULT_*`) into axis `a`'s ADC from its next conversion on.
pub fn set_fault(a: usize, fault: u8) {
    if let Some(f) = at(&FAULT, a) {
        f.store(fault, Relaxed);
    }
}
/// AD4020 state: CNV level, SDI level (the last MOSI bit), the CNV-low period (0 power-up,
/// 1 CS frame, 2 daisy-chain), CNV rise tick, bytes clocked since CNV fell, the register,
/// the code sampled at the last rising edge, the bus rate.
static CNV_HIGH: [AtomicBool; CHIPS] = [const { AtomicBool::new(false) }; CHIPS];
static SDI_HIGH: [AtomicBool; CHIPS] = [const { AtomicBool::new(false) }; CHIPS];
static PERIOD: [AtomicU8; CHIPS] = [const { AtomicU8::new(0) }; CHIPS];
static RISE: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static CLOCKED: [AtomicBool; CHIPS] = [const { AtomicBool::new(false) }; CHIPS];
static ADC_REG: [AtomicU32; CHIPS] = [const { AtomicU32::new(ad4000::REG_RESET as u32) }; CHIPS];
static SAMPLED: [AtomicI32; CHIPS] = [const { AtomicI32::new(0) }; CHIPS];
static ADC_BUS: [AtomicU32; CHIPS] = [const { AtomicU32::new(BUS_RESET_HZ) }; CHIPS];
const POWER_UP: u8 = 0;
const CS: u8 = 1;
const CHAIN: u8 = 2;
/// The extreme codes of the AD4020 (an input at or beyond them sets the over-voltage flag).
const CODE_LO: i32 = -(1 << 19);
const CODE_HI: i32 = (1 << 19) - 1;
/// 97 % of the positive full scale.
const DISCONNECTED_CODE: i32 = CODE_HI / 100 * 97;

/// AD5791 state: DAC register, control register, the code driving the output, written and
/// loaded since reset, LDAC level and fall tick, pending read-back (bit 31: pending), bus.
const CTRL_POWER_ON: u32 = ad5791::CTRL_OPGND | ad5791::CTRL_DACTRI;
static DAC_REG: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static DAC_CTRL: [AtomicU32; CHIPS] = [const { AtomicU32::new(CTRL_POWER_ON) }; CHIPS];
static DAC_ACTIVE: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static WRITTEN: [AtomicBool; CHIPS] = [const { AtomicBool::new(false) }; CHIPS];
static LOADED: [AtomicBool; CHIPS] = [const { AtomicBool::new(false) }; CHIPS];
static LDAC_LOW: [AtomicBool; CHIPS] = [const { AtomicBool::new(false) }; CHIPS];
static LDAC_FALL: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static READBACK: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static DAC_BUS: [AtomicU32; CHIPS] = [const { AtomicU32::new(BUS_RESET_HZ) }; CHIPS];
/// The tick SYNC rose at the end of the last frame, and whether there was one.
static SYNC_RISE: [AtomicU32; CHIPS] = [const { AtomicU32::new(0) }; CHIPS];
static FRAMED: [AtomicBool; CHIPS] = [const { AtomicBool::new(false) }; CHIPS];
/// Whether the output was driven (a release is checked once).
static DRIVEN: [AtomicBool; CHIPS] = [const { AtomicBool::new(false) }; CHIPS];
const PENDING: u32 = 1 << 31;

/// `reg[a]`, or nothing for an axis without a chip (never taken: `A < CHIPS`).
fn at<T>(reg: &'static [T; CHIPS], a: usize) -> Option<&'static T> {
    reg.get(a)
}

/// The input code of axis `a`'s ADC.
pub fn set_input(a: usize, code: i32) {
    if let Some(i) = at(&INPUT, a) {
        i.store(code, Relaxed);
    }
}

/// What axis `a`'s AD5791 output does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Output {
    /// Clamped to AGND (OPGND): 0 V.
    Clamped,
    Floating,
    /// Driven at this register code.
    Driven(u32),
}

pub fn output(a: usize) -> Output {
    let (Some(ctrl), Some(active)) = (at(&DAC_CTRL, a), at(&DAC_ACTIVE, a)) else {
        return Output::Clamped;
    };
    let ctrl = ctrl.load(Relaxed);
    if ctrl & ad5791::CTRL_OPGND != 0 {
        Output::Clamped
    } else if ctrl & ad5791::CTRL_DACTRI != 0 {
        Output::Floating
    } else {
        Output::Driven(active.load(Relaxed))
    }
}

/// Axis `a`'s output as a DAC code for the stage (0 V while clamped or floating; offset
/// binary, 0 V at code 0).
pub fn dac_out(a: usize) -> i32 {
    match output(a) {
        Output::Driven(c) => c as i32,
        Output::Clamped | Output::Floating => 0,
    }
}

/// The output changed: checks a release (floating, or driven at the power-on code).
fn output_changed(a: usize) -> Result<(), Violation> {
    let (Some(driven), Some(loaded)) = (at(&DRIVEN, a), at(&LOADED, a)) else {
        return Ok(());
    };
    match output(a) {
        Output::Floating => {
            driven.store(false, Relaxed);
            Err(violate(8))
        }
        Output::Driven(_) => {
            let was = driven.swap(true, Relaxed);
            if !was && !loaded.load(Relaxed) {
                return Err(violate(9));
            }
            Ok(())
        }
        Output::Clamped => {
            driven.store(false, Relaxed);
            Ok(())
        }
    }
}

fn set_rate(bus: Option<&AtomicU32>, max_hz: u32) -> u32 {
    let hz = max_hz.min(BUS_MAX_HZ);
    if let Some(b) = bus {
        b.store(hz, Relaxed);
    }
    hz
}

/// The AD4020's CNV pin: the rising edge latches the mode from SDI and samples the input,
/// the falling edge selects the part (not before `t_CONV`).
pub struct Cnv<const A: usize>;
/// The AD5791's LDAC pin: the falling edge loads the DAC register into the output.
pub struct Ldac<const A: usize>;

impl<const A: usize> PinErrorType for Cnv<A> {
    type Error = Violation;
}
impl<const A: usize> OutputPin for Cnv<A> {
    fn set_high(&mut self) -> Result<(), Violation> {
        let (Some(high), Some(sdi), Some(period), Some(rise), Some(s), Some(i)) = (
            at(&CNV_HIGH, A),
            at(&SDI_HIGH, A),
            at(&PERIOD, A),
            at(&RISE, A),
            at(&SAMPLED, A),
            at(&INPUT, A),
        ) else {
            return Ok(());
        };
        if !high.swap(true, Relaxed) {
            period.store(if sdi.load(Relaxed) { CS } else { CHAIN }, Relaxed);
            rise.store(clock::now(), Relaxed);
            let input = i.load(Relaxed);
            let code = match at(&FAULT, A).map_or(FAULT_NONE, |f| f.load(Relaxed)) {
                FAULT_FLOATING => s.load(Relaxed),
                // The stage's noise rides on the pulled-up input.
                FAULT_DISCONNECTED => DISCONNECTED_CODE + (input & 3),
                _ => input,
            };
            s.store(code, Relaxed);
        }
        Ok(())
    }
    fn set_low(&mut self) -> Result<(), Violation> {
        let (Some(high), Some(rise), Some(clocked)) =
            (at(&CNV_HIGH, A), at(&RISE, A), at(&CLOCKED, A))
        else {
            return Ok(());
        };
        if !high.swap(false, Relaxed) {
            return Ok(());
        }
        clocked.store(false, Relaxed);
        if clock::elapsed_min_ns(rise.load(Relaxed)) < T_CONV_MAX_NS {
            return Err(violate(4));
        }
        Ok(())
    }
}

impl<const A: usize> PinErrorType for Ldac<A> {
    type Error = Violation;
}
impl<const A: usize> OutputPin for Ldac<A> {
    fn set_low(&mut self) -> Result<(), Violation> {
        let (Some(low), Some(fall), Some(reg), Some(active), Some(written), Some(loaded)) = (
            at(&LDAC_LOW, A),
            at(&LDAC_FALL, A),
            at(&DAC_REG, A),
            at(&DAC_ACTIVE, A),
            at(&WRITTEN, A),
            at(&LOADED, A),
        ) else {
            return Ok(());
        };
        if !low.swap(true, Relaxed) {
            fall.store(clock::now(), Relaxed);
            active.store(reg.load(Relaxed), Relaxed);
            loaded.store(written.load(Relaxed), Relaxed);
            output_changed(A)?;
        }
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Violation> {
        let (Some(low), Some(fall)) = (at(&LDAC_LOW, A), at(&LDAC_FALL, A)) else {
            return Ok(());
        };
        if low.swap(false, Relaxed) && clock::elapsed_min_ns(fall.load(Relaxed)) < LDAC_LOW_MIN_NS {
            return Err(violate(7));
        }
        Ok(())
    }
}

/// The AD4020's serial interface (3-wire CS mode: CNV is the chip select).
pub struct AdcSpi<const A: usize>;
/// The AD5791's serial interface: 24-bit frames, a read answered in the next frame.
pub struct DacSpi<const A: usize>;

impl<const A: usize> ErrorType for AdcSpi<A> {
    type Error = Violation;
}
impl<const A: usize> SpiClock for AdcSpi<A> {
    fn set_sclk_max_hz(&mut self, max_hz: u32) -> u32 {
        set_rate(at(&ADC_BUS, A), max_hz)
    }
}
impl<const A: usize> SpiDevice for AdcSpi<A> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Violation> {
        let (Some(high), Some(sdi), Some(period), Some(clocked), Some(reg), Some(s), Some(bus)) = (
            at(&CNV_HIGH, A),
            at(&SDI_HIGH, A),
            at(&PERIOD, A),
            at(&CLOCKED, A),
            at(&ADC_REG, A),
            at(&SAMPLED, A),
            at(&ADC_BUS, A),
        ) else {
            return Ok(());
        };
        if high.load(Relaxed) {
            return Err(violate(0));
        }
        if bus.load(Relaxed) > ADC_SCK_MAX_HZ {
            return Err(violate(1));
        }
        let period = period.load(Relaxed);
        let mosi_high = wire::last_mosi_high(ops, sdi.load(Relaxed));
        if period == CHAIN {
            sdi.store(mosi_high, Relaxed);
            return Err(violate(2));
        }
        let (mosi, n) = wire::mosi_head::<2>(ops);
        let start = period == CS && !clocked.load(Relaxed);
        let command = n > 0 && matches!(mosi[0], ad4000::CMD_WRITE | ad4000::CMD_READ);
        if command && !start {
            return Err(violate(3));
        }
        let out: [u8; 4] = match mosi[0] {
            ad4000::CMD_WRITE if command && n >= 2 => {
                if mosi[1] & ad4000::REG_RESERVED != ad4000::REG_RESERVED {
                    return Err(violate(10));
                }
                let w = ad4000::REG_WRITABLE as u32;
                reg.store((reg.load(Relaxed) & !w) | (mosi[1] as u32 & w), Relaxed);
                [0xFF; 4]
            }
            ad4000::CMD_READ if command => [0xFF, reg.load(Relaxed) as u8, 0xFF, 0xFF],
            _ if start || period == POWER_UP => {
                let r = reg.load(Relaxed) as u8;
                let cfg = ad4000::Ad4000Config {
                    status: r & ad4000::REG_STATUS_BITS != 0,
                    ..ADC_CONFIG
                };
                let code = s.load(Relaxed);
                let over = code <= CODE_LO || code >= CODE_HI;
                ad4000::encode(&cfg, code, ad4000::status_of(r, over))
            }
            _ => [0; 4],
        };
        let out = match at(&FAULT, A).map_or(FAULT_NONE, |f| f.load(Relaxed)) {
            FAULT_STUCK_LOW => [0; 4],
            FAULT_STUCK_HIGH => [0xFF; 4],
            _ => out,
        };
        sdi.store(mosi_high, Relaxed);
        clocked.store(true, Relaxed);
        wire::clock_miso(ops, &out, |ns| TimerDelay.delay_ns(ns));
        Ok(())
    }
}

impl<const A: usize> ErrorType for DacSpi<A> {
    type Error = Violation;
}
impl<const A: usize> SpiClock for DacSpi<A> {
    fn set_sclk_max_hz(&mut self, max_hz: u32) -> u32 {
        set_rate(at(&DAC_BUS, A), max_hz)
    }
}
impl<const A: usize> SpiDevice for DacSpi<A> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), Violation> {
        let (Some(bus), Some(readback), Some(rise), Some(framed)) = (
            at(&DAC_BUS, A),
            at(&READBACK, A),
            at(&SYNC_RISE, A),
            at(&FRAMED, A),
        ) else {
            return Ok(());
        };
        // SYNC falls now (it rose at the end of the last frame: a frame's own bus time is
        // not modelled, so the whole gap must be t6).
        let short = framed.swap(true, Relaxed)
            && clock::elapsed_min_ns(rise.load(Relaxed)) < SYNC_HIGH_MIN_NS;
        let r = if short {
            Err(violate(11))
        } else {
            dac_frame::<A>(ops, bus, readback)
        };
        rise.store(clock::now(), Relaxed);
        r
    }
}

/// One SYNC-low frame of axis `A`'s AD5791 (the bus rules, then [`frame`]).
fn dac_frame<const A: usize>(
    ops: &mut [Operation<'_, u8>],
    bus: &AtomicU32,
    readback: &AtomicU32,
) -> Result<(), Violation> {
    let pending = readback.swap(0, Relaxed);
    let rb = pending.to_be_bytes();
    let out = [rb[1], rb[2], rb[3]];
    let mut word = 0u32;
    let mut n = 0usize;
    for op in ops.iter_mut() {
        let (r, w): (&mut [u8], &[u8]) = match op {
            Operation::Write(w) => (&mut [], w),
            Operation::Transfer(r, w) => (r, w),
            Operation::Read(r) => (r, &[]),
            Operation::TransferInPlace(_) | Operation::DelayNs(_) => (&mut [], &[]),
        };
        for i in 0..r.len().max(w.len()) {
            word = (word << 8) | w.get(i).copied().unwrap_or(0) as u32;
            if let Some(x) = r.get_mut(i) {
                *x = out.get(n).copied().unwrap_or(0);
            }
            n += 1;
        }
    }
    let hz = bus.load(Relaxed);
    if hz > DAC_SCLK_MAX_HZ {
        return Err(violate(5));
    }
    let read_command = word & (ad5791::READ) != 0 && n == 3;
    if (pending & PENDING != 0 || read_command) && hz > DAC_SCLK_READBACK_MAX_HZ {
        return Err(violate(6));
    }
    if n != 3 {
        return Ok(()); // not a 24-bit frame: ignored, as the chip does
    }
    frame::<A>(word & 0xFF_FFFF)
}

/// One 24-bit frame into axis `A`'s AD5791.
fn frame<const A: usize>(word: u32) -> Result<(), Violation> {
    let (Some(dac), Some(ctrl), Some(active), Some(written), Some(loaded), Some(rb), Some(low)) = (
        at(&DAC_REG, A),
        at(&DAC_CTRL, A),
        at(&DAC_ACTIVE, A),
        at(&WRITTEN, A),
        at(&LOADED, A),
        at(&READBACK, A),
        at(&LDAC_LOW, A),
    ) else {
        return Ok(());
    };
    let (reg, data) = ((word >> 20) & 0b111, word & ad5791::DATA_MASK);
    if word & ad5791::READ != 0 {
        let v = match reg {
            ad5791::REG_DAC => dac.load(Relaxed),
            ad5791::REG_CTRL => ctrl.load(Relaxed),
            _ => 0,
        };
        rb.store(v | PENDING, Relaxed);
        return Ok(());
    }
    match reg {
        ad5791::REG_DAC => {
            dac.store(data, Relaxed);
            written.store(true, Relaxed);
            if low.load(Relaxed) {
                active.store(data, Relaxed);
                loaded.store(true, Relaxed);
                return output_changed(A);
            }
        }
        ad5791::REG_CTRL => {
            ctrl.store(data & ad5791::CTRL_MASK, Relaxed);
            return output_changed(A);
        }
        ad5791::REG_SWCTRL if data & ad5791::SW_RESET != 0 => {
            dac.store(0, Relaxed);
            active.store(0, Relaxed);
            ctrl.store(CTRL_POWER_ON, Relaxed);
            written.store(false, Relaxed);
            loaded.store(false, Relaxed);
            return output_changed(A);
        }
        ad5791::REG_SWCTRL if data & ad5791::SW_LDAC != 0 => {
            active.store(dac.load(Relaxed), Relaxed);
            loaded.store(written.load(Relaxed), Relaxed);
            return output_changed(A);
        }
        _ => {}
    }
    Ok(())
}

pub type Adc<const A: usize = 0> = PositionAdc<AdcSpi<A>, Cnv<A>, TimerDelay>;
pub type Dac<const A: usize = 0> = ActuatorDac<DacSpi<A>, Ldac<A>, TimerDelay>;

/// The drivers on axis `A`'s mock chips, brought up: the ADC configured in CNV frames, the
/// DAC released at `safe_code` (its read-back checked by the driver).
pub fn drivers_of<const A: usize>(
    safe_code: i32,
) -> Result<(Adc<A>, Dac<A>), piezo_core::drivers::Error<Violation, Violation>> {
    let mut dac = Dac::new(DacSpi, Ldac, TimerDelay, DAC_CONFIG)?;
    dac.init(safe_code)?;
    let mut adc = Adc::new(AdcSpi, Cnv, TimerDelay, ADC_CONFIG)?;
    adc.init()?;
    Ok((adc, dac))
}
