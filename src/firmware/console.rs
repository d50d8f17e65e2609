//! The serial command line, written once for every board: the board supplies its port
//! ([`Port`]).

use super::control_loop::Loop;
use super::converters::Converters;
use super::ctl::{Ctl, PointTable};
use super::execute::{push_stats, run, stream_frames};
use super::target::{R, REPLY_LEN};
use crate::command::{self, Command, Error, LineBuffer, RecCmd};
use crate::pipeline::Parts;
use rtic_core::Mutex;

/// A board's serial port, and what the board adds to the protocol.
pub trait Port {
    /// Sends one line (the port adds its line end).
    fn send(&mut self, line: &str);
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
    /// A line of the board's own, outside the protocol (the QEMU test harness' `exit`):
    /// true when the board took it (no reply is sent).
    fn harness(&mut self, _line: &[u8]) -> bool {
        false
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
}

/// The command task's replica of the loop, with what only commands use (the point table of
/// `table add`, the axis of `axis`). Its configuration follows the live loop's: only
/// commands change it, and each command's changes go to both.
pub struct Replica<C> {
    lp: Loop<C>,
    table: PointTable,
    axis: usize,
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
        }
    }

    /// The command line of a control state fresh from [`Ctl::new`]`(sample_hz)` (its
    /// replica built the same way: no copy of the live state on the caller's stack).
    pub fn for_new(sample_hz: R) -> Self {
        Self {
            line: LineBuffer::new(),
            replica: Replica {
                lp: Loop::new(sample_hz),
                table: PointTable::new(),
                axis: 0,
            },
        }
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
                    |i| ctl.lock(|c| c.rec.frame(i).copied()),
                    |l| port.send(l),
                );
                return true;
            }
            Ok(Command::Stats) => push_stats(&mut reply, &ctl.lock(|c| c.timing)),
            Ok(c @ (Command::StatsReset | Command::Rec(_))) => {
                ctl.lock(|ctl| ctl.execute(c, &mut reply))
            }
            Ok(c) => {
                let r = &mut self.replica;
                ctl.lock(|live| r.lp.p.sync_state(&live.lp.p));
                match run(&mut r.lp, &mut r.table, &mut r.axis, c, &mut reply) {
                    Ok(parts) if parts != Parts::NONE => {
                        ctl.lock(|live| live.lp.adopt(&r.lp, parts))
                    }
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
