//! The external SPI pair: AD4020 (CNV from TIM2 CH1) and AD5791 (LDAC from TIM2 CH2),
//! through the core's drivers.

use super::spi::{CycleDelay, Gpio, HardwarePin, SpiDev};
use crate::safe::amp;
use crate::selftest;
use core::sync::atomic::Ordering::Relaxed;
use piezo_core::firmware::{self, ActuatorDac, PositionAdc, AXES};
use stm32h7xx_hal::gpio::{Output, PushPull, PA0, PB3, PE4};
use stm32h7xx_hal::{pac, spi::Enabled, spi::Spi, timer::Timer};

pub type AdcBus = SpiDev<Spi<pac::SPI1, Enabled, u8>, HardwarePin>;
pub type DacBus = SpiDev<Spi<pac::SPI4, Enabled, u8>, Gpio<PE4<Output<PushPull>>>>;
/// The AD4020 while configuring: CNV (PA0) as a GPIO the driver toggles (register access
/// needs CNV frames); afterwards [`Adc`] with CNV from TIM2 CH1.
pub type AdcSetup = PositionAdc<AdcBus, Gpio<PA0<Output<PushPull>>>, CycleDelay>;
pub type Adc = PositionAdc<AdcBus, HardwarePin, CycleDelay>;
/// The AD5791 while configuring: LDAC (PB3) as a GPIO the driver pulses (`init` loads the
/// safe code); afterwards [`Dac`] with LDAC from TIM2 CH2.
pub type DacSetup = ActuatorDac<DacBus, Gpio<PB3<Output<PushPull>>>, CycleDelay>;
pub type Dac = ActuatorDac<DacBus, HardwarePin, CycleDelay>;

/// AD4020 (CNV from TIM2 CH1) and AD5791 through the core's drivers.
pub struct Io {
    pub adc: Adc,
    pub dac: Dac,
    pub timer: Timer<pac::TIM2>,
    /// The code the DAC holds (the last write that succeeded).
    pub held: i32,
}

impl firmware::Io for Io {
    /// This period's ADC code (a failed read gives a code outside every sensor window:
    /// the pipeline's range check takes the safe state), and whether a period was lost.
    #[inline(always)]
    fn sample(&mut self) -> ([i32; AXES], bool) {
        // CC1IF cleared first, so the interrupt pending again means the next CNV. No lost
        // flag here: CC1OF is set only in input-capture mode (CH1 is PWM); lost samples are
        // counted from the gap between the periods' triggers (`Dwt::periods_between`).
        self.timer.inner().sr.modify(|_, w| w.cc1if().clear_bit());
        let code = self.adc.read().unwrap_or(i32::MIN);
        selftest::ADC.store(code, Relaxed);
        ([code; AXES], false)
    }

    /// Writes the DAC register (TIM2 CH2's LDAC edge loads it at the next period's start);
    /// on failure returns the code it still holds.
    #[inline(always)]
    fn write(&mut self, codes: [i32; AXES]) -> [Option<i32>; AXES] {
        let [code] = codes;
        let held = match self.dac.write_code(code) {
            Ok(()) => {
                self.held = code;
                [None]
            }
            Err(_) => [Some(self.held)],
        };
        if selftest::STATE.load(Relaxed) == selftest::REQUESTED {
            // Two frames at <= 10.87 MHz (about 5 us): this period may overrun once.
            selftest::WROTE.store(code, Relaxed);
            selftest::READ.store(self.dac.read_code().unwrap_or(i32::MIN), Relaxed);
            selftest::STATE.store(selftest::DONE, Relaxed);
        }
        held
    }

    /// The amplifier enable line (PG12).
    #[inline(always)]
    fn amplifier(&mut self, on: bool) {
        amp::set(on);
    }
}
