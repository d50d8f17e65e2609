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
