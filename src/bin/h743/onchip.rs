//! The on-chip converters: ADC1 (16 bit, started by TIM2 TRGO) and DAC1 channel 1
//! (12 bit); with `xy` also ADC2 (same trigger) and DAC1 channel 2.

use piezo_core::firmware::{self, AXES};
use stm32h7xx_hal::{adc, pac, timer::Timer, traits::DacOut};

pub type DacChannel = stm32h7xx_hal::dac::C1<pac::DAC, stm32h7xx_hal::dac::Enabled>;
#[cfg(feature = "xy")]
pub type DacChannel2 = stm32h7xx_hal::dac::C2<pac::DAC, stm32h7xx_hal::dac::Enabled>;

/// Polls of ADC2's end of conversion after ADC1's (same trigger, same timing: it is
/// normally done already).
#[cfg(feature = "xy")]
const ADC2_POLLS: u32 = 64;

/// On-chip ADC1 (16 bit, started by TIM2 TRGO) and DAC1 channel 1 (12 bit); with `xy`
/// also ADC2 (same trigger) and DAC1 channel 2.
pub struct Io {
    pub adc: adc::Adc<pac::ADC1, adc::Enabled>,
    pub dac: DacChannel,
    #[cfg(feature = "xy")]
    pub adc2: adc::Adc<pac::ADC2, adc::Enabled>,
    #[cfg(feature = "xy")]
    pub dac2: DacChannel2,
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
        self.dac.set_value(x as u16);
        #[cfg(feature = "xy")]
        self.dac2.set_value(y as u16);
        [None; AXES]
    }
}
