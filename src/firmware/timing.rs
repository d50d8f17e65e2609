//! Timing statistics of the control task.

/// Min/max/last of a cycle count, and how many samples there were.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub struct CycleStats {
    pub min: u32,
    pub max: u32,
    pub last: u32,
    pub count: u32,
}

impl CycleStats {
    pub const fn new() -> Self {
        Self {
            min: u32::MAX,
            max: 0,
            last: 0,
            count: 0,
        }
    }
    #[inline(always)]
    pub fn record(&mut self, cycles: u32) {
        self.last = cycles;
        self.min = self.min.min(cycles);
        self.max = self.max.max(cycles);
        self.count = self.count.wrapping_add(1);
    }
}

impl Default for CycleStats {
    fn default() -> Self {
        Self::new()
    }
}

/// The NMPC solver's record since its mode was selected (`stats`): boundaries that posted a
/// job, and boundaries that found the previous job still unsolved (their step kept the
/// shifted plan).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NmpcCounts {
    pub jobs: u32,
    pub missed: u32,
}

/// Timing of the control task, reported by `stats` and reset by `stats reset`.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub struct Timing {
    /// The pipeline step alone.
    pub step: CycleStats,
    /// The whole interrupt handler (converter access, step, recorder, bookkeeping).
    pub isr: CycleStats,
    /// From the period's trigger to the control interrupt's first reading of the counter
    /// (boards whose counter tells, [`super::Clock::since_trigger`]; else no samples).
    pub delay: CycleStats,
    /// Samples whose processing missed the deadline (the next sample was due or lost; a
    /// period after `n` samples lost entirely counts `n`).
    pub overruns: u32,
    /// Samples lost entirely, seen from the gap between two periods' triggers (boards whose
    /// counter spans periods, [`super::Clock::periods_between`]).
    pub lost: u32,
    /// The last period's trigger on the board's counter (`None`: none yet, or no board
    /// clock that tells).
    pub last_trigger: Option<u32>,
}

impl Timing {
    pub const fn new() -> Self {
        Self {
            step: CycleStats::new(),
            isr: CycleStats::new(),
            delay: CycleStats::new(),
            overruns: 0,
            lost: 0,
            last_trigger: None,
        }
    }
}

impl Default for Timing {
    fn default() -> Self {
        Self::new()
    }
}
