//! The serial command line, written once for every board: the board supplies its port
//! ([`Port`]).

use super::converters::Converters;
use super::ctl::Ctl;
use super::execute::stream_frames;
use super::target::REPLY_LEN;
use crate::command::{self, Command, Error, LineBuffer, RecCmd};
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

/// The command line: bytes in, one reply line per command out (`rec read` streams its
/// frames first, each under a short lock of the control state).
pub struct CommandLine {
    line: LineBuffer,
}

impl CommandLine {
    pub const fn new() -> Self {
        Self {
            line: LineBuffer::new(),
        }
    }

    /// Takes one received byte; at the end of a line runs the command and sends its reply.
    /// Returns true when a reply went out (empty lines and harness lines get none).
    pub fn byte<C, M, P>(&mut self, byte: u8, ctl: &mut M, port: &mut P) -> bool
    where
        C: Converters,
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
            Ok(c) => ctl.lock(|ctl| ctl.execute(c, &mut reply)),
            Err(e) => reply.push_error(e),
        }
        port.send(reply.as_str());
        true
    }
}

impl Default for CommandLine {
    fn default() -> Self {
        Self::new()
    }
}
