//! Sends command lines and collects their replies: line framing, sync, timeouts.
use std::io;
use std::time::{Duration, Instant};

use piezo_core::command::Command;

use super::error::{io_err, SerialError};
use super::lines::checked_line;
use super::link::Link;

/// Longest reply line accepted (bytes); a longer run without newline is garbage (wrong baud
/// rate, binary output) and fails the command instead of growing a buffer forever.
pub const MAX_REPLY: usize = 4096;

/// One line from the firmware.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Line {
    /// `ok` or `ok <details>`: the command succeeded.
    Ok(String),
    /// `err <code> <message>`; `code` is `None` when the number is unreadable.
    Err { code: Option<u8>, message: String },
    /// Anything else (frames of `rec read`, the bench table, boot messages).
    Data(String),
}

/// Classifies one received line (without its newline). Never panics.
pub fn parse_line(line: &str) -> Line {
    let line = line.trim_end_matches('\r');
    if line == "ok" {
        return Line::Ok(String::new());
    }
    if let Some(rest) = line.strip_prefix("ok ") {
        return Line::Ok(rest.trim().to_string());
    }
    if let Some(rest) = line.strip_prefix("err ") {
        let rest = rest.trim();
        let (num, message) = rest.split_once(' ').unwrap_or((rest, ""));
        return Line::Err {
            code: num.parse().ok(),
            message: message.trim().to_string(),
        };
    }
    Line::Data(line.to_string())
}

/// The reply to one command: data lines, then the `ok` details.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Response {
    pub data: Vec<String>,
    /// Text after `ok` (empty for a bare `ok`).
    pub details: String,
}

impl Response {
    /// The whole reply line as the firmware sent it.
    pub fn reply_line(&self) -> String {
        if self.details.is_empty() {
            "ok".into()
        } else {
            format!("ok {}", self.details)
        }
    }
}

/// Sends command lines and collects their replies.
pub struct Client {
    link: Box<dyn Link>,
    pending: Vec<u8>,
    /// Longest wait for the next reply line.
    pub timeout: Duration,
}

impl Client {
    pub fn new(link: Box<dyn Link>, timeout: Duration) -> Self {
        Self {
            link,
            pending: Vec::new(),
            timeout,
        }
    }

    /// Sends one line as it is (no `\n`/`\r` inside) and waits for its `ok`/`err` line.
    pub fn raw(&mut self, line: &str) -> Result<Response, SerialError> {
        if line.contains(['\n', '\r']) {
            return Err(SerialError::BadCommand {
                command: line.escape_debug().to_string(),
                why: "one command per line: no line breaks inside".into(),
            });
        }
        self.send_line(line)?;
        let mut resp = Response::default();
        loop {
            match parse_line(&self.read_line(line)?) {
                Line::Ok(details) => {
                    resp.details = details;
                    return Ok(resp);
                }
                Line::Err { code, message } => {
                    return Err(SerialError::Firmware {
                        command: line.to_string(),
                        code,
                        message,
                    })
                }
                Line::Data(d) => {
                    // Bounded: a reply never has more data lines than the recorder frames
                    // or the bench rows; anything beyond is runaway output.
                    if resp.data.len() >= 1 << 16 {
                        return Err(SerialError::BadReply {
                            command: line.to_string(),
                            line: d,
                            why: "more than 65536 data lines without an ok".into(),
                        });
                    }
                    resp.data.push(d);
                }
            }
        }
    }

    /// Sends a command of the protocol (checked with the firmware's parser first).
    pub fn send(&mut self, cmd: &Command<'_>) -> Result<Response, SerialError> {
        let line = checked_line(cmd)?;
        self.raw(&line)
    }

    /// Gets in step with the firmware: ends any partial line it holds, then sends `ping`
    /// and skips everything up to `ok pong` (boot messages, replies to an earlier client).
    /// Returns the skipped lines.
    pub fn sync(&mut self) -> Result<Vec<String>, SerialError> {
        let cmd = "ping";
        self.link
            .send(b"\n")
            .map_err(|source| io_err(cmd, source))?;
        self.send_line(cmd)?;
        let mut skipped = Vec::new();
        loop {
            let l = self.read_line(cmd)?;
            // Connecting mid-line leaves the tail of a line before the reply.
            if l.ends_with("ok pong") {
                return Ok(skipped);
            }
            if skipped.len() >= 1 << 16 {
                return Err(SerialError::BadReply {
                    command: cmd.into(),
                    line: l,
                    why: "no `ok pong` among 65536 lines".into(),
                });
            }
            skipped.push(l);
        }
    }

    pub(crate) fn send_line(&mut self, line: &str) -> Result<(), SerialError> {
        let mut bytes = Vec::with_capacity(line.len() + 1);
        bytes.extend_from_slice(line.as_bytes());
        bytes.push(b'\n');
        self.link
            .send(&bytes)
            .map_err(|source| io_err(line, source))
    }

    /// Next complete line (lossy UTF-8, `\r` removed); waits at most [`Client::timeout`]
    /// for it.
    pub(crate) fn read_line(&mut self, command: &str) -> Result<String, SerialError> {
        let bytes = self.read_until(command, b'\n', MAX_REPLY, "a newline (wrong baud rate?)")?;
        let text = String::from_utf8_lossy(&bytes);
        Ok(text.trim_end_matches('\r').to_string())
    }

    /// The next COBS packet of a binary transfer (`rec bin`): the bytes before its zero
    /// delimiter; waits at most [`Client::timeout`]. Longer than any packet: `BadReply`.
    pub fn read_packet(&mut self, command: &str) -> Result<Vec<u8>, SerialError> {
        let most = piezo_core::bulk::MAX_FRAMED;
        self.read_until(command, 0, most, "a packet delimiter")
    }

    /// Drops everything received until nothing has arrived for `quiet` (the rest of a
    /// damaged transfer), at most [`Client::timeout`] in all.
    pub fn discard_until_quiet(&mut self, quiet: Duration) {
        self.pending.clear();
        let deadline = Instant::now() + self.timeout;
        let mut buf = [0u8; 1024];
        while Instant::now() < deadline {
            match self.link.recv(&mut buf, quiet) {
                Ok(n) if n > 0 => continue,
                _ => return,
            }
        }
    }

    /// The bytes before the next `end` byte (dropped with it), at most `most` of them;
    /// waits at most [`Client::timeout`].
    fn read_until(
        &mut self,
        command: &str,
        end: u8,
        most: usize,
        what: &str,
    ) -> Result<Vec<u8>, SerialError> {
        let deadline = Instant::now() + self.timeout;
        loop {
            if let Some(pos) = self.pending.iter().position(|&b| b == end) {
                let mut line: Vec<u8> = self.pending.drain(..=pos).collect();
                line.truncate(pos);
                return Ok(line);
            }
            if self.pending.len() > most {
                let head = String::from_utf8_lossy(&self.pending[..80]).into_owned();
                self.pending.clear();
                return Err(SerialError::BadReply {
                    command: command.into(),
                    line: format!("{}...", head.escape_debug()),
                    why: format!("over {most} bytes without {what}"),
                });
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(SerialError::Timeout {
                    command: command.into(),
                    after: self.timeout,
                });
            }
            let mut buf = [0u8; 1024];
            match self.link.recv(&mut buf, left) {
                Ok(0) => {
                    return Err(SerialError::Closed {
                        command: command.into(),
                    })
                }
                Ok(n) => self.pending.extend_from_slice(&buf[..n.min(buf.len())]),
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut
                            | io::ErrorKind::WouldBlock
                            | io::ErrorKind::Interrupted
                    ) => {}
                Err(e) => return Err(io_err(command, e)),
            }
        }
    }
}

/// A link that answers from a script, for the tests of this module and its neighbours.
#[cfg(test)]
pub(crate) mod scripted {
    use super::*;
    use std::sync::{Arc, Mutex};

    /// A link that answers from a script: each written line is looked up in `replies`.
    pub struct Scripted {
        replies: Vec<(String, Vec<u8>)>,
        out: Vec<u8>,
        written: Arc<Mutex<Vec<u8>>>,
        closed: bool,
    }

    impl Link for Scripted {
        fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
            self.written.lock().unwrap().extend_from_slice(bytes);
            for line in String::from_utf8_lossy(bytes).split('\n') {
                if let Some((_, r)) = self.replies.iter().find(|(l, _)| l == line) {
                    self.out.extend_from_slice(r);
                }
            }
            Ok(())
        }
        fn recv(&mut self, buf: &mut [u8], _timeout: Duration) -> io::Result<usize> {
            if self.out.is_empty() {
                return if self.closed {
                    Ok(0)
                } else {
                    Err(io::ErrorKind::TimedOut.into())
                };
            }
            // Dribble a few bytes at a time, as a UART does.
            let n = self.out.len().min(buf.len()).min(7);
            buf[..n].copy_from_slice(&self.out[..n]);
            self.out.drain(..n);
            Ok(n)
        }
    }

    pub fn client(replies: &[(&str, &[u8])], pre: &[u8], closed: bool) -> Client {
        let link = Scripted {
            replies: replies
                .iter()
                .map(|(l, r)| (l.to_string(), r.to_vec()))
                .collect(),
            out: pre.to_vec(),
            written: Arc::default(),
            closed,
        };
        Client::new(Box::new(link), Duration::from_millis(50))
    }
}

#[cfg(test)]
mod tests {
    use super::scripted::client;
    use super::*;
    use crate::serial::error::known_error;
    use piezo_core::command;

    #[test]
    fn classifies_reply_lines() {
        assert_eq!(parse_line("ok"), Line::Ok(String::new()));
        assert_eq!(parse_line("ok pong\r"), Line::Ok("pong".into()));
        assert_eq!(
            parse_line("err 9 unknown mode name"),
            Line::Err {
                code: Some(9),
                message: "unknown mode name".into()
            }
        );
        assert_eq!(
            parse_line("err x?"),
            Line::Err {
                code: None,
                message: "".into()
            }
        );
        assert_eq!(parse_line("okay"), Line::Data("okay".into()));
        assert_eq!(
            parse_line("12 1.5 2 3 4"),
            Line::Data("12 1.5 2 3 4".into())
        );
        assert_eq!(known_error(12), Some(command::Error::Busy));
        assert_eq!(known_error(0), None);
        for e in command::Error::ALL {
            assert_eq!(known_error(e.code()), Some(e));
        }
    }

    #[test]
    fn replies_are_collected_and_errors_name_the_command() {
        let mut c = client(
            &[
                ("ping", b"ok pong\n"),
                ("mode fancy", b"err 9 unknown mode name\n"),
                ("rec read 0 2", b"0 1 2 3 4\r\n1 5 6 7 8\nok rec read 2\n"),
            ],
            b"boot noise\xff\xfe\nready\n",
            false,
        );
        let skipped = c.sync().unwrap();
        assert_eq!(skipped.len(), 2);
        let e = c.send(&Command::Mode("fancy")).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("`mode fancy`")
                && msg.contains("firmware error 9")
                && msg.contains("UnknownMode"),
            "{msg}"
        );
        let r = c.raw("rec read 0 2").unwrap();
        assert_eq!(r.data, vec!["0 1 2 3 4", "1 5 6 7 8"]);
        assert_eq!(r.details, "rec read 2");
    }

    #[test]
    fn silence_garbage_and_hangup_are_errors_not_panics() {
        let mut c = client(&[], b"", false);
        let e = c.raw("ping").unwrap_err();
        assert!(matches!(e, SerialError::Timeout { .. }), "{e}");
        assert!(e.to_string().contains("`ping`: no reply"), "{e}");

        let mut c = client(&[("ping", &[0x55u8; 5000])], b"", false);
        let e = c.raw("ping").unwrap_err();
        assert!(matches!(e, SerialError::BadReply { .. }), "{e}");

        let mut c = client(&[], b"partial", true);
        let e = c.raw("stats").unwrap_err();
        assert!(matches!(e, SerialError::Closed { .. }), "{e}");

        let mut c = client(&[], b"", false);
        let e = c.raw("ping\nping").unwrap_err();
        assert!(matches!(e, SerialError::BadCommand { .. }), "{e}");
    }
}
