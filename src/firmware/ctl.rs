//! Everything the control task owns.

use super::control_loop::Loop;
use super::converters::Converters;
use super::target::{c, RecStorage, AXES, R, REC_CH};
use super::timing::{NmpcCounts, Timing};
use crate::command::Error;
use crate::feedback::nmpc::{NmpcJob, HORIZON};
use crate::feedback::{Feedback, Nmpc};
use crate::pipeline::TABLE_LEN;
use crate::recorder::{self, Recorder};
use crate::Real;

/// Everything the control task owns: the loop, the recorder and the timing; and the point
/// table the executor fills (`table add`) and hands to the reference on `wave table`
/// (the control step never reads it).
pub struct Ctl<C> {
    pub lp: Loop<C>,
    pub rec: Recorder<R, REC_CH, RecStorage>,
    pub timing: Timing,
    pub table: PointTable,
    /// The axis the 1-axis waves go to (`axis <n>`).
    pub axis: usize,
    /// Control periods run since start-up (wrapping; `stats reset` leaves it).
    pub periods: u32,
}

impl<C: Converters> Ctl<C> {
    /// With the recorder over `storage` (a board's RAM region), capturing
    /// [`super::REC_N`] frames by default (fewer if the storage is smaller; `rec len`
    /// changes it).
    pub fn with_recorder(sample_hz: R, storage: RecStorage) -> Self {
        let mut rec = Recorder::with_storage(storage);
        let _ = rec.set_capture_len(super::REC_N.min(rec.capacity()));
        Self {
            lp: Loop::new(sample_hz),
            rec,
            timing: Timing::new(),
            table: PointTable::new(),
            axis: 0,
            periods: 0,
        }
    }

    /// On the host (tests, tools): a recorder of 4 x [`super::REC_N`] frames on the heap
    /// (a board supplies its RAM with [`Ctl::with_recorder`]).
    #[cfg(not(target_os = "none"))]
    pub fn new(sample_hz: R) -> Self {
        extern crate std;
        let frames = std::vec![[R::ZERO; REC_CH]; 4 * super::REC_N];
        Self::with_recorder(sample_hz, frames.into_boxed_slice())
    }

    /// A deferred NMPC's job on `axis` with a copy of the law to solve it on (the boards'
    /// solver task, under a short lock; `None` when no law waits for a plan).
    pub fn nmpc_job(&self, axis: usize) -> Option<(Nmpc<R>, NmpcJob<R>)> {
        match self.lp.p.feedback().get(axis)? {
            Feedback::Nmpc(n) => n.job().map(|j| (*n, j)),
            _ => None,
        }
    }

    /// Hands the plan solved for `job` to the law of `axis`; false if the law no longer
    /// asks for it (a newer boundary, or another law).
    pub fn nmpc_deliver(&mut self, axis: usize, job: &NmpcJob<R>, plan: [R; HORIZON]) -> bool {
        match self.lp.p.feedback_mut(axis) {
            Some(Feedback::Nmpc(n)) => n.deliver(job, plan),
            _ => false,
        }
    }

    /// The NMPC solver's counts summed over the axes that run NMPC (`None`: none does).
    pub fn nmpc_counts(&self) -> Option<NmpcCounts> {
        self.lp.p.feedback().iter().fold(None, |acc, f| match f {
            Feedback::Nmpc(n) => {
                let (s, a) = (n.state(), acc.unwrap_or_default());
                Some(NmpcCounts {
                    jobs: a.jobs.wrapping_add(s.jobs),
                    missed: a.missed.wrapping_add(s.missed),
                })
            }
            _ => acc,
        })
    }

    /// True when some axis' NMPC waits for a plan (the control task pends the solver).
    #[inline]
    pub fn nmpc_waiting(&self) -> bool {
        self.lp
            .p
            .feedback()
            .iter()
            .any(|f| matches!(f, Feedback::Nmpc(n) if n.job().is_some()))
    }

    /// Feeds the recorder (only while it captures: the signals cost a few instructions).
    #[inline(always)]
    pub fn record(&mut self, adc_code: [i32; AXES], dac_code: [i32; AXES]) {
        if matches!(
            self.rec.state(),
            recorder::State::Armed | recorder::State::Triggered
        ) {
            let s = self.lp.signals(adc_code, dac_code);
            self.rec.push(&s);
        }
    }
}

/// Points of `wave table` as `table add` appends them (um).
pub struct PointTable {
    points: [R; TABLE_LEN],
    pub(super) len: usize,
}

impl PointTable {
    pub const fn new() -> Self {
        Self {
            points: [R::ZERO; TABLE_LEN],
            len: 0,
        }
    }

    /// The points so far.
    pub fn points(&self) -> &[R] {
        self.points.get(..self.len).unwrap_or(&[])
    }

    /// Appends all of `values` or, if they do not fit, none.
    pub(super) fn add(&mut self, values: &[f32]) -> Result<(), Error> {
        let free = self.points.get_mut(self.len..).unwrap_or(&mut []);
        if values.len() > free.len() {
            return Err(Error::OutOfRange);
        }
        for (d, v) in free.iter_mut().zip(values) {
            *d = c(*v as f64);
        }
        self.len += values.len();
        Ok(())
    }
}

impl Default for PointTable {
    fn default() -> Self {
        Self::new()
    }
}
