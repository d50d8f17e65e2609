//! Command protocol of the serial port: line-based text, `no_std`, bounded parser.
//!
//! # Protocol
//! One command per line: ASCII, at most [`MAX_LINE`] bytes before the `\n` (a `\r` before
//! it is ignored), words separated by spaces. Every command gets exactly one reply line
//! (`rec read` first sends its data lines):
//! * `ok[ <details>]` on success,
//! * `err <code> <message>` on failure; the codes are [`Error::code`] (stable numbers).
//!
//! | command | effect | reply |
//! |---|---|---|
//! | `ping` | liveness | `ok pong` |
//! | `help` | list of commands | `ok ping help get set mode ff wave stats rec bench` |
//! | `get <param>` | read a parameter | `ok <param> <value>` |
//! | `set <param> <value>` | write a parameter (range-checked) | `ok <param> <value>` |
//! | `mode <law>` | select the feedback law (bumpless) | `ok mode <law>` |
//! | `ff <compensator>` | select the feedforward compensator | `ok ff <name>` |
//! | `wave off` / `wave hold <um>` | stop the waveform / hold a position | `ok wave ...` |
//! | `wave sine\|triangle\|square <amp_um> <freq_hz> [<offset_um>]` | start a waveform | `ok wave ...` |
//! | `stats` / `stats reset` | timing (cycles min/max/last, overruns) / reset it | `ok ...` |
//! | `rec sel <signal>...` | recorder channels (up to its channel count) | `ok rec sel ...` |
//! | `rec trig now` | trigger at once when armed | `ok` |
//! | `rec trig rise\|fall\|level <channel> <level> [<pre>]` | trigger on a channel | `ok` |
//! | `rec arm` / `rec stop` | start / abort a capture | `ok` |
//! | `rec status` | `idle`, `armed`, `triggered` or `done` and frame count | `ok rec <state> <n>` |
//! | `rec read <start> <count>` | frames as `<i> <v0> <v1> ...` lines | `ok rec read <n>` |
//! | `bench` | instructions/cycles per step for every mode (QEMU board) | `ok bench ...` |
//!
//! Parameter, law and signal names are checked by whoever executes the command (the
//! firmware), which answers [`Error::UnknownParam`], [`Error::UnknownMode`] or
//! [`Error::UnknownSignal`].
//!
//! The parser never allocates, never panics (a proptest feeds it arbitrary bytes) and its
//! work is bounded by [`MAX_LINE`].

use core::fmt;

/// Longest accepted line (bytes, without the terminator).
pub const MAX_LINE: usize = 96;
/// Most words in one line (the command word included).
pub const MAX_WORDS: usize = 10;

/// Everything that can be wrong with a command line. Codes are stable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// The line exceeded [`MAX_LINE`] bytes; it was discarded.
    LineTooLong,
    /// A byte outside printable ASCII.
    NotAscii,
    /// The first word is not a command.
    UnknownCommand,
    /// A required argument is missing.
    MissingArgument,
    /// More arguments than the command takes.
    TooManyArguments,
    /// An argument is not a finite number (or not a non-negative integer where one is needed).
    BadNumber,
    /// No parameter of that name.
    UnknownParam,
    /// The value is outside the parameter's range.
    OutOfRange,
    /// No feedback law / feedforward compensator of that name.
    UnknownMode,
    /// No signal of that name, or no such recorder channel.
    UnknownSignal,
    /// A sub-command word is not one the command knows.
    BadKeyword,
    /// The command is valid but cannot run now (e.g. reading a recorder while it records).
    Busy,
    /// This board does not implement the command.
    Unsupported,
}

impl Error {
    /// Stable numeric code sent in `err <code> <message>`.
    pub fn code(self) -> u8 {
        match self {
            Error::LineTooLong => 1,
            Error::NotAscii => 2,
            Error::UnknownCommand => 3,
            Error::MissingArgument => 4,
            Error::TooManyArguments => 5,
            Error::BadNumber => 6,
            Error::UnknownParam => 7,
            Error::OutOfRange => 8,
            Error::UnknownMode => 9,
            Error::UnknownSignal => 10,
            Error::BadKeyword => 11,
            Error::Busy => 12,
            Error::Unsupported => 13,
        }
    }

    /// Human-readable message (one line, no trailing newline).
    pub fn message(self) -> &'static str {
        match self {
            Error::LineTooLong => "line too long (max 96 bytes)",
            Error::NotAscii => "non-ASCII or control byte in line",
            Error::UnknownCommand => "unknown command (try help)",
            Error::MissingArgument => "missing argument",
            Error::TooManyArguments => "too many arguments",
            Error::BadNumber => "argument is not a finite number",
            Error::UnknownParam => "unknown parameter",
            Error::OutOfRange => "value out of range",
            Error::UnknownMode => "unknown mode name",
            Error::UnknownSignal => "unknown signal or channel",
            Error::BadKeyword => "unknown sub-command",
            Error::Busy => "not possible in the current state",
            Error::Unsupported => "not supported on this board",
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "err {} {}", self.code(), self.message())
    }
}

/// Waveform shapes of the `wave` command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    Sine,
    Triangle,
    Square,
}

impl Shape {
    pub fn name(self) -> &'static str {
        match self {
            Shape::Sine => "sine",
            Shape::Triangle => "triangle",
            Shape::Square => "square",
        }
    }
}

/// What starts a recording.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TriggerCmd {
    /// Trigger at once.
    Now,
    /// Channel crosses `level` upwards.
    Rising {
        channel: usize,
        level: f32,
        pre: usize,
    },
    /// Channel crosses `level` downwards.
    Falling {
        channel: usize,
        level: f32,
        pre: usize,
    },
    /// Channel crosses `level` in either direction.
    Level {
        channel: usize,
        level: f32,
        pre: usize,
    },
}

/// Recorder sub-commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RecCmd<'a> {
    /// Channel signal names (1..=[`MAX_WORDS`]-2 of them).
    Select(Words<'a>),
    Trigger(TriggerCmd),
    Arm,
    Stop,
    Status,
    Read {
        start: usize,
        count: usize,
    },
}

/// A parsed command; names borrow from the line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command<'a> {
    /// Empty line: no reply needed.
    Empty,
    Ping,
    Help,
    Get(&'a str),
    Set(&'a str, f32),
    Mode(&'a str),
    Feedforward(&'a str),
    WaveOff,
    WaveHold(f32),
    Wave {
        shape: Shape,
        amp_um: f32,
        freq_hz: f32,
        offset_um: f32,
    },
    Stats,
    StatsReset,
    Rec(RecCmd<'a>),
    Bench,
}

/// Up to [`MAX_WORDS`] words of a line, without allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Words<'a> {
    words: [&'a str; MAX_WORDS],
    len: usize,
}

impl<'a> Words<'a> {
    fn split(line: &'a str) -> Result<Self, Error> {
        let mut words = [""; MAX_WORDS];
        let mut len = 0;
        for w in line.split(' ').filter(|w| !w.is_empty()) {
            let slot = words.get_mut(len).ok_or(Error::TooManyArguments)?;
            *slot = w;
            len += 1;
        }
        Ok(Self { words, len })
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn get(&self, i: usize) -> Option<&'a str> {
        if i < self.len {
            self.words.get(i).copied()
        } else {
            None
        }
    }

    pub fn iter(&self) -> impl Iterator<Item = &'a str> + '_ {
        self.words.iter().take(self.len).copied()
    }

    /// The words from index `from` on.
    fn tail(&self, from: usize) -> Self {
        let mut out = Self {
            words: [""; MAX_WORDS],
            len: 0,
        };
        for w in self.iter().skip(from) {
            if let Some(slot) = out.words.get_mut(out.len) {
                *slot = w;
                out.len += 1;
            }
        }
        out
    }

    fn arg(&self, i: usize) -> Result<&'a str, Error> {
        self.get(i).ok_or(Error::MissingArgument)
    }

    fn num(&self, i: usize) -> Result<f32, Error> {
        parse_f32(self.arg(i)?)
    }

    fn index(&self, i: usize) -> Result<usize, Error> {
        self.arg(i)?.parse::<usize>().map_err(|_| Error::BadNumber)
    }

    /// Fails unless the line has at most `n` words.
    fn at_most(&self, n: usize) -> Result<(), Error> {
        if self.len > n {
            Err(Error::TooManyArguments)
        } else {
            Ok(())
        }
    }
}

/// A finite `f32`; `nan`, `inf` and garbage are [`Error::BadNumber`].
pub fn parse_f32(s: &str) -> Result<f32, Error> {
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(Error::BadNumber),
    }
}

/// Parses one line (without its terminator).
pub fn parse(line: &[u8]) -> Result<Command<'_>, Error> {
    if line.len() > MAX_LINE {
        return Err(Error::LineTooLong);
    }
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if !line.iter().all(|b| (b' '..=b'~').contains(b)) {
        return Err(Error::NotAscii);
    }
    let text = core::str::from_utf8(line).map_err(|_| Error::NotAscii)?;
    parse_words(&Words::split(text)?)
}

fn parse_words<'a>(w: &Words<'a>) -> Result<Command<'a>, Error> {
    let Some(cmd) = w.get(0) else {
        return Ok(Command::Empty);
    };
    let c = match cmd {
        "ping" => {
            w.at_most(1)?;
            Command::Ping
        }
        "help" => {
            w.at_most(1)?;
            Command::Help
        }
        "bench" => {
            w.at_most(1)?;
            Command::Bench
        }
        "get" => {
            w.at_most(2)?;
            Command::Get(w.arg(1)?)
        }
        "set" => {
            w.at_most(3)?;
            let name = w.arg(1)?;
            Command::Set(name, w.num(2)?)
        }
        "mode" => {
            w.at_most(2)?;
            Command::Mode(w.arg(1)?)
        }
        "ff" => {
            w.at_most(2)?;
            Command::Feedforward(w.arg(1)?)
        }
        "wave" => parse_wave(w)?,
        "stats" => match w.get(1) {
            None => Command::Stats,
            Some("reset") => {
                w.at_most(2)?;
                Command::StatsReset
            }
            Some(_) => return Err(Error::BadKeyword),
        },
        "rec" => Command::Rec(parse_rec(w)?),
        _ => return Err(Error::UnknownCommand),
    };
    Ok(c)
}

fn parse_wave<'a>(w: &Words<'a>) -> Result<Command<'a>, Error> {
    let shape = match w.arg(1)? {
        "off" => {
            w.at_most(2)?;
            return Ok(Command::WaveOff);
        }
        "hold" => {
            w.at_most(3)?;
            return Ok(Command::WaveHold(w.num(2)?));
        }
        "sine" => Shape::Sine,
        "triangle" => Shape::Triangle,
        "square" => Shape::Square,
        _ => return Err(Error::BadKeyword),
    };
    w.at_most(5)?;
    let amp_um = w.num(2)?;
    let freq_hz = w.num(3)?;
    let offset_um = if w.len() > 4 { w.num(4)? } else { 0.0 };
    if !(freq_hz >= 0.0) || !(amp_um >= 0.0) {
        return Err(Error::OutOfRange);
    }
    Ok(Command::Wave {
        shape,
        amp_um,
        freq_hz,
        offset_um,
    })
}

fn parse_rec<'a>(w: &Words<'a>) -> Result<RecCmd<'a>, Error> {
    let r = match w.arg(1)? {
        "sel" => {
            let names = w.tail(2);
            if names.is_empty() {
                return Err(Error::MissingArgument);
            }
            RecCmd::Select(names)
        }
        "trig" => {
            let kind = w.arg(2)?;
            if kind == "now" {
                w.at_most(3)?;
                return Ok(RecCmd::Trigger(TriggerCmd::Now));
            }
            w.at_most(6)?;
            let channel = w.index(3)?;
            let level = w.num(4)?;
            let pre = if w.len() > 5 { w.index(5)? } else { 0 };
            RecCmd::Trigger(match kind {
                "rise" => TriggerCmd::Rising {
                    channel,
                    level,
                    pre,
                },
                "fall" => TriggerCmd::Falling {
                    channel,
                    level,
                    pre,
                },
                "level" => TriggerCmd::Level {
                    channel,
                    level,
                    pre,
                },
                _ => return Err(Error::BadKeyword),
            })
        }
        "arm" => {
            w.at_most(2)?;
            RecCmd::Arm
        }
        "stop" => {
            w.at_most(2)?;
            RecCmd::Stop
        }
        "status" => {
            w.at_most(2)?;
            RecCmd::Status
        }
        "read" => {
            w.at_most(4)?;
            RecCmd::Read {
                start: w.index(2)?,
                count: w.index(3)?,
            }
        }
        _ => return Err(Error::BadKeyword),
    };
    Ok(r)
}

/// Collects bytes from the serial port into lines of at most [`MAX_LINE`] bytes.
/// An overlong line is dropped whole and reported once, at its end.
#[derive(Debug, Clone)]
pub struct LineBuffer {
    buf: [u8; MAX_LINE + 1],
    len: usize,
    overflow: bool,
}

impl Default for LineBuffer {
    fn default() -> Self {
        Self::new()
    }
}

impl LineBuffer {
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_LINE + 1],
            len: 0,
            overflow: false,
        }
    }

    /// Adds one byte; at `\n` returns the completed line (without `\n`), or
    /// [`Error::LineTooLong`] if it did not fit.
    pub fn push(&mut self, byte: u8) -> Option<Result<&[u8], Error>> {
        if byte == b'\n' {
            let len = core::mem::take(&mut self.len);
            if core::mem::take(&mut self.overflow) {
                return Some(Err(Error::LineTooLong));
            }
            return Some(Ok(self.buf.get(..len).unwrap_or(&[])));
        }
        match self.buf.get_mut(self.len) {
            Some(slot) if !self.overflow => {
                *slot = byte;
                self.len += 1;
            }
            _ => {
                self.overflow = true;
                self.len = 0;
            }
        }
        None
    }
}

/// A reply line built with `write!` into a fixed buffer; text beyond the capacity is cut
/// (and [`Reply::truncated`] says so) instead of failing.
#[derive(Debug, Clone)]
pub struct Reply<const N: usize> {
    buf: [u8; N],
    len: usize,
    truncated: bool,
}

impl<const N: usize> Default for Reply<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Reply<N> {
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            truncated: false,
        }
    }
    pub fn clear(&mut self) {
        self.len = 0;
        self.truncated = false;
    }
    pub fn as_bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(self.as_bytes()).unwrap_or("")
    }
    pub fn truncated(&self) -> bool {
        self.truncated
    }
}

impl<const N: usize> fmt::Write for Reply<N> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        for &b in s.as_bytes() {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = b;
                    self.len += 1;
                }
                None => {
                    self.truncated = true;
                    break;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::fmt::Write;
    use proptest::prelude::*;

    fn p(s: &str) -> Result<Command<'_>, Error> {
        parse(s.as_bytes())
    }

    #[test]
    fn parses_every_command() {
        assert_eq!(p("ping"), Ok(Command::Ping));
        assert_eq!(p("  ping \r"), Ok(Command::Ping));
        assert_eq!(p(""), Ok(Command::Empty));
        assert_eq!(p("get kp"), Ok(Command::Get("kp")));
        assert_eq!(p("set kp 1.5e-3"), Ok(Command::Set("kp", 1.5e-3)));
        assert_eq!(p("mode hgo"), Ok(Command::Mode("hgo")));
        assert_eq!(p("ff ims-cbw"), Ok(Command::Feedforward("ims-cbw")));
        assert_eq!(p("wave off"), Ok(Command::WaveOff));
        assert_eq!(p("wave hold 12.5"), Ok(Command::WaveHold(12.5)));
        assert_eq!(
            p("wave sine 5 100 20"),
            Ok(Command::Wave {
                shape: Shape::Sine,
                amp_um: 5.0,
                freq_hz: 100.0,
                offset_um: 20.0
            })
        );
        assert_eq!(p("stats"), Ok(Command::Stats));
        assert_eq!(p("stats reset"), Ok(Command::StatsReset));
        assert_eq!(p("rec arm"), Ok(Command::Rec(RecCmd::Arm)));
        assert_eq!(
            p("rec trig rise 1 2.5 100"),
            Ok(Command::Rec(RecCmd::Trigger(TriggerCmd::Rising {
                channel: 1,
                level: 2.5,
                pre: 100
            })))
        );
        assert_eq!(
            p("rec read 0 16"),
            Ok(Command::Rec(RecCmd::Read {
                start: 0,
                count: 16
            }))
        );
        match p("rec sel y_um u_volts") {
            Ok(Command::Rec(RecCmd::Select(w))) => {
                assert_eq!(w.len(), 2);
                assert_eq!(w.get(0), Some("y_um"));
                assert_eq!(w.get(1), Some("u_volts"));
                assert_eq!(w.get(2), None);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn every_error_has_its_code() {
        assert_eq!(p("jump").unwrap_err().code(), 3);
        assert_eq!(p("set kp").unwrap_err(), Error::MissingArgument);
        assert_eq!(p("set kp nan").unwrap_err(), Error::BadNumber);
        assert_eq!(p("set kp inf").unwrap_err(), Error::BadNumber);
        assert_eq!(p("set kp 1 2").unwrap_err(), Error::TooManyArguments);
        assert_eq!(p("wave saw 1 2").unwrap_err(), Error::BadKeyword);
        assert_eq!(p("wave sine 1 -2").unwrap_err(), Error::OutOfRange);
        assert_eq!(p("rec read -1 3").unwrap_err(), Error::BadNumber);
        assert_eq!(parse(b"ping\x00").unwrap_err(), Error::NotAscii);
        assert_eq!(
            parse(&[b'a'; MAX_LINE + 1]).unwrap_err(),
            Error::LineTooLong
        );
        assert_eq!(
            p("a b c d e f g h i j k").unwrap_err(),
            Error::TooManyArguments
        );
        assert_eq!(
            Error::UnknownParam.to_string(),
            "err 7 unknown parameter".to_string()
        );
    }

    #[test]
    fn line_buffer_splits_lines_and_rejects_long_ones() {
        let mut lb = LineBuffer::new();
        let mut lines = std::vec::Vec::new();
        for &b in b"ping\r\nget kp\n".iter() {
            if let Some(l) = lb.push(b) {
                lines.push(l.map(|l| l.to_vec()));
            }
        }
        assert_eq!(lines, vec![Ok(b"ping\r".to_vec()), Ok(b"get kp".to_vec())]);
        for _ in 0..MAX_LINE + 5 {
            assert!(lb.push(b'x').is_none());
        }
        assert_eq!(lb.push(b'\n'), Some(Err(Error::LineTooLong)));
        // The next line is fine again.
        for &b in b"ping" {
            lb.push(b);
        }
        assert_eq!(lb.push(b'\n'), Some(Ok(&b"ping"[..])));
    }

    #[test]
    fn reply_truncates_instead_of_failing() {
        let mut r = Reply::<8>::new();
        write!(r, "ok {}", 123456789).unwrap();
        assert_eq!(r.as_str(), "ok 12345");
        assert!(r.truncated());
        r.clear();
        write!(r, "ok").unwrap();
        assert_eq!(r.as_str(), "ok");
        assert!(!r.truncated());
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = parse(&bytes);
            let mut lb = LineBuffer::new();
            for &b in &bytes {
                if let Some(Ok(line)) = lb.push(b) {
                    let _ = parse(line);
                }
            }
        }

        #[test]
        fn arbitrary_words_never_panic(words in proptest::collection::vec(
            prop_oneof![
                proptest::sample::select(&[
                    "rec", "trig", "sel", "wave", "sine", "set", "1e3", "-1", "read", "3",
                    "rise", "stats", "reset", "hold", "now", "arm",
                ][..]).prop_map(|s| s.to_string()),
                "[a-z0-9.]{0,6}",
            ],
            0..12)) {
            let line = words.join(" ");
            let _ = parse(line.as_bytes());
        }
    }
}
