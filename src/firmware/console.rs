//! The serial command line, written once for every board: the board supplies its port
//! ([`Port`]).

use super::budget::Budget;
use super::control_loop::Loop;
use super::converters::Converters;
use super::ctl::{Ctl, PointTable};
use super::execute::{push_stats, run, stream_bin, stream_frames};
use super::flash_job::{FlashDone, FlashOp, SettingsJob};
use super::storage::{decode, stored, Boot, SettingsFlash, MAX_RECORD};
use super::target::{R, REPLY_LEN};
use crate::command::{self, Command, Error, LineBuffer, RecCmd};
use crate::pipeline::Parts;
use rtic_core::Mutex;

/// A board's serial port, and what the board adds to the protocol.
pub trait Port {
    /// Sends one line (the port adds its line end).
    fn send(&mut self, line: &str);
    /// Sends bytes as they are (the packets of `rec bin`).
    fn send_bytes(&mut self, bytes: &[u8]);
    /// `bench`: sends the board's table of instructions per step and returns its row
    /// count. Boards without one answer [`Error::Unsupported`].
    fn bench(&mut self) -> Result<usize, Error> {
        Err(Error::Unsupported)
    }
    /// `selftest`: exercises the board's converters and safe-state hardware and appends
    /// what it found to `reply` (after `ok selftest`). Boards without one answer
    /// [`Error::Unsupported`].
    fn selftest(&mut self, _reply: &mut command::Reply<REPLY_LEN>) -> Result<(), Error> {
        Err(Error::Unsupported)
    }
    /// `save`/`load`: hands the operation to the board's settings-flash job, which runs it
    /// in thread mode ([`super::flash_job`]); the reply goes out when the board passes the
    /// outcome to [`CommandLine::flash_poll`]. Boards without one answer
    /// [`Error::Unsupported`].
    fn flash(&mut self, _op: FlashOp, _record: &[u8]) -> Result<(), Error> {
        Err(Error::Unsupported)
    }
    /// A line of the board's own, outside the protocol (the QEMU test harness' `exit`):
    /// true when the board took it (no reply is sent).
    fn harness(&mut self, _line: &[u8]) -> bool {
        false
    }
}

/// A board's port with its settings-flash job (the resource its command task shares with
/// idle): `save`/`load` go to the job, the rest to the port.
pub struct WithFlash<'a, P, J> {
    pub port: &'a mut P,
    pub job: &'a mut J,
}

impl<P: Port, J: Mutex<T = SettingsJob>> Port for WithFlash<'_, P, J> {
    fn send(&mut self, line: &str) {
        self.port.send(line)
    }
    fn send_bytes(&mut self, bytes: &[u8]) {
        self.port.send_bytes(bytes)
    }
    fn bench(&mut self) -> Result<usize, Error> {
        self.port.bench()
    }
    fn selftest(&mut self, reply: &mut command::Reply<REPLY_LEN>) -> Result<(), Error> {
        self.port.selftest(reply)
    }
    fn flash(&mut self, op: FlashOp, record: &[u8]) -> Result<(), Error> {
        self.job.lock(|j| j.ask(op, record))
    }
    fn harness(&mut self, line: &[u8]) -> bool {
        self.port.harness(line)
    }
}

impl<C: Converters> Ctl<C> {
    /// What a board's command task does with one received line, without its replica and
    /// locks: `rec read` and `rec bin` streamed from the recorder, any other command run,
    /// a line the parser refused answered with its error; an empty line gets no reply. The
    /// host's in-process firmware (tests, tools) answers with it.
    pub fn serve(&mut self, line: Result<&[u8], Error>, port: &mut impl Port) {
        let mut r = command::Reply::<REPLY_LEN>::new();
        match line.and_then(command::parse) {
            Ok(Command::Empty) => return,
            Ok(Command::Rec(RecCmd::Bin { start, count })) => {
                let rec = &self.rec;
                return stream_bin(start, count, rec.readable(), |i| rec.read(i).copied(), port);
            }
            Ok(Command::Rec(RecCmd::Read { start, count })) => {
                let rec = &self.rec;
                return stream_frames(start, count, |i| rec.read(i).copied(), |l| port.send(l));
            }
            Ok(cmd) => self.execute(cmd, &mut r),
            Err(e) => r.push_error(e),
        }
        port.send(r.as_str());
    }
}

/// On the host, a byte queue is a port (the in-process firmware of tests and tools).
#[cfg(not(target_os = "none"))]
mod host_ports {
    extern crate std;
    use std::collections::VecDeque;

    impl super::Port for VecDeque<u8> {
        fn send(&mut self, line: &str) {
            self.extend(line.as_bytes());
            self.push_back(b'\n');
        }
        fn send_bytes(&mut self, bytes: &[u8]) {
            self.extend(bytes);
        }
    }
}

/// The command line: bytes in, one reply line per command out.
///
/// Nothing here holds the control task's lock longer than a copy: a command runs on the
/// command task's replica of the loop ([`Replica`]: validation, law and compensator
/// builds, the reply), between two short locks: the live state copied into the replica
/// before, the changed parts copied into the live pipeline after (with one bumpless
/// restart, [`crate::pipeline::Pipeline::adopt`]). `stats` copies the timing out;
/// `rec read` streams its frames, each copied under its own lock; the recorder's own
/// commands set a few fields under the lock.
pub struct CommandLine<C> {
    line: LineBuffer,
    replica: Replica<C>,
    /// What the board's control period affords each mode (`mode`/`ff` beyond it: err 18).
    budget: Budget,
    /// A `save` or `load` is with the board's flash job: every command is refused (`err
    /// 12`) until its reply went out, so replies stay in the order of the commands.
    flash_pending: bool,
}

/// The command task's replica of the loop, with what only commands use (the point table of
/// `table add`, the axis of `axis`). Its configuration follows the live loop's: only
/// commands change it, and each command's changes go to both.
pub struct Replica<C> {
    lp: Loop<C>,
    table: PointTable,
    axis: usize,
}

/// Hands the changed `parts` of the replica `from` to the live loop, the compensator and the
/// law each under a lock of its own: the control interrupt waits for one copy at a time (the
/// mode budgets' `BLOCKING_M4F`; both in one lock were 1320-1480 instructions on the M4F).
/// A period between the locks runs a new compensator with the law before, each valid and
/// each restarted bumplessly by the step after its hand-over.
fn hand_over<C: Converters, M: Mutex<T = Ctl<C>>>(ctl: &mut M, from: &Loop<C>, parts: Parts) {
    let mut rest = parts;
    for part in [Parts::FEEDFORWARD, Parts::FEEDBACK] {
        if rest.contains(part) && rest != part {
            ctl.lock(|live| live.lp.adopt(from, part));
            rest = rest.without(part);
        }
    }
    ctl.lock(|live| live.lp.adopt(from, rest));
}

impl<C: Converters> CommandLine<C> {
    /// `live` is the loop as the control task starts with it.
    pub fn new(live: &Loop<C>) -> Self {
        Self {
            line: LineBuffer::new(),
            replica: Replica {
                lp: live.clone(),
                table: PointTable::new(),
                axis: 0,
            },
            budget: Budget::UNLIMITED,
            flash_pending: false,
        }
    }

    /// The command line of a control state fresh from [`Ctl::new`]`(sample_hz)` (its
    /// replica built the same way: no copy of the live state on the caller's stack), with
    /// the board's mode budget.
    pub fn for_new(sample_hz: R, budget: Budget) -> Self {
        Self {
            line: LineBuffer::new(),
            replica: Replica {
                lp: Loop::new(sample_hz),
                table: PointTable::new(),
                axis: 0,
            },
            budget,
            flash_pending: false,
        }
    }

    /// The board's mode budget ([`Budget::UNLIMITED`] until set).
    pub fn set_budget(&mut self, budget: Budget) {
        self.budget = budget;
    }

    /// Installs a checked settings record on the replica and hands it to the live loop (all
    /// or nothing: a refused record changes neither).
    fn apply<M: Mutex<T = Ctl<C>>>(
        &mut self,
        rec: &super::Record,
        ctl: &mut M,
    ) -> Result<(), Error> {
        let r = &mut self.replica;
        ctl.lock(|live| r.lp.p.sync_state(&live.lp.p));
        r.lp.apply_settings(rec)?;
        hand_over(
            ctl,
            &r.lp,
            Parts::MODEL.union(Parts::LIMITS).union(Parts::SENSOR),
        );
        Ok(())
    }

    /// A record read from the flash (`got`: its length in `buf`, `None` if none stored),
    /// checked and installed like [`CommandLine::apply`]; the number of settings.
    fn install_loaded<M: Mutex<T = Ctl<C>>>(
        &mut self,
        got: Result<Option<usize>, Error>,
        buf: &[u8; MAX_RECORD],
        ctl: &mut M,
    ) -> Result<usize, Error> {
        let n = got?.ok_or(Error::NoSettings)?;
        let rec = decode(buf.get(..n).ok_or(Error::BadSettings)?)?;
        self.apply(&rec, ctl).map(|()| rec.len())
    }

    /// At power-up: the stored settings if a valid record is there (installed like `load`),
    /// else the defaults stay.
    pub fn boot_settings<M, F>(&mut self, ctl: &mut M, flash: &mut SettingsFlash<F>) -> Boot
    where
        M: Mutex<T = Ctl<C>>,
        F: embedded_storage::nor_flash::NorFlash,
    {
        let mut buf = [0u8; MAX_RECORD];
        let got = flash.boot_load(&mut buf);
        let installed = self.install_loaded(got, &buf, ctl);
        Boot::of(flash, installed)
    }

    /// The command task's side of a `save`/`load` (call it on every run of the task; the
    /// board's idle pends the task when the flash job finished): takes the outcome from
    /// the port's job and sends its reply (`load` installs the record first, all or nothing). True
    /// when a reply went out.
    pub fn flash_poll<M, J, P>(&mut self, ctl: &mut M, port: &mut WithFlash<'_, P, J>) -> bool
    where
        M: Mutex<T = Ctl<C>>,
        J: Mutex<T = SettingsJob>,
        P: Port,
    {
        let mut buf = [0u8; MAX_RECORD];
        let Some(FlashDone { op, result }) = port.job.lock(|j| j.take(&mut buf)) else {
            return false;
        };
        self.flash_pending = false;
        let mut reply = command::Reply::<REPLY_LEN>::new();
        match op {
            FlashOp::Save => match result.and_then(|n| n.ok_or(Error::Flash)) {
                Ok(n) => {
                    reply.push_str("ok save ");
                    reply.push_usize(stored().count());
                    reply.push_str(" settings ");
                    reply.push_usize(n);
                    reply.push_str(" B");
                }
                Err(e) => reply.push_error(e),
            },
            FlashOp::Load => match self.install_loaded(result, &buf, ctl) {
                Ok(n) => {
                    reply.push_str("ok load ");
                    reply.push_usize(n);
                    reply.push_str(" settings");
                }
                Err(e) => reply.push_error(e),
            },
        }
        port.send(reply.as_str());
        true
    }

    /// Takes one received byte; at the end of a line runs the command and sends its reply.
    /// Returns true when a reply went out (empty lines and harness lines get none).
    pub fn byte<M, P>(&mut self, byte: u8, ctl: &mut M, port: &mut P) -> bool
    where
        M: Mutex<T = Ctl<C>>,
        P: Port,
    {
        let Some(line) = self.line.push(byte) else {
            return false;
        };
        if let Ok(l) = line {
            if port.harness(l) {
                return false;
            }
        }
        let mut reply = command::Reply::<REPLY_LEN>::new();
        match line.and_then(command::parse) {
            Ok(Command::Empty) => return false,
            // A `save` (an erase takes seconds) refuses only what would change state.
            Ok(c) if self.flash_pending && !c.reads_only() => reply.push_error(Error::Busy),
            Ok(Command::Bench) => match port.bench() {
                Ok(rows) => {
                    reply.push_str("ok bench ");
                    reply.push_usize(rows);
                }
                Err(e) => reply.push_error(e),
            },
            Ok(Command::Selftest) => {
                reply.push_str("ok selftest");
                if let Err(e) = port.selftest(&mut reply) {
                    reply.clear();
                    reply.push_error(e);
                }
            }
            Ok(Command::Rec(RecCmd::Read { start, count })) => {
                stream_frames(
                    start,
                    count,
                    |i| ctl.lock(|c| c.rec.read(i).copied()),
                    |l| port.send(l),
                );
                return true;
            }
            Ok(Command::Rec(RecCmd::Bin { start, count })) => {
                let available = ctl.lock(|c| c.rec.readable());
                stream_bin(
                    start,
                    count,
                    available,
                    |i| ctl.lock(|c| c.rec.read(i).copied()),
                    port,
                );
                return true;
            }
            Ok(Command::Save) => {
                let r = &mut self.replica;
                ctl.lock(|live| r.lp.p.sync_state(&live.lp.p));
                let mut buf = [0u8; MAX_RECORD];
                let asked =
                    r.lp.settings_record(&mut buf)
                        .and_then(|n| buf.get(..n).ok_or(Error::Flash))
                        .and_then(|rec| port.flash(FlashOp::Save, rec));
                match asked {
                    Ok(()) => {
                        self.flash_pending = true;
                        return false;
                    }
                    Err(e) => reply.push_error(e),
                }
            }
            Ok(Command::Load) => match port.flash(FlashOp::Load, &[]) {
                Ok(()) => {
                    self.flash_pending = true;
                    return false;
                }
                Err(e) => reply.push_error(e),
            },
            Ok(Command::Stats) => {
                let (t, nmpc) = ctl.lock(|c| (c.timing, c.nmpc_counts()));
                push_stats(&mut reply, &t, nmpc)
            }
            Ok(c @ (Command::StatsReset | Command::Rec(_))) => {
                ctl.lock(|ctl| ctl.execute(c, &mut reply))
            }
            Ok(c) => {
                let r = &mut self.replica;
                // A mode that does not fit the period is refused before anything changes.
                let fits = match &c {
                    Command::Mode(law) => self.budget.check(law, r.lp.ff),
                    Command::Feedforward(ff) => self.budget.check(r.lp.law, ff),
                    _ => Ok(()),
                };
                if let Err(e) = fits {
                    reply.push_error(e);
                    port.send(reply.as_str());
                    return true;
                }
                ctl.lock(|live| r.lp.p.sync_state(&live.lp.p));
                match run(&mut r.lp, &mut r.table, &mut r.axis, c, &mut reply) {
                    Ok(parts) if parts != Parts::NONE => hand_over(ctl, &r.lp, parts),
                    Ok(_) => {}
                    // A refused command changed nothing (the setters check everything
                    // before they change anything), so the replica still matches.
                    Err(e) => {
                        reply.clear();
                        reply.push_error(e);
                    }
                }
            }
            Err(e) => reply.push_error(e),
        }
        port.send(reply.as_str());
        true
    }
}
