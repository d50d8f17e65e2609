//! The on-chip converters: ADC1 (16 bit, started by TIM2 TRGO) and DAC1 channel 1
//! (12 bit); with `xy` also ADC2 (same trigger) and DAC1 channel 2.

use crate::safe::{amp, dac1};
use crate::selftest;
use core::sync::atomic::Ordering::Relaxed;
use piezo_core::firmware::{self, AXES};
use stm32h7xx_hal::{adc, pac, timer::Timer};

/// Polls of ADC2's end of conversion after ADC1's (same trigger, same timing: it is
/// normally done already).
#[cfg(feature = "xy")]
const ADC2_POLLS: u32 = 64;

/// On-chip ADC1 (16 bit, started by TIM2 TRGO) and DAC1 channel 1 (12 bit, register level:
/// [`dac1`], set up at the safe code first thing at boot); with `xy` also ADC2 (same
/// trigger) and DAC1 channel 2.
pub struct Io {
    pub adc: adc::Adc<pac::ADC1, adc::Enabled>,
    #[cfg(feature = "xy")]
    pub adc2: adc::Adc<pac::ADC2, adc::Enabled>,
    pub timer: Timer<pac::TIM2>,
}

/// The conversion result of `regs`, and whether one was overwritten (OVR).
#[inline(always)]
fn take(regs: &pac::adc1::RegisterBlock) -> (i32, bool) {
    // Reading DR clears EOC. OVR means a conversion was overwritten.
    let overrun = regs.isr.read().ovr().bit_is_set();
    if overrun {
        regs.isr.write(|w| w.ovr().set_bit());
    }
    (regs.dr.read().bits() as i32, overrun)
}

impl firmware::Io for Io {
    /// This period's ADC codes, and whether a conversion was lost (a missed deadline).
    #[inline(always)]
    fn sample(&mut self) -> ([i32; AXES], bool) {
        let (x, overrun) = take(self.adc.inner());
        selftest::ADC.store(x, Relaxed);
        #[cfg(not(feature = "xy"))]
        return ([x], overrun);
        #[cfg(feature = "xy")]
        {
            let regs: &pac::adc1::RegisterBlock = self.adc2.inner();
            let mut ready = false;
            for _ in 0..ADC2_POLLS {
                if regs.isr.read().eoc().bit_is_set() {
                    ready = true;
                    break;
                }
            }
            let (y, overrun2) = take(regs);
            // Late: an old sample would be stale; outside the sensor window instead.
            let y = if ready { y } else { i32::MIN };
            ([x, y], overrun || overrun2 || !ready)
        }
    }

    /// Writes the DACs; per axis, the code a DAC still holds after a failed write
    /// (never, on-chip).
    #[inline(always)]
    fn write(&mut self, codes: [i32; AXES]) -> [Option<i32>; AXES] {
        #[cfg(not(feature = "xy"))]
        let [x] = codes;
        #[cfg(feature = "xy")]
        let [x, y] = codes;
        // DOR took last period's DHR on this period's TIM2 trigger: the read-back.
        match selftest::STATE.load(Relaxed) {
            selftest::WRITTEN => {
                selftest::READ.store(dac1::output(0) as i32, Relaxed);
                selftest::STATE.store(selftest::DONE, Relaxed);
            }
            selftest::REQUESTED => {
                selftest::WROTE.store(x & 0x0FFF, Relaxed);
                selftest::STATE.store(selftest::WRITTEN, Relaxed);
            }
            _ => {}
        }
        dac1::set(0, x as u16);
        #[cfg(feature = "xy")]
        dac1::set(1, y as u16);
        [None; AXES]
    }

    /// The amplifier enable line (PG12).
    #[inline(always)]
    fn amplifier(&mut self, on: bool) {
        amp::set(on);
    }
}

/// ADC2 on the DAC's own pin for `selftest`'s scale (one axis; in the xy build ADC2 samples
/// the y sensor): PA4 is ADC12_INP18, so the conversion sees what the wiring leaves of the
/// DAC's output. Software-started single conversions, 16 bit, the longest sampling time
/// (810.5 ADC clocks, 22.5 us at 36 MHz) for the unbuffered pin's ~15 kOhm source.
#[cfg(not(feature = "xy"))]
pub mod dac_pin {
    use stm32h7xx_hal::pac;

    const CHANNEL: u8 = 18;
    /// Polls of the end of conversion (each at least a few core cycles: over 100 us at
    /// 400 MHz, against a conversion of about 23 us).
    const POLLS: u32 = 40_000;

    #[allow(unsafe_code)]
    fn regs() -> &'static pac::adc1::RegisterBlock {
        // SAFETY: in the one-axis on-chip build ADC2 is this module's alone (init enables
        // and calibrates it through the HAL, then only `setup` and `convert` touch it, both
        // from the command task).
        unsafe { &*pac::ADC2::ptr() }
    }

    /// The channel, resolution and sampling time, software trigger, single conversions
    /// (ADC2 enabled by the HAL, idle).
    #[allow(unsafe_code)]
    pub fn setup() {
        let r = regs();
        r.cfgr
            .modify(|_, w| w.res().sixteen_bit().exten().disabled().cont().clear_bit());
        // SAFETY: PCSEL holds one bit per channel (20); SQ1 takes a channel number < 20.
        r.pcsel
            .modify(|r, w| unsafe { w.pcsel().bits(r.pcsel().bits() | 1 << CHANNEL) });
        r.smpr2.modify(|_, w| w.smp18().cycles810_5());
        r.sqr1
            .modify(|_, w| unsafe { w.sq1().bits(CHANNEL) }.l().bits(0));
    }

    /// One conversion of the pin (16-bit code), or `None` when ADC2 is off, busy, or gives
    /// no result within [`POLLS`].
    pub fn convert() -> Option<u32> {
        let r = regs();
        let cr = r.cr.read();
        if cr.aden().bit_is_clear() || cr.adstart().bit_is_set() {
            return None;
        }
        r.isr.write(|w| w.eoc().clear());
        r.cr.modify(|_, w| w.adstart().set_bit());
        (0..POLLS)
            .any(|_| r.isr.read().eoc().bit_is_set())
            .then(|| r.dr.read().bits() & 0xFFFF)
    }
}
