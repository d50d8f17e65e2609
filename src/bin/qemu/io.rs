//! The board's converters: the simulated stages behind the mock chips, through the
//! firmware's drivers, plus the amplifier enable line and the `selftest` hand-over.

use super::chips;
use super::stage::SimStage;
use core::sync::atomic::{AtomicI32, AtomicU8, Ordering::Relaxed};
use piezo_core::drivers::Error;
use piezo_core::firmware::{self, AXES, SAMPLE_HZ};

/// `selftest` hand-over with the control period: the command line sets [`REQUESTED`], the
/// next period reads axis 0's DAC register back after its write and answers here.
pub mod selftest {
    use super::*;
    pub const IDLE: u8 = 0;
    pub const REQUESTED: u8 = 1;
    pub const DONE: u8 = 2;
    pub static STATE: AtomicU8 = AtomicU8::new(IDLE);
    /// The code the period wrote and the one it read back (`i32::MIN`: the read failed).
    pub static WROTE: AtomicI32 = AtomicI32::new(0);
    pub static READ: AtomicI32 = AtomicI32::new(0);
    /// The last ADC code of axis 0.
    pub static ADC: AtomicI32 = AtomicI32::new(0);
}

/// Sensor fault injection (harness line `sensor <fault>`): samples from the first faulty
/// conversion to the period that turned the amplifier off (the safe state), inclusive.
pub mod inject {
    use core::sync::atomic::{AtomicBool, AtomicU32};
    /// A fault is injected and the safe state not reached yet.
    pub static ACTIVE: AtomicBool = AtomicBool::new(false);
    /// Samples since the injection.
    pub static SAMPLES: AtomicU32 = AtomicU32::new(0);
    /// Samples to the safe state (`u32::MAX`: not reached).
    pub static SAFE_AFTER: AtomicU32 = AtomicU32::new(u32::MAX);
}

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
    /// Brings every axis' chips up: the DAC at `safe_code` first, then the ADC. On error
    /// the rule the driver broke (the DAC stays clamped or at the safe code).
    pub fn new(safe_code: i32) -> Result<Self, &'static str> {
        fn rule(e: Error<chips::Violation, chips::Violation>) -> &'static str {
            match e {
                Error::Spi(v) | Error::Pin(v) => v.0,
                Error::Verify { .. } => "a register read back differently",
                Error::Config(m) => m,
                Error::Status(_) => "the ADC's status bits were wrong",
            }
        }
        let (adc, dac) = chips::drivers_of::<0>(safe_code).map_err(rule)?;
        #[cfg(feature = "xy")]
        let (adc1, dac1) = chips::drivers_of::<1>(safe_code).map_err(rule)?;
        Ok(Self {
            stage: core::array::from_fn(|_| SimStage::new(SAMPLE_HZ as f32)),
            adc,
            dac,
            #[cfg(feature = "xy")]
            adc1,
            #[cfg(feature = "xy")]
            dac1,
        })
    }
}

impl firmware::Io for SimIo {
    /// One sample of every axis: the stage moves under its DAC's output, the ADC driver
    /// samples and reads it (CNV high for `t_CONV`, waited on the chips' timer). A failed
    /// read gives a code outside every sensor window (the safe state). No sample is ever
    /// lost (SysTick paces the stage itself).
    #[inline(always)]
    fn sample(&mut self) -> ([i32; AXES], bool) {
        if inject::ACTIVE.load(Relaxed) {
            inject::SAMPLES.fetch_add(1, Relaxed);
        }
        let mut codes = [i32::MIN; AXES];
        let (mut stage, mut code) = (self.stage.iter_mut(), codes.iter_mut());
        if let (Some(s), Some(c)) = (stage.next(), code.next()) {
            *c = read_axis(s, &mut self.adc);
            selftest::ADC.store(*c, Relaxed);
        }
        #[cfg(feature = "xy")]
        if let (Some(s), Some(c)) = (stage.next(), code.next()) {
            *c = read_axis(s, &mut self.adc1);
        }
        (codes, false)
    }

    /// Writes and loads every axis' DAC code; a failed write reports the code its DAC
    /// still holds. Answers a pending `selftest` with axis 0's read-back.
    #[inline(always)]
    fn write(&mut self, codes: [i32; AXES]) -> [Option<i32>; AXES] {
        let mut held = [None; AXES];
        let (mut code, mut h) = (codes.iter(), held.iter_mut());
        if let (Some(c), Some(h)) = (code.next(), h.next()) {
            *h = self.dac.set_code(*c).err().map(|_| chips::dac_out(0));
            if selftest::STATE.load(Relaxed) == selftest::REQUESTED {
                selftest::WROTE.store(*c, Relaxed);
                let read = self.dac.read_code().unwrap_or(i32::MIN);
                selftest::READ.store(read, Relaxed);
                selftest::STATE.store(selftest::DONE, Relaxed);
            }
        }
        #[cfg(feature = "xy")]
        if let (Some(c), Some(h)) = (code.next(), h.next()) {
            *h = self.dac1.set_code(*c).err().map(|_| chips::dac_out(1));
        }
        held
    }

    /// The amplifier enable line (the mock pin [`chips::AMP_ON`]).
    #[inline(always)]
    fn amplifier(&mut self, on: bool) {
        chips::AMP_ON.store(on, Relaxed);
        if !on && inject::ACTIVE.swap(false, Relaxed) {
            inject::SAFE_AFTER.store(inject::SAMPLES.load(Relaxed), Relaxed);
        }
    }
}

/// One axis: stage step, conversion (`t_CONV` waited), read. Not inlined: one call per
/// axis, and the ELF's debug info keeps naming `Ad4000::read` in the control interrupt
/// (`.ci/firmware-code.py`).
#[inline(never)]
fn read_axis<const A: usize>(stage: &mut SimStage, adc: &mut chips::Adc<A>) -> i32 {
    let y = stage.step(chips::dac_out(A));
    chips::set_input(A, y);
    adc.convert().unwrap_or(i32::MIN)
}
