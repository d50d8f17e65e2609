//! Measured and simulated records: one CSV convention for every tool that reads or writes
//! one (`piezo sim --out`, `piezo serial record`, `piezo fit`, `diagnose`, `predict`).
//!
//! ```text
//! # any number of comment lines (kept, written back)
//! t_s,u_V,y_um,r   <- header: time, input(s), output(s), other columns by name
//! 0.000,1.8,-123.0,0
//! ```
//!
//! **Units are in the header names**: a column is `<name>_<unit>` (also read: `<name> [unit]`
//! and `<name> (unit)`, as spreadsheets write them). The roles come from the name: `t` is
//! the time, `u` or `u1..uk` the inputs, `y` or `y1..yn` the outputs (multi-channel:
//! `u1_V,u2_V,y1_um,y2_um`); every other column is kept by its full header name (`r`,
//! `ref_um`, `y_meas`), its values as they are. Accepted units, converted on reading to the
//! internal s, V and um:
//!
//! | quantity | units (factor to the internal unit) |
//! |---|---|
//! | time `t` | `s`, `ms` (1e-3), `us` / `µs` (1e-6) |
//! | input `u` | `V`, `volts` (the firmware's signal names), `mV` (1e-3) |
//! | output `y` | `um` / `µm`, `nm` (1e-3), `mm` (1e3), `m` (1e6) |
//!
//! A `_suffix` that is no known unit is part of the name (`y_meas` is an extra column, not
//! `y` in "meas"); a bracketed unit is always a unit, and an unknown one on a time, input or
//! output column is refused (`y [ft]`: "unknown length unit"), as is a unit of the wrong
//! quantity (`u_um`). Files without units (`t,u,y`, the measured records in `shared/data`)
//! are read in the default units s, V and um with their values as they are, and the reader
//! says so in [`Record::unit_note`] (the tools print it). A record written back keeps
//! that: units in the header only when every time, input and output column stated one.
//!
//! `piezo serial record` writes `i,t_s,ref_um,y_um,u_volts,...`: the firmware's signal
//! names already end in their unit, so `t_s`, `u_volts` and `y_um` are the time, input and
//! output of this convention and the other signals are extras. Columns of foreign files
//! (or both axes of an XY capture, `u_volts,u1_volts`) are chosen with a [`Layout`]
//! (`--t-col`, `--u-col`, `--y-col`); errors name the missing column and list those present.
//!
//! Samples must be uniformly spaced in `t` (a jitter of up to [`JITTER`] of the
//! median step is accepted, e.g. time stamps printed with few digits). Every value must be finite.
//! Channels are stored column-major: `u[k][i]` is input `k` at sample `i`.

// `!(x > y)` keeps NaN out; intended.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod units;
pub use units::{split_unit, Quantity};

use anyhow::Context as _;
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
    /// `Some` when a time, input or output column stated no unit: which ones, and the
    /// units they were read in (the tools print it). `None`: every unit was stated (and
    /// the values converted to s, V, um).
    pub unit_note: Option<String>,
}

/// Where a record keeps its time, inputs and outputs, and the units of those columns
/// that state none. The default finds `t`, `u`/`u1..uk`, `y`/`y1..yn` by name (each with
/// or without a unit) and reads unitless columns in s, V and um.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Time column by its full header name (`None`: `t` or `t_<unit>`).
    pub t: Option<String>,
    /// Input columns by full header name, in channel order (empty: by name).
    pub u: Vec<String>,
    /// Output columns by full header name, in channel order (empty: by name).
    pub y: Vec<String>,
    /// Unit of input columns that name none (a voltage unit).
    pub u_unit: String,
    /// Unit of output columns that name none (a length unit).
    pub y_unit: String,
    /// A record without output columns is accepted (`y` is then empty): input records of
    /// `piezo predict`.
    pub outputs_optional: bool,
}

impl Default for Layout {
    fn default() -> Self {
        Self {
            t: None,
            u: Vec::new(),
            y: Vec::new(),
            u_unit: Quantity::Voltage.internal().into(),
            y_unit: Quantity::Length.internal().into(),
            outputs_optional: false,
        }
    }
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

/// Channel columns of `base` found by name: `base` alone or `base1..basek` (with or without
/// a unit), as header positions in channel order. `optional`: none is no error.
fn auto_channels(
    names: &[&str],
    parts: &[(&str, Option<&str>)],
    base: char,
    optional: bool,
    line: usize,
) -> Result<Vec<usize>, RecordError> {
    // (header position, channel number), number 0 = plain `base`.
    let idx: Vec<(usize, usize)> = parts
        .iter()
        .enumerate()
        .filter_map(|(j, (n, _))| channel(n, base).map(|k| (j, k)))
        .collect();
    if idx.is_empty() {
        if optional {
            return Ok(Vec::new());
        }
        // `y_ft`: looks like an output with a unit this reader does not know.
        let hints: Vec<String> = names
            .iter()
            .filter_map(|n| {
                let (name, unit) = n.rsplit_once('_')?;
                channel(name, base).map(|_| format!("`{}`: unknown unit `{}`", clip(n), clip(unit)))
            })
            .collect();
        let hint = if hints.is_empty() {
            String::new()
        } else {
            format!(" ({})", hints.join(", "))
        };
        return err(
            line,
            format!(
                "header has no `{base}` column (need `{base}` or `{base}1`, `{base}2`, ..., optionally with a unit as in `{base}_{}`; or choose columns with --{base}-col){hint}; the columns are {}",
                match base {
                    'u' => Quantity::Voltage.internal(),
                    _ => Quantity::Length.internal(),
                },
                listing(names)
            ),
        );
    }
    let plain = idx.iter().filter(|&&(_, n)| n == 0).count();
    if plain > 1 {
        let cols: Vec<String> = idx
            .iter()
            .map(|&(j, _)| format!("`{}`", names[j]))
            .collect();
        return err(
            line,
            format!(
                "header has {plain} `{base}` columns ({}); choose with --{base}-col",
                cols.join(", ")
            ),
        );
    }
    if plain == 1 {
        if idx.len() > 1 {
            return err(
                line,
                format!("header mixes `{base}` with numbered `{base}1..` columns; choose with --{base}-col"),
            );
        }
        return Ok(vec![idx[0].0]);
    }
    let k = idx.len();
    let mut out = Vec::with_capacity(k);
    for want in 1..=k {
        match idx.iter().find(|&&(_, n)| n == want) {
            Some(&(j, _)) => out.push(j),
            None => {
                return err(
                    line,
                    format!("header has {k} `{base}` columns but no `{base}{want}` (numbering must be 1..{k})"),
                )
            }
        }
    }
    Ok(out)
}

/// The header names as a list for errors.
fn listing(names: &[&str]) -> String {
    names
        .iter()
        .map(|n| format!("`{}`", clip(n)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A parsed header: where each column goes and the factor to its internal unit.
struct Header {
    map: Vec<Col>,
    nu: usize,
    ny: usize,
    extras: Vec<String>,
    scale: Vec<f64>,
    unit_note: Option<String>,
}

impl Record {
    /// A single- or multi-channel record from columns (s, V, um; `u[k][i]` is input `k` at
    /// sample `i`); checks it like a parsed file.
    ///
    /// ```
    /// use piezo_ident::record::Record;
    /// let t = vec![0.0, 1e-3, 2e-3];
    /// let r = Record::new(t.clone(), vec![vec![0.0, 1.0, 2.0]], vec![vec![0.0, 0.5, 1.1]]).unwrap();
    /// assert_eq!((r.len(), r.sample_rate_hz().round()), (3, 1000.0));
    /// assert!(r.to_csv().starts_with("t_s,u_V,y_um\n")); // built in s, V, um: stated
    /// // A gap in time is refused, as in a file.
    /// let err = Record::new(vec![0.0, 1e-3, 5e-3], r.u.clone(), r.y.clone()).unwrap_err();
    /// assert!(err.to_string().contains("uniform"), "{err}");
    /// ```
    pub fn new(t: Vec<f64>, u: Vec<Vec<f64>>, y: Vec<Vec<f64>>) -> Result<Self, RecordError> {
        let r = Self {
            comments: Vec::new(),
            t,
            u,
            y,
            extra: Vec::new(),
            unit_note: None,
        };
        r.check(false)?;
        Ok(r)
    }

    /// A record of inputs only (`y` empty: what a model is simulated on), checked like
    /// [`Record::new`].
    pub fn inputs(t: Vec<f64>, u: Vec<Vec<f64>>) -> Result<Self, RecordError> {
        let r = Self {
            comments: Vec::new(),
            t,
            u,
            y: Vec::new(),
            extra: Vec::new(),
            unit_note: None,
        };
        r.check(true)?;
        Ok(r)
    }

    /// Reads a CSV record from a file, columns and units found by name
    /// ([`Layout::default`]).
    pub fn read(path: impl AsRef<Path>) -> anyhow::Result<Self> {
        Self::read_with(path, &Layout::default())
    }

    /// Reads a CSV record from a file with the columns and default units of `layout`.
    pub fn read_with(path: impl AsRef<Path>, layout: &Layout) -> anyhow::Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read(path)
            .with_context(|| format!("cannot read record {}", path.display()))?;
        let text = String::from_utf8(text).map_err(|e| {
            anyhow::anyhow!(
                "record {}: not UTF-8 text (byte {})",
                path.display(),
                e.utf8_error().valid_up_to()
            )
        })?;
        Self::parse_with(&text, layout)
            .map_err(|e| anyhow::anyhow!("record {}: {e}", path.display()))
    }

    /// Parses CSV text ([`Layout::default`]).
    pub fn parse(text: &str) -> Result<Self, RecordError> {
        Self::parse_with(text, &Layout::default())
    }

    /// Parses CSV text with the columns and default units of `layout`; time, inputs and
    /// outputs are converted to s, V and um.
    ///
    /// ```
    /// use piezo_ident::record::{Layout, Record};
    /// let r = Record::parse("t_ms,u_mV,y_nm\n0,1500,2500\n1,1600,2600\n").unwrap();
    /// assert_eq!((r.t[1], r.u[0][0], r.y[0][0], r.unit_note), (1e-3, 1.5, 2.5, None));
    /// let text = "time [s],drive (V),pos_um\n0,1,2\n0.5,1,2\n";
    /// let own = |s: &str| vec![s.to_string()];
    /// let l = Layout { t: Some("time [s]".into()), u: own("drive (V)"), y: own("pos_um"), ..Layout::default() };
    /// assert_eq!(Record::parse_with(text, &l).unwrap().y, vec![vec![2.0, 2.0]]);
    /// ```
    pub fn parse_with(text: &str, layout: &Layout) -> Result<Self, RecordError> {
        let mut comments = Vec::new();
        let mut head: Option<(Header, usize)> = None;
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
            let Some((h, header_line)) = &head else {
                let h = Self::header(s, line, layout)?;
                u = vec![Vec::new(); h.nu];
                y = vec![Vec::new(); h.ny];
                extra = h.extras.iter().map(|n| (n.clone(), Vec::new())).collect();
                head = Some((h, line));
                continue;
            };
            let fields: Vec<&str> = s.split(',').collect();
            if fields.len() != h.map.len() {
                return err(
                    line,
                    format!(
                        "{} columns, but the header (line {header_line}) has {}",
                        fields.len(),
                        h.map.len()
                    ),
                );
            }
            for (j, (f, c)) in fields.iter().zip(&h.map).enumerate() {
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
                // A unit conversion can overflow a finite value.
                let v = v * h.scale[j];
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
        let Some((h, _)) = head else {
            return err(0, "no header line (expected e.g. `t_s,u_V,y_um`)");
        };
        let r = Self {
            comments,
            t,
            u,
            y,
            extra,
            unit_note: h.unit_note,
        };
        r.check_time(|i| row_lines.get(i).copied().unwrap_or(0))?;
        Ok(r)
    }

    /// Parses the header: the column of time, each input and output (by `layout` or by
    /// name), the extras, and each column's unit factor.
    fn header(s: &str, line: usize, layout: &Layout) -> Result<Header, RecordError> {
        let names: Vec<&str> = s.split(',').map(str::trim).collect();
        for (j, n) in names.iter().enumerate() {
            if n.is_empty() {
                return err(line, format!("header column {} has no name", j + 1));
            }
            if n.parse::<f64>().is_ok() {
                return err(
                    line,
                    format!(
                        "expected a header line (e.g. `t_s,u_V,y_um`), found numbers (`{}`)",
                        clip(n)
                    ),
                );
            }
            if names[..j].contains(n) {
                return err(line, format!("header names column `{}` twice", clip(n)));
            }
        }
        let parts: Vec<(&str, Option<&str>)> = names.iter().map(|n| split_unit(n)).collect();
        let find = |want: &str, role: &str| -> Result<usize, RecordError> {
            names.iter().position(|n| *n == want.trim()).map_or_else(
                || {
                    err(
                        line,
                        format!(
                            "no {role} column `{}` in the header; the columns are {}",
                            clip(want),
                            listing(&names)
                        ),
                    )
                },
                Ok,
            )
        };
        let t_col = match &layout.t {
            Some(want) => find(want, "time")?,
            None => {
                let ts: Vec<usize> = (0..names.len()).filter(|&j| parts[j].0 == "t").collect();
                match ts.as_slice() {
                    [j] => *j,
                    [] => {
                        return err(
                            line,
                            format!(
                                "header has no `t` column (time: `t` in seconds, or with a unit as in `t_s`, `t_ms`; or choose it with --t-col); the columns are {}",
                                listing(&names)
                            ),
                        )
                    }
                    more => {
                        let cols: Vec<&str> = more.iter().map(|&j| names[j]).collect();
                        return err(
                            line,
                            format!(
                                "header has {} time columns ({}); choose one with --t-col",
                                more.len(),
                                listing(&cols)
                            ),
                        );
                    }
                }
            }
        };
        let pick = |wanted: &[String], base: char, role: &str, optional: bool| {
            if wanted.is_empty() {
                auto_channels(&names, &parts, base, optional, line)
            } else {
                wanted.iter().map(|w| find(w, role)).collect()
            }
        };
        let us = pick(&layout.u, 'u', "input", false)?;
        let ys = pick(&layout.y, 'y', "output", layout.outputs_optional)?;
        let roles: Vec<(usize, Quantity, &str)> = std::iter::once((t_col, Quantity::Time, "s"))
            .chain(
                us.iter()
                    .map(|&j| (j, Quantity::Voltage, layout.u_unit.as_str())),
            )
            .chain(
                ys.iter()
                    .map(|&j| (j, Quantity::Length, layout.y_unit.as_str())),
            )
            .collect();
        let mut map = vec![Col::Extra(0); names.len()];
        let mut seen = vec![false; names.len()];
        let mut scale = vec![1.0; names.len()];
        let mut unitless = Vec::new();
        for (k, &(j, q, default)) in roles.iter().enumerate() {
            if seen[j] {
                return err(
                    line,
                    format!(
                        "column `{}` is chosen twice (time, input and output columns must differ)",
                        clip(names[j])
                    ),
                );
            }
            seen[j] = true;
            map[j] = match k {
                0 => Col::T,
                k if k <= us.len() => Col::U(k - 1),
                k => Col::Y(k - 1 - us.len()),
            };
            scale[j] = match parts[j].1 {
                Some(unit) => q
                    .factor(unit)
                    .or_else(|m| err(line, format!("column `{}`: {m}", clip(names[j]))))?,
                None => {
                    unitless.push(format!("`{}` ({default})", clip(names[j])));
                    q.factor(default).or_else(|m| {
                        err(
                            line,
                            format!(
                                "column `{}` states no unit, and the default {} unit: {m}",
                                clip(names[j]),
                                q.name()
                            ),
                        )
                    })?
                }
            };
        }
        let mut extras = Vec::new();
        for (j, n) in names.iter().enumerate() {
            if !seen[j] {
                map[j] = Col::Extra(extras.len());
                extras.push(n.to_string());
            }
        }
        let unit_note = (!unitless.is_empty()).then(|| {
            format!(
                "no unit in the header for {}: read in the units in parentheses (a header such as `t_s,u_V,y_um` states them)",
                unitless.join(", ")
            )
        });
        Ok(Header {
            map,
            nu: us.len(),
            ny: ys.len(),
            extras,
            scale,
            unit_note,
        })
    }

    /// Structure and time checks for records built in code.
    fn check(&self, outputs_optional: bool) -> Result<(), RecordError> {
        if self.u.is_empty() || (self.y.is_empty() && !outputs_optional) {
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
            unit_note: self.unit_note.clone(),
        }
    }

    /// The header names of time, inputs and outputs as [`Record::to_csv`] writes them:
    /// `t_s`, `u_V` or `u1_V..`, `y_um` or `y1_um..`; without units (`t`, `u`, `y`) when
    /// the record was read with a unit assumed ([`Record::unit_note`]).
    pub fn header_names(&self) -> (String, Vec<String>, Vec<String>) {
        let unit = |q: Quantity| match self.unit_note {
            None => format!("_{}", q.internal()),
            Some(_) => String::new(),
        };
        let names = |base: char, k: usize, q: Quantity| -> Vec<String> {
            if k == 1 {
                vec![format!("{base}{}", unit(q))]
            } else {
                (1..=k).map(|i| format!("{base}{i}{}", unit(q))).collect()
            }
        };
        (
            format!("t{}", unit(Quantity::Time)),
            names('u', self.u.len(), Quantity::Voltage),
            names('y', self.y.len(), Quantity::Length),
        )
    }

    /// CSV text: comments, header (units as in [`Record::header_names`]), rows (shortest
    /// round-trip number format).
    pub fn to_csv(&self) -> String {
        let mut s = String::new();
        for c in &self.comments {
            let _ = writeln!(s, "#{c}");
        }
        let (t, u, y) = self.header_names();
        let mut header = vec![t];
        header.extend(u);
        header.extend(y);
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
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data")
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
mod tests;
