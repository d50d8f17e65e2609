//! The H743's safe state at register level (RM0433), so it works before the HAL is set up
//! and from the panic and HardFault handlers, where the HAL's owned peripherals are out of
//! reach.
//!
//! * [`early`]: the first thing `init` runs: the independent watchdog started and frozen
//!   under the debugger, the reset cause read, the amplifier enable line driven low, the
//!   on-chip DAC at the safe code.
//! * [`halt`]: a panic or HardFault: interrupts off, amplifier off, the safe code into every
//!   DAC of the build (the AD5791 through the same driver over a register-level SPI4), then
//!   a wait for the watchdog reset.
//!
//! The hardware side (README, bring-up guide): a pull-down on the amplifier enable line
//! (amplifier off while the MCU is in reset or its pin is not yet driven) and on the DAC
//! output the amplifier sees (0 V while no DAC drives it).

use core::sync::atomic::{AtomicI32, AtomicU32, Ordering::Relaxed};
use stm32h7xx_hal::pac;

/// RCC_RSR as read at boot, before RMVF cleared it.
pub static RESET_FLAGS: AtomicU32 = AtomicU32::new(0);
/// The DAC's safe code (the pipeline's safe voltage at the DAC's own scale): set in `init`,
/// read by [`halt`].
pub static SAFE_CODE: AtomicI32 = AtomicI32::new(0);
/// The independent watchdog while booting (ms), before the loop's own 10 ms.
pub const BOOT_WATCHDOG_MS: u32 = 100;

/// The DAC code of the pipeline's safe voltage at the DAC's own scale: the start-up code
/// the pipeline itself computes (`Output::code_in_range` of the safe voltage, axis 0's
/// converter configuration), without building the pipeline (which would put a copy of the
/// control state on `init`'s stack). 0 if the configuration were refused.
#[inline(never)]
pub fn safe_code<C: piezo_core::firmware::Converters>() -> i32 {
    use piezo_core::firmware::{c, converter_config, SAMPLE_HZ};
    let config = converter_config::<C>(c(SAMPLE_HZ as f64));
    let [axis, ..] = config.axes;
    piezo_core::pipeline::Output::new(&axis.limits, &axis.dac, config.sample_hz)
        .map_or(0, |o| o.code_in_range(axis.safe_volts) << C::DAC_SHIFT)
}

pub use piezo_core::firmware::reset::reset_cause;

/// Boot, before anything that can fail: IWDG1 started at [`BOOT_WATCHDOG_MS`] and frozen
/// while the core is halted by a debugger (DBGMCU_APB4FZ1.DBG_IWDG1); RCC_RSR kept and
/// cleared (RMVF); the amplifier off; the on-chip DAC at `safe_code` (on-chip builds; the
/// AD5791 of `spi-converters` sits clamped at 0 V from its own power-on until `init` brings
/// it up at the safe code).
#[allow(unsafe_code)]
pub fn early(iwdg: &pac::IWDG, dbgmcu: &pac::DBGMCU, rcc: &pac::RCC, safe_code: u16) {
    dbgmcu.apb4fz1.modify(|_, w| w.dbg_iwdg1().set_bit());
    // IWDG1 (RM0433 "Independent watchdog"): KR = 0xCCCC starts it (and the LSI), 0x5555
    // unlocks PR/RLR; /64 prescaler (PR = 4): 32 kHz / 64 = 2 ms per count.
    // SAFETY: the documented key values and field ranges (PR 3 bits, RLR 12 bits).
    iwdg.kr.write(|w| unsafe { w.bits(0xCCCC) });
    iwdg.kr.write(|w| unsafe { w.bits(0x5555) });
    iwdg.pr.write(|w| unsafe { w.bits(4) });
    iwdg.rlr.write(|w| unsafe { w.bits(BOOT_WATCHDOG_MS / 2) });
    iwdg.kr.write(|w| unsafe { w.bits(0xAAAA) });
    RESET_FLAGS.store(rcc.rsr.read().bits(), Relaxed);
    rcc.rsr.modify(|_, w| w.rmvf().set_bit());
    amp::init(rcc);
    #[cfg(not(feature = "spi-converters"))]
    dac1::init(rcc, safe_code);
    #[cfg(feature = "spi-converters")]
    let _ = safe_code;
}

/// Polls of HSERDY before the boot gives HSE up (a poll is a few cycles of the 64 MHz HSI
/// the boot runs on: a few ms, far under the boot watchdog's 100 ms; an HSE in bypass is
/// ready within microseconds of a good clock).
const HSE_POLLS: u32 = 100_000;
/// RCC_CR bits (RM0433): HSEON, HSERDY, HSEBYP, HSECSSON.
const CR_HSEON: u32 = 1 << 16;
const CR_HSERDY: u32 = 1 << 17;
const CR_HSEBYP: u32 = 1 << 18;
const CR_HSECSSON: u32 = 1 << 19;

/// HSE in bypass (the ST-LINK's 8 MHz MCO) started with a bounded wait; true when ready.
/// The HAL's `freeze` waits for HSERDY without a bound, so a missing MCO would hang the
/// boot until the watchdog resets it, over and over; on false HSE is off again and the
/// caller runs the PLL from HSI.
#[allow(unsafe_code)]
pub fn hse_start(rcc: &pac::RCC) -> bool {
    // SAFETY: RCC_CR bits of HSE alone; HSEBYP is written while HSE is off (at reset).
    rcc.cr
        .modify(|r, w| unsafe { w.bits(r.bits() | CR_HSEBYP) });
    rcc.cr.modify(|r, w| unsafe { w.bits(r.bits() | CR_HSEON) });
    let ready = (0..HSE_POLLS).any(|_| rcc.cr.read().bits() & CR_HSERDY != 0);
    if !ready {
        // SAFETY: as above.
        rcc.cr
            .modify(|r, w| unsafe { w.bits(r.bits() & !(CR_HSEON | CR_HSEBYP)) });
    }
    ready
}

/// The clock security system on HSE (RCC_CR.HSECSSON): a failing HSE raises the NMI, whose
/// handler takes the safe state ([`NonMaskableInt`]).
#[allow(unsafe_code)]
pub fn css_on() {
    // SAFETY: RCC_CR.HSECSSON alone, after HSE is ready (a write-once-to-set bit).
    let rcc = unsafe { &*pac::RCC::ptr() };
    rcc.cr
        .modify(|r, w| unsafe { w.bits(r.bits() | CR_HSECSSON) });
}

/// The NMI: the clock security system saw HSE fail (nothing else raises it here). The safe
/// state, then the watchdog resets the MCU and the next boot falls back to HSI if HSE is
/// still missing. Never returns (an NMI cannot be masked; returning would re-enter).
///
/// # Safety
/// The NMI preempts everything; it only takes the safe state, whose register writes are
/// the halt path's own (amplifier line, DAC), and never returns.
#[cortex_m_rt::exception]
#[allow(unsafe_code)]
unsafe fn NonMaskableInt() -> ! {
    halt()
}

/// Interrupts off, amplifier off, the safe code out; never returns (the watchdog, no
/// longer fed, resets the MCU within its timeout).
pub fn halt() -> ! {
    safe_out();
    park()
}

/// The watchdog's wait.
fn park() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

/// Interrupts off, amplifier off, the safe code into every DAC.
fn safe_out() {
    cortex_m::interrupt::disable();
    amp::off();
    let code = SAFE_CODE.load(Relaxed);
    #[cfg(not(feature = "spi-converters"))]
    {
        dac1::untriggered();
        dac1::set(0, code as u16);
        dac1::set(1, code as u16);
    }
    #[cfg(feature = "spi-converters")]
    {
        use crate::spi::{CycleDelay, PanicLdac, PanicSpi4};
        let dac = piezo_core::drivers::Ad5791::new(
            PanicSpi4,
            PanicLdac,
            CycleDelay,
            piezo_core::firmware::DAC_CONFIG,
        );
        if let Ok(mut dac) = dac {
            dac.set_code(code).ok();
        }
    }
}

/// A panic (thread mode only: no interrupt handler has a panic path, checked by
/// `.ci/firmware-safety.py`): the safe code written first, the message only after, over
/// defmt (its formatting and transport may take long or fail).
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    safe_out();
    defmt::error!("panic: {}", defmt::Display2Format(info));
    park()
}

// A HardFault (a bus fault, a stack overflow caught by flip-link, ...): the safe state,
// from a known-good stack (the entry moves MSP to the stack's top first).
#[allow(unsafe_code)]
mod hard_fault {
    piezo_core::hard_fault_entry!(super::hard_fault_halt);
}

/// The HardFault's safe state, entered from the assembly entry on the fresh stack.
extern "C" fn hard_fault_halt() -> ! {
    halt()
}

/// The amplifier enable line: PG12, push-pull output, high = amplifier on. A pull-down on
/// the board holds it low through reset.
pub mod amp {
    use stm32h7xx_hal::pac;
    const PIN: u32 = 12;

    #[allow(unsafe_code)]
    fn gpiog() -> &'static pac::gpiog::RegisterBlock {
        // SAFETY: this module is PG12's only user; BSRR writes touch PG12 alone.
        unsafe { &*pac::GPIOG::ptr() }
    }

    /// GPIOG clocked (RCC_AHB4ENR.GPIOGEN), PG12 low, then an output (GPIOG_MODER12 = 01).
    #[allow(unsafe_code)]
    pub fn init(rcc: &pac::RCC) {
        rcc.ahb4enr.modify(|_, w| w.gpiogen().set_bit());
        let _ = rcc.ahb4enr.read(); // the clock is on before the first GPIOG access
        off();
        let mask = 0b11 << (2 * PIN);
        // SAFETY: MODER12 = 0b01 (general-purpose output); the other pins keep theirs.
        gpiog()
            .moder
            .modify(|r, w| unsafe { w.bits((r.bits() & !mask) | (0b01 << (2 * PIN))) });
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    pub fn off() {
        // SAFETY: BSRR.BR12 resets PG12 only.
        gpiog().bsrr.write(|w| unsafe { w.bits(1 << (PIN + 16)) });
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    pub fn set(on: bool) {
        let bit = if on { 1 << PIN } else { 1 << (PIN + 16) };
        // SAFETY: BSRR.BS12/BR12 set or reset PG12 only.
        gpiog().bsrr.write(|w| unsafe { w.bits(bit) });
    }

    /// The line's level as driven (GPIOG_ODR12).
    pub fn is_on() -> bool {
        gpiog().odr.read().bits() & (1 << PIN) != 0
    }
}

#[cfg(not(feature = "spi-converters"))]
/// The on-chip DAC1 (12 bit) at register level: channel 1 on PA4, channel 2 (`xy`) on PA5.
/// The pins are analog at reset (GPIOA_MODER reset value), as the DAC needs. The HAL's DAC
/// is not used: its constructor resets the DAC and its buffer calibration disables the
/// channel (the output floats) in an unbounded loop; the factory trim stays in use.
pub mod dac1 {
    use stm32h7xx_hal::pac;

    #[allow(unsafe_code)]
    fn regs() -> &'static pac::dac::RegisterBlock {
        // SAFETY: DAC1 is this module's alone; the control task writes the holding
        // registers, the halt path too after masking interrupts.
        unsafe { &*pac::DAC::ptr() }
    }

    /// DAC_CR: EN1, TEN1, TSEL1[3:0] (bits 5:2); channel 2 the same 16 bits up.
    const EN: u32 = 1 | 1 << 16;
    const TEN: u32 = 1 << 1 | 1 << 17;
    const TSEL: u32 = 0b1111 << 2 | 0b1111 << 18;
    /// TSEL = 2: dac_chx_trg2 = tim2_trgo (RM0433 "DAC interconnection"; the PAC's 3-bit
    /// field is too narrow, hence raw bits).
    const TSEL_TIM2: u32 = 2 << 2 | 2 << 18;
    #[cfg(not(feature = "xy"))]
    const CHANNELS: u32 = 0xFFFF;
    #[cfg(feature = "xy")]
    const CHANNELS: u32 = 0xFFFF_FFFF;

    /// Clock on (RCC_APB1LENR.DAC12EN), holding registers at `code`, normal mode with the
    /// output buffer off (DAC_MCR.MODEx = 010: the full 0..VREF+ range, so code 0 really
    /// is 0 V; the buffered output stops about 0.2 V from either rail, DS12110), channel(s)
    /// enabled (DAC_CR.ENx), no trigger yet: DHR moves to the output one APB clock after
    /// each write.
    #[allow(unsafe_code)]
    pub fn init(rcc: &pac::RCC, code: u16) {
        rcc.apb1lenr.modify(|_, w| w.dac12en().set_bit());
        let _ = rcc.apb1lenr.read();
        set(0, code);
        set(1, code);
        // SAFETY: MODE = 0b010 is a valid mode (normal, buffer off, external pin).
        regs()
            .mcr
            .modify(|_, w| unsafe { w.mode1().bits(0b010).mode2().bits(0b010) });
        // SAFETY: EN bits of the build's channels.
        regs()
            .cr
            .modify(|r, w| unsafe { w.bits(r.bits() | (EN & CHANNELS)) });
    }

    /// Reconfigures DAC_CR (TENx/TSELx only change while the channel is off, RM0433): the
    /// channel is off for the few cycles between the two writes, its output register keeps
    /// its code, and the board's pull-down holds the line meanwhile.
    #[allow(unsafe_code)]
    fn reconfigure(trigger: u32) {
        let cr = &regs().cr;
        // SAFETY: raw DAC_CR bits of the build's channels: EN, TEN, TSEL fields only.
        cr.modify(|r, w| unsafe { w.bits(r.bits() & !(EN & CHANNELS)) });
        cr.modify(|r, w| unsafe {
            w.bits((r.bits() & !((TEN | TSEL) & CHANNELS)) | (trigger & CHANNELS))
        });
        cr.modify(|r, w| unsafe { w.bits(r.bits() | (EN & CHANNELS)) });
    }

    /// The loop's mode: DHR moves to the output on TIM2's update (TRGO), the edge that
    /// also starts the ADC: a fixed one-period ADC-to-DAC latency, whatever the step's
    /// length. Set before TIM2 starts.
    pub fn trigger_from_tim2() {
        reconfigure(TEN | TSEL_TIM2);
    }

    /// The halt path's mode: no trigger, so the safe code goes out at once even with TIM2
    /// stopped.
    pub fn untriggered() {
        reconfigure(0);
    }

    /// Channel `ch` (0 or 1) to `code` (12 bit, right aligned: DAC_DHR12R1/2).
    #[inline(always)]
    #[allow(unsafe_code)]
    pub fn set(ch: usize, code: u16) {
        let v = (code & 0x0FFF) as u32;
        // SAFETY: DHR12Rx holds 12 data bits; the mask keeps the rest 0.
        if ch == 0 {
            regs().dhr12r1.write(|w| unsafe { w.bits(v) });
        } else {
            regs().dhr12r2.write(|w| unsafe { w.bits(v) });
        }
    }

    /// The code channel `ch` outputs (DAC_DOR1/2), for `selftest`'s read-back.
    pub fn output(ch: usize) -> u16 {
        let d = regs();
        (if ch == 0 {
            d.dor1.read().bits()
        } else {
            d.dor2.read().bits()
        } & 0x0FFF) as u16
    }
}
