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

use super::laws::{FFS, LAWS};
use crate::command::Error;

/// Worst-case instructions of one step per law (rows, [`LAWS`] order) and feedforward
/// (columns, [`FFS`] order) on the QEMU M4F, f32: the bench's worst (`30-qemu.sh`, which
/// fails if a measurement exceeds this table) rounded up to the next 200 instructions, plus
/// 200 (the bench counts in 40-instruction SysTick ticks). `open-loop` stands
/// for the open-loop modes (`open-loop`, `feedforward`).
pub const WORST_M4F: [[u32; FFS.len()]; LAWS.len()] = [
    [600, 1200, 800],      // open-loop
    [800, 1200, 800],      // pid
    [800, 1200, 800],      // ff+pid
    [1000, 1200, 1200],    // hgo-robust
    [1000, 1200, 1200],    // ff+hgo-robust
    [2000, 2200, 2200],    // fts
    [2000, 2200, 2200],    // ff+fts
    [2000, 2200, 2200],    // fts-gbw
    [800, 1200, 1000],     // adrc
    [800, 1200, 1000],     // ff+adrc
    [14600, 14600, 14600], // nmpc
    [14800, 14800, 14800], // ff+nmpc
    [15200, 15400, 15400], // nmpc-gbw
];

/// The share of the period a step may use: the rest is the interrupt's entry and exit, the
/// converters, the recorder and the timing ([`Budget::overhead`] on top), and the command
/// task.
const USE_PERCENT: u32 = 90;

/// What one control period affords, and what each mode costs (instructions or core cycles,
/// the same unit throughout).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Budget {
    /// Instructions (cycles) per control period.
    period: u32,
    /// Per period besides the step: interrupt entry and exit, converter drivers, recorder,
    /// timing.
    overhead: u32,
    /// Worst-case step per law x feedforward; 0: unknown (not refused).
    worst: [[u32; FFS.len()]; LAWS.len()],
}

impl Budget {
    /// No limit: every combination fits (host tools and tests).
    pub const UNLIMITED: Self = Self {
        period: u32::MAX,
        overhead: 0,
        worst: [[0; FFS.len()]; LAWS.len()],
    };

    /// [`WORST_M4F`] against `period` instructions (cycles) per control period.
    pub const fn m4f(period: u32, overhead: u32) -> Self {
        Self {
            period,
            overhead,
            worst: WORST_M4F,
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
            worst,
        }
    }

    /// The worst case of `law` with `ff`, when known (`feedforward` is the open-loop row).
    pub fn worst(&self, law: &str, ff: &str) -> Option<u32> {
        let law = if law == "feedforward" {
            "open-loop"
        } else {
            law
        };
        let row = LAWS.iter().position(|l| *l == law)?;
        let col = FFS.iter().position(|f| *f == ff)?;
        self.worst
            .get(row)
            .and_then(|r| r.get(col))
            .copied()
            .filter(|w| *w > 0)
    }

    /// Instructions (cycles) a step may take: [`USE_PERCENT`] of the period less the
    /// overhead.
    pub fn allowance(&self) -> u32 {
        ((self.period as u64 * USE_PERCENT as u64 / 100) as u32).saturating_sub(self.overhead)
    }

    /// `Ok` when `law` with `ff` fits the period (or its cost is unknown), else
    /// [`Error::OverBudget`].
    pub fn check(&self, law: &str, ff: &str) -> Result<(), Error> {
        match self.worst(law, ff) {
            Some(w) if w > self.allowance() => Err(Error::OverBudget),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nmpc_is_refused_at_100_khz_on_the_m4f_and_the_main_mode_fits() {
        // QEMU M4F: 10 000 instructions per 10 us period, the SPI driver path ~800.
        let b = Budget::m4f(10_000, 1_200);
        assert_eq!(b.check("ff+hgo-robust", "ims-cbw"), Ok(()));
        assert_eq!(b.check("feedforward", "ims-cbw"), Ok(()));
        assert_eq!(b.check("fts-gbw", "ims-cbw-delayed"), Ok(()));
        for law in ["nmpc", "ff+nmpc", "nmpc-gbw"] {
            for ff in FFS {
                assert_eq!(b.check(law, ff), Err(Error::OverBudget), "{law} {ff}");
            }
        }
        // At 20 kHz NMPC fits.
        assert_eq!(Budget::m4f(50_000, 1_200).check("nmpc", "linear"), Ok(()));
        // Unknown names are not this check's business (the mode parser refuses them).
        assert_eq!(b.check("nonsense", "ims-cbw"), Ok(()));
        assert_eq!(Budget::UNLIMITED.check("nmpc", "linear"), Ok(()));
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
