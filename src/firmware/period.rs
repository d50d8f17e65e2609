//! The control period, written once for every board: the board supplies its converters
//! ([`Io`]) and its cycle counter ([`Clock`]).

use super::converters::Converters;
use super::ctl::Ctl;
use super::target::AXES;
use rtic_core::Mutex;

/// A board's converters as the control period sees them.
pub trait Io {
    /// This period's ADC codes, and whether a sample was lost since the last period (a
    /// missed deadline). A failed read gives a code outside every sensor window: the
    /// pipeline's range check then takes the safe state.
    fn sample(&mut self) -> ([i32; AXES], bool);
    /// Writes and loads the DAC codes; per axis, the code a DAC still holds after a failed
    /// write.
    fn write(&mut self, codes: [i32; AXES]) -> [Option<i32>; AXES];
    /// Drives the amplifier enable line: on while no fault is latched (the pipeline is not
    /// in its safe state), off otherwise. Called every period after the DAC write.
    fn amplifier(&mut self, _on: bool) {}
}

/// A board's cycle counter.
pub trait Clock {
    /// The counter now.
    fn now(&self) -> u32;
    /// Ticks from `start` to `end`, two readings within one control period.
    fn elapsed(&self, start: u32, end: u32) -> u32;
    /// Ticks per control period: a period that takes longer missed its deadline.
    fn period(&self) -> u32;
    /// The next period is due already (its interrupt is pending): this one overran.
    fn next_due(&self) -> bool {
        false
    }
    /// Ticks from this period's trigger (the timer event) to `now`, on a board whose
    /// counter can tell (QEMU's SysTick counts from its reload): the control interrupt's
    /// delay, by higher-priority work or a lock held by a lower-priority task.
    fn since_trigger(&self, _now: u32) -> Option<u32> {
        None
    }
}

/// One control period, from the interrupt that says a sample is ready: read the ADCs, step
/// the pipeline, write the DACs (a failed write latches the safe state), feed the recorder,
/// record the timing. Returns whether the period met its deadline (the H743 feeds its
/// watchdog only then). No panic, bounded.
#[inline(always)]
pub fn control_period<C, I, K, M>(io: &mut I, clock: &K, ctl: &mut M) -> bool
where
    C: Converters,
    I: Io,
    K: Clock,
    M: Mutex<T = Ctl<C>>,
{
    let t0 = clock.now();
    let delay = clock.since_trigger(t0);
    let (code, lost) = io.sample();
    ctl.lock(|ctl| {
        let t1 = clock.now();
        let dac_code = ctl.lp.step(code);
        let t2 = clock.now();
        for (axis, held) in io.write(dac_code).into_iter().enumerate() {
            if let Some(held) = held {
                ctl.lp.dac_write_failed(axis, held);
            }
        }
        io.amplifier(ctl.lp.p.state().fault.is_none());
        ctl.record(code, dac_code);
        let late = lost || clock.next_due();
        let isr = clock.elapsed(t0, clock.now());
        let late = late || isr > clock.period();
        let t = &mut ctl.timing;
        t.step.record(clock.elapsed(t1, t2));
        t.isr.record(isr);
        if let Some(d) = delay {
            t.delay.record(d);
        }
        if late {
            t.overruns = t.overruns.wrapping_add(1);
        }
        ctl.periods = ctl.periods.wrapping_add(1);
        !late
    })
}
