//! `save` and `load` run in thread mode (the board's idle), never in the command task: the
//! flash and `sequential-storage` keep panic paths (the HAL's slice reads and its unlock
//! `assert!`) that no handler may reach, and an H743 sector erase takes about 2 s (RM0433:
//! 128 KiB sector, x64 parallelism, typical; 4 s at most), which would hold the command
//! task's priority level that long.
//!
//! The hand-over: the command task asks ([`SettingsJob::ask`], `err 12` while one is under
//! way), idle takes the work and runs it on the flash ([`run_flash_job`]) and pends the
//! command task, which takes the outcome and replies ([`super::CommandLine::flash_poll`]).
//! Every copy between them is of a whole fixed-size buffer, so the command task's side has
//! no length check that could panic.

use super::storage::{SettingsFlash, MAX_RECORD};
use crate::command::Error;
use embedded_storage::nor_flash::NorFlash;
use rtic_core::Mutex;

/// A settings-flash operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashOp {
    /// Store the record.
    Save,
    /// Read the stored record.
    Load,
}

/// One operation and its record (the one to store, or the one read).
#[derive(Clone)]
pub struct FlashWork {
    op: FlashOp,
    buf: [u8; MAX_RECORD],
    len: usize,
}

impl FlashWork {
    pub const fn new() -> Self {
        Self {
            op: FlashOp::Load,
            buf: [0; MAX_RECORD],
            len: 0,
        }
    }

    /// Runs the operation on `flash` (thread mode): `Ok(Some(len))` is the record's length
    /// (stored, or read into this work's buffer), `Ok(None)` nothing stored (`load`).
    pub fn run<F: NorFlash>(
        &mut self,
        flash: &mut SettingsFlash<F>,
    ) -> Result<Option<usize>, Error> {
        match self.op {
            FlashOp::Save => {
                let record = self.buf.get(..self.len).ok_or(Error::Flash)?;
                flash.save(record).map(|()| Some(self.len))
            }
            FlashOp::Load => {
                let got = flash.load(&mut self.buf)?;
                self.len = got.unwrap_or(0);
                Ok(got)
            }
        }
    }
}

impl Default for FlashWork {
    fn default() -> Self {
        Self::new()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    Free,
    Asked,
    Running,
    Done,
}

/// The hand-over between the command task and idle (a resource both share).
pub struct SettingsJob {
    state: State,
    work: FlashWork,
    result: Result<Option<usize>, Error>,
}

/// A finished operation as the command task receives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FlashDone {
    pub op: FlashOp,
    /// As [`FlashWork::run`]'s; a loaded record is in the buffer passed to
    /// [`SettingsJob::take`].
    pub result: Result<Option<usize>, Error>,
}

impl SettingsJob {
    pub const fn new() -> Self {
        Self {
            state: State::Free,
            work: FlashWork::new(),
            result: Ok(None),
        }
    }

    /// Command task: queues `op` (`record`, at most [`MAX_RECORD`] bytes, is what `save`
    /// stores; `load` ignores it). [`Error::Busy`] while an operation is under way or its
    /// outcome not yet taken.
    pub fn ask(&mut self, op: FlashOp, record: &[u8]) -> Result<(), Error> {
        if self.state != State::Free {
            return Err(Error::Busy);
        }
        if record.len() > MAX_RECORD {
            return Err(Error::Flash);
        }
        for (d, s) in self.work.buf.iter_mut().zip(record) {
            *d = *s;
        }
        self.work.op = op;
        self.work.len = record.len();
        self.state = State::Asked;
        Ok(())
    }

    /// Idle: moves the asked work into `work` (false: nothing asked).
    pub fn start(&mut self, work: &mut FlashWork) -> bool {
        if self.state != State::Asked {
            return false;
        }
        *work = self.work.clone();
        self.state = State::Running;
        true
    }

    /// Idle: the outcome of the work [`SettingsJob::start`] handed out.
    pub fn finish(&mut self, work: &FlashWork, result: Result<Option<usize>, Error>) {
        if self.state == State::Running {
            self.work = work.clone();
            self.result = result;
            self.state = State::Done;
        }
    }

    /// Command task: the finished operation, a loaded record copied into `out`; the job is
    /// free again. `None` while nothing has finished.
    pub fn take(&mut self, out: &mut [u8; MAX_RECORD]) -> Option<FlashDone> {
        if self.state != State::Done {
            return None;
        }
        *out = self.work.buf;
        self.state = State::Free;
        Some(FlashDone {
            op: self.work.op,
            result: self.result,
        })
    }
}

impl Default for SettingsJob {
    fn default() -> Self {
        Self::new()
    }
}

/// Idle's side: runs an asked operation on `flash` (the job's lock is held only for the
/// copies, not for the flash; no flash: [`Error::Unsupported`]). True when an outcome is
/// ready: the board then pends its command task.
pub fn run_flash_job<J, F>(
    job: &mut J,
    work: &mut FlashWork,
    flash: Option<&mut SettingsFlash<F>>,
) -> bool
where
    J: Mutex<T = SettingsJob>,
    F: NorFlash,
{
    if !job.lock(|j| j.start(work)) {
        return false;
    }
    let result = flash.map_or(Err(Error::Unsupported), |f| work.run(f));
    job.lock(|j| j.finish(work, result));
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::firmware::RamNor;

    type Nor = RamNor<8192, 2048, 32>;

    #[test]
    fn a_save_then_a_load_hand_over_through_the_job() {
        let mut flash = SettingsFlash::new(Nor::new(), 0..8192).unwrap();
        let mut job = SettingsJob::new();
        let mut work = FlashWork::new();
        let mut out = [0u8; MAX_RECORD];
        job.ask(FlashOp::Save, b"abc").unwrap();
        assert_eq!(job.ask(FlashOp::Load, &[]), Err(Error::Busy));
        assert!(job.take(&mut out).is_none(), "nothing finished yet");
        assert!(run_flash_job(
            &mut rtic_core::Exclusive(&mut job),
            &mut work,
            Some(&mut flash)
        ));
        assert!(!run_flash_job(
            &mut rtic_core::Exclusive(&mut job),
            &mut work,
            Some(&mut flash)
        ));
        assert_eq!(
            job.ask(FlashOp::Load, &[]),
            Err(Error::Busy),
            "outcome not taken"
        );
        let done = job.take(&mut out).unwrap();
        assert_eq!((done.op, done.result), (FlashOp::Save, Ok(Some(3))));
        job.ask(FlashOp::Load, &[]).unwrap();
        assert!(run_flash_job(
            &mut rtic_core::Exclusive(&mut job),
            &mut work,
            Some(&mut flash)
        ));
        let done = job.take(&mut out).unwrap();
        assert_eq!((done.op, done.result), (FlashOp::Load, Ok(Some(3))));
        assert_eq!(&out[..3], b"abc");
    }

    #[test]
    fn a_load_of_an_empty_flash_finds_nothing_and_a_long_record_is_refused() {
        let mut flash = SettingsFlash::new(Nor::new(), 0..8192).unwrap();
        let mut job = SettingsJob::new();
        let mut work = FlashWork::new();
        let mut out = [0u8; MAX_RECORD];
        assert_eq!(
            job.ask(FlashOp::Save, &[0; MAX_RECORD + 1]),
            Err(Error::Flash)
        );
        job.ask(FlashOp::Load, &[]).unwrap();
        run_flash_job(
            &mut rtic_core::Exclusive(&mut job),
            &mut work,
            Some(&mut flash),
        );
        assert_eq!(job.take(&mut out).unwrap().result, Ok(None));
    }
}
