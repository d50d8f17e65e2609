//! Mode budgets (issue 15 item 4): every feedback law x feedforward has a worst-case control
//! step, and the command line refuses a combination whose worst case does not fit the
//! control period at the board's rate and clock (`err 18`); nothing changes then.
//!
//! The worst cases are instructions per step (the pipeline step alone: ADC code in, DAC code
//! out), measured by the QEMU board's bench on the M4F (f32): every step of a 2000-step
//! closed-loop run timed, from rest and across a parameter change ([`WORST_M4F`]). The QEMU
//! board builds its budget from its own measurement at boot; CI checks that none of its
//! measured worst cases exceeds this table, so the table cannot go stale. The H743 uses the
//! table with one instruction per core cycle (its code in ITCM, its state in DTCM; not
//! measured on a board).

use super::laws::{FFS, LAWS, NMPC_DECIMATION};
use super::target::AXES;
use crate::command::Error;

/// Worst-case instructions of one step per law (rows, [`LAWS`] order) and feedforward
/// (columns, [`FFS`] order) on the QEMU M4F, f32: the bench's worst (`30-qemu.sh`, which
/// fails if a measurement exceeds this table) rounded up to the next 200 instructions, plus
/// 200 (the bench counts in 40-instruction SysTick ticks). `open-loop` stands
/// for the open-loop modes (`open-loop`, `feedforward`).
pub const WORST_M4F: [[u32; FFS.len()]; LAWS.len()] = [
    [600, 1200, 800],   // open-loop
    [800, 1200, 800],   // pid
    [800, 1200, 800],   // ff+pid
    [1000, 1200, 1200], // hgo-robust
    [1000, 1200, 1200], // ff+hgo-robust
    [2000, 2200, 2200], // fts
    [2000, 2200, 2200], // ff+fts
    [2000, 2200, 2200], // fts-gbw
    [800, 1200, 1000],  // adrc
    [800, 1200, 1000],  // ff+adrc
    [1000, 1200, 1200], // nmpc (the step; its solve: SOLVE_M4F)
    [1000, 1200, 1200], // ff+nmpc
    [1000, 1200, 1200], // nmpc-gbw
];

/// [`WORST_M4F`] for the two-axis (`xy`) build: its step runs the feedforward and the law
/// once per axis, so a one-axis row understates it (measured 36 of 39 rows above
/// [`WORST_M4F`], `fts` 3280-3600 against 2000-2200). Measured and rounded the same way by
/// the xy QEMU board's bench (`36-qemu-xy.sh` fails if a measurement exceeds it).
pub const WORST_M4F_XY: [[u32; FFS.len()]; LAWS.len()] = [
    [800, 1400, 1000],  // open-loop
    [1200, 1800, 1400], // pid
    [1200, 1800, 1400], // ff+pid
    [1600, 1800, 1800], // hgo-robust
    [1600, 1800, 1800], // ff+hgo-robust
    [3600, 3800, 3800], // fts
    [3600, 3800, 3800], // ff+fts
    [3600, 3800, 3800], // fts-gbw
    [1200, 1600, 1400], // adrc
    [1200, 1600, 1400], // ff+adrc
    [1600, 1800, 2000], // nmpc (the step; its solve: SOLVE_M4F_XY)
    [1600, 2000, 2000], // ff+nmpc
    [1800, 2000, 2000], // nmpc-gbw
];

/// The worst-case table of this build's axis count: [`WORST_M4F`] or [`WORST_M4F_XY`].
pub const WORST_M4F_BUILD: [[u32; FFS.len()]; LAWS.len()] =
    if AXES == 2 { WORST_M4F_XY } else { WORST_M4F };

/// The deferred NMPC's solver task ([`super::solve_nmpc`], priority 2) per MPC boundary:
/// every axis' solve with its two locks, worst over the same bench runs as [`WORST_M4F`],
/// rounded the same way (each row's largest); 0 for the laws that solve nothing apart.
/// It must fit the periods of one MPC move beside the control task.
const fn solve_rows(nmpc: u32, ff_nmpc: u32, nmpc_gbw: u32) -> [[u32; FFS.len()]; LAWS.len()] {
    let mut t = [[0; FFS.len()]; LAWS.len()];
    t[LAWS.len() - 3] = [nmpc; FFS.len()];
    t[LAWS.len() - 2] = [ff_nmpc; FFS.len()];
    t[LAWS.len() - 1] = [nmpc_gbw; FFS.len()];
    t
}
/// One axis (bench worst 15 560 to 16 360).
pub const SOLVE_M4F: [[u32; FFS.len()]; LAWS.len()] = solve_rows(16_000, 16_000, 16_600);
/// Two axes: both solves in one run of the task (bench worst 29 360 to 30 800).
pub const SOLVE_M4F_XY: [[u32; FFS.len()]; LAWS.len()] = solve_rows(30_000, 29_800, 31_000);
/// [`SOLVE_M4F`] or [`SOLVE_M4F_XY`] for this build.
pub const SOLVE_M4F_BUILD: [[u32; FFS.len()]; LAWS.len()] =
    if AXES == 2 { SOLVE_M4F_XY } else { SOLVE_M4F };
/// The solver's copy of a law and its job under the lock (the control interrupt waits that
/// long at most): bench worst 1 320 one axis, 1 720 two, rounded as above. A solver mode's
/// blocking is the larger of this and [`BLOCKING_M4F`] (one lock at a time).
pub const SOLVER_LOCK_M4F_BUILD: u32 = if AXES == 2 { 2_000 } else { 1_600 };

/// The longest the command task's lock delays the control interrupt (instructions on the
/// QEMU M4F, taken as core cycles on the H743 like the table): the hand-over of a new
/// compensator or law, one lock each (`console::hand_over`). Measured by the command flood
/// (`31-qemu-flood.sh`: 880-1080 in 18 of 19 floods, once 1560, not traced to a command;
/// with both copies in one lock it was 1160-1480), rounded up to the next 200, plus 200; the
/// flood fails 600 above it. A step fits when it fits the period together with the
/// overhead and this.
pub const BLOCKING_M4F: u32 = 1400;

/// What one control period affords, and what each mode costs (instructions or core cycles,
/// the same unit throughout).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Budget {
    /// Instructions (cycles) per control period.
    period: u32,
    /// Per period besides the step: interrupt entry and exit, converter drivers, recorder,
    /// timing.
    overhead: u32,
    /// The longest the command task can delay the period's start ([`BLOCKING_M4F`]).
    blocking: u32,
    /// Worst-case step per law x feedforward; 0: unknown (not refused).
    worst: [[u32; FFS.len()]; LAWS.len()],
    /// Worst solver-task run per MPC boundary (deferred NMPC); 0: no solver.
    solve: [[u32; FFS.len()]; LAWS.len()],
    /// The solver's lock ([`SOLVER_LOCK_M4F_BUILD`]).
    solver_lock: u32,
    /// Control periods per MPC boundary ([`super::NMPC_DECIMATION`]).
    decimation: u32,
}

impl Budget {
    /// No limit: every combination fits (host tools and tests).
    pub const UNLIMITED: Self = Self {
        period: u32::MAX,
        overhead: 0,
        blocking: 0,
        worst: [[0; FFS.len()]; LAWS.len()],
        solve: [[0; FFS.len()]; LAWS.len()],
        solver_lock: 0,
        decimation: NMPC_DECIMATION,
    };

    /// This build's table ([`WORST_M4F_BUILD`]: one or two axes) against `period`
    /// instructions (cycles) per control period.
    pub const fn m4f(period: u32, overhead: u32) -> Self {
        Self {
            period,
            overhead,
            blocking: BLOCKING_M4F,
            worst: WORST_M4F_BUILD,
            solve: SOLVE_M4F_BUILD,
            solver_lock: SOLVER_LOCK_M4F_BUILD,
            decimation: NMPC_DECIMATION,
        }
    }

    /// A board's own measurement (`worst[law][ff]`, 0 where not measured).
    pub const fn measured(
        period: u32,
        overhead: u32,
        worst: [[u32; FFS.len()]; LAWS.len()],
    ) -> Self {
        Self {
            period,
            overhead,
            blocking: BLOCKING_M4F,
            worst,
            solve: [[0; FFS.len()]; LAWS.len()],
            solver_lock: 0,
            decimation: NMPC_DECIMATION,
        }
    }

    /// With a board's own measurement of the solver task (`solve[law][ff]` per MPC
    /// boundary, 0 where none) and of its lock.
    pub const fn with_solver(mut self, solve: [[u32; FFS.len()]; LAWS.len()], lock: u32) -> Self {
        self.solve = solve;
        self.solver_lock = lock;
        self
    }

    /// The worst case of `law` with `ff`, when known (`feedforward` is the open-loop row).
    pub fn worst(&self, law: &str, ff: &str) -> Option<u32> {
        Self::cell(&self.worst, law, ff)
    }

    /// The worst solver-task run of `law` with `ff` per MPC boundary, for a law that solves
    /// apart (deferred NMPC).
    pub fn solve(&self, law: &str, ff: &str) -> Option<u32> {
        Self::cell(&self.solve, law, ff)
    }

    fn cell(t: &[[u32; FFS.len()]; LAWS.len()], law: &str, ff: &str) -> Option<u32> {
        let law = if law == "feedforward" {
            "open-loop"
        } else {
            law
        };
        let row = LAWS.iter().position(|l| *l == law)?;
        let col = FFS.iter().position(|f| *f == ff)?;
        t.get(row)
            .and_then(|r| r.get(col))
            .copied()
            .filter(|w| *w > 0)
    }

    /// Instructions (cycles) a step may take: the period less the overhead and the
    /// command task's blocking (every term a measured worst case, rounded up).
    pub fn allowance(&self) -> u32 {
        self.period
            .saturating_sub(self.overhead)
            .saturating_sub(self.blocking)
    }

    /// `Ok` when `law` with `ff` fits the period (or its cost is unknown), else
    /// [`Error::OverBudget`]. A law with a solver task fits when its step fits beside the
    /// larger of the two locks, and its solve fits what the control task leaves of the
    /// periods of one MPC move (less one lock of the command task, which can hold it off).
    pub fn check(&self, law: &str, ff: &str) -> Result<(), Error> {
        let step = self.worst(law, ff).unwrap_or(0);
        match self.solve(law, ff) {
            None if step > self.allowance() => Err(Error::OverBudget),
            None => Ok(()),
            Some(solve) => {
                let blocking = self.blocking.max(self.solver_lock);
                let busy = self.overhead.saturating_add(step);
                let allowance = self
                    .period
                    .saturating_sub(self.overhead)
                    .saturating_sub(blocking);
                let free = (self.period.saturating_sub(busy) as u64 * self.decimation as u64)
                    .saturating_sub(self.blocking as u64);
                if step > allowance || solve as u64 > free {
                    Err(Error::OverBudget)
                } else {
                    Ok(())
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nmpc_fits_at_100_khz_on_the_m4f_with_its_solver_apart_and_the_main_mode_fits() {
        // QEMU M4F: 10 000 instructions per 10 us period, the SPI driver path ~800.
        let b = Budget::m4f(10_000, 1_200);
        assert_eq!(b.check("ff+hgo-robust", "ims-cbw"), Ok(()));
        assert_eq!(b.check("feedforward", "ims-cbw"), Ok(()));
        assert_eq!(b.check("fts-gbw", "ims-cbw-delayed"), Ok(()));
        for law in ["nmpc", "ff+nmpc", "nmpc-gbw"] {
            for ff in FFS {
                assert_eq!(b.check(law, ff), Ok(()), "{law} {ff}");
                assert!(b.solve(law, ff).is_some(), "{law} {ff}");
            }
        }
        // The solve counted inside the step (the former firmware) did not fit.
        let inline = Budget::measured(10_000, 1_200, SOLVE_M4F);
        assert_eq!(inline.check("nmpc", "linear"), Err(Error::OverBudget));
        // Unknown names are not this check's business (the mode parser refuses them).
        assert_eq!(b.check("nonsense", "ims-cbw"), Ok(()));
        assert_eq!(Budget::UNLIMITED.check("nmpc", "linear"), Ok(()));
    }

    #[test]
    fn a_solve_that_does_not_fit_its_move_is_refused() {
        // H743, 4000 cycles a period. On-chip converters (400 besides the step): ten
        // periods leave 22 600 cycles for the solver. The SPI pair (1200): 14 600, less
        // than one solve.
        let on_chip = Budget::measured(4_000, 400, WORST_M4F).with_solver(SOLVE_M4F, 1_600);
        let spi = Budget::measured(4_000, 1_200, WORST_M4F).with_solver(SOLVE_M4F, 1_600);
        assert_eq!(on_chip.check("nmpc", "ims-cbw"), Ok(()));
        assert_eq!(spi.check("nmpc", "ims-cbw"), Err(Error::OverBudget));
        assert_eq!(spi.check("ff+hgo-robust", "ims-cbw"), Ok(()));
        // The solver's lock counts as blocking: a lock longer than the step's room refuses.
        let long_lock = Budget::measured(4_000, 400, WORST_M4F).with_solver(SOLVE_M4F, 2_500);
        assert_eq!(long_lock.check("nmpc", "ims-cbw"), Err(Error::OverBudget));
        // Two axes solve twice per boundary.
        let xy = Budget::measured(4_000, 400, WORST_M4F_XY).with_solver(SOLVE_M4F_XY, 2_000);
        assert_eq!(xy.check("nmpc", "ims-cbw"), Err(Error::OverBudget));
    }

    #[test]
    fn the_two_axis_table_refuses_what_only_one_axis_fits_on_the_h743() {
        // H743: 400 MHz / 100 kHz = 4000 cycles per period, 400 of them besides the step.
        let (one, two) = (
            Budget::measured(4_000, 400, WORST_M4F),
            Budget::measured(4_000, 400, WORST_M4F_XY),
        );
        assert_eq!(one.check("fts", "linear"), Ok(()));
        assert_eq!(two.check("fts", "linear"), Err(Error::OverBudget));
        assert_eq!(two.check("ff+hgo-robust", "ims-cbw"), Ok(()));
        // Two axes never cost less than one.
        for (r1, r2) in WORST_M4F.iter().zip(WORST_M4F_XY.iter()) {
            for (w1, w2) in r1.iter().zip(r2.iter()) {
                assert!(w2 >= w1, "{w2} < {w1}");
            }
        }
        let build = if AXES == 2 { WORST_M4F_XY } else { WORST_M4F };
        assert_eq!(WORST_M4F_BUILD, build);
    }

    #[test]
    fn the_command_tasks_blocking_is_in_the_budget() {
        // H743 with the SPI pair: 4000 cycles, 1200 of them the drivers. The main mode
        // fits with the blocking; `fts` with IMS fit 90 % of the period before, but not
        // with a lock of 1400 cycles in front of it.
        let spi = Budget::measured(4_000, 1_200, WORST_M4F);
        assert_eq!(spi.allowance(), 4_000 - 1_200 - BLOCKING_M4F);
        assert_eq!(spi.check("ff+hgo-robust", "ims-cbw"), Ok(()));
        assert_eq!(spi.check("fts", "ims-cbw"), Err(Error::OverBudget));
        assert!(
            WORST_M4F[5][2] <= 4_000 * 90 / 100 - 1_200,
            "fts fit the former rule"
        );
    }

    #[test]
    fn every_combination_has_a_worst_case() {
        let b = Budget::m4f(10_000, 0);
        for law in LAWS {
            for ff in FFS {
                assert!(b.worst(law, ff).is_some(), "{law} {ff}");
            }
        }
    }
}
