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
    /// Whole control periods from one trigger to a later one (both read by
    /// [`Clock::since_trigger`]), on a counter that spans periods (the H743's DWT);
    /// `None` on one that wraps every period (QEMU's SysTick).
    fn periods_between(&self, _from: u32, _to: u32) -> Option<u32> {
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
        let t = &mut ctl.timing;
        // Samples lost entirely: the trigger counter wraps every period, so a period that
        // starts a whole period late reads its trigger a period late, and the gap between
        // two periods' triggers counts the periods that got no run of their own.
        let trigger = delay.map(|d| t0.wrapping_sub(d));
        let missed = match (t.last_trigger, trigger) {
            (Some(from), Some(to)) => clock
                .periods_between(from, to)
                .map_or(0, |n| n.saturating_sub(1)),
            _ => 0,
        };
        t.last_trigger = trigger;
        let late = lost || missed > 0 || clock.next_due();
        let isr = clock.elapsed(t0, clock.now());
        let late = late || isr > clock.period();
        t.step.record(clock.elapsed(t1, t2));
        t.isr.record(isr);
        if let Some(d) = delay {
            t.delay.record(d);
        }
        t.lost = t.lost.wrapping_add(missed);
        // A converter's own lost flag (the ADC's overrun) may name the same lost sample.
        t.overruns = t.overruns.wrapping_add(missed.max(u32::from(late)));
        ctl.periods = ctl.periods.wrapping_add(1);
        !late
    })
}

/// The boards' NMPC solver task, written once: for every axis whose NMPC waits for a plan
/// ([`Ctl::nmpc_waiting`]; the control task pends this task then), the law and its job are
/// copied under one short lock, solved without it, and the plan handed back under another
/// ([`crate::feedback::Nmpc::set_deferred`]). Runs below the control task and above the
/// command task. Bounded: one solve per axis. Returns the plans taken.
pub fn solve_nmpc<C, M>(ctl: &mut M) -> u32
where
    C: Converters,
    M: Mutex<T = Ctl<C>>,
{
    let mut taken = 0;
    for axis in 0..AXES {
        let Some((law, job)) = ctl.lock(|c| c.nmpc_job(axis)) else {
            continue;
        };
        let plan = law.solve_job(&job);
        if ctl.lock(|c| c.nmpc_deliver(axis, &job, plan)) {
            taken += 1;
        }
    }
    taken
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::firmware::{c, OnChip, SAMPLE_HZ};
    use core::cell::Cell;
    use rtic_core::Exclusive;

    const PERIOD: u32 = 4000;

    /// A board whose counter spans periods (as the H743's DWT) and whose trigger counter
    /// wraps every period (as its TIM2): `now` is set per period by the test.
    struct Board {
        now: Cell<u32>,
        spans: bool,
    }

    impl Clock for Board {
        fn now(&self) -> u32 {
            self.now.get()
        }
        fn elapsed(&self, start: u32, end: u32) -> u32 {
            end.wrapping_sub(start)
        }
        fn period(&self) -> u32 {
            PERIOD
        }
        fn since_trigger(&self, now: u32) -> Option<u32> {
            Some(now % PERIOD)
        }
        fn periods_between(&self, from: u32, to: u32) -> Option<u32> {
            self.spans
                .then(|| (to.wrapping_sub(from) + PERIOD / 2) / PERIOD)
        }
    }

    struct Converters;

    impl Io for Converters {
        fn sample(&mut self) -> ([i32; AXES], bool) {
            ([0; AXES], false)
        }
        fn write(&mut self, _: [i32; AXES]) -> [Option<i32>; AXES] {
            [None; AXES]
        }
    }

    /// Periods starting at these counter readings: (lost, overruns).
    fn run(starts: &[u32], spans: bool) -> (u32, u32) {
        let mut ctl = crate::firmware::Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
        let clock = Board {
            now: Cell::new(0),
            spans,
        };
        for &s in starts {
            clock.now.set(s);
            control_period(&mut Converters, &clock, &mut Exclusive(&mut ctl));
        }
        (ctl.timing.lost, ctl.timing.overruns)
    }

    #[test]
    fn a_sample_lost_entirely_is_counted() {
        // On time, and late within their own period: nothing lost.
        assert_eq!(
            run(&[10, PERIOD + 10, 2 * PERIOD + 3900, 3 * PERIOD + 20], true),
            (0, 0)
        );
        // The third trigger passed without a run: its period started after the fourth
        // trigger, where the wrapping trigger counter reads a small delay.
        assert_eq!(run(&[10, PERIOD + 10, 3 * PERIOD + 30], true), (1, 1));
        // Three triggers without a run.
        assert_eq!(run(&[10, 4 * PERIOD + 30], true), (3, 3));
        // A counter that wraps every period cannot tell (QEMU's SysTick).
        assert_eq!(run(&[10, 4 * PERIOD + 30], false), (0, 0));
    }

    /// `stats` gives the NMPC solver's record: jobs posted, and boundaries whose plan had
    /// not come back (here while no solver ran), then none missed while one runs.
    #[test]
    fn stats_name_the_nmpc_jobs_and_the_missed_ones() {
        use crate::feedback::Feedback;
        use crate::firmware::{Converters as _, NMPC_DECIMATION};
        let mut ctl = crate::firmware::Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
        let stats =
            |ctl: &mut crate::firmware::Ctl<OnChip>| ctl.answer("stats").as_str().to_owned();
        assert!(
            stats(&mut ctl).ends_with(" lost 0 late -"),
            "{}",
            stats(&mut ctl)
        );
        assert!(!stats(&mut ctl).contains("nmpc"));
        assert_eq!(ctl.answer("mode nmpc").as_str(), "ok mode nmpc");
        for axis in 0..AXES {
            if let Some(Feedback::Nmpc(n)) = ctl.lp.p.feedback_mut(axis) {
                n.set_deferred(true);
            }
        }
        let mid = 1 << (OnChip::ADC_BITS - 1);
        let counts = |ctl: &mut crate::firmware::Ctl<OnChip>| {
            let s = stats(ctl);
            let w: Vec<&str> = s.split_whitespace().collect();
            assert_eq!(w[w.len() - 4..w.len() - 3], ["nmpc_jobs"], "{s}");
            assert_eq!(w[w.len() - 2], "nmpc_missed", "{s}");
            let n = |i: usize| w[w.len() - i].parse::<u32>().unwrap();
            (n(3), n(1))
        };
        let axes = AXES as u32;
        for _ in 0..5 * NMPC_DECIMATION {
            ctl.lp.step([mid; AXES]);
        }
        // Without a solver every job but each axis' first is missed.
        let (jobs, missed) = counts(&mut ctl);
        assert!(jobs >= 4 * axes && missed == jobs - axes, "{jobs} {missed}");
        for _ in 0..5 * NMPC_DECIMATION {
            ctl.lp.step([mid; AXES]);
            solve_nmpc(&mut Exclusive(&mut ctl));
        }
        // With one, five more boundaries per axis; at most the job left unsolved when the
        // solver started is missed.
        let (jobs2, missed2) = counts(&mut ctl);
        assert_eq!(jobs2, jobs + 5 * axes);
        assert!(missed2 - missed <= axes, "{missed} -> {missed2}");
        // `stats reset` clears the timing, not the solver's record (it is the mode's).
        assert!(ctl.answer("stats reset").as_str().starts_with("ok"));
        assert!(stats(&mut ctl).contains(" nmpc_jobs "));
        assert_eq!(ctl.answer("mode hgo-robust").as_str(), "ok mode hgo-robust");
        assert!(!stats(&mut ctl).contains("nmpc"));
    }
}
