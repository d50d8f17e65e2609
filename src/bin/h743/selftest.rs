//! `selftest`: the command line asks, the next control period reads axis 0's DAC back after
//! its write (the on-chip DAC's output register one period later, after the trigger that
//! loads it; or the AD5791's DAC register at the read-back SCLK) and answers; the reply adds the last ADC code against the sensor window,
//! the amplifier enable line and the reset cause, and (on-chip, one axis) the DAC's scale as
//! its pin sees it.

use crate::safe::{amp, reset_cause, RESET_FLAGS};
use core::sync::atomic::{AtomicI32, AtomicU8, Ordering::Relaxed};
use piezo_core::command::Reply;
#[cfg(not(any(feature = "spi-converters", feature = "xy")))]
use piezo_core::firmware::{dac_scale, push_dac_scale};
use piezo_core::firmware::{push_dac_readback, Converters, REPLY_LEN};

pub const IDLE: u8 = 0;
pub const REQUESTED: u8 = 1;
pub const DONE: u8 = 2;
/// The period wrote its code; the next one reads the output register (the DAC loads it on
/// the next TIM2 trigger; on-chip only).
#[cfg(not(feature = "spi-converters"))]
pub const WRITTEN: u8 = 3;
pub static STATE: AtomicU8 = AtomicU8::new(IDLE);
/// The code the period wrote and the one it read back (`i32::MIN`: the read failed).
pub static WROTE: AtomicI32 = AtomicI32::new(0);
pub static READ: AtomicI32 = AtomicI32::new(0);
/// The last ADC code of axis 0.
pub static ADC: AtomicI32 = AtomicI32::new(0);

/// Asks the control period for a read-back, waits for it (bounded: the command task runs
/// below the control task, so a running loop answers within one period),
/// and appends the findings.
pub fn run<C: Converters>(r: &mut Reply<REPLY_LEN>) {
    STATE.store(REQUESTED, Relaxed);
    // At least 1 ms of polls at 400 MHz (a poll is several cycles).
    let done = (0..400_000).any(|_| STATE.load(Relaxed) == DONE);
    STATE.store(IDLE, Relaxed);
    r.push_str(" reset ");
    r.push_str(reset_cause(RESET_FLAGS.load(Relaxed)));
    r.push_str(" dac ");
    push_dac_readback(r, done.then(|| (READ.load(Relaxed), WROTE.load(Relaxed))));
    let adc = ADC.load(Relaxed);
    let s = C::sensor(0.0);
    r.push_str(" adc ");
    r.push_i32(adc);
    let seen = adc >> C::ADC_SHIFT;
    r.push_str(if (s.code_min..=s.code_max).contains(&seen) {
        " in"
    } else {
        " out"
    });
    r.push_str(" amp ");
    r.push_str(if amp::is_on() { "on" } else { "off" });
    // The DAC's scale as its pin sees it (on-chip, one axis): the pin converted by ADC2
    // between two reads of the DAC's output code.
    #[cfg(not(any(feature = "spi-converters", feature = "xy")))]
    {
        use crate::safe::dac1;
        let before = dac1::output(0) as u32;
        let pin = crate::onchip::dac_pin::convert();
        let after = dac1::output(0) as u32;
        push_dac_scale(r, dac_scale(before, after, pin, 12, 16));
    }
}
