//! Measured and simulated records: CSV with `#` comments, header `t,u|u1..uk,y|y1..yn`.
//!
//! ```text
//! # any number of comment lines (kept, written back)
//! t,u,y,r          <- header: `t`, `u` or `u1..uk`, `y` or `y1..yn`, other columns by name
//! 0.000,1.8,-123.0,0
//! ```
//! Samples must be uniformly spaced in `t` (a jitter of up to [`JITTER`] of the is
//! median step is accepted, e.g. time stamps printed with few digits). Every value must be finite.
//! Channels are stored column-major: `u[k][i]` is input `k` at sample `i`.

// `!(x > y)` keeps NaN out; intended.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::fmt::{self, Write as _};
use std::path::Path;

/// Largest accepted deviation of one time step from the median step, relative to the mean.
pub const JITTER: f64 = 0.05;

/// A record: time, inputs, outputs, other named columns, and the comment lines.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Comment lines without the leading `#` (leading space kept).
    pub comments: Vec<String>,
    /// Sample times (s), strictly increasing and uniform up to [`JITTER`].
    pub t: Vec<f64>,
    /// Input channels, `u[k][i]`.
    pub u: Vec<Vec<f64>>,
    /// Output channels, `y[k][i]`.
    pub y: Vec<Vec<f64>>,
    /// Other columns by header name, in file order.
    pub extra: Vec<(String, Vec<f64>)>,
}

/// Why a record could not be read; `line` is 1-based (0 when no line applies).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordError {
    pub line: usize,
    pub msg: String,
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}", self.msg)
        } else {
            write!(f, "line {}: {}", self.line, self.msg)
        }
    }
}

impl std::error::Error for RecordError {}

fn err<T>(line: usize, msg: impl Into<String>) -> Result<T, RecordError> {
    Err(RecordError {
        line,
        msg: msg.into(),
    })
}

/// Where a header column goes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Col {
    T,
    U(usize),
    Y(usize),
    Extra(usize),
}

/// `name` is `base` alone (index 0) or `base` followed by a positive integer.
fn channel(name: &str, base: char) -> Option<usize> {
    let rest = name.strip_prefix(base)?;
    if rest.is_empty() {
        Some(0)
    } else if rest.bytes().all(|b| b.is_ascii_digit()) && !rest.starts_with('0') {
        rest.parse().ok()
    } else {
        None
    }
}

/// Maps channel names to positions: either exactly `base` or exactly `base1..basek`.
fn channel_slots(idx: &[(usize, usize)], base: char, line: usize) -> Result<usize, RecordError> {
    // idx: (header position, channel number), number 0 = plain `base`.
    if idx.is_empty() {
        return err(
            line,
            format!("header has no `{base}` column (need `{base}` or `{base}1`, `{base}2`, ...)"),
        );
    }
    if idx.iter().any(|&(_, n)| n == 0) {
        if idx.len() > 1 {
            return err(
                line,
                format!("header mixes `{base}` with numbered `{base}1..` columns"),
            );
        }
        return Ok(1);
    }
    let k = idx.len();
    for want in 1..=k {
        if !idx.iter().any(|&(_, n)| n == want) {
            return err(line, format!("header has {k} `{base}` columns but no `{base}{want}` (numbering must be 1..{k})"));
        }
    }
    Ok(k)
}

impl Record {
    /// A single- or multi-channel record from columns; checks it like a parsed file.
    pub fn new(t: Vec<f64>, u: Vec<Vec<f64>>, y: Vec<Vec<f64>>) -> Result<Self, RecordError> {
        let r = Self {
            comments: Vec::new(),
            t,
            u,
            y,
            extra: Vec::new(),
        };
        r.check()?;
        Ok(r)
    }

    /// Reads a CSV record from a file.
    pub fn read(path: impl AsRef<Path>) -> anyhow::Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read(path)
            .map_err(|e| anyhow::anyhow!("cannot read record {}: {e}", path.display()))?;
        let text = String::from_utf8(text).map_err(|e| {
            anyhow::anyhow!(
                "record {}: not UTF-8 text (byte {})",
                path.display(),
                e.utf8_error().valid_up_to()
            )
        })?;
        Self::parse(&text).map_err(|e| anyhow::anyhow!("record {}: {e}", path.display()))
    }

    /// Parses CSV text.
    pub fn parse(text: &str) -> Result<Self, RecordError> {
        let mut comments = Vec::new();
        let mut cols: Option<(Vec<Col>, usize)> = None;
        let mut t = Vec::new();
        let mut u: Vec<Vec<f64>> = Vec::new();
        let mut y: Vec<Vec<f64>> = Vec::new();
        let mut extra: Vec<(String, Vec<f64>)> = Vec::new();
        // Line of the first and of each data row, for errors found after parsing.
        let mut row_lines = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = i + 1;
            let s = raw.trim();
            if let Some(c) = s.strip_prefix('#') {
                comments.push(c.to_string());
                continue;
            }
            if s.is_empty() {
                continue;
            }
            let Some((map, header_line)) = &cols else {
                let (map, nu, ny, names) = Self::header(s, line)?;
                u = vec![Vec::new(); nu];
                y = vec![Vec::new(); ny];
                extra = names.into_iter().map(|n| (n, Vec::new())).collect();
                cols = Some((map, line));
                continue;
            };
            let fields: Vec<&str> = s.split(',').collect();
            if fields.len() != map.len() {
                return err(
                    line,
                    format!(
                        "{} columns, but the header (line {header_line}) has {}",
                        fields.len(),
                        map.len()
                    ),
                );
            }
            for (j, (f, c)) in fields.iter().zip(map).enumerate() {
                let f = f.trim();
                let v: f64 = match f.parse() {
                    Ok(v) => v,
                    Err(_) => {
                        return err(
                            line,
                            format!("column {}: `{}` is not a number", j + 1, clip(f)),
                        )
                    }
                };
                if !v.is_finite() {
                    return err(
                        line,
                        format!("column {}: `{}` is not finite", j + 1, clip(f)),
                    );
                }
                let dst = match *c {
                    Col::T => &mut t,
                    Col::U(k) => &mut u[k],
                    Col::Y(k) => &mut y[k],
                    Col::Extra(k) => &mut extra[k].1,
                };
                dst.push(v);
            }
            row_lines.push(line);
        }
        if cols.is_none() {
            return err(0, "no header line (expected e.g. `t,u,y`)");
        }
        let r = Self {
            comments,
            t,
            u,
            y,
            extra,
        };
        r.check_time(|i| row_lines.get(i).copied().unwrap_or(0))?;
        Ok(r)
    }

    /// Parses the header: column map, number of inputs and outputs, extra names.
    #[allow(clippy::type_complexity)]
    fn header(s: &str, line: usize) -> Result<(Vec<Col>, usize, usize, Vec<String>), RecordError> {
        let names: Vec<&str> = s.split(',').map(str::trim).collect();
        for (j, n) in names.iter().enumerate() {
            if n.is_empty() {
                return err(line, format!("header column {} has no name", j + 1));
            }
            if n.parse::<f64>().is_ok() {
                return err(
                    line,
                    format!(
                        "expected a header line (e.g. `t,u,y`), found numbers (`{}`)",
                        clip(n)
                    ),
                );
            }
            if names[..j].contains(n) {
                return err(line, format!("header names column `{}` twice", clip(n)));
            }
        }
        let mut ts = 0;
        let mut us = Vec::new();
        let mut ys = Vec::new();
        let mut extras = Vec::new();
        for (j, n) in names.iter().enumerate() {
            if *n == "t" {
                ts += 1;
            } else if let Some(k) = channel(n, 'u') {
                us.push((j, k));
            } else if let Some(k) = channel(n, 'y') {
                ys.push((j, k));
            } else {
                extras.push(n.to_string());
            }
        }
        if ts == 0 {
            return err(line, "header has no `t` column (time in seconds)");
        }
        let nu = channel_slots(&us, 'u', line)?;
        let ny = channel_slots(&ys, 'y', line)?;
        let mut map = Vec::with_capacity(names.len());
        let mut e = 0;
        for (j, n) in names.iter().enumerate() {
            let slot = |v: &[(usize, usize)]| v.iter().find(|p| p.0 == j).map(|p| p.1.max(1) - 1);
            map.push(if *n == "t" {
                Col::T
            } else if let Some(k) = slot(&us) {
                Col::U(k)
            } else if let Some(k) = slot(&ys) {
                Col::Y(k)
            } else {
                e += 1;
                Col::Extra(e - 1)
            });
        }
        Ok((map, nu, ny, extras))
    }

    /// Structure and time checks for records built in code.
    fn check(&self) -> Result<(), RecordError> {
        if self.u.is_empty() || self.y.is_empty() {
            return err(
                0,
                "a record needs at least one input and one output channel",
            );
        }
        let n = self.t.len();
        for (name, c) in self
            .u
            .iter()
            .map(|c| ("u", c))
            .chain(self.y.iter().map(|c| ("y", c)))
            .chain(self.extra.iter().map(|(n, c)| (n.as_str(), c)))
        {
            if c.len() != n {
                return err(
                    0,
                    format!("column `{name}` has {} samples, `t` has {n}", c.len()),
                );
            }
            if let Some(i) = c.iter().position(|v| !v.is_finite()) {
                return err(0, format!("column `{name}` sample {i} is not finite"));
            }
        }
        if let Some(i) = self.t.iter().position(|v| !v.is_finite()) {
            return err(0, format!("t sample {i} is not finite"));
        }
        self.check_time(|_| 0)
    }

    /// At least two rows, `t` strictly increasing and uniform up to [`JITTER`].
    fn check_time(&self, line_of: impl Fn(usize) -> usize) -> Result<(), RecordError> {
        let n = self.t.len();
        if n < 2 {
            return err(0, format!("{n} data rows; a record needs at least 2"));
        }
        for i in 1..n {
            if !(self.t[i] > self.t[i - 1]) {
                return err(
                    line_of(i),
                    format!(
                        "t = {} does not increase (previous row t = {})",
                        self.t[i],
                        self.t[i - 1]
                    ),
                );
            }
        }
        // Median step: one gap or glitch does not move the reference.
        let mut steps: Vec<f64> = self.t.windows(2).map(|w| w[1] - w[0]).collect();
        steps.sort_by(f64::total_cmp);
        let dt = steps[steps.len() / 2];
        if !(dt > 0.0) || !dt.is_finite() {
            return err(0, "time step is not positive and finite");
        }
        for i in 1..n {
            let step = self.t[i] - self.t[i - 1];
            if !((step - dt).abs() <= JITTER * dt) {
                return err(
                    line_of(i),
                    format!(
                        "non-uniform sampling: step {step:.6e} s from t = {} differs from the median step {dt:.6e} s by more than {:.0} %",
                        self.t[i - 1],
                        JITTER * 100.0
                    ),
                );
            }
        }
        Ok(())
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True for a record without samples (never the case for a checked record).
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Mean sample period (s).
    pub fn dt(&self) -> f64 {
        match (self.t.first(), self.t.last()) {
            (Some(a), Some(b)) if self.t.len() > 1 => (b - a) / (self.t.len() - 1) as f64,
            _ => f64::NAN,
        }
    }

    /// Sample rate (Hz) from the mean period.
    pub fn sample_rate_hz(&self) -> f64 {
        1.0 / self.dt()
    }

    /// A column by header name (`t`, `u`, `u2`, `y`, `y1`, or an extra name).
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        if name == "t" {
            return Some(&self.t);
        }
        for (base, chans) in [('u', &self.u), ('y', &self.y)] {
            if let Some(k) = channel(name, base) {
                let idx = match (k, chans.len()) {
                    (0, 1) => 0,
                    (0, _) => return None,
                    (k, _) => k - 1,
                };
                return chans.get(idx).map(|c| c.as_slice());
            }
        }
        self.extra
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, c)| c.as_slice())
    }

    /// Samples `start..end` (clamped) as a new record with the same comments and columns.
    pub fn slice(&self, start: usize, end: usize) -> Self {
        let end = end.min(self.len());
        let start = start.min(end);
        let cut = |c: &Vec<f64>| c[start..end].to_vec();
        Self {
            comments: self.comments.clone(),
            t: cut(&self.t),
            u: self.u.iter().map(cut).collect(),
            y: self.y.iter().map(cut).collect(),
            extra: self
                .extra
                .iter()
                .map(|(n, c)| (n.clone(), cut(c)))
                .collect(),
        }
    }

    /// CSV text: comments, header, rows (shortest round-trip number format).
    pub fn to_csv(&self) -> String {
        let mut s = String::new();
        for c in &self.comments {
            let _ = writeln!(s, "#{c}");
        }
        let names = |base: char, k: usize| -> Vec<String> {
            if k == 1 {
                vec![base.to_string()]
            } else {
                (1..=k).map(|i| format!("{base}{i}")).collect()
            }
        };
        let mut header = vec!["t".to_string()];
        header.extend(names('u', self.u.len()));
        header.extend(names('y', self.y.len()));
        header.extend(self.extra.iter().map(|(n, _)| n.clone()));
        s.push_str(&header.join(","));
        s.push('\n');
        for i in 0..self.len() {
            let _ = write!(s, "{}", self.t[i]);
            for c in self
                .u
                .iter()
                .chain(&self.y)
                .chain(self.extra.iter().map(|(_, c)| c))
            {
                let _ = write!(s, ",{}", c.get(i).copied().unwrap_or(f64::NAN));
            }
            s.push('\n');
        }
        s
    }

    /// Writes the record as CSV, creating parent folders.
    pub fn write(&self, path: impl AsRef<Path>) -> anyhow::Result<()> {
        let path = path.as_ref();
        if let Some(dir) = path.parent() {
            if !dir.as_os_str().is_empty() {
                std::fs::create_dir_all(dir)?;
            }
        }
        std::fs::write(path, self.to_csv())
            .map_err(|e| anyhow::anyhow!("cannot write record {}: {e}", path.display()))
    }
}

/// The shared data folder: `$PIEZO_DATA`, else `shared/data` beside the repository.
pub fn data_dir() -> std::path::PathBuf {
    std::env::var_os("PIEZO_DATA")
        .map(Into::into)
        .unwrap_or_else(|| {
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data")
        })
}

/// Shortens user text quoted in an error.
fn clip(s: &str) -> String {
    if s.chars().count() > 40 {
        format!("{}...", s.chars().take(40).collect::<String>())
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn parses_comments_channels_and_extras() {
        let r =
            Record::parse("# hello\n# fs = 2 Hz\nt,y2,u,r,y1\n0,1,2,3,4\n0.5,5,6,7,8\n").unwrap();
        assert_eq!(r.comments, vec![" hello", " fs = 2 Hz"]);
        assert_eq!(r.t, vec![0.0, 0.5]);
        assert_eq!(r.u, vec![vec![2.0, 6.0]]);
        assert_eq!(r.y, vec![vec![4.0, 8.0], vec![1.0, 5.0]]);
        assert_eq!(r.extra, vec![("r".to_string(), vec![3.0, 7.0])]);
        assert_eq!(r.sample_rate_hz(), 2.0);
        assert_eq!(r.column("y2"), Some(&[1.0, 5.0][..]));
        assert_eq!(r.column("r"), Some(&[3.0, 7.0][..]));
        assert_eq!(r.column("y"), None);
        // Round trip through text.
        assert_eq!(Record::parse(&r.to_csv()).unwrap(), r);
    }

    fn msg(text: &str) -> String {
        Record::parse(text).unwrap_err().to_string()
    }

    #[test]
    fn errors_name_line_and_cause() {
        assert_eq!(
            msg("t,u,y\n0,1,2\n1,x,3\n"),
            "line 3: column 2: `x` is not a number"
        );
        assert_eq!(
            msg("t,u,y\n0,1,2\n1,2\n"),
            "line 3: 2 columns, but the header (line 1) has 3"
        );
        assert_eq!(
            msg("#c\nt,u,y\n0,1,2\n1,NaN,3\n"),
            "line 4: column 2: `NaN` is not finite"
        );
        assert!(msg("t,u\n0,1\n1,2\n").contains("no `y` column"));
        assert!(msg("u,y\n0,1\n1,2\n").contains("no `t` column"));
        assert!(msg("t,u1,u3,y\n0,1,2,3\n1,1,2,3\n").contains("no `u2`"));
        assert!(msg("t,u,u1,y\n0,1,2,3\n").contains("mixes"));
        assert!(msg("t,u,y,u\n").contains("twice"));
        assert!(msg("0,1,2\n1,2,3\n").contains("found numbers"));
        assert_eq!(
            msg("t,u,y\n0,1,2\n1,1,2\n1,1,2\n"),
            "line 4: t = 1 does not increase (previous row t = 1)"
        );
        assert!(
            msg("t,u,y\n0,1,2\n1,1,2\n2,1,2\n4,1,2\n").starts_with("line 5: non-uniform sampling")
        );
        assert!(msg("t,u,y\n0,1,2\n").contains("at least 2"));
        assert!(msg("# only\n").contains("no header"));
        assert!(msg("").contains("no header"));
    }

    #[test]
    fn accepts_rounded_time_stamps() {
        let r =
            Record::parse("t,u,y\n0.0000000,1,2\n0.0013333,1,2\n0.0026667,1,2\n0.0040000,1,2\n")
                .unwrap();
        assert!((r.sample_rate_hz() - 750.0).abs() < 1e-3);
    }

    #[test]
    fn reads_every_shared_data_file() {
        let dir = data_dir();
        if !dir.exists() {
            eprintln!("skipped: {} not found (set PIEZO_DATA)", dir.display());
            return;
        }
        let mut n = 0;
        for sub in std::fs::read_dir(&dir).unwrap() {
            let sub = sub.unwrap().path();
            if !sub.is_dir() {
                continue;
            }
            for f in std::fs::read_dir(&sub).unwrap() {
                let f = f.unwrap().path();
                if f.extension().is_some_and(|e| e == "csv") {
                    let r = Record::read(&f).unwrap_or_else(|e| panic!("{e}"));
                    assert!(r.len() > 1000, "{}", f.display());
                    // The fine steering mirror has three actuators and three sensors.
                    let axes = if sub.ends_with("fsm-benchmark") { 3 } else { 1 };
                    assert_eq!((r.u.len(), r.y.len()), (axes, axes), "{}", f.display());
                    assert!(!r.comments.is_empty());
                    n += 1;
                }
            }
        }
        // 6 single-axis records and the mirror's 18 (3 levels x 6 realizations).
        assert_eq!(n, 24);
    }

    proptest! {
        #[test]
        fn never_panics_on_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
            let _ = Record::parse(&String::from_utf8_lossy(&bytes));
        }

        #[test]
        fn never_panics_on_csv_like_text(s in "[tuy0-9,.\\-e#\n NaN]{0,200}") {
            let _ = Record::parse(&s);
        }

        #[test]
        fn round_trips(u in proptest::collection::vec(-1e6f64..1e6, 2..50), fs in 1.0f64..1e5) {
            let n = u.len();
            let t: Vec<f64> = (0..n).map(|i| i as f64 / fs).collect();
            let y: Vec<f64> = u.iter().map(|v| v * 0.5).collect();
            let r = Record::new(t, vec![u.clone(), y.clone()], vec![y]).unwrap();
            prop_assert_eq!(Record::parse(&r.to_csv()).unwrap(), r);
        }
    }
}
