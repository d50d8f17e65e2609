//! The grammar: a line's words into a [`Command`], bounded and without allocation.

use super::error::Error;
use super::number::{parse_f32, parse_usize};
use super::{MAX_LEVELS, MAX_LINE, MAX_LINES, MAX_WORDS, TABLE_ADD_MAX};
use crate::pipeline::excitation::{MULTISINE_MAX, PRBS_ORDER_MAX, PRBS_ORDER_MIN};

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

impl TriggerCmd {
    /// The edge triggers' keywords (`rec trigger <kind> ...`).
    pub const EDGES: [&'static str; 3] = ["rise", "fall", "level"];

    /// The edge trigger named `kind` (one of [`Self::EDGES`]).
    pub fn edge(kind: &str, channel: usize, level: f32, pre: usize) -> Option<Self> {
        Some(match kind {
            "rise" => Self::Rising {
                channel,
                level,
                pre,
            },
            "fall" => Self::Falling {
                channel,
                level,
                pre,
            },
            "level" => Self::Level {
                channel,
                level,
                pre,
            },
            _ => return None,
        })
    }
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
    /// Record every n-th period (`Some`), or report the divider (`None`).
    Divider(Option<usize>),
    /// Frames per capture (`Some`), or report it and the capacity (`None`).
    Length(Option<usize>),
    /// Frames as COBS packets with a CRC-32 each ([`crate::bulk`]).
    Bin {
        start: usize,
        count: usize,
    },
}

/// The points of one `table add` line (1..=[`TABLE_ADD_MAX`]), without allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Points {
    values: [f32; TABLE_ADD_MAX],
    len: usize,
}

impl Points {
    /// `None` unless `values` has 1..=[`TABLE_ADD_MAX`] points.
    pub fn from_slice(values: &[f32]) -> Option<Self> {
        if values.is_empty() || values.len() > TABLE_ADD_MAX {
            return None;
        }
        let mut p = Self {
            values: [0.0; TABLE_ADD_MAX],
            len: values.len(),
        };
        p.values.iter_mut().zip(values).for_each(|(d, s)| *d = *s);
        Some(p)
    }

    pub fn as_slice(&self) -> &[f32] {
        self.values.get(..self.len).unwrap_or(&[])
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
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
    /// `cbw <d> <alpha> <beta> <gamma>`: the four CBW parameters at once (one check, one
    /// rebuild: a fitted model can be valid where a mix of old and new values is not).
    Cbw([f32; 4]),
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
    /// Staircase `low_um` .. `high_um` in `levels` (2..=[`MAX_LEVELS`]) levels and back.
    WaveSteps {
        low_um: f32,
        high_um: f32,
        levels: u16,
        freq_hz: f32,
    },
    /// Periodic spline through the point table, at this frequency (Hz).
    WaveTable(f32),
    /// PRBS between `low_um` and `high_um`: an LFSR of `order` bits, `bit_hz` bits/s.
    WavePrbs {
        low_um: f32,
        high_um: f32,
        order: u8,
        bit_hz: f32,
        seed: u32,
    },
    /// Linear chirp `f0_hz` -> `f1_hz` over `duration_s`, repeated.
    WaveChirp {
        amp_um: f32,
        f0_hz: f32,
        f1_hz: f32,
        duration_s: f32,
        offset_um: f32,
    },
    /// Multisine: `harmonics` equal harmonics of `f0_hz`, peak `amp_um` around `offset_um`.
    WaveMultisine {
        amp_um: f32,
        f0_hz: f32,
        harmonics: u8,
        offset_um: f32,
        seed: u32,
    },
    /// 2-axis raster: x triangle over `span_um[0]` at `line_hz`, y triangle over
    /// `span_um[1]` at `line_hz / (2 lines)`, around `center_um`.
    WaveRaster {
        span_um: [f32; 2],
        lines: u16,
        line_hz: f32,
        center_um: [f32; 2],
    },
    /// 2-axis Lissajous scan: sines at `freq_hz`, y `phase_deg` ahead of x.
    WaveLissajous {
        amp_um: [f32; 2],
        freq_hz: [f32; 2],
        phase_deg: f32,
        center_um: [f32; 2],
    },
    /// Select the axis of the 1-axis waves (`Some`), or report it (`None`).
    Axis(Option<usize>),
    /// Empty the point table.
    TableClear,
    /// Append points (um) to the table.
    TableAdd(Points),
    /// Number of points in the table.
    TableLen,
    Stats,
    StatsReset,
    Rec(RecCmd<'a>),
    /// Latched fault and fault counters.
    Fault,
    /// Leave the safe state a fault latched.
    FaultClear,
    Bench,
    /// Exercise the converters and the safe-state hardware and report (board-specific).
    Selftest,
    /// `save`: store the settings in flash (only while the loop does not drive the stage).
    Save,
    /// `load`: the stored settings, checked, all installed or none.
    Load,
    /// `defaults`: the built-in settings (the flash keeps what it holds).
    Defaults,
}

impl Command<'_> {
    /// A query that changes nothing (no setting, mode, reference, recorder or fault):
    /// answered while a `save`/`load` is under way, which refuses every other command
    /// (the record on its way to the flash and the live settings stay the same).
    pub fn reads_only(&self) -> bool {
        matches!(
            self,
            Command::Empty
                | Command::Ping
                | Command::Help
                | Command::Get(_)
                | Command::Axis(None)
                | Command::TableLen
                | Command::Stats
                | Command::Fault
                | Command::Rec(
                    RecCmd::Status
                        | RecCmd::Read { .. }
                        | RecCmd::Bin { .. }
                        | RecCmd::Divider(None)
                        | RecCmd::Length(None)
                )
        )
    }
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
        // Byte scan (no core::str::split: its searcher carries panic paths).
        let mut start = 0;
        for (i, c) in line.bytes().chain(core::iter::once(b' ')).enumerate() {
            if c != b' ' {
                continue;
            }
            if i > start {
                let slot = words.get_mut(len).ok_or(Error::TooManyArguments)?;
                *slot = line.get(start..i).ok_or(Error::NotAscii)?;
                len += 1;
            }
            start = i + 1;
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
        parse_usize(self.arg(i)?)
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
        "selftest" => {
            w.at_most(1)?;
            Command::Selftest
        }
        "save" | "load" | "defaults" => {
            w.at_most(1)?;
            match cmd {
                "save" => Command::Save,
                "load" => Command::Load,
                _ => Command::Defaults,
            }
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
        "cbw" => {
            w.at_most(5)?;
            Command::Cbw([w.num(1)?, w.num(2)?, w.num(3)?, w.num(4)?])
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
        "axis" => {
            w.at_most(2)?;
            Command::Axis(match w.get(1) {
                Some(_) => Some(w.index(1)?),
                None => None,
            })
        }
        "table" => match w.arg(1)? {
            "clear" => {
                w.at_most(2)?;
                Command::TableClear
            }
            "len" => {
                w.at_most(2)?;
                Command::TableLen
            }
            "add" => {
                let mut values = [0.0; TABLE_ADD_MAX];
                let mut len = 0;
                for (slot, word) in values.iter_mut().zip(w.iter().skip(2)) {
                    *slot = parse_f32(word)?;
                    len += 1;
                }
                w.at_most(2 + TABLE_ADD_MAX)?;
                if len == 0 {
                    return Err(Error::MissingArgument);
                }
                Command::TableAdd(Points { values, len })
            }
            _ => return Err(Error::BadKeyword),
        },
        "stats" => match w.get(1) {
            None => Command::Stats,
            Some("reset") => {
                w.at_most(2)?;
                Command::StatsReset
            }
            Some(_) => return Err(Error::BadKeyword),
        },
        "rec" => Command::Rec(parse_rec(w)?),
        "fault" => match w.get(1) {
            None => Command::Fault,
            Some("clear") => {
                w.at_most(2)?;
                Command::FaultClear
            }
            Some(_) => return Err(Error::BadKeyword),
        },
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
        "steps" => {
            w.at_most(6)?;
            let (low_um, high_um) = (w.num(2)?, w.num(3)?);
            let levels = w.index(4)?;
            let freq_hz = w.num(5)?;
            if !(2..=MAX_LEVELS as usize).contains(&levels) || !(freq_hz >= 0.0) {
                return Err(Error::OutOfRange);
            }
            return Ok(Command::WaveSteps {
                low_um,
                high_um,
                levels: levels as u16,
                freq_hz,
            });
        }
        "table" => {
            w.at_most(3)?;
            let freq_hz = w.num(2)?;
            if !(freq_hz >= 0.0) {
                return Err(Error::OutOfRange);
            }
            return Ok(Command::WaveTable(freq_hz));
        }
        "raster" => {
            // 4 arguments, or 6 with the centre.
            w.at_most(8)?;
            let span_um = [w.num(2)?, w.num(3)?];
            let lines = w.index(4)?;
            let line_hz = w.num(5)?;
            let center_um = match w.len() {
                6 => [span_um[0] * 0.5, span_um[1] * 0.5],
                _ => [w.num(6)?, w.num(7)?],
            };
            let ok = span_um[0] >= 0.0
                && span_um[1] >= 0.0
                && (1..=MAX_LINES as usize).contains(&lines)
                && line_hz >= 0.0;
            if !ok {
                return Err(Error::OutOfRange);
            }
            return Ok(Command::WaveRaster {
                span_um,
                lines: lines as u16,
                line_hz,
                center_um,
            });
        }
        "lissajous" => {
            // 4 arguments; 5: + phase; 6: + centre; 7: + phase and centre.
            w.at_most(9)?;
            let amp_um = [w.num(2)?, w.num(3)?];
            let freq_hz = [w.num(4)?, w.num(5)?];
            let (phase_deg, center_um) = match w.len() {
                6 => (90.0, amp_um),
                7 => (w.num(6)?, amp_um),
                8 => (90.0, [w.num(6)?, w.num(7)?]),
                _ => (w.num(6)?, [w.num(7)?, w.num(8)?]),
            };
            let ok = amp_um[0] >= 0.0
                && amp_um[1] >= 0.0
                && freq_hz[0] >= 0.0
                && freq_hz[1] >= 0.0
                && (-360.0..=360.0).contains(&phase_deg);
            if !ok {
                return Err(Error::OutOfRange);
            }
            return Ok(Command::WaveLissajous {
                amp_um,
                freq_hz,
                phase_deg,
                center_um,
            });
        }
        "prbs" => {
            w.at_most(7)?;
            let (low_um, high_um) = (w.num(2)?, w.num(3)?);
            let order = w.index(4)?;
            let bit_hz = w.num(5)?;
            let seed = if w.len() > 6 { w.index(6)? } else { 1 };
            let ok = (PRBS_ORDER_MIN as usize..=PRBS_ORDER_MAX as usize).contains(&order)
                && bit_hz > 0.0
                && seed <= u32::MAX as usize;
            if !ok {
                return Err(Error::OutOfRange);
            }
            return Ok(Command::WavePrbs {
                low_um,
                high_um,
                order: order as u8,
                bit_hz,
                seed: seed as u32,
            });
        }
        "chirp" => {
            w.at_most(7)?;
            let amp_um = w.num(2)?;
            let (f0_hz, f1_hz) = (w.num(3)?, w.num(4)?);
            let duration_s = w.num(5)?;
            let offset_um = if w.len() > 6 { w.num(6)? } else { 0.0 };
            let ok = amp_um >= 0.0 && f0_hz >= 0.0 && f1_hz >= 0.0 && duration_s > 0.0;
            if !ok {
                return Err(Error::OutOfRange);
            }
            return Ok(Command::WaveChirp {
                amp_um,
                f0_hz,
                f1_hz,
                duration_s,
                offset_um,
            });
        }
        "multisine" => {
            w.at_most(7)?;
            let amp_um = w.num(2)?;
            let f0_hz = w.num(3)?;
            let harmonics = w.index(4)?;
            let offset_um = if w.len() > 5 { w.num(5)? } else { 0.0 };
            let seed = if w.len() > 6 { w.index(6)? } else { 0 };
            let ok = amp_um >= 0.0
                && f0_hz > 0.0
                && (1..=MULTISINE_MAX).contains(&harmonics)
                && seed <= u32::MAX as usize;
            if !ok {
                return Err(Error::OutOfRange);
            }
            return Ok(Command::WaveMultisine {
                amp_um,
                f0_hz,
                harmonics: harmonics as u8,
                offset_um,
                seed: seed as u32,
            });
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
            RecCmd::Trigger(TriggerCmd::edge(kind, channel, level, pre).ok_or(Error::BadKeyword)?)
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
        "div" => {
            w.at_most(3)?;
            RecCmd::Divider(match w.get(2) {
                Some(_) => Some(w.index(2)?),
                None => None,
            })
        }
        "read" => {
            w.at_most(4)?;
            RecCmd::Read {
                start: w.index(2)?,
                count: w.index(3)?,
            }
        }
        "bin" => {
            w.at_most(4)?;
            RecCmd::Bin {
                start: w.index(2)?,
                count: w.index(3)?,
            }
        }
        "len" => {
            w.at_most(3)?;
            RecCmd::Length(match w.get(2) {
                Some(_) => Some(w.index(2)?),
                None => None,
            })
        }
        _ => return Err(Error::BadKeyword),
    };
    Ok(r)
}

#[cfg(test)]
mod tests;
