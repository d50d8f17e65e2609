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
//! | `help` | list of commands and parameters | `ok ping help get set cbw mode ff wave axis table stats rec fault bench; params: ...` |
//! | `get <param>` | read a parameter | `ok <param> <value>` |
//! | `set <param> <value>` | write a parameter (range-checked) | `ok <param> <value>` |
//! | `cbw <d> <alpha> <beta> <gamma>` | the CBW model (um/V, um/V, 1/V, 1/V) at once, as `piezo fit --model cbw` reports it | `ok cbw <d> <alpha> <beta> <gamma>` |
//! | `mode <law>` | select the feedback law (bumpless) | `ok mode <law>` |
//! | `ff <compensator>` | select the feedforward compensator | `ok ff <name>` |
//! | `wave off` / `wave hold <um>` | stop the waveform (every axis) / hold a position | `ok wave ...` |
//! | `wave sine\|triangle\|square <amp_um> <freq_hz> [<offset_um>]` | start a waveform | `ok wave ...` |
//! | `wave steps <low_um> <high_um> <levels> <freq_hz>` | staircase low..high..low, `levels` in 2..=[`MAX_LEVELS`] (2: square) | `ok wave steps ...` |
//! | `table clear` | empty the point table | `ok table 0` |
//! | `table add <um> [<um>...]` | append up to [`TABLE_ADD_MAX`] points (all or none; at most [`TABLE_LEN`] in all, else `err 8`) | `ok table <n>` |
//! | `table len` | points in the table | `ok table <n>` |
//! | `wave raster <x_span_um> <y_span_um> <lines> <line_hz> [<xc_um> <yc_um>]` | 2-axis raster: x triangle at `line_hz` over `x_span_um`, y triangle over `y_span_um` at `line_hz / (2 lines)` (one sweep of y per `lines` x periods), centred on (`xc_um`, `yc_um`) (default: half the spans, so the scan starts at 0); `lines` in 1..=[`MAX_LINES`]; 1-axis board: `err 13` | `ok wave raster <x_span> <y_span> <lines> <line_hz> <xc> <yc>` |
//! | `wave lissajous <x_amp_um> <y_amp_um> <fx_hz> <fy_hz> [<phase_deg>] [<xc_um> <yc_um>]` | 2-axis Lissajous: sines, y `phase_deg` ahead of x (default 90, in -360..=360), centred on (`xc_um`, `yc_um`) (default: the amplitudes, so the scan starts at 0); 1-axis board: `err 13` | `ok wave lissajous <x_amp> <y_amp> <fx> <fy> <phase> <xc> <yc>` |
//! | `axis [<n>]` | axis the 1-axis waves (`hold`, `sine`, `triangle`, `square`, `steps`, `table`) apply to (default 0; `err 8` beyond the board's axes); without `n`: report it | `ok axis <n> of <axes>` |
//! | `wave table <freq_hz>` | periodic spline through the table's points, one period per `1/freq_hz` (fewer than 2 points: `err 12`) | `ok wave table <freq_hz> <n>` |
//! | `stats` / `stats reset` | timing (cycles min/max/last, overruns) / reset it | `ok ...` |
//! | `rec sel <signal>...` | recorder channels (up to its channel count): `ref_um y_um error_um ff_volts u_volts adc_code dac_code` of axis 0, `ref1_um y1_um error1_um ff1_volts u1_volts adc1_code dac1_code` of axis 1 (1-axis board: `err 13`) | `ok rec sel ...` |
//! | `rec trig now` | trigger at once when armed | `ok` |
//! | `rec trig rise\|fall\|level <channel> <level> [<pre>]` | trigger on a channel | `ok` |
//! | `rec arm` / `rec stop` | start / abort a capture | `ok` |
//! | `rec div [<n>]` | record every `n`-th period, 1..=1000 (the buffer spans `n` times longer, e.g. a whole XY scan); without `n`: report it | `ok rec div <n>` |
//! | `rec status` | `idle`, `armed`, `triggered` or `done` and the frames of the capture in place (all N when done) | `ok rec <state> <n>` |
//! | `rec read <start> <count>` | frames as `<i> <v0> <v1> ...` lines | `ok rec read <n>` |
//! | `fault` | latched fault (`none`, `sensor-range`, `non-finite`, `dac-write`) and counters | `ok fault <state> sensor <n> nonfinite <n> dac <n>` |
//! | `fault clear` | leave the safe state (bumpless, in the current mode) | `ok fault none` |
//! | `bench` | instructions/cycles per step for every mode (QEMU board) | `ok bench ...` |
//!
//! Parameters (the firmware's `help` lists them): `u_min`, `u_max` (V), `slew` (V/s);
//! read-only `um_per_code`, `volts_per_code`, `sample_hz`; the hysteresis model and gains
//! the laws and compensators are built from: `cbw_d`, `cbw_alpha` (um/V), `cbw_beta`,
//! `cbw_gamma` (1/V) of the CBW (n = 1) that `piezo fit --model cbw` identifies,
//! `um_per_volt`, `offset_um` (open-loop scaling), `hgo_eps` (s), `lambda1`, `lambda2`
//! (1/s, robust law), `pid_kp` (V/um), `pid_ki` (V/(um s)). A model or gain `set` is
//! checked by the core's constructors and installs the rebuilt law and compensator
//! bumplessly; a refused value (`err 8`) changes nothing.
//!
//! On a 2-axis (XY) board `mode`, `ff`, `set` (limits and model) and `wave off` act on every axis;
//! `get` reads axis 0 (the axes are configured alike).
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
/// Most levels of `wave steps`.
pub const MAX_LEVELS: u16 = 64;
/// Most x lines per y sweep of `wave raster`.
pub const MAX_LINES: u16 = 4096;
/// Most points of one `table add` line.
pub const TABLE_ADD_MAX: usize = MAX_WORDS - 2;
/// Capacity of the point table of `wave table` (the reference generator's).
pub use crate::pipeline::TABLE_LEN;

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
    /// A number with more than [`MAX_DIGITS`] significant digits.
    TooManyDigits,
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
            Error::TooManyDigits => 14,
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
            Error::TooManyDigits => "number has more than 19 significant digits",
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
    /// Record every n-th period (`Some`), or report the divider (`None`).
    Divider(Option<usize>),
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

/// Most significant decimal digits a number may have. Leading zeros and trailing zeros
/// do not count (`0.000150000` has 2); 19 digits fit a `u64`, more than `f32`'s 9 needed.
pub const MAX_DIGITS: u32 = 19;

/// A finite `f32` from decimal text, correctly rounded (nearest, ties to even), without
/// core's float parser (bounded work, no panic path in the firmware's serial handler).
///
/// Accepted syntax: `[+-]digits[.digits][(e|E)[+-]digits]`, also `5.` and `.5`, with at
/// most [`MAX_DIGITS`] significant digits. Values that round to zero give `0` (`-0` with a
/// minus sign), as core's parser does.
/// * [`Error::BadNumber`]: not that syntax (`nan`, `inf`, `0x10`, `1e`, `1.2.3`, ...), or a
///   value beyond `f32::MAX` once rounded;
/// * [`Error::TooManyDigits`]: more than [`MAX_DIGITS`] significant digits.
pub fn parse_f32(s: &str) -> Result<f32, Error> {
    let b = s.as_bytes();
    let (neg, b) = match b.split_first() {
        Some((b'-', r)) => (true, r),
        Some((b'+', r)) => (false, r),
        _ => (false, b),
    };
    // Value = m * 10^exp10, m the significant digits; zeros after the last nonzero digit
    // wait in `zeros` (they only move the exponent).
    let (mut m, mut n_sig, mut zeros, mut exp10) = (0u64, 0u32, 0u32, 0i32);
    let (mut digits, mut dot) = (0u32, false);
    let mut rest: &[u8] = &[];
    for (i, &c) in b.iter().enumerate() {
        match c {
            b'0'..=b'9' => {
                digits = digits.saturating_add(1);
                if dot {
                    exp10 = exp10.saturating_sub(1);
                }
                if c == b'0' {
                    if n_sig > 0 {
                        zeros = zeros.saturating_add(1);
                    }
                    continue;
                }
                let n = n_sig.saturating_add(zeros).saturating_add(1);
                if n > MAX_DIGITS {
                    return Err(Error::TooManyDigits);
                }
                let scale = POW10_U64
                    .get(zeros as usize + 1)
                    .ok_or(Error::TooManyDigits)?;
                m = m
                    .checked_mul(*scale)
                    .and_then(|m| m.checked_add((c - b'0') as u64))
                    .ok_or(Error::TooManyDigits)?;
                n_sig = n;
                zeros = 0;
            }
            b'.' if !dot => dot = true,
            b'e' | b'E' => {
                rest = b.get(i + 1..).unwrap_or(&[]);
                if rest.is_empty() {
                    return Err(Error::BadNumber);
                }
                break;
            }
            _ => return Err(Error::BadNumber),
        }
    }
    if digits == 0 {
        return Err(Error::BadNumber);
    }
    exp10 = exp10.saturating_add(zeros as i32);
    if !rest.is_empty() {
        let (eneg, ed) = match rest.split_first() {
            Some((b'-', r)) => (true, r),
            Some((b'+', r)) => (false, r),
            _ => (false, rest),
        };
        if ed.is_empty() {
            return Err(Error::BadNumber);
        }
        let mut e = 0i32;
        for &c in ed {
            if !c.is_ascii_digit() {
                return Err(Error::BadNumber);
            }
            // Saturate far beyond f32's range: the value is then 0 or too large anyway.
            e = (e * 10 + (c - b'0') as i32).min(100_000);
        }
        exp10 = exp10.saturating_add(if eneg { -e } else { e });
    }
    let sign = |v: f32| if neg { -v } else { v };
    // V in [10^(n_sig-1+exp10), 10^(n_sig+exp10)).
    let top = (n_sig as i32).saturating_add(exp10);
    if m == 0 || top <= -46 {
        // Below half the smallest subnormal (7.0e-46): rounds to zero.
        return Ok(sign(0.0));
    }
    if top > 39 {
        return Err(Error::BadNumber);
    }
    // Candidate from f64 arithmetic (relative error < 1e-15, far below f32's 6e-8), then
    // exact comparisons with the rounding midpoints around it decide.
    let p = pow10_f64(exp10.unsigned_abs());
    let approx = if exp10 >= 0 {
        m as f64 * p
    } else {
        m as f64 / p
    };
    let mut bits = (approx as f32).to_bits().min(F32_INF_BITS);
    for _ in 0..8 {
        let up = bits < F32_INF_BITS && {
            let c = cmp_midpoint(m, exp10, bits);
            c.is_gt() || (c.is_eq() && bits & 1 == 1)
        };
        if up {
            bits += 1;
            continue;
        }
        let down = bits > 0 && {
            let c = cmp_midpoint(m, exp10, bits - 1);
            c.is_lt() || (c.is_eq() && bits & 1 == 1)
        };
        if down {
            bits -= 1;
            continue;
        }
        break;
    }
    if bits >= F32_INF_BITS {
        return Err(Error::BadNumber);
    }
    Ok(sign(f32::from_bits(bits)))
}

/// Bit pattern of `f32::INFINITY`; one above `f32::MAX`.
const F32_INF_BITS: u32 = 0x7F80_0000;

/// 10^0 ..= 10^19.
const POW10_U64: [u64; 20] = {
    let mut t = [1u64; 20];
    let mut i = 1;
    while i < 20 {
        t[i] = t[i - 1] * 10;
        i += 1;
    }
    t
};

/// 10^n as f64 (exact up to 10^22, then within a few ulp); `n` is at most 65 here.
fn pow10_f64(n: u32) -> f64 {
    const EXACT: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let mut p = 1.0;
    let mut n = n.min(330);
    while n > 22 {
        p *= 1e22;
        n -= 22;
    }
    p * EXACT.get(n as usize).copied().unwrap_or(1.0)
}

/// Compares `m * 10^exp10` with the midpoint between the positive f32 of bit pattern
/// `bits` and the next one up, exactly (integers of up to 384 bits).
fn cmp_midpoint(m: u64, exp10: i32, bits: u32) -> core::cmp::Ordering {
    let (ef, frac) = (bits >> 23, bits & 0x7F_FFFF);
    let (sig, e2) = if ef == 0 {
        (frac, -149)
    } else {
        (frac | 0x80_0000, ef as i32 - 150)
    };
    // Midpoint = (2 sig + 1) * 2^(e2 - 1).
    let (mut lhs, mut rhs) = (Big::new(m), Big::new(2 * sig as u64 + 1));
    if exp10 >= 0 {
        lhs.mul_pow10(exp10.unsigned_abs());
    } else {
        rhs.mul_pow10(exp10.unsigned_abs());
    }
    let e = e2 - 1;
    if e >= 0 {
        rhs.shl(e.unsigned_abs());
    } else {
        lhs.shl(e.unsigned_abs());
    }
    lhs.cmp(&rhs)
}

/// Unsigned integer of [`Big::WORDS`] 64-bit words, least significant first; a result
/// that does not fit saturates to "larger than any that does" (never wraps, never panics).
#[derive(Clone, Copy, PartialEq, Eq)]
struct Big {
    w: [u64; Big::WORDS],
    overflow: bool,
}

impl Big {
    const WORDS: usize = 6;

    fn new(v: u64) -> Self {
        let mut w = [0; Self::WORDS];
        w[0] = v;
        Self { w, overflow: false }
    }

    fn mul_small(&mut self, x: u64) {
        let mut carry = 0u128;
        for w in self.w.iter_mut() {
            let t = *w as u128 * x as u128 + carry;
            *w = t as u64;
            carry = t >> 64;
        }
        self.overflow |= carry != 0;
    }

    fn mul_pow10(&mut self, mut n: u32) {
        while n > 0 {
            let k = n.min(19);
            self.mul_small(POW10_U64.get(k as usize).copied().unwrap_or(1));
            n -= k;
        }
    }

    fn bit_len(&self) -> u32 {
        let mut len = 0;
        for (i, w) in self.w.iter().enumerate() {
            if *w != 0 {
                len = i as u32 * 64 + (64 - w.leading_zeros());
            }
        }
        len
    }

    fn shl(&mut self, n: u32) {
        if self.bit_len() == 0 {
            return;
        }
        if self.bit_len().saturating_add(n) > 64 * Self::WORDS as u32 {
            self.overflow = true;
            return;
        }
        let (words, bits) = ((n / 64) as usize, n % 64);
        let src = self.w;
        let at = |j: Option<usize>| j.and_then(|j| src.get(j)).copied().unwrap_or(0);
        for (i, w) in self.w.iter_mut().enumerate() {
            let lo = at(i.checked_sub(words));
            let below = at(i.checked_sub(words + 1));
            *w = if bits == 0 {
                lo
            } else {
                (lo << bits) | (below >> (64 - bits))
            };
        }
    }
}

impl PartialOrd for Big {
    fn partial_cmp(&self, other: &Self) -> Option<core::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Big {
    fn cmp(&self, other: &Self) -> core::cmp::Ordering {
        match (self.overflow, other.overflow) {
            (true, false) => return core::cmp::Ordering::Greater,
            (false, true) => return core::cmp::Ordering::Less,
            _ => {}
        }
        for (a, b) in self.w.iter().rev().zip(other.w.iter().rev()) {
            if a != b {
                return a.cmp(b);
            }
        }
        core::cmp::Ordering::Equal
    }
}

/// A non-negative integer (`[+]digits`), without core's integer parser.
pub fn parse_usize(s: &str) -> Result<usize, Error> {
    let b = s.as_bytes();
    let b = b.strip_prefix(b"+").unwrap_or(b);
    if b.is_empty() {
        return Err(Error::BadNumber);
    }
    let mut v = 0usize;
    for &c in b {
        if !c.is_ascii_digit() {
            return Err(Error::BadNumber);
        }
        v = v
            .checked_mul(10)
            .and_then(|v| v.checked_add((c - b'0') as usize))
            .ok_or(Error::OutOfRange)?;
    }
    Ok(v)
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

    /// Appends text (cut at the capacity). The `push_*` writers are what the firmware uses:
    /// no `core::fmt`, so no indirect calls and a known stack bound in its handlers.
    pub fn push_str(&mut self, s: &str) {
        self.push_bytes(s.as_bytes());
    }

    fn push_bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
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
    }

    /// `s`, then spaces up to `width` bytes (left-aligned column).
    pub fn push_padded(&mut self, s: &str, width: usize) {
        self.push_str(s);
        for _ in s.len()..width {
            self.push_bytes(b" ");
        }
    }

    /// Spaces, then `s`, `width` bytes in all (right-aligned column).
    pub fn push_right(&mut self, s: &str, width: usize) {
        for _ in s.len()..width {
            self.push_bytes(b" ");
        }
        self.push_str(s);
    }

    /// `v / 10^decimals` with exactly `decimals` digits after the point (`1234, 2` ->
    /// `12.34`): fixed-point counters without floats.
    pub fn push_fixed(&mut self, v: u32, decimals: u32) {
        let scale = POW10_U64.get(decimals as usize).copied().unwrap_or(1);
        let v = v as u64;
        self.push_u64(v / scale);
        if decimals == 0 {
            return;
        }
        self.push_bytes(b".");
        let mut frac = Reply::<20>::new();
        frac.push_u64(v % scale);
        for _ in frac.len..decimals as usize {
            self.push_bytes(b"0");
        }
        self.push_bytes(frac.as_bytes());
    }

    /// Decimal integer.
    pub fn push_u64(&mut self, mut v: u64) {
        let mut digits = [0u8; 20];
        let mut n = 0;
        for d in digits.iter_mut().rev() {
            *d = b'0' + (v % 10) as u8;
            v /= 10;
            n += 1;
            if v == 0 {
                break;
            }
        }
        self.push_bytes(digits.get(digits.len() - n..).unwrap_or(&[]));
    }

    pub fn push_u32(&mut self, v: u32) {
        self.push_u64(v as u64);
    }

    pub fn push_usize(&mut self, v: usize) {
        self.push_u64(v as u64);
    }

    pub fn push_i32(&mut self, v: i32) {
        if v < 0 {
            self.push_bytes(b"-");
        }
        self.push_u64(v.unsigned_abs() as u64);
    }

    /// `err <code> <message>`, the reply to a failed command.
    pub fn push_error(&mut self, e: Error) {
        self.push_str("err ");
        self.push_u32(e.code() as u32);
        self.push_bytes(b" ");
        self.push_str(e.message());
    }

    /// A number in the fewest of 6 to 9 significant digits that [`parse_f32`] reads back to
    /// the same `f32` (9 always do), trailing zeros dropped, `%g` style: positional for
    /// 1e-4 <= |v| < 1e9 (`0.16`, `150`, `20000`, `0.0001`), else `1.5e-5`,
    /// `3.4028235e38`; `nan`, `inf`, `-inf`.
    pub fn push_f32(&mut self, v: f32) {
        if v.is_nan() {
            return self.push_str("nan");
        }
        if v.is_sign_negative() && v != 0.0 {
            self.push_bytes(b"-");
        }
        let a = v.abs();
        if a.is_infinite() {
            return self.push_str("inf");
        }
        let mut text = Reply::<24>::new();
        for p in 6..=9 {
            text.clear();
            text.push_g(a, p);
            if p == 9 || parse_f32(text.as_str()).map(f32::to_bits) == Ok(a.to_bits()) {
                break;
            }
        }
        self.push_bytes(text.as_bytes());
    }

    /// Finite non-negative `v` to `p` (1..=9) significant digits, `%g` style.
    fn push_g(&mut self, v: f32, p: u32) {
        let x = v as f64;
        if x <= 0.0 {
            return self.push_bytes(b"0");
        }
        // Decimal exponent: 10^e <= x < 10^(e+1), from the binary one, then corrected.
        let e2 = ((x.to_bits() >> 52) & 0x7FF) as i32 - 1023;
        let mut e = (e2 * 30103).div_euclid(100_000);
        for _ in 0..3 {
            if x < pow10_signed(e) {
                e -= 1;
            } else if x >= pow10_signed(e + 1) {
                e += 1;
            }
        }
        // p digits, rounded; 999.5 (p = 3) rounds up to the next decade.
        let p = p.clamp(1, 9);
        let full = POW10_U64.get(p as usize).copied().unwrap_or(1);
        let mut d = (x * pow10_signed(p as i32 - 1 - e) + 0.5) as u64;
        if d >= full {
            d /= 10;
            e += 1;
        }
        let mut buf = [b'0'; 9];
        let digits = buf.get_mut(..p as usize).unwrap_or(&mut []);
        for slot in digits.iter_mut().rev() {
            *slot = b'0' + (d % 10) as u8;
            d /= 10;
        }
        let mut n = digits.len();
        while n > 1 && digits.get(n - 1) == Some(&b'0') {
            n -= 1;
        }
        let digits = digits.get(..n).unwrap_or(&[]);
        if (-4..9).contains(&e) {
            if e < 0 {
                self.push_bytes(b"0.");
                for _ in 0..(-e - 1) {
                    self.push_bytes(b"0");
                }
                self.push_bytes(digits);
            } else {
                let int = e as usize + 1;
                for i in 0..int {
                    self.push_bytes(&[digits.get(i).copied().unwrap_or(b'0')]);
                }
                if let Some(frac) = digits.get(int..).filter(|f| !f.is_empty()) {
                    self.push_bytes(b".");
                    self.push_bytes(frac);
                }
            }
        } else {
            let (first, rest) = digits.split_first().unwrap_or((&b'0', &[]));
            self.push_bytes(&[*first]);
            if !rest.is_empty() {
                self.push_bytes(b".");
                self.push_bytes(rest);
            }
            self.push_bytes(b"e");
            self.push_i32(e);
        }
    }
}

/// 10^n as f64 for |n| <= 330 (approximate beyond 10^22).
fn pow10_signed(n: i32) -> f64 {
    let p = pow10_f64(n.unsigned_abs());
    if n < 0 {
        1.0 / p
    } else {
        p
    }
}

impl<const N: usize> fmt::Write for Reply<N> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        self.push_str(s);
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
        assert_eq!(
            p("cbw 0.39 0.27 1e-3 1.8e-4"),
            Ok(Command::Cbw([0.39, 0.27, 1e-3, 1.8e-4]))
        );
        assert_eq!(p("cbw 0.39 0.27 1e-3"), Err(Error::MissingArgument));
        assert_eq!(p("cbw 0.39 0.27 1e-3 1 2"), Err(Error::TooManyArguments));
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
        assert_eq!(p("fault"), Ok(Command::Fault));
        assert_eq!(p("fault clear"), Ok(Command::FaultClear));
        assert_eq!(p("fault reset"), Err(Error::BadKeyword));
        assert_eq!(p("fault clear now"), Err(Error::TooManyArguments));
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
    fn parses_scans_and_axis() {
        assert_eq!(
            p("wave raster 20 10 16 50"),
            Ok(Command::WaveRaster {
                span_um: [20.0, 10.0],
                lines: 16,
                line_hz: 50.0,
                center_um: [10.0, 5.0],
            })
        );
        assert_eq!(
            p("wave raster 20 10 16 50 30 40"),
            Ok(Command::WaveRaster {
                span_um: [20.0, 10.0],
                lines: 16,
                line_hz: 50.0,
                center_um: [30.0, 40.0],
            })
        );
        let liss = |phase_deg, center_um| {
            Ok(Command::WaveLissajous {
                amp_um: [5.0, 4.0],
                freq_hz: [30.0, 40.0],
                phase_deg,
                center_um,
            })
        };
        assert_eq!(p("wave lissajous 5 4 30 40"), liss(90.0, [5.0, 4.0]));
        assert_eq!(p("wave lissajous 5 4 30 40 45"), liss(45.0, [5.0, 4.0]));
        assert_eq!(
            p("wave lissajous 5 4 30 40 10 20"),
            liss(90.0, [10.0, 20.0])
        );
        assert_eq!(
            p("wave lissajous 5 4 30 40 -45 10 20"),
            liss(-45.0, [10.0, 20.0])
        );
        for (line, e) in [
            ("wave raster 20 10 16", Error::MissingArgument),
            ("wave raster 20 10 16 50 30", Error::MissingArgument),
            ("wave raster 20 10 16 50 30 40 1", Error::TooManyArguments),
            ("wave raster 20 10 0 50", Error::OutOfRange),
            ("wave raster 20 10 4097 50", Error::OutOfRange),
            ("wave raster -20 10 16 50", Error::OutOfRange),
            ("wave raster 20 10 16 -50", Error::OutOfRange),
            ("wave raster 20 10 1.5 50", Error::BadNumber),
            ("wave lissajous 5 4 30", Error::MissingArgument),
            ("wave lissajous 5 4 30 -40", Error::OutOfRange),
            ("wave lissajous 5 -4 30 40", Error::OutOfRange),
            ("wave lissajous 5 4 30 40 400", Error::OutOfRange),
            ("wave lissajous 5 4 30 40 nan", Error::BadNumber),
            ("wave lissajous 5 4 30 40 90 1 2 3", Error::TooManyArguments),
            ("axis -1", Error::BadNumber),
            ("axis 1 2", Error::TooManyArguments),
        ] {
            assert_eq!(p(line), Err(e), "{line}");
        }
        assert_eq!(p("axis"), Ok(Command::Axis(None)));
        assert_eq!(p("rec div"), Ok(Command::Rec(RecCmd::Divider(None))));
        assert_eq!(p("rec div 10"), Ok(Command::Rec(RecCmd::Divider(Some(10)))));
        assert_eq!(p("rec div 1 2"), Err(Error::TooManyArguments));
        assert_eq!(p("axis 1"), Ok(Command::Axis(Some(1))));
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
    fn parses_steps_and_table_commands() {
        assert_eq!(
            p("wave steps 10 30 5 2.5"),
            Ok(Command::WaveSteps {
                low_um: 10.0,
                high_um: 30.0,
                levels: 5,
                freq_hz: 2.5
            })
        );
        assert_eq!(p("wave steps 1 2 64 1").map(|_| ()), Ok(()));
        assert_eq!(p("wave steps 1 2 1 1"), Err(Error::OutOfRange));
        assert_eq!(p("wave steps 1 2 65 1"), Err(Error::OutOfRange));
        assert_eq!(p("wave steps 1 2 4 -1"), Err(Error::OutOfRange));
        assert_eq!(p("wave steps 1 2 4.5 1"), Err(Error::BadNumber));
        assert_eq!(p("wave steps 1 2 4"), Err(Error::MissingArgument));
        assert_eq!(p("wave steps 1 2 4 1 0"), Err(Error::TooManyArguments));
        assert_eq!(p("wave table 10"), Ok(Command::WaveTable(10.0)));
        assert_eq!(p("wave table"), Err(Error::MissingArgument));
        assert_eq!(p("wave table -1"), Err(Error::OutOfRange));
        assert_eq!(p("wave table 1 2"), Err(Error::TooManyArguments));
        assert_eq!(p("table clear"), Ok(Command::TableClear));
        assert_eq!(p("table len"), Ok(Command::TableLen));
        assert_eq!(p("table"), Err(Error::MissingArgument));
        assert_eq!(p("table drop"), Err(Error::BadKeyword));
        assert_eq!(p("table len 3"), Err(Error::TooManyArguments));
        assert_eq!(p("table add"), Err(Error::MissingArgument));
        assert_eq!(p("table add 1 x"), Err(Error::BadNumber));
        assert_eq!(
            p("table add 1.5 -2 3e1"),
            Ok(Command::TableAdd(
                Points::from_slice(&[1.5, -2.0, 30.0]).unwrap()
            ))
        );
        let full = "table add 1 2 3 4 5 6 7 8";
        match p(full) {
            Ok(Command::TableAdd(pts)) => {
                assert_eq!(pts.len(), TABLE_ADD_MAX);
                assert_eq!(pts.as_slice(), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            p("table add 1 2 3 4 5 6 7 8 9"),
            Err(Error::TooManyArguments)
        );
        assert!(Points::from_slice(&[]).is_none());
        assert!(Points::from_slice(&[0.0; TABLE_ADD_MAX + 1]).is_none());
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

    /// Significant digits of a decimal string (what [`MAX_DIGITS`] counts).
    fn significant_digits(s: &str) -> usize {
        let mant = s.split(['e', 'E']).next().unwrap_or("");
        let d: String = mant.chars().filter(|c| c.is_ascii_digit()).collect();
        d.trim_start_matches('0').trim_end_matches('0').len()
    }

    /// Our parser against core's: same bits, or the documented error.
    fn check_against_std(s: &str) {
        let ours = parse_f32(s);
        match s.parse::<f32>() {
            Ok(v) if significant_digits(s) > MAX_DIGITS as usize => {
                assert_eq!(ours, Err(Error::TooManyDigits), "{s} (std {v})")
            }
            Ok(v) if v.is_finite() => {
                let got = ours.unwrap_or_else(|e| panic!("{s}: {e:?}, std {v}"));
                assert_eq!(got.to_bits(), v.to_bits(), "{s}: {got:e} vs std {v:e}");
            }
            _ => assert_eq!(ours, Err(Error::BadNumber), "{s}"),
        }
    }

    #[test]
    fn float_parser_matches_std_on_edge_cases() {
        for s in [
            "0",
            "-0",
            "+0",
            "0.0",
            "00012",
            "1",
            "-1",
            "1.5e-3",
            "12.5",
            ".5",
            "5.",
            "-.5e1",
            "150",
            "0.16",
            "1e10",
            "1E10",
            "1e+10",
            "3.4028235e38",
            "3.4028236e38",
            "3.40282356e38",
            "3.40282357e38",
            "1e39",
            "1e-45",
            "7e-46",
            "7.006e-46",
            "7.0064923216240862e-46",
            "7.0064923216240863e-46",
            "1.4012984e-45",
            "1.1754942e-38",
            "1.17549435e-38",
            "16777217",
            "16777219",
            "33554433",
            "0.000000000000000000000000000000000000000000001",
            "9999999999999999999",
            "99999999999999999999",
            "1000000000000000000000000",
            "0.1000000000000000000001",
            "123456789.123456789",
            "2.5",
            "8388608.5",
            "8388609.5",
            "1e-65",
            "1e-99999",
            "1e99999",
            "0e99999",
            "",
            ".",
            "-",
            "+",
            "e5",
            "1e",
            "1e+",
            "1e-",
            "--1",
            "+-1",
            "1.2.3",
            "0x10",
            "1_000",
            "inf",
            "-inf",
            "nan",
            "NaN",
            "infinity",
            "1 ",
            " 1",
            "1e5.5",
            "1..2",
            "1ee5",
            "١",
        ] {
            check_against_std(s);
        }
        assert_eq!(parse_f32("-0").map(|v| v.is_sign_negative()), Ok(true));
        assert_eq!(parse_f32("1e39"), Err(Error::BadNumber));
        assert_eq!(parse_f32("12345678901234567891"), Err(Error::TooManyDigits));
        // Leading and trailing zeros are not significant digits.
        assert_eq!(
            parse_f32("0.000000000000000000000000001500000000000000000000"),
            Ok(1.5e-27)
        );
        assert_eq!(parse_usize("+17"), Ok(17));
        assert_eq!(parse_usize("-1"), Err(Error::BadNumber));
        assert_eq!(parse_usize(""), Err(Error::BadNumber));
        assert_eq!(
            parse_usize("99999999999999999999999"),
            Err(Error::OutOfRange)
        );
    }

    #[test]
    fn number_writer_prints_like_g8() {
        let f = |v: f32| {
            let mut r = Reply::<32>::new();
            r.push_f32(v);
            r.as_str().to_string()
        };
        assert_eq!(f(0.16), "0.16");
        assert_eq!(f(150.0), "150");
        assert_eq!(f(20_000.0), "20000");
        assert_eq!(f(-2.5), "-2.5");
        assert_eq!(f(0.0), "0");
        assert_eq!(f(1.5e-5), "1.5e-5");
        assert_eq!(f(0.0001), "0.0001");
        assert_eq!(f(12_345_678.0), "12345678");
        assert_eq!(f(123_456_790.0), "123456790");
        assert_eq!(f(1.5e9), "1.5e9");
        assert_eq!(f(f32::MAX), "3.4028235e38");
        assert_eq!(f(f32::MIN_POSITIVE), "1.1754944e-38");
        assert_eq!(f(1e-45), "1.4013e-45");
        assert_eq!(f(f32::from_bits(3_351_468_226)), "-100017.516");
        assert_eq!(f(f32::NAN), "nan");
        assert_eq!(f(f32::NEG_INFINITY), "-inf");
        let mut r = Reply::<64>::new();
        r.push_str("ok ");
        r.push_i32(-42);
        r.push_bytes(b" ");
        r.push_u32(u32::MAX);
        r.push_bytes(b" ");
        r.push_padded("ab", 4);
        r.push_str("|");
        r.push_right("ab", 4);
        r.push_bytes(b" ");
        r.push_fixed(1205, 2);
        r.push_bytes(b" ");
        r.push_fixed(40_000, 3);
        assert_eq!(r.as_str(), "ok -42 4294967295 ab  |  ab 12.05 40.000");
        r.clear();
        r.push_error(Error::UnknownParam);
        assert_eq!(r.as_str(), Error::UnknownParam.to_string());
    }

    proptest! {
        #[test]
        fn float_parser_matches_std_on_printed_floats(bits in any::<u32>(), prec in 0usize..12) {
            let v = f32::from_bits(bits);
            prop_assume!(v.is_finite());
            for s in [
                format!("{v}"),
                format!("{v:e}"),
                format!("{v:.prec$e}"),
                format!("{v:.prec$}"),
                format!("{:.prec$e}", v as f64 * 1.000_000_03),
            ] {
                check_against_std(&s);
            }
        }

        #[test]
        fn float_parser_matches_std_on_decimal_strings(
            neg in any::<bool>(),
            digits in "[0-9]{1,22}",
            dot in 0usize..23,
            exp in proptest::option::of(-70i32..45),
        ) {
            let dot = dot.min(digits.len());
            let mut s = String::new();
            if neg {
                s.push('-');
            }
            s.push_str(&digits[..dot]);
            s.push('.');
            s.push_str(&digits[dot..]);
            if let Some(e) = exp {
                s.push_str(&format!("e{e}"));
            }
            check_against_std(&s);
        }

        #[test]
        fn printed_numbers_read_back(bits in any::<u32>()) {
            let v = f32::from_bits(bits);
            prop_assume!(v.is_finite());
            let mut r = Reply::<32>::new();
            r.push_f32(v);
            let back = parse_f32(r.as_str()).unwrap();
            prop_assert_eq!(back.to_bits(), v.to_bits(), "{:e} -> {} -> {:e}", v, r.as_str(), back);
            // No longer than needed by more than 3 digits: core's shortest form.
            let shortest = significant_digits(&format!("{:e}", v));
            prop_assert!(significant_digits(r.as_str()) <= shortest.max(6));
        }

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
                    "rise", "stats", "reset", "hold", "now", "arm", "steps", "table",
                    "add", "clear", "len", "raster", "lissajous", "axis",
                ][..]).prop_map(|s| s.to_string()),
                "[a-z0-9.]{0,6}",
            ],
            0..12)) {
            let line = words.join(" ");
            let _ = parse(line.as_bytes());
        }
    }
}
