//! The board's converters: the simulated stages behind the mock chips, through the
//! firmware's drivers.

use super::chips;
use super::stage::SimStage;
use piezo_core::firmware::{self, AXES, SAMPLE_HZ};

/// The simulated stage and the converter drivers of every axis the build drives (xy build:
/// two independent, identical stages, each behind its own AD4020/AD5791 pair).
pub struct SimIo {
    stage: [SimStage; AXES],
    adc: chips::Adc<0>,
    dac: chips::Dac<0>,
    #[cfg(feature = "xy")]
    adc1: chips::Adc<1>,
    #[cfg(feature = "xy")]
    dac1: chips::Dac<1>,
}

impl SimIo {
    pub fn new() -> Self {
        let (adc, dac) = chips::drivers_of::<0>();
        #[cfg(feature = "xy")]
        let (adc1, dac1) = chips::drivers_of::<1>();
        Self {
            stage: core::array::from_fn(|_| SimStage::new(SAMPLE_HZ as f32)),
            adc,
            dac,
            #[cfg(feature = "xy")]
            adc1,
            #[cfg(feature = "xy")]
            dac1,
        }
    }
}

impl firmware::Io for SimIo {
    /// One sample of every axis: the stage moves under its DAC's output, the ADC driver
    /// samples and reads it. A failed read gives a code outside every sensor window (the
    /// safe state). No sample is ever lost (SysTick paces the stage itself).
    #[inline(always)]
    fn sample(&mut self) -> ([i32; AXES], bool) {
        let mut codes = [i32::MIN; AXES];
        let (mut stage, mut code) = (self.stage.iter_mut(), codes.iter_mut());
        if let (Some(s), Some(c)) = (stage.next(), code.next()) {
            *c = read_axis(s, &mut self.adc);
        }
        #[cfg(feature = "xy")]
        if let (Some(s), Some(c)) = (stage.next(), code.next()) {
            *c = read_axis(s, &mut self.adc1);
        }
        (codes, false)
    }

    /// Writes and loads every axis' DAC code; a failed write reports the code its DAC
    /// still holds.
    #[inline(always)]
    fn write(&mut self, codes: [i32; AXES]) -> [Option<i32>; AXES] {
        let mut held = [None; AXES];
        let (mut code, mut h) = (codes.iter(), held.iter_mut());
        if let (Some(c), Some(h)) = (code.next(), h.next()) {
            *h = self.dac.set_code(*c).err().map(|_| chips::dac_out::<0>());
        }
        #[cfg(feature = "xy")]
        if let (Some(c), Some(h)) = (code.next(), h.next()) {
            *h = self.dac1.set_code(*c).err().map(|_| chips::dac_out::<1>());
        }
        held
    }
}

/// One axis: stage step, conversion, read. Not inlined: one call per axis, and the ELF's
/// debug info keeps naming `Ad4000::read` in the control interrupt (`.ci/firmware-code.py`).
#[inline(never)]
fn read_axis<const A: usize>(stage: &mut SimStage, adc: &mut chips::Adc<A>) -> i32 {
    let y = stage.step(chips::dac_out::<A>());
    chips::input_code(A).store(y, core::sync::atomic::Ordering::Relaxed);
    match adc.start_conversion() {
        Ok(()) => adc.read().unwrap_or(i32::MIN),
        Err(_) => i32::MIN,
    }
}
