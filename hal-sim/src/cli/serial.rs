//! `piezo serial`: the host side of the firmware's command protocol
//! ([`piezo_core::command`]: one ASCII line per command, one `ok ...` or `err <code> <message>`
//! reply line, `rec read` and `bench` send data lines before it).
//!
//! Transport: a serial port (`--port /dev/ttyACM0 [--baud 115200]`) or TCP (`--tcp
//! 127.0.0.1:PORT`, e.g. QEMU `-serial tcp::PORT,server=on,wait=off`).
//!
//! Every command the host builds is a [`Command`] of the core's protocol module, written by
//! [`format_command`] (an exhaustive match: a new command in the firmware's enum does not
//! compile here until the host knows it) and parsed back with the firmware's own parser
//! before it is sent, so host and firmware cannot drift apart.
//!
//! ```text
//! piezo serial --tcp 127.0.0.1:4444 -- "mode ff+pid" "wave sine 5 100 10"
//! piezo serial --port /dev/ttyACM0 wave sine 5um 100Hz --offset 10um
//! piezo serial --tcp 127.0.0.1:4444 wave steps 10um 30um 5 2Hz
//! piezo serial --tcp 127.0.0.1:4444 wave table --freq 10Hz --points 0,20,5,15
//! piezo serial --tcp 127.0.0.1:4444 record --signals ref_um,y_um,u_volts --out rec.csv --svg rec.svg
//! ```
use std::fmt;
use std::io::{self, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use piezo_core::command::{
    self, Command, Points, RecCmd, Shape, TriggerCmd, MAX_LEVELS, MAX_LINE, MAX_LINES, MAX_WORDS,
    TABLE_ADD_MAX, TABLE_LEN,
};
use piezo_core::recorder::Signal;

use crate::plot::{write_grid, Plot};

/// Longest reply line accepted (bytes); a longer run without newline is garbage (wrong baud
/// rate, binary output) and fails the command instead of growing a buffer forever.
pub const MAX_REPLY: usize = 4096;
/// Frames asked for per `rec read` (keeps each reply short on a 115200 Bd port).
pub const READ_CHUNK: usize = 128;

// ---------------------------------------------------------------------------------------
// Command lines: built from the core's `Command` enum, checked with the core's parser.

/// Writes `cmd` as the line the firmware's parser reads back as `cmd`. Numbers use the
/// shortest representation that round-trips (`f32` `Display`).
pub fn format_command(cmd: &Command<'_>) -> String {
    match cmd {
        Command::Empty => String::new(),
        Command::Ping => "ping".into(),
        Command::Help => "help".into(),
        Command::Get(name) => format!("get {name}"),
        Command::Set(name, v) => format!("set {name} {v}"),
        Command::Cbw([d, a, b, g]) => format!("cbw {d} {a} {b} {g}"),
        Command::Mode(law) => format!("mode {law}"),
        Command::Feedforward(name) => format!("ff {name}"),
        Command::WaveOff => "wave off".into(),
        Command::WaveHold(y_um) => format!("wave hold {y_um}"),
        Command::Wave {
            shape,
            amp_um,
            freq_hz,
            offset_um,
        } => format!("wave {} {amp_um} {freq_hz} {offset_um}", shape.name()),
        Command::WaveSteps {
            low_um,
            high_um,
            levels,
            freq_hz,
        } => format!("wave steps {low_um} {high_um} {levels} {freq_hz}"),
        Command::WaveTable(freq_hz) => format!("wave table {freq_hz}"),
        Command::WaveRaster {
            span_um: [sx, sy],
            lines,
            line_hz,
            center_um: [cx, cy],
        } => format!("wave raster {sx} {sy} {lines} {line_hz} {cx} {cy}"),
        Command::WaveLissajous {
            amp_um: [ax, ay],
            freq_hz: [fx, fy],
            phase_deg,
            center_um: [cx, cy],
        } => format!("wave lissajous {ax} {ay} {fx} {fy} {phase_deg} {cx} {cy}"),
        Command::Axis(None) => "axis".into(),
        Command::Axis(Some(n)) => format!("axis {n}"),
        Command::TableClear => "table clear".into(),
        Command::TableLen => "table len".into(),
        Command::TableAdd(points) => {
            let mut s = String::from("table add");
            for v in points.as_slice() {
                s.push_str(&format!(" {v}"));
            }
            s
        }
        Command::Stats => "stats".into(),
        Command::StatsReset => "stats reset".into(),
        Command::Rec(r) => match r {
            RecCmd::Select(names) => {
                let mut s = String::from("rec sel");
                for n in names.iter() {
                    s.push(' ');
                    s.push_str(n);
                }
                s
            }
            RecCmd::Trigger(t) => match t {
                TriggerCmd::Now => "rec trig now".into(),
                TriggerCmd::Rising {
                    channel,
                    level,
                    pre,
                } => format!("rec trig rise {channel} {level} {pre}"),
                TriggerCmd::Falling {
                    channel,
                    level,
                    pre,
                } => format!("rec trig fall {channel} {level} {pre}"),
                TriggerCmd::Level {
                    channel,
                    level,
                    pre,
                } => format!("rec trig level {channel} {level} {pre}"),
            },
            RecCmd::Arm => "rec arm".into(),
            RecCmd::Stop => "rec stop".into(),
            RecCmd::Status => "rec status".into(),
            RecCmd::Read { start, count } => format!("rec read {start} {count}"),
            RecCmd::Divider(None) => "rec div".into(),
            RecCmd::Divider(Some(n)) => format!("rec div {n}"),
        },
        Command::Fault => "fault".into(),
        Command::FaultClear => "fault clear".into(),
        Command::Bench => "bench".into(),
    }
}

/// [`format_command`], then the firmware's parser must read the line back as `cmd` and it
/// must fit the firmware's line buffer.
pub fn checked_line(cmd: &Command<'_>) -> Result<String, SerialError> {
    let line = format_command(cmd);
    check_built(&line, Some(cmd))?;
    Ok(line)
}

/// Checks a line the host built: it fits [`MAX_LINE`] and the firmware's parser accepts it
/// (and, with `expect`, reads it back as that command).
fn check_built(line: &str, expect: Option<&Command<'_>>) -> Result<(), SerialError> {
    let bad = |why: String| SerialError::BadCommand {
        command: line.to_string(),
        why,
    };
    if line.len() > MAX_LINE {
        return Err(bad(format!(
            "{} bytes, the firmware takes at most {MAX_LINE} (it would answer err 1)",
            line.len()
        )));
    }
    match command::parse(line.as_bytes()) {
        Err(e) => Err(bad(format!("the protocol parser rejects it: {e}"))),
        Ok(parsed) => match expect {
            Some(cmd) if parsed != *cmd => Err(bad(format!(
                "the protocol parser reads it as {parsed:?}, not {cmd:?}"
            ))),
            _ => Ok(()),
        },
    }
}

/// `rec sel <names>`: every name must be a recorder [`Signal`].
pub fn select_line(signals: &[Signal]) -> Result<String, SerialError> {
    let mut line = String::from("rec sel");
    for s in signals {
        line.push(' ');
        line.push_str(s.name());
    }
    if signals.is_empty() || signals.len() > MAX_WORDS - 2 {
        return Err(SerialError::BadCommand {
            command: line,
            why: format!("select 1 to {} signals", MAX_WORDS - 2),
        });
    }
    check_built(&line, None)?;
    Ok(line)
}

/// The `table add` lines that load `points_um` (after a `table clear`): as many points
/// per line as fit [`MAX_LINE`] and [`TABLE_ADD_MAX`], each line checked by the firmware's
/// parser. Refuses fewer than 2 or more than [`TABLE_LEN`] points before anything is sent.
pub fn table_lines(points_um: &[f32]) -> Result<Vec<String>, SerialError> {
    if !(2..=TABLE_LEN).contains(&points_um.len()) {
        return Err(SerialError::BadCommand {
            command: "wave table".into(),
            why: format!(
                "{} points; the firmware's table takes 2 to {TABLE_LEN}",
                points_um.len()
            ),
        });
    }
    let mut lines = Vec::new();
    let mut chunk: Vec<f32> = Vec::new();
    let line_of = |chunk: &[f32]| -> Result<String, SerialError> {
        let pts = Points::from_slice(chunk).ok_or_else(|| SerialError::BadCommand {
            command: "table add".into(),
            why: format!("1 to {TABLE_ADD_MAX} points per line"),
        })?;
        checked_line(&Command::TableAdd(pts))
    };
    for &v in points_um {
        chunk.push(v);
        let fits = chunk.len() <= TABLE_ADD_MAX
            && format_command(&Command::TableAdd(
                Points::from_slice(&chunk).expect("1..=TABLE_ADD_MAX points"),
            ))
            .len()
                <= MAX_LINE;
        if !fits {
            chunk.pop();
            lines.push(line_of(&chunk)?);
            chunk.clear();
            chunk.push(v);
        }
    }
    lines.push(line_of(&chunk)?);
    Ok(lines)
}

/// Points (um) from a file: numbers (optionally with a length unit) separated by commas,
/// spaces or newlines; `#` starts a comment.
pub fn read_points(path: &std::path::Path) -> Result<Vec<f64>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let data = line.split('#').next().unwrap_or("");
        for field in data.split(|c: char| c == ',' || c.is_whitespace()) {
            if field.is_empty() {
                continue;
            }
            let v = parse_um(field).map_err(|e| anyhow!("{}:{}: {e}", path.display(), n + 1))?;
            points.push(v);
        }
    }
    Ok(points)
}

/// Every protocol error, for mapping a reply's code back to its meaning. The match below
/// fails to compile when the firmware gains an error the host does not list.
pub const ERRORS: [command::Error; 14] = {
    use command::Error::*;
    [
        LineTooLong,
        NotAscii,
        UnknownCommand,
        MissingArgument,
        TooManyArguments,
        BadNumber,
        UnknownParam,
        OutOfRange,
        UnknownMode,
        UnknownSignal,
        BadKeyword,
        Busy,
        Unsupported,
        TooManyDigits,
    ]
};

#[allow(dead_code)]
fn errors_are_listed(e: command::Error) {
    use command::Error::*;
    match e {
        LineTooLong | NotAscii | UnknownCommand | MissingArgument | TooManyArguments
        | BadNumber | UnknownParam | OutOfRange | UnknownMode | UnknownSignal | BadKeyword
        | Busy | Unsupported | TooManyDigits => {}
    }
}

/// The protocol error of a numbered reply code.
pub fn known_error(code: u8) -> Option<command::Error> {
    ERRORS.into_iter().find(|e| e.code() == code)
}

/// Unit of a recorder signal (for the CSV header and the plots).
pub fn signal_unit(s: Signal) -> &'static str {
    match s {
        Signal::RefUm
        | Signal::YUm
        | Signal::ErrorUm
        | Signal::RefUm1
        | Signal::YUm1
        | Signal::ErrorUm1 => "um",
        Signal::FfVolts | Signal::UVolts | Signal::FfVolts1 | Signal::UVolts1 => "V",
        Signal::AdcCode | Signal::DacCode | Signal::AdcCode1 | Signal::DacCode1 => "code",
    }
}

/// Unit of a channel named by the firmware (its names end in their unit).
fn name_unit(name: &str) -> &'static str {
    match Signal::from_name(name) {
        Some(s) => signal_unit(s),
        None if name.ends_with("_um") => "um",
        None if name.ends_with("_volts") => "V",
        None => "?",
    }
}

// ---------------------------------------------------------------------------------------
// Replies.

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

/// Why a command failed.
#[derive(Debug)]
pub enum SerialError {
    /// The firmware answered `err <code> <message>`.
    Firmware {
        command: String,
        code: Option<u8>,
        message: String,
    },
    /// No complete reply line within the timeout.
    Timeout {
        command: String,
        after: Duration,
    },
    /// The other end closed the connection.
    Closed {
        command: String,
    },
    /// A reply the host cannot use.
    BadReply {
        command: String,
        line: String,
        why: String,
    },
    /// A command line the host refuses to send.
    BadCommand {
        command: String,
        why: String,
    },
    Io {
        command: String,
        source: io::Error,
    },
}

impl fmt::Display for SerialError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SerialError::Firmware {
                command,
                code,
                message,
            } => {
                match code {
                    Some(c) => write!(f, "`{command}`: firmware error {c}: {message}")?,
                    None => write!(f, "`{command}`: firmware error (no code): {message}")?,
                }
                match code.and_then(known_error) {
                    Some(e) => write!(f, " ({e:?})"),
                    None => write!(f, " (a code this host does not know)"),
                }
            }
            SerialError::Timeout { command, after } => write!(
                f,
                "`{command}`: no reply within {:.1} s (firmware running? right port and baud rate?)",
                after.as_secs_f64()
            ),
            SerialError::Closed { command } => write!(
                f,
                "`{command}`: connection closed before the reply (firmware exited or reset?)"
            ),
            SerialError::BadReply { command, line, why } => {
                write!(f, "`{command}`: unusable reply `{line}`: {why}")
            }
            SerialError::BadCommand { command, why } => {
                write!(f, "`{command}`: not sent: {why}")
            }
            SerialError::Io { command, source } => write!(f, "`{command}`: {source}"),
        }
    }
}

// The I/O error's text is part of the message already, so no `source`.
impl std::error::Error for SerialError {}

// ---------------------------------------------------------------------------------------
// Transport.

/// A byte stream to the firmware.
pub trait Link: Send {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Reads what has arrived, waiting at most `timeout`. `Ok(0)`: the other end closed;
    /// nothing within the timeout is an error of kind `TimedOut` or `WouldBlock`.
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
}

impl Link for TcpStream {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.write_all(bytes)?;
        self.flush()
    }
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        self.set_read_timeout(Some(timeout.max(Duration::from_millis(1))))?;
        self.read(buf)
    }
}

struct Serial(Box<dyn serialport::SerialPort>);

impl Link for Serial {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.0.write_all(bytes)?;
        self.0.flush()
    }
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        self.0
            .set_timeout(timeout.max(Duration::from_millis(1)))
            .map_err(io::Error::from)?;
        self.0.read(buf)
    }
}

/// Opens a TCP connection (the address may be a host name).
pub fn connect_tcp(addr: &str, timeout: Duration) -> Result<TcpStream> {
    let addrs: Vec<_> = addr
        .to_socket_addrs()
        .with_context(|| format!("--tcp {addr}: not a host:port address"))?
        .collect();
    let mut last = None;
    for a in &addrs {
        match TcpStream::connect_timeout(a, timeout) {
            Ok(s) => {
                s.set_nodelay(true).ok();
                return Ok(s);
            }
            Err(e) => last = Some(e),
        }
    }
    match last {
        Some(e) => Err(anyhow!("--tcp {addr}: cannot connect: {e}")),
        None => bail!("--tcp {addr}: the name resolves to no address"),
    }
}

/// Opens a serial port, 8N1, no flow control, and drops anything already received.
pub fn open_serial(path: &str, baud: u32, timeout: Duration) -> Result<Box<dyn Link>> {
    let port = serialport::new(path, baud)
        .timeout(timeout)
        .open()
        .with_context(|| format!("--port {path}: cannot open at {baud} Bd"))?;
    port.clear(serialport::ClearBuffer::Input).ok();
    Ok(Box::new(Serial(port)))
}

// ---------------------------------------------------------------------------------------
// Client.

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

    fn send_line(&mut self, line: &str) -> Result<(), SerialError> {
        let mut bytes = Vec::with_capacity(line.len() + 1);
        bytes.extend_from_slice(line.as_bytes());
        bytes.push(b'\n');
        self.link
            .send(&bytes)
            .map_err(|source| io_err(line, source))
    }

    /// Next complete line (lossy UTF-8, `\r` removed); waits at most [`Client::timeout`]
    /// for it.
    fn read_line(&mut self, command: &str) -> Result<String, SerialError> {
        let deadline = Instant::now() + self.timeout;
        loop {
            if let Some(pos) = self.pending.iter().position(|&b| b == b'\n') {
                let line: Vec<u8> = self.pending.drain(..=pos).collect();
                let text = String::from_utf8_lossy(&line[..pos]);
                return Ok(text.trim_end_matches('\r').to_string());
            }
            if self.pending.len() > MAX_REPLY {
                let head = String::from_utf8_lossy(&self.pending[..80]).into_owned();
                self.pending.clear();
                return Err(SerialError::BadReply {
                    command: command.into(),
                    line: format!("{}...", head.escape_debug()),
                    why: format!("over {MAX_REPLY} bytes without a newline (wrong baud rate?)"),
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

/// A hang-up is [`SerialError::Closed`]; other I/O errors keep their text.
fn io_err(command: &str, source: io::Error) -> SerialError {
    use io::ErrorKind::*;
    match source.kind() {
        ConnectionReset | ConnectionAborted | BrokenPipe | UnexpectedEof => SerialError::Closed {
            command: command.into(),
        },
        _ => SerialError::Io {
            command: command.into(),
            source,
        },
    }
}

// ---------------------------------------------------------------------------------------
// Typed replies.

/// `get <param>` reply `ok <param> <value>`.
pub fn parse_get(resp: &Response, param: &str) -> Result<f64, String> {
    let mut w = resp.details.split_whitespace();
    match (w.next(), w.next(), w.next()) {
        (Some(p), Some(v), None) if p == param => v
            .parse::<f64>()
            .map_err(|_| format!("value `{v}` is not a number")),
        _ => Err(format!("expected `ok {param} <value>`")),
    }
}

/// Timing counts of `stats`: DWT cycles on the H743, SysTick ticks (25 MHz) under QEMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Stats {
    pub step_min: u32,
    pub step_max: u32,
    pub step_last: u32,
    pub isr_min: u32,
    pub isr_max: u32,
    pub isr_last: u32,
    pub samples: u32,
    pub overruns: u32,
}

/// `ok step <min> <max> <last> isr <min> <max> <last> samples <n> overruns <n>`.
pub fn parse_stats(details: &str) -> Result<Stats, String> {
    let w: Vec<&str> = details.split_whitespace().collect();
    let expect = "step <min> <max> <last> isr <min> <max> <last> samples <n> overruns <n>";
    let keys = [(0, "step"), (4, "isr"), (8, "samples"), (10, "overruns")];
    if w.len() != 12 || keys.iter().any(|&(i, k)| w.get(i) != Some(&k)) {
        return Err(format!("expected `{expect}`"));
    }
    let n = |i: usize| -> Result<u32, String> {
        let s = w.get(i).copied().unwrap_or("");
        s.parse::<u32>()
            .map_err(|_| format!("`{s}` is not a count in `{expect}`"))
    };
    Ok(Stats {
        step_min: n(1)?,
        step_max: n(2)?,
        step_last: n(3)?,
        isr_min: n(5)?,
        isr_max: n(6)?,
        isr_last: n(7)?,
        samples: n(9)?,
        overruns: n(11)?,
    })
}

/// State of the recorder from `rec status` (`ok rec <state> <frames>`).
pub fn parse_rec_status(details: &str) -> Result<(String, usize), String> {
    let mut w = details.split_whitespace();
    match (w.next(), w.next(), w.next(), w.next()) {
        (Some("rec"), Some(state), Some(n), None)
            if matches!(state, "idle" | "armed" | "triggered" | "done") =>
        {
            n.parse::<usize>()
                .map(|n| (state.to_string(), n))
                .map_err(|_| format!("frame count `{n}` is not a number"))
        }
        _ => Err("expected `ok rec idle|armed|triggered|done <frames>`".into()),
    }
}

/// Channel names of the `rec sel` reply (`ok rec sel <name>...`).
pub fn parse_rec_sel(details: &str) -> Result<Vec<String>, String> {
    let mut w = details.split_whitespace();
    if (w.next(), w.next()) != (Some("rec"), Some("sel")) {
        return Err("expected `ok rec sel <signal>...`".into());
    }
    let names: Vec<String> = w.map(str::to_string).collect();
    if names.is_empty() {
        return Err("no channels in the reply".into());
    }
    Ok(names)
}

/// One frame line of `rec read`: `<index> <v0> <v1> ...` with `channels` values (any
/// number of at least one for `None`).
pub fn parse_frame(line: &str, channels: Option<usize>) -> Result<(usize, Vec<f64>), String> {
    let mut w = line.split_whitespace();
    let i = w
        .next()
        .and_then(|s| s.parse::<usize>().ok())
        .ok_or("no frame index")?;
    let v = w
        .map(|s| {
            s.parse::<f64>()
                .map_err(|_| format!("`{s}` is not a number"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    match channels {
        Some(n) if v.len() != n => Err(format!("{} values, expected {n}", v.len())),
        None if v.is_empty() => Err("no values".into()),
        _ => Ok((i, v)),
    }
}

// ---------------------------------------------------------------------------------------
// Quantities with units on the command line.

/// A number with an optional unit; bare numbers are in `base`.
fn quantity(s: &str, what: &str, units: &[(&str, f64)]) -> Result<f64, String> {
    let t = s.trim();
    let split = t
        .char_indices()
        .find(|&(i, c)| {
            !(c.is_ascii_digit()
                || c == '.'
                || ((c == '-' || c == '+')
                    && (i == 0 || t[..i].ends_with('e') || t[..i].ends_with('E')))
                || ((c == 'e' || c == 'E')
                    && t[i + 1..]
                        .starts_with(|d: char| d.is_ascii_digit() || d == '-' || d == '+')))
        })
        .map(|(i, _)| i)
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let unit = unit.trim();
    let v: f64 = num
        .parse()
        .map_err(|_| format!("`{s}`: not a {what} (a number, optionally with a unit)"))?;
    let names = || units.iter().map(|(u, _)| *u).collect::<Vec<_>>().join(", ");
    let factor = if unit.is_empty() {
        1.0
    } else {
        units
            .iter()
            .find(|(u, _)| *u == unit)
            .map(|(_, f)| *f)
            .ok_or_else(|| format!("`{s}`: unknown unit `{unit}` for a {what}; use {}", names()))?
    };
    let v = v * factor;
    if !v.is_finite() || v.abs() > f32::MAX as f64 {
        return Err(format!("`{s}`: not a finite {what}"));
    }
    Ok(v)
}

/// Position in um (`12.5`, `12.5um`, `300nm`, `0.1mm`).
pub fn parse_um(s: &str) -> Result<f64, String> {
    quantity(
        s,
        "position",
        &[("um", 1.0), ("µm", 1.0), ("nm", 1e-3), ("mm", 1e3)],
    )
}

/// Frequency in Hz (`100`, `100Hz`, `2kHz`, `25MHz`, `500mHz`).
pub fn parse_hz(s: &str) -> Result<f64, String> {
    quantity(
        s,
        "frequency",
        &[("Hz", 1.0), ("kHz", 1e3), ("MHz", 1e6), ("mHz", 1e-3)],
    )
}

/// Voltage in V (`120`, `120V`, `500mV`).
pub fn parse_volts(s: &str) -> Result<f64, String> {
    quantity(s, "voltage", &[("V", 1.0), ("mV", 1e-3), ("kV", 1e3)])
}

/// Slew rate in V/s (`20000`, `20V/ms`, `20kV/s`, `0.02V/us`).
pub fn parse_volts_per_s(s: &str) -> Result<f64, String> {
    quantity(
        s,
        "slew rate",
        &[
            ("V/s", 1.0),
            ("kV/s", 1e3),
            ("V/ms", 1e3),
            ("V/us", 1e6),
            ("V/µs", 1e6),
        ],
    )
}

/// f64 quantity as the protocol's f32 (already checked finite and in range).
fn f32_of(v: f64) -> f32 {
    v as f32
}

// ---------------------------------------------------------------------------------------
// CLI.

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Raw lines: piezo serial --tcp 127.0.0.1:4444 -- \"mode ff+pid\" \"wave sine 5 100 10\"\n\
Protocol: one ASCII line per command (max 96 bytes); reply `ok [details]` or `err <code> <message>`; \
`help` lists the commands and parameters."
)]
pub struct Args {
    #[command(flatten)]
    pub conn: Conn,
    #[command(subcommand)]
    pub action: Option<Action>,
    /// Raw command lines (after `--`), sent in order; each reply is printed.
    #[arg(last = true, value_name = "LINE")]
    pub lines: Vec<String>,
}

/// Where the firmware is.
#[derive(clap::Args, Debug, Clone)]
pub struct Conn {
    /// Serial device of the firmware's command port (Nucleo: the ST-LINK VCP, /dev/ttyACM0).
    #[arg(long, global = true, conflicts_with = "tcp")]
    pub port: Option<String>,
    /// Baud rate of --port.
    #[arg(long, global = true, default_value_t = 115_200)]
    pub baud: u32,
    /// TCP address of the serial port (QEMU: -serial tcp::PORT,server=on,wait=off).
    #[arg(long, global = true, value_name = "HOST:PORT")]
    pub tcp: Option<String>,
    /// Longest wait for a reply line, in seconds.
    #[arg(long, global = true, default_value_t = 2.0, value_name = "S")]
    pub timeout_s: f64,
    /// Do not send the `ping` that skips stale output before the first command.
    #[arg(long, global = true)]
    pub no_sync: bool,
    /// Raw lines: go on after a command the firmware refuses (exit status 1 at the end).
    #[arg(long, global = true)]
    pub keep_going: bool,
}

#[derive(clap::Subcommand, Debug)]
pub enum Action {
    /// Send raw command lines, print every reply.
    Send {
        #[arg(required = true, value_name = "LINE")]
        lines: Vec<String>,
    },
    /// Check the link (`ping`).
    Ping,
    /// List the firmware's commands and parameters (its `help` command).
    Commands,
    /// Select the control mode: open-loop, feedforward or a feedback law (pid, ff+pid,
    /// hgo-robust, ff+hgo-robust, fts, ff+fts, adrc, ff+adrc, nmpc, ff+nmpc); bumpless.
    Mode {
        law: String,
        /// Feedforward compensator to select first (linear, ims-cbw, ims-cbw-delayed).
        #[arg(long)]
        ff: Option<String>,
    },
    /// Set the output limits; with no option, print them.
    Limits {
        /// Lowest output voltage (`0`, `0V`).
        #[arg(long, value_parser = parse_volts, allow_hyphen_values = true)]
        u_min: Option<f64>,
        /// Highest output voltage (`120V`).
        #[arg(long, value_parser = parse_volts, allow_hyphen_values = true)]
        u_max: Option<f64>,
        /// Slew limit (`20V/ms`, `20000` = V/s).
        #[arg(long, value_parser = parse_volts_per_s)]
        slew: Option<f64>,
    },
    /// Start a waveform, hold a position or stop (hold where it is).
    #[command(subcommand)]
    Wave(WaveCmd),
    /// Select the axis the 1-axis waves (sine, triangle, square, steps, table, hold) go to
    /// (`axis 1`: y of an XY build); with no number, print it.
    Axis { axis: Option<usize> },
    /// Every parameter of the firmware (names from its `help`) with its value.
    Params,
    /// Send the CBW model of a `piezo fit --model cbw` report to the firmware as one
    /// `cbw <d> <alpha> <beta> <gamma>` line (checked and installed as a whole).
    LoadFit {
        /// The report: `piezo fit --out <dir>` writes `<dir>/fit.json`, `--json` prints it.
        fit: PathBuf,
    },
    /// Link, parameters, timing and recorder state.
    Status,
    /// Timing of the control task (counts: DWT cycles on the H743, SysTick ticks in QEMU).
    Stats {
        /// Reset the counters after reading them.
        #[arg(long)]
        reset: bool,
        /// Clock of the counts, to print microseconds too (H743 400e6, QEMU 25e6).
        #[arg(long, value_parser = parse_hz)]
        clock: Option<f64>,
    },
    /// Capture with the recorder and write CSV (optionally SVG).
    Record(RecordArgs),
    /// Instructions per control step for every mode (QEMU board).
    Bench,
}

#[derive(clap::Subcommand, Debug)]
pub enum WaveCmd {
    /// Sine around --offset (`wave sine 5um 100Hz --offset 10um`).
    Sine(WaveArgs),
    /// Triangle around --offset.
    Triangle(WaveArgs),
    /// Square between offset - amplitude and offset + amplitude.
    Square(WaveArgs),
    /// Staircase from LOW up to HIGH in LEVELS levels and back down, once per period
    /// (`wave steps 10um 30um 5 2Hz`; 2 levels is a square wave).
    Steps {
        #[arg(value_parser = parse_um, allow_hyphen_values = true)]
        low: f64,
        #[arg(value_parser = parse_um, allow_hyphen_values = true)]
        high: f64,
        /// Number of levels, 2 to 64.
        #[arg(value_parser = clap::value_parser!(u16).range(2..=MAX_LEVELS as i64))]
        levels: u16,
        #[arg(value_parser = parse_hz)]
        freq: f64,
    },
    /// Periodic spline through 2 to 64 points, one period per 1/--freq (`wave table
    /// --freq 10Hz --points 0,20,5,15` or `--file points.csv`). Loads the firmware's table
    /// (`table clear`, `table add ...`) and starts it (`wave table`).
    Table(TableArgs),
    /// Hold a position (`wave hold 12.5um`).
    Hold {
        #[arg(value_parser = parse_um, allow_hyphen_values = true)]
        position: f64,
    },
    /// Stop the waveform and hold where it is (every axis).
    Off,
    /// XY raster (2-axis firmware, `--features xy`): x triangle over X_SPAN at LINE_FREQ,
    /// y triangle over Y_SPAN, one y sweep per LINES x periods (`wave raster 20um 20um 16
    /// 50Hz --center 30um,30um`).
    Raster {
        #[arg(value_parser = parse_um)]
        x_span: f64,
        #[arg(value_parser = parse_um)]
        y_span: f64,
        /// x periods per y sweep, 1 to 4096.
        #[arg(value_parser = clap::value_parser!(u16).range(1..=MAX_LINES as i64))]
        lines: u16,
        #[arg(value_parser = parse_hz)]
        line_freq: f64,
        /// Centre `x,y` of the scan (default: half the spans, so it starts at 0).
        #[arg(long, value_delimiter = ',', num_args = 1, value_parser = parse_um, allow_hyphen_values = true)]
        center: Option<Vec<f64>>,
    },
    /// XY Lissajous scan (2-axis firmware): sines of X_AMP at FX and Y_AMP at FY, y --phase
    /// ahead (`wave lissajous 10um 10um 40Hz 30Hz --center 30um,30um`).
    Lissajous {
        #[arg(value_parser = parse_um)]
        x_amp: f64,
        #[arg(value_parser = parse_um)]
        y_amp: f64,
        #[arg(value_parser = parse_hz)]
        fx: f64,
        #[arg(value_parser = parse_hz)]
        fy: f64,
        /// Phase of y ahead of x, degrees (-360 to 360).
        #[arg(long, default_value_t = 90.0, allow_hyphen_values = true)]
        phase: f64,
        /// Centre `x,y` of the scan (default: the amplitudes, so it starts at 0).
        #[arg(long, value_delimiter = ',', num_args = 1, value_parser = parse_um, allow_hyphen_values = true)]
        center: Option<Vec<f64>>,
    },
}

/// `--center x,y` (two positions), or `default`.
fn center_of(center: &Option<Vec<f64>>, default: [f64; 2]) -> Result<[f32; 2]> {
    match center.as_deref() {
        None => Ok(default.map(f32_of)),
        Some(&[x, y]) => Ok([f32_of(x), f32_of(y)]),
        Some(v) => bail!("--center takes two positions x,y, got {}", v.len()),
    }
}

#[derive(clap::Args, Debug)]
pub struct WaveArgs {
    /// Amplitude (`5um`, `500nm`; bare numbers in um).
    #[arg(value_parser = parse_um)]
    pub amplitude: f64,
    /// Frequency (`100Hz`, `1kHz`; bare numbers in Hz).
    #[arg(value_parser = parse_hz)]
    pub freq: f64,
    /// Centre position.
    #[arg(long, default_value = "0um", value_parser = parse_um, allow_hyphen_values = true)]
    pub offset: f64,
}

#[derive(clap::Args, Debug)]
pub struct TableArgs {
    /// Frequency of one pass through the points (`10Hz`).
    #[arg(long, value_parser = parse_hz)]
    pub freq: f64,
    /// Points, comma separated (`0,20,5um,15`; bare numbers in um).
    #[arg(
        long,
        value_delimiter = ',',
        value_parser = parse_um,
        allow_hyphen_values = true,
        required_unless_present = "file"
    )]
    pub points: Vec<f64>,
    /// File of points: numbers separated by commas, spaces or newlines, `#` comments.
    #[arg(long, conflicts_with = "points")]
    pub file: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// Signals, comma separated (ref_um, y_um, error_um, ff_volts, u_volts, adc_code,
    /// dac_code; axis 1 of an XY build: ref1_um, y1_um, error1_um, ff1_volts, u1_volts,
    /// adc1_code, dac1_code); the firmware records 4 channels, unnamed ones keep their
    /// signal.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "ref_um,y_um,u_volts,error_um"
    )]
    pub signals: Vec<String>,
    /// Both axes of an XY build: the signals ref_um,y_um,ref1_um,y1_um (the SVG gets an
    /// x-y panel of reference and measured path).
    #[arg(long, conflicts_with = "signals")]
    pub xy: bool,
    /// Record every N-th control period (1 to 1000): the 1024 frames span N times longer
    /// (`--every 20` at 100 kHz: 205 ms, a whole XY scan).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub every: u32,
    /// `now`, or `rise|fall|level:<signal>:<level>` (level in the signal's unit).
    #[arg(long, default_value = "now")]
    pub trigger: String,
    /// Frames kept before the trigger.
    #[arg(long, default_value_t = 0)]
    pub pre: usize,
    /// Longest wait for the trigger, in seconds of the firmware's own time (control periods
    /// it reports in `stats`, so an emulator running slower than real time gets the same
    /// budget); the capture's own length is added.
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    pub wait_s: f64,
    /// Wall-clock cap on the whole wait, in seconds: only for a firmware that stopped
    /// running or a dead link (the firmware's time above is what bounds a normal wait).
    #[arg(long, default_value_t = 600.0, value_name = "S")]
    pub wall_cap_s: f64,
    /// Read the finished capture without arming a new one (--signals then only names the
    /// columns, in the order the capture was selected).
    #[arg(long)]
    pub no_arm: bool,
    /// CSV file: `i,t_s,<signal>...`, `#` lines say what and the units.
    #[arg(long)]
    pub out: PathBuf,
    /// SVG plot of every channel against time.
    #[arg(long)]
    pub svg: Option<PathBuf>,
}

/// Opens the link of `conn` and syncs (unless --no-sync).
pub fn connect(conn: &Conn) -> Result<Client> {
    if !(conn.timeout_s.is_finite() && conn.timeout_s > 0.0 && conn.timeout_s <= 3600.0) {
        bail!(
            "--timeout-s must be in (0, 3600] seconds, got {}",
            conn.timeout_s
        );
    }
    let timeout = Duration::from_secs_f64(conn.timeout_s);
    let link: Box<dyn Link> = match (&conn.port, &conn.tcp) {
        (Some(p), None) => open_serial(p, conn.baud, timeout)?,
        (None, Some(a)) => Box::new(connect_tcp(a, timeout)?),
        _ => bail!("say where the firmware is: --port <device> or --tcp <host:port>"),
    };
    let mut client = Client::new(link, timeout);
    if !conn.no_sync {
        client.sync().context("no answer to ping")?;
    }
    Ok(client)
}

pub fn run(args: Args) -> Result<()> {
    let action = match (args.action, args.lines.is_empty()) {
        (Some(a), true) => a,
        (None, false) => Action::Send { lines: args.lines },
        (Some(_), false) => bail!("give either a subcommand or raw lines after --, not both"),
        (None, true) => {
            bail!("nothing to send: give a subcommand (see --help) or raw lines after --")
        }
    };
    let mut c = connect(&args.conn)?;
    let out = &mut io::stdout().lock();
    execute(&mut c, action, args.conn.keep_going, out)
}

/// Runs one action on a connected client, printing to `out`.
pub fn execute(
    c: &mut Client,
    action: Action,
    keep_going: bool,
    out: &mut impl Write,
) -> Result<()> {
    match action {
        Action::Send { lines } => {
            let mut failed = 0;
            for l in &lines {
                match c.raw(l) {
                    Ok(r) => {
                        for d in &r.data {
                            writeln!(out, "{d}")?;
                        }
                        writeln!(out, "{}", r.reply_line())?;
                    }
                    Err(e @ SerialError::Firmware { .. }) if keep_going => {
                        writeln!(out, "{}", firmware_line(&e))?;
                        eprintln!("error: {e}");
                        failed += 1;
                    }
                    Err(e) => return Err(e.into()),
                }
            }
            if failed > 0 {
                bail!("{failed} of {} commands failed", lines.len());
            }
        }
        Action::Ping => {
            let t = Instant::now();
            let r = c.send(&Command::Ping)?;
            writeln!(
                out,
                "{} ({:.1} ms round trip)",
                r.reply_line(),
                t.elapsed().as_secs_f64() * 1e3
            )?;
        }
        Action::Commands => writeln!(out, "{}", c.send(&Command::Help)?.reply_line())?,
        Action::Bench => {
            let r = c.send(&Command::Bench)?;
            for d in &r.data {
                writeln!(out, "{d}")?;
            }
            writeln!(out, "{}", r.reply_line())?;
        }
        Action::Mode { law, ff } => {
            if let Some(ff) = ff {
                let r = c.send(&Command::Feedforward(&ff))?;
                writeln!(out, "{}", r.reply_line())?;
            }
            let r = c.send(&Command::Mode(&law))?;
            writeln!(out, "{}", r.reply_line())?;
        }
        Action::Limits { u_min, u_max, slew } => {
            // Widen before narrowing so the firmware's u_min < u_max check holds in between.
            let mut sets = Vec::new();
            if let Some(v) = u_max {
                sets.push(("u_max", v));
            }
            if let Some(v) = u_min {
                sets.push(("u_min", v));
            }
            if let (Some(_), Some(hi)) = (u_min, u_max) {
                // A new maximum at or below the present minimum needs the minimum first.
                if hi <= get_param(c, "u_min")? {
                    sets.reverse();
                }
            }
            if let Some(v) = slew {
                sets.push(("slew", v));
            }
            for (p, v) in sets {
                c.send(&Command::Set(p, f32_of(v)))?;
            }
            let lo = get_param(c, "u_min")?;
            let hi = get_param(c, "u_max")?;
            let sl = get_param(c, "slew")?;
            writeln!(
                out,
                "output {lo} V .. {hi} V, slew limit {sl} V/s ({} V/ms)",
                sl / 1e3
            )?;
        }
        Action::Wave(w) => {
            let (shape, a) = match w {
                WaveCmd::Sine(a) => (Shape::Sine, a),
                WaveCmd::Triangle(a) => (Shape::Triangle, a),
                WaveCmd::Square(a) => (Shape::Square, a),
                WaveCmd::Hold { position } => {
                    let r = c.send(&Command::WaveHold(f32_of(position)))?;
                    writeln!(out, "{}", r.reply_line())?;
                    return Ok(());
                }
                WaveCmd::Off => {
                    let r = c.send(&Command::WaveOff)?;
                    writeln!(out, "{}", r.reply_line())?;
                    return Ok(());
                }
                WaveCmd::Raster {
                    x_span,
                    y_span,
                    lines,
                    line_freq,
                    center,
                } => {
                    let center_um = center_of(&center, [x_span / 2.0, y_span / 2.0])?;
                    let r = c.send(&Command::WaveRaster {
                        span_um: [f32_of(x_span), f32_of(y_span)],
                        lines,
                        line_hz: f32_of(line_freq),
                        center_um,
                    })?;
                    writeln!(out, "{}", r.reply_line())?;
                    return Ok(());
                }
                WaveCmd::Lissajous {
                    x_amp,
                    y_amp,
                    fx,
                    fy,
                    phase,
                    center,
                } => {
                    let center_um = center_of(&center, [x_amp, y_amp])?;
                    let r = c.send(&Command::WaveLissajous {
                        amp_um: [f32_of(x_amp), f32_of(y_amp)],
                        freq_hz: [f32_of(fx), f32_of(fy)],
                        phase_deg: f32_of(phase),
                        center_um,
                    })?;
                    writeln!(out, "{}", r.reply_line())?;
                    return Ok(());
                }
                WaveCmd::Steps {
                    low,
                    high,
                    levels,
                    freq,
                } => {
                    let r = c.send(&Command::WaveSteps {
                        low_um: f32_of(low),
                        high_um: f32_of(high),
                        levels,
                        freq_hz: f32_of(freq),
                    })?;
                    writeln!(out, "{}", r.reply_line())?;
                    return Ok(());
                }
                WaveCmd::Table(t) => {
                    let points = match &t.file {
                        Some(f) => read_points(f)?,
                        None => t.points.clone(),
                    };
                    let points: Vec<f32> = points.into_iter().map(f32_of).collect();
                    // Every line is built and checked before the first is sent.
                    let lines = table_lines(&points)?;
                    c.send(&Command::TableClear)?;
                    let mut last = None;
                    for l in &lines {
                        last = Some(c.raw(l)?);
                    }
                    if let Some(r) = last {
                        writeln!(out, "{}", r.reply_line())?;
                    }
                    let r = c.send(&Command::WaveTable(f32_of(t.freq)))?;
                    writeln!(out, "{}", r.reply_line())?;
                    return Ok(());
                }
            };
            let r = c.send(&Command::Wave {
                shape,
                amp_um: f32_of(a.amplitude),
                freq_hz: f32_of(a.freq),
                offset_um: f32_of(a.offset),
            })?;
            writeln!(out, "{}", r.reply_line())?;
        }
        Action::Axis { axis } => {
            let r = c.send(&Command::Axis(axis))?;
            writeln!(out, "{}", r.reply_line())?;
        }
        Action::Params => print_params(c, out)?,
        Action::LoadFit { fit } => {
            let m = read_fit_cbw(&fit)?;
            let [d, alpha, beta, gamma] = m.params;
            writeln!(
                out,
                "{}: CBW of parts[{}]: d {d} um/V, alpha {alpha} um/V, beta {beta} 1/V, gamma {gamma} 1/V",
                fit.display(),
                m.part
            )?;
            let r = c
                .send(&Command::Cbw(m.params.map(f32_of)))
                .map_err(|e| match e {
                    e @ SerialError::Firmware { .. } => anyhow!(
                        "{}: the firmware refused the CBW model of parts[{}]: {e} (the core \
                     accepts alpha > 0, beta >= |gamma| (004 eq. 3) and, for IMS, d above \
                     the largest hysteresis slope over 0..150 V, alpha + (beta - gamma) * \
                     min(alpha/(beta + gamma), alpha * 150 V))",
                        fit.display(),
                        m.part
                    ),
                    other => other.into(),
                })?;
            writeln!(out, "{}", r.reply_line())?;
            if m.offset_um != 0.0 {
                writeln!(
                    out,
                    "note: the fit's output offset {} um is not sent (the firmware's CBW has \
                     none; the sensor reads the stage's own zero)",
                    m.offset_um
                )?;
            }
        }
        Action::Status => status(c, out)?,
        Action::Stats { reset, clock } => {
            print_stats(out, &read_stats(c)?, clock)?;
            if reset {
                c.send(&Command::StatsReset)?;
                writeln!(out, "counters reset")?;
            }
        }
        Action::Record(a) => {
            let rec = record(c, &a)?;
            rec.write_csv(&a.out)?;
            if let Some(svg) = &a.svg {
                rec.write_svg(svg)?;
            }
            rec.summary(out)?;
            writeln!(out, "wrote {}", a.out.display())?;
            if let Some(svg) = &a.svg {
                writeln!(out, "wrote {}", svg.display())?;
            }
        }
    }
    Ok(())
}

/// The `err ...` line of a firmware error, as the firmware sent it.
fn firmware_line(e: &SerialError) -> String {
    match e {
        SerialError::Firmware { code, message, .. } => match code {
            Some(c) => format!("err {c} {message}"),
            None => format!("err {message}"),
        },
        other => other.to_string(),
    }
}

fn get_param(c: &mut Client, name: &str) -> Result<f64> {
    let r = c.send(&Command::Get(name))?;
    parse_get(&r, name).map_err(|why| {
        SerialError::BadReply {
            command: format!("get {name}"),
            line: r.reply_line(),
            why,
        }
        .into()
    })
}

fn print_stats(out: &mut impl Write, s: &Stats, clock_hz: Option<f64>) -> Result<()> {
    let us = |n: u32| match clock_hz {
        Some(f) if f > 0.0 => format!(" ({:.3} us)", n as f64 / f * 1e6),
        _ => String::new(),
    };
    writeln!(
        out,
        "control step    min {}{} max {}{} last {}{}",
        s.step_min,
        us(s.step_min),
        s.step_max,
        us(s.step_max),
        s.step_last,
        us(s.step_last)
    )?;
    writeln!(
        out,
        "interrupt       min {}{} max {}{} last {}{}",
        s.isr_min,
        us(s.isr_min),
        s.isr_max,
        us(s.isr_max),
        s.isr_last,
        us(s.isr_last)
    )?;
    writeln!(out, "samples {}  overruns {}", s.samples, s.overruns)?;
    Ok(())
}

/// `stats`, parsed; a reply that does not parse is an error naming it.
fn read_stats(c: &mut Client) -> Result<Stats> {
    let r = c.send(&Command::Stats)?;
    parse_stats(&r.details)
        .map_err(|why| SerialError::BadReply {
            command: "stats".into(),
            line: r.reply_line(),
            why,
        })
        .map_err(Into::into)
}

fn status(c: &mut Client, out: &mut impl Write) -> Result<()> {
    let t = Instant::now();
    c.send(&Command::Ping)?;
    writeln!(
        out,
        "link            ok ({:.1} ms round trip)",
        t.elapsed().as_secs_f64() * 1e3
    )?;
    print_params(c, out)?;
    print_stats(out, &read_stats(c)?, None)?;
    let r = c.send(&Command::Rec(RecCmd::Status))?;
    let (state, n) = parse_rec_status(&r.details).map_err(|why| SerialError::BadReply {
        command: "rec status".into(),
        line: r.reply_line(),
        why,
    })?;
    writeln!(out, "recorder        {state}, {n} frames")?;
    Ok(())
}

/// Every parameter with its value; the list comes from the firmware (`help` ends with
/// `params: <names>`).
fn print_params(c: &mut Client, out: &mut impl Write) -> Result<()> {
    let help = c.send(&Command::Help)?;
    let params: Vec<String> = help
        .details
        .split_once("params:")
        .map(|(_, p)| p.split_whitespace().map(str::to_string).collect())
        .unwrap_or_default();
    if params.is_empty() {
        bail!(
            "`help` lists no parameters: {:?} (expected `... params: <names>`)",
            help.reply_line()
        );
    }
    for p in &params {
        let v = get_param(c, p)?;
        writeln!(out, "{p:<15} {v}")?;
    }
    Ok(())
}

/// The CBW model of a `piezo fit` report, in the firmware's units.
#[derive(Debug, Clone, PartialEq)]
pub struct FitCbw {
    /// Index into the report's `parts`.
    pub part: usize,
    /// `d`, `alpha` (um/V), `beta`, `gamma` (1/V).
    pub params: [f64; 4],
    /// The fit's output offset (um), which the firmware's model does not have.
    pub offset_um: f64,
}

/// Reads the first CBW part (`siso` or `direct`) of the `fit.json` that `piezo fit --model
/// cbw` writes; the fit's `gamma/beta` becomes `gamma`. Errors name the file and the key.
pub fn read_fit_cbw(path: &std::path::Path) -> Result<FitCbw> {
    let p = path.display();
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {p}"))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{p}: not JSON (expected the fit.json of `piezo fit`)"))?;
    let parts = v
        .get("parts")
        .and_then(|x| x.as_array())
        .with_context(|| format!("{p}: no `parts` array (not a `piezo fit` report)"))?;
    let mut models = Vec::new();
    for (i, part) in parts.iter().enumerate() {
        let model = part
            .pointer("/fit/model")
            .and_then(|m| m.as_str())
            .with_context(|| format!("{p}: parts[{i}] has no `fit.model`"))?;
        let kind = part.get("kind").and_then(|k| k.as_str()).unwrap_or("siso");
        if model == "cbw" && kind != "coupling" {
            return cbw_of_part(path, i, part);
        }
        models.push(format!("{model} ({kind})"));
    }
    bail!(
        "{p}: no CBW fit in `parts` (found: {}); identify one with `piezo fit --model cbw`",
        if models.is_empty() {
            "none".to_string()
        } else {
            models.join(", ")
        }
    )
}

fn cbw_of_part(path: &std::path::Path, i: usize, part: &serde_json::Value) -> Result<FitCbw> {
    let p = path.display();
    let params = part
        .pointer("/fit/params")
        .and_then(|x| x.as_array())
        .with_context(|| format!("{p}: parts[{i}].fit.params is missing or not a list"))?;
    let key = |name: &str| -> Result<f64> {
        let v = params
            .iter()
            .find(|kv| kv.get(0).and_then(|k| k.as_str()) == Some(name))
            .with_context(|| format!("{p}: parts[{i}].fit.params lacks `{name}`"))?;
        v.get(1)
            .and_then(|x| x.as_f64())
            .filter(|x| x.is_finite())
            .with_context(|| format!("{p}: parts[{i}].fit.params `{name}` is not a finite number"))
    };
    let num = |ptr: &str, default: f64| -> Result<f64> {
        match part.pointer(ptr) {
            None => Ok(default),
            Some(x) => x.as_f64().filter(|x| x.is_finite()).with_context(|| {
                format!(
                    "{p}: parts[{i}]{} is not a finite number",
                    ptr.replace('/', ".")
                )
            }),
        }
    };
    let sign = num("/fit/sign", 1.0)?;
    if sign != 1.0 {
        bail!(
            "{p}: parts[{i}].fit.sign is {sign}: the fit mirrors the model (y falls as u rises); \
             the firmware's CBW needs y rising with u"
        );
    }
    let beta = key("beta")?;
    Ok(FitCbw {
        part: i,
        params: [key("d")?, key("alpha")?, beta, key("gamma/beta")? * beta],
        offset_um: num("/fit/offset", 0.0)?,
    })
}

/// The signals of `record --xy`: reference and position of both axes.
pub const XY_SIGNALS: [&str; 4] = ["ref_um", "y_um", "ref1_um", "y1_um"];

/// A finished capture.
#[derive(Debug, Clone)]
pub struct Recording {
    pub channels: Vec<String>,
    /// Frames per second (the control rate over the recorder's divider).
    pub sample_hz: f64,
    /// Frames before the trigger (time 0 is frame `pre`).
    pub pre: usize,
    pub trigger: String,
    /// Frames, oldest first.
    pub frames: Vec<Vec<f64>>,
}

impl Recording {
    pub fn t_s(&self, i: usize) -> f64 {
        (i as f64 - self.pre as f64) / self.sample_hz
    }

    pub fn write_csv(&self, path: &std::path::Path) -> Result<()> {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# piezo serial record: {} frames at {} Hz, trigger {}, {} frames before it (t_s = 0 at the trigger)",
            self.frames.len(),
            self.sample_hz,
            self.trigger,
            self.pre
        );
        let units: Vec<String> = self
            .channels
            .iter()
            .map(|n| format!("{n} [{}]", name_unit(n)))
            .collect();
        let _ = writeln!(s, "# units: i [frame], t_s [s], {}", units.join(", "));
        let _ = writeln!(s, "i,t_s,{}", self.channels.join(","));
        for (i, f) in self.frames.iter().enumerate() {
            let _ = write!(s, "{i},{:e}", self.t_s(i));
            for v in f {
                let _ = write!(s, ",{v}");
            }
            s.push('\n');
        }
        if let Some(dir) = path.parent() {
            if !dir.as_os_str().is_empty() {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
            }
        }
        std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
    }

    /// One panel per unit (positions together, voltages together, codes together).
    pub fn write_svg(&self, path: &std::path::Path) -> Result<()> {
        let t_ms: Vec<f64> = (0..self.frames.len()).map(|i| self.t_s(i) * 1e3).collect();
        let mut plots = Vec::new();
        let mut seen = Vec::new();
        for u in self.channels.iter().map(|n| name_unit(n)) {
            if seen.contains(&u) {
                continue;
            }
            seen.push(u);
            let mut p = Plot::new(
                &format!("recorder, trigger {}", self.trigger),
                "t [ms]",
                &format!("[{u}]"),
            );
            for (k, name) in self.channels.iter().enumerate() {
                if name_unit(name) == u {
                    let y: Vec<f64> = self
                        .frames
                        .iter()
                        .map(|f| f.get(k).copied().unwrap_or(f64::NAN))
                        .collect();
                    p = p.line(name, &t_ms, &y);
                }
            }
            plots.push(p);
        }
        // Both axes' reference and position: the path in the x-y plane.
        if let [Some(rx), Some(x), Some(ry), Some(y)] = XY_SIGNALS.map(|n| self.column(n)) {
            plots.push(
                Plot::new(
                    &format!("x-y path, trigger {}", self.trigger),
                    "x [um]",
                    "y [um]",
                )
                .line("reference (ref_um, ref1_um)", &rx, &ry)
                .line("measured (y_um, y1_um)", &x, &y),
            );
        }
        write_grid(path, &plots, 1).with_context(|| format!("writing {}", path.display()))
    }

    /// The values of channel `name`, if it was recorded.
    pub fn column(&self, name: &str) -> Option<Vec<f64>> {
        let k = self.channels.iter().position(|c| c == name)?;
        Some(
            self.frames
                .iter()
                .map(|f| f.get(k).copied().unwrap_or(f64::NAN))
                .collect(),
        )
    }

    /// RMS of reference minus position per axis whose pair was recorded (axis, um).
    pub fn tracking_rms(&self) -> Vec<(usize, f64)> {
        [("ref_um", "y_um"), ("ref1_um", "y1_um")]
            .iter()
            .enumerate()
            .filter_map(|(axis, (r, y))| {
                let (r, y) = (self.column(r)?, self.column(y)?);
                let n = r.len().max(1) as f64;
                let e2: f64 = r.iter().zip(&y).map(|(r, y)| (r - y) * (r - y)).sum();
                Some((axis, (e2 / n).sqrt()))
            })
            .collect()
    }

    /// Min/mean/max per channel.
    pub fn summary(&self, out: &mut impl Write) -> Result<()> {
        writeln!(
            out,
            "recorded {} frames at {} Hz ({:.3} ms), trigger {}",
            self.frames.len(),
            self.sample_hz,
            self.frames.len() as f64 / self.sample_hz * 1e3,
            self.trigger
        )?;
        for (k, name) in self.channels.iter().enumerate() {
            let v: Vec<f64> = self
                .frames
                .iter()
                .filter_map(|f| f.get(k).copied())
                .collect();
            let (lo, hi) = v
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
            writeln!(
                out,
                "  {name:<10} min {lo:>12.5} mean {mean:>12.5} max {hi:>12.5} {}",
                name_unit(name)
            )?;
        }
        for (axis, rms) in self.tracking_rms() {
            writeln!(out, "  tracking error axis {axis}: {rms:.5} um RMS")?;
        }
        Ok(())
    }
}

/// Parses `--trigger`: `now` or `rise|fall|level:<signal or channel>:<level>`, with the
/// channel index resolved against the selected `channels`.
pub fn parse_trigger(spec: &str, channels: &[String], pre: usize) -> Result<TriggerCmd> {
    if spec == "now" {
        if pre != 0 {
            bail!("--pre needs an edge trigger (rise|fall|level:<signal>:<level>), not `now`");
        }
        return Ok(TriggerCmd::Now);
    }
    let parts: Vec<&str> = spec.split(':').collect();
    let [kind, ch, level] = parts.as_slice() else {
        bail!("--trigger `{spec}`: use now or rise|fall|level:<signal>:<level>");
    };
    let channel = match channels.iter().position(|n| n == ch) {
        Some(i) => i,
        None => match ch.parse::<usize>() {
            Ok(i) if i < channels.len() => i,
            _ => bail!(
                "--trigger `{spec}`: `{ch}` is not a recorded channel ({})",
                channels.join(", ")
            ),
        },
    };
    let level: f32 = command::parse_f32(level)
        .map_err(|_| anyhow!("--trigger `{spec}`: level `{level}` is not a finite number"))?;
    Ok(match *kind {
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
        _ => bail!("--trigger `{spec}`: `{kind}` is not rise, fall or level"),
    })
}

/// Selects, triggers, arms, waits for the capture and reads it.
pub fn record(c: &mut Client, a: &RecordArgs) -> Result<Recording> {
    if !(a.wait_s.is_finite() && a.wait_s > 0.0) {
        bail!("--wait-s must be positive, got {}", a.wait_s);
    }
    if !(a.wall_cap_s.is_finite() && a.wall_cap_s > 0.0) {
        bail!("--wall-cap-s must be positive, got {}", a.wall_cap_s);
    }
    let sample_hz = get_param(c, "sample_hz")?;
    if !(sample_hz.is_finite() && sample_hz > 0.0) {
        bail!("the firmware reports sample_hz {sample_hz}");
    }
    let (channels, trigger, pre) = if a.no_arm {
        let (state, n) = rec_status(c)?;
        if state != "done" || n == 0 {
            bail!("--no-arm: the recorder holds no finished capture (it is {state})");
        }
        let names: Vec<String> = a.signals.iter().map(|s| s.trim().to_string()).collect();
        (names, "unknown (--no-arm)".to_string(), a.pre)
    } else {
        let mut signals = Vec::new();
        let names = if a.xy {
            XY_SIGNALS.map(String::from).to_vec()
        } else {
            a.signals.clone()
        };
        for name in &names {
            let s = Signal::from_name(name.trim()).ok_or_else(|| {
                anyhow!(
                    "--signals: unknown signal `{name}`; one of {}",
                    Signal::ALL.map(|s| s.name()).join(", ")
                )
            })?;
            signals.push(s);
        }
        // A capture left armed (an interrupted session) would refuse the new selection.
        c.send(&Command::Rec(RecCmd::Stop))?;
        let line = select_line(&signals)?;
        let r = c.raw(&line)?;
        let channels = parse_rec_sel(&r.details).map_err(|why| SerialError::BadReply {
            command: line.clone(),
            line: r.reply_line(),
            why,
        })?;
        let trig = parse_trigger(&a.trigger, &channels, a.pre)?;
        c.send(&Command::Rec(RecCmd::Trigger(trig)))?;
        c.send(&Command::Rec(RecCmd::Divider(Some(a.every as usize))))?;
        c.send(&Command::Rec(RecCmd::Arm))?;
        (channels, a.trigger.clone(), a.pre)
    };
    // Frames per second: the control rate over the divider the capture ran with.
    let div = rec_divider(c)?;
    let n = wait_for_capture(c, a, sample_hz)?;
    let sample_hz = sample_hz / div as f64;
    let mut frames = Vec::with_capacity(n);
    // Values per frame: the selected channels, or what the first frame has (--no-arm).
    let mut width = (!a.no_arm).then_some(channels.len());
    while frames.len() < n {
        let start = frames.len();
        let count = READ_CHUNK.min(n - start);
        let cmd = Command::Rec(RecCmd::Read { start, count });
        let line = checked_line(&cmd)?;
        let r = c.send(&cmd)?;
        let bad = |l: &str, why: String| SerialError::BadReply {
            command: line.clone(),
            line: l.to_string(),
            why,
        };
        if r.data.len() != count {
            return Err(bad(
                &r.reply_line(),
                format!("{} frame lines, asked for {count}", r.data.len()),
            )
            .into());
        }
        if r.details != format!("rec read {count}") {
            return Err(bad(&r.reply_line(), format!("expected `ok rec read {count}`")).into());
        }
        for (k, l) in r.data.iter().enumerate() {
            let (i, v) = parse_frame(l, width).map_err(|why| bad(l, why))?;
            width = Some(v.len());
            if i != start + k {
                return Err(bad(l, format!("frame {i}, expected {}", start + k)).into());
            }
            frames.push(v);
        }
    }
    let mut channels = channels;
    if let Some(first) = frames.first() {
        // --no-arm without enough names: number the rest.
        while channels.len() < first.len() {
            channels.push(format!("ch{}", channels.len()));
        }
    }
    Ok(Recording {
        channels,
        sample_hz,
        pre,
        trigger,
        frames,
    })
}

/// The recorder's divider (`rec div` -> `ok rec div <n>`).
fn rec_divider(c: &mut Client) -> Result<u32> {
    let r = c.send(&Command::Rec(RecCmd::Divider(None)))?;
    r.details
        .strip_prefix("rec div ")
        .and_then(|n| n.parse::<u32>().ok())
        .filter(|n| *n >= 1)
        .ok_or_else(|| {
            SerialError::BadReply {
                command: "rec div".into(),
                line: r.reply_line(),
                why: "expected `ok rec div <n>`, n >= 1".into(),
            }
            .into()
        })
}

/// Waits until the recorder is done; returns its frame count. The wait is bounded by the
/// firmware's progress, counted in the control periods it reports (`stats`, `samples`):
/// `--wait-s` of its time may pass with the capture still armed (no trigger) or with no
/// new frame once triggered. Under an emulator that runs slower than real time the
/// firmware's time runs slower too, so a busy host cannot fail a healthy capture;
/// `--wall-cap-s` only ends a wait on a firmware whose loop stopped or a dead link.
fn wait_for_capture(c: &mut Client, a: &RecordArgs, sample_hz: f64) -> Result<usize> {
    let budget = a.wait_s * sample_hz;
    let wall_deadline = Instant::now() + Duration::from_secs_f64(a.wall_cap_s);
    let mut last = read_stats(c)?.samples;
    let mut progress = (String::new(), 0);
    // Control periods since the last progress (a state change or a new frame).
    let mut idle = 0.0f64;
    loop {
        let (state, n) = rec_status(c)?;
        if state == "done" {
            return Ok(n);
        }
        if state == "idle" {
            bail!("the recorder went idle without a capture (stopped by someone else?)");
        }
        // `stats reset` (by anyone) restarts the count: periods are summed across it.
        let now = read_stats(c)?.samples;
        let ran = if now >= last { now - last } else { now } as f64;
        last = now;
        if (state.as_str(), n) != (progress.0.as_str(), progress.1) {
            progress = (state, n);
            idle = 0.0;
            continue;
        }
        idle += ran;
        if idle >= budget {
            bail!(
                "the recorder is still {state} after {} s (trigger `{}` never fired?): \
                 {idle} control periods of the firmware's time without progress ({n} frames)",
                a.wait_s,
                a.trigger,
            );
        }
        if Instant::now() >= wall_deadline {
            bail!(
                "the recorder is still {state} after {} s of wall-clock time (--wall-cap-s) \
                 with {n} frames; the firmware ran {idle} control periods since its last \
                 progress (is its control loop running?)",
                a.wall_cap_s
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn rec_status(c: &mut Client) -> Result<(String, usize)> {
    let r = c.send(&Command::Rec(RecCmd::Status))?;
    parse_rec_status(&r.details).map_err(|why| {
        SerialError::BadReply {
            command: "rec status".into(),
            line: r.reply_line(),
            why,
        }
        .into()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::sync::{Arc, Mutex};

    /// A link that answers from a script: each written line is looked up in `replies`.
    struct Scripted {
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

    fn client(replies: &[(&str, &[u8])], pre: &[u8], closed: bool) -> Client {
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

    #[derive(clap::Parser, Debug)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    #[test]
    fn cli_definition_is_valid_and_parses_units() {
        use clap::{CommandFactory, Parser};
        Cli::command().debug_assert();
        let a = Cli::try_parse_from([
            "serial",
            "--tcp",
            "127.0.0.1:1",
            "wave",
            "sine",
            "5um",
            "0.1kHz",
            "--offset",
            "-2um",
        ])
        .unwrap()
        .args;
        match a.action {
            Some(Action::Wave(WaveCmd::Sine(w))) => {
                assert_eq!((w.amplitude, w.freq, w.offset), (5.0, 100.0, -2.0))
            }
            other => panic!("{other:?}"),
        }
        let a = Cli::try_parse_from(["serial", "--tcp", "h:1", "--", "mode pid", "stats"])
            .unwrap()
            .args;
        assert_eq!(a.lines, vec!["mode pid", "stats"]);
        assert!(a.action.is_none());
        let e = Cli::try_parse_from(["serial", "limits", "--slew", "5 parsecs"]).unwrap_err();
        assert!(e.to_string().contains("unknown unit"), "{e}");
        let a = Cli::try_parse_from(["serial", "wave", "steps", "-1um", "2um", "5", "3Hz"])
            .unwrap()
            .args;
        match a.action {
            Some(Action::Wave(WaveCmd::Steps {
                low,
                high,
                levels,
                freq,
            })) => assert_eq!((low, high, levels, freq), (-1.0, 2.0, 5, 3.0)),
            other => panic!("{other:?}"),
        }
        assert!(Cli::try_parse_from(["serial", "wave", "steps", "1", "2", "65", "3"]).is_err());
        let a = Cli::try_parse_from([
            "serial",
            "wave",
            "table",
            "--freq",
            "10Hz",
            "--points",
            "-1,2um,300nm",
        ])
        .unwrap()
        .args;
        match a.action {
            Some(Action::Wave(WaveCmd::Table(t))) => {
                assert_eq!(
                    (t.freq, t.points, t.file),
                    (10.0, vec![-1.0, 2.0, 0.3], None)
                )
            }
            other => panic!("{other:?}"),
        }
        // One source of points, exactly.
        assert!(Cli::try_parse_from(["serial", "wave", "table", "--freq", "1"]).is_err());
        assert!(Cli::try_parse_from([
            "serial", "wave", "table", "--freq", "1", "--points", "1,2", "--file", "p.csv"
        ])
        .is_err());
    }

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
        for e in ERRORS {
            assert_eq!(known_error(e.code()), Some(e));
        }
    }

    #[test]
    fn typed_replies_parse_and_refuse_garbage() {
        let s = parse_stats("step 10 20 15 isr 30 40 35 samples 1000 overruns 2").unwrap();
        assert_eq!((s.step_max, s.isr_last, s.overruns), (20, 35, 2));
        assert!(parse_stats("step 10 20 isr 30 40 35 samples 1000 overruns 2").is_err());
        assert!(parse_stats("step a 20 15 isr 30 40 35 samples 1000 overruns 2").is_err());
        assert!(parse_stats("").is_err());
        assert_eq!(
            parse_rec_status("rec done 1024").unwrap(),
            ("done".to_string(), 1024)
        );
        assert!(parse_rec_status("rec sleeping 3").is_err());
        assert!(parse_rec_status("rec done -1").is_err());
        assert_eq!(
            parse_rec_sel("rec sel ref_um y_um").unwrap(),
            vec!["ref_um".to_string(), "y_um".to_string()]
        );
        assert!(parse_rec_sel("rec sel").is_err());
        assert_eq!(
            parse_frame("3 1.5 -2 inf 4", Some(4)).unwrap(),
            (3, vec![1.5, -2.0, f64::INFINITY, 4.0])
        );
        assert!(parse_frame("3 1.5 -2 4", Some(4)).is_err());
        assert!(parse_frame("x 1 2 3 4", None).is_err());
        assert!(parse_frame("3 1 2 3 zz", Some(4)).is_err());
        let r = Response {
            data: vec![],
            details: "u_max 150".into(),
        };
        assert_eq!(parse_get(&r, "u_max"), Ok(150.0));
        assert!(parse_get(&r, "u_min").is_err());
    }

    #[test]
    fn units_scale_and_unknown_units_fail() {
        assert_eq!(parse_um("5"), Ok(5.0));
        assert_eq!(parse_um("5um"), Ok(5.0));
        assert_eq!(parse_um("-2.5 um"), Ok(-2.5));
        assert!((parse_um("300nm").unwrap() - 0.3).abs() < 1e-12);
        assert_eq!(parse_um("0.1mm"), Ok(100.0));
        assert_eq!(parse_um("1e1um"), Ok(10.0));
        assert_eq!(parse_hz("2kHz"), Ok(2000.0));
        assert_eq!(parse_volts_per_s("20V/ms"), Ok(20_000.0));
        assert_eq!(parse_volts("120V"), Ok(120.0));
        let e = parse_um("5 furlong").unwrap_err();
        assert!(e.contains("unknown unit `furlong`"), "{e}");
        assert!(parse_hz("fast").is_err());
        assert!(parse_hz("1e60Hz").is_err());
        assert!(parse_volts("nan").is_err());
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

    #[test]
    fn built_lines_are_checked_by_the_firmware_parser() {
        assert_eq!(
            checked_line(&Command::Wave {
                shape: Shape::Sine,
                amp_um: 5.0,
                freq_hz: 100.0,
                offset_um: 10.0
            })
            .unwrap(),
            "wave sine 5 100 10"
        );
        // A negative amplitude is refused on the host with the protocol's own error.
        let e = checked_line(&Command::Wave {
            shape: Shape::Sine,
            amp_um: -5.0,
            freq_hz: 100.0,
            offset_um: 10.0,
        })
        .unwrap_err();
        assert!(e.to_string().contains("err 8"), "{e}");
        // Too long for the firmware's line buffer.
        let e = checked_line(&Command::Wave {
            shape: Shape::Triangle,
            amp_um: 3.0e38,
            freq_hz: 3.0e38,
            offset_um: -3.0e38,
        })
        .unwrap_err();
        assert!(e.to_string().contains("at most 96"), "{e}");
        assert_eq!(
            select_line(&[Signal::RefUm, Signal::UVolts]).unwrap(),
            "rec sel ref_um u_volts"
        );
        assert!(select_line(&[]).is_err());
    }

    #[test]
    fn table_lines_refuse_bad_counts_and_pack_lines() {
        assert!(table_lines(&[1.0]).is_err());
        assert!(table_lines(&[0.0; TABLE_LEN + 1]).is_err());
        let lines = table_lines(&[1.0; 20]).unwrap();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[0], "table add 1 1 1 1 1 1 1 1");
        assert_eq!(lines[2], "table add 1 1 1 1");
        // Long numbers: the line length limits a line before the word count does.
        let long = [-1.2345678e-12f32; 8];
        let lines = table_lines(&long).unwrap();
        assert!(lines.len() > 1, "{lines:?}");
        assert!(lines.iter().all(|l| l.len() <= MAX_LINE));
        let dir = std::env::temp_dir().join(format!("piezo-points-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("points.csv");
        std::fs::write(&f, "# um\n0, 20\n5um 1.5e1\n\n300nm # last\n").unwrap();
        assert_eq!(read_points(&f).unwrap(), vec![0.0, 20.0, 5.0, 15.0, 0.3]);
        std::fs::write(&f, "1\n2,x\n").unwrap();
        let e = read_points(&f).unwrap_err().to_string();
        assert!(e.contains("points.csv:2:") && e.contains("`x`"), "{e}");
    }

    #[test]
    fn trigger_spec_resolves_channels() {
        let ch: Vec<String> = ["ref_um", "y_um", "u_volts", "error_um"]
            .map(String::from)
            .to_vec();
        assert_eq!(parse_trigger("now", &ch, 0).unwrap(), TriggerCmd::Now);
        assert_eq!(
            parse_trigger("rise:y_um:10.5", &ch, 100).unwrap(),
            TriggerCmd::Rising {
                channel: 1,
                level: 10.5,
                pre: 100
            }
        );
        assert_eq!(
            parse_trigger("fall:2:3", &ch, 0).unwrap(),
            TriggerCmd::Falling {
                channel: 2,
                level: 3.0,
                pre: 0
            }
        );
        assert!(parse_trigger("rise:dac_code:1", &ch, 0).is_err());
        assert!(parse_trigger("rise:y_um:nan", &ch, 0).is_err());
        assert!(parse_trigger("up:y_um:1", &ch, 0).is_err());
        assert!(parse_trigger("now", &ch, 5).is_err());
    }

    fn finite() -> impl Strategy<Value = f32> {
        prop_oneof![
            -1.0e6f32..1.0e6,
            any::<f32>().prop_filter("finite", |v| v.is_finite() && v.abs() < 1e12),
            Just(0.0f32),
            Just(-0.0f32),
        ]
    }

    fn name() -> impl Strategy<Value = String> {
        "[a-z_+\\-0-9]{1,16}"
    }

    proptest! {
        /// Every command the host can build reads back identically with the firmware's
        /// parser (or the host refuses it before sending).
        #[test]
        fn every_built_command_round_trips(
            which in 0usize..31, a in finite(), b in finite(), d in finite(),
            n in name(), i in 0usize..5000, k in 0usize..5000,
        ) {
            let shape = [Shape::Sine, Shape::Triangle, Shape::Square][which % 3];
            let cmd = match which {
                0 => Command::Ping,
                1 => Command::Help,
                2 => Command::Get(&n),
                3 => Command::Set(&n, a),
                4 => Command::Mode(&n),
                5 => Command::Feedforward(&n),
                6 => Command::WaveOff,
                7 => Command::WaveHold(a),
                8..=10 => Command::Wave { shape, amp_um: a.abs(), freq_hz: b.abs(), offset_um: d },
                11 => Command::Stats,
                12 => Command::StatsReset,
                13 => Command::Rec(RecCmd::Trigger(TriggerCmd::Now)),
                14 => Command::Rec(RecCmd::Trigger(TriggerCmd::Rising { channel: i, level: a, pre: k })),
                15 => Command::Rec(RecCmd::Trigger(TriggerCmd::Falling { channel: i, level: a, pre: k })),
                16 => Command::Rec(RecCmd::Trigger(TriggerCmd::Level { channel: i, level: a, pre: k })),
                17 => Command::Rec(RecCmd::Read { start: i, count: k }),
                18 => Command::Rec([RecCmd::Arm, RecCmd::Stop, RecCmd::Status][i % 3]),
                19 => Command::WaveSteps {
                    low_um: a,
                    high_um: d,
                    levels: 2 + (i % (MAX_LEVELS as usize - 1)) as u16,
                    freq_hz: b.abs(),
                },
                20 => Command::WaveTable(b.abs()),
                21 => Command::TableClear,
                22 => Command::TableLen,
                23 => Command::TableAdd(Points::from_slice(&[a, b, d][..1 + i % 3]).unwrap()),
                24 => Command::WaveRaster {
                    span_um: [a.abs(), b.abs()],
                    lines: 1 + (i % MAX_LINES as usize) as u16,
                    line_hz: d.abs(),
                    center_um: [d, a],
                },
                25 => Command::WaveLissajous {
                    amp_um: [a.abs(), d.abs()],
                    freq_hz: [b.abs(), a.abs()],
                    phase_deg: (d % 360.0),
                    center_um: [b, d],
                },
                26 => Command::Axis(Some(i)),
                27 => Command::Axis(None),
                28 => Command::Rec(RecCmd::Divider([None, Some(k)][i % 2])),
                29 => Command::Cbw([a, b, d, -a]),
                _ => Command::Bench,
            };
            let line = format_command(&cmd);
            match checked_line(&cmd) {
                Ok(l) => {
                    prop_assert_eq!(&l, &line);
                    prop_assert_eq!(command::parse(l.as_bytes()), Ok(cmd));
                }
                // Only an overlong line may be refused.
                Err(e) => prop_assert!(line.len() > MAX_LINE, "{e}"),
            }
        }

        /// The table is loaded in lines the firmware reads back as exactly these points.
        #[test]
        fn table_lines_carry_every_point(points in proptest::collection::vec(finite(), 2..=TABLE_LEN)) {
            let lines = table_lines(&points).unwrap();
            let mut back = Vec::new();
            for l in &lines {
                prop_assert!(l.len() <= MAX_LINE);
                match command::parse(l.as_bytes()) {
                    Ok(Command::TableAdd(p)) => back.extend_from_slice(p.as_slice()),
                    other => prop_assert!(false, "{l}: {other:?}"),
                }
            }
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            prop_assert_eq!(bits(&back), bits(&points));
            // Greedy: the next line's first point would not have fitted in this one.
            for w in lines.windows(2) {
                let next = w[1].split(' ').nth(2).unwrap();
                let full = w[0].split(' ').count() - 2 == TABLE_ADD_MAX;
                prop_assert!(full || w[0].len() + 1 + next.len() > MAX_LINE, "{:?}", w);
            }
        }

        #[test]
        fn select_lines_round_trip(idx in proptest::collection::vec(0usize..Signal::COUNT, 1..5)) {
            let sig: Vec<Signal> = idx.iter().map(|&i| Signal::ALL[i]).collect();
            let line = select_line(&sig).unwrap();
            match command::parse(line.as_bytes()) {
                Ok(Command::Rec(RecCmd::Select(w))) => {
                    let names: Vec<&str> = w.iter().collect();
                    let want: Vec<&str> = sig.iter().map(|s| s.name()).collect();
                    prop_assert_eq!(names, want);
                    prop_assert_eq!(format_command(&Command::Rec(RecCmd::Select(w))), line);
                }
                other => prop_assert!(false, "{other:?}"),
            }
        }

        #[test]
        fn garbage_replies_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let mut c = client(&[], &bytes, true);
            for _ in 0..4 {
                let _ = c.raw("rec read 0 4");
            }
            if let Ok(s) = std::str::from_utf8(&bytes) {
                let _ = parse_stats(s);
                let _ = parse_rec_status(s);
                let _ = parse_frame(s, None);
                let _ = parse_line(s);
                let _ = parse_um(s);
            }
        }
    }
}
