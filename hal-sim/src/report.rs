//! `index.html` of a command's `--out` folder (`piezo sim`, `demo`, `fit`, `diagnose`): one
//! page that works offline (inline style, no script, the plots linked relatively) with the
//! run's tables and plots and a link to every file the run wrote, so a folder of CSVs and
//! SVGs opens as one report, from disk or through `piezo ui --report DIR`.
//!
//! A command fills [`Section`]s; [`Report::write`] then links, below them, every file of the
//! folder written since [`Report::start`] that no section linked (the plots among them
//! shown), so nothing written is left out whatever path wrote it.
//!
//! The page is a few `format!`s with [`esc`]: a template engine would add a dependency for
//! less than this file.
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use anyhow::{Context, Result};
use serde_json::Value;

/// The report's file name in the `--out` folder.
pub const INDEX: &str = "index.html";

/// A file older than the run's start by more than this is not the run's (file systems with
/// coarse timestamps round down).
const MTIME_SLACK: Duration = Duration::from_secs(2);

/// Columns that name a row, first in a table of objects.
const LEAD: [&str; 9] = [
    "scenario",
    "controller",
    "name",
    "cause",
    "model",
    "record",
    "round",
    "input",
    "output",
];

/// Values of a list shown in one cell (the file has them all).
const LIST_MAX: usize = 12;

/// Escapes text for HTML (element content and quoted attributes).
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// A relative path as a URL path: `/` between the parts, bytes outside the unreserved set
/// (and `+`) percent-encoded, so `sine_ff+pid.svg` and a name with `#` or a space both work.
pub fn href(rel: &str) -> String {
    let mut o = String::new();
    for b in rel.replace('\\', "/").bytes() {
        if b.is_ascii_alphanumeric() || b"-_.~/+".contains(&b) {
            o.push(b as char);
        } else {
            let _ = write!(o, "%{b:02X}");
        }
    }
    o
}

/// A number for a table: 4 significant digits, exponent outside 1e-3 .. 1e6.
pub fn num(v: f64) -> String {
    if !v.is_finite() {
        format!("{v}")
    } else if v == 0.0 {
        "0".into()
    } else if v.fract() == 0.0 && v.abs() < 1e9 {
        format!("{v}")
    } else if (1e-3..1e6).contains(&v.abs()) {
        let digits = (3 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.3e}")
    }
}

/// One table cell.
#[derive(Clone, Debug)]
pub enum Cell {
    Text(String),
    Num(f64),
    /// Links to files of the folder (relative paths), shown by their text.
    Links(Vec<(String, String)>),
}

impl From<&str> for Cell {
    fn from(s: &str) -> Self {
        Cell::Text(s.into())
    }
}

impl From<String> for Cell {
    fn from(s: String) -> Self {
        Cell::Text(s)
    }
}

impl From<f64> for Cell {
    fn from(v: f64) -> Self {
        Cell::Num(v)
    }
}

impl From<usize> for Cell {
    fn from(v: usize) -> Self {
        Cell::Text(v.to_string())
    }
}

/// A table: a header and rows of cells.
#[derive(Clone, Debug, Default)]
pub struct Table {
    head: Vec<String>,
    rows: Vec<Vec<Cell>>,
}

impl Table {
    pub fn new(head: &[&str]) -> Self {
        Self {
            head: head.iter().map(|s| s.to_string()).collect(),
            rows: Vec::new(),
        }
    }

    pub fn row(&mut self, cells: Vec<Cell>) -> &mut Self {
        self.rows.push(cells);
        self
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Objects as rows: a column per key holding a scalar in any of them, the names of
    /// [`LEAD`] first, the others as they come (serde_json's maps are sorted by key); nested
    /// values are flattened to `key.sub`, arrays of numbers written out.
    pub fn from_objects(rows: &[Value]) -> Self {
        let flat: Vec<Vec<(String, Cell)>> = rows
            .iter()
            .map(|r| {
                let mut out = Vec::new();
                flatten("", r, &mut out);
                out
            })
            .collect();
        let mut head: Vec<String> = LEAD
            .iter()
            .filter(|k| flat.iter().any(|r| r.iter().any(|(n, _)| n == *k)))
            .map(|k| k.to_string())
            .collect();
        for r in &flat {
            for (k, _) in r {
                if !head.contains(k) {
                    head.push(k.clone());
                }
            }
        }
        let rows = flat
            .into_iter()
            .map(|r| {
                head.iter()
                    .map(|k| {
                        r.iter()
                            .find(|(n, _)| n == k)
                            .map_or(Cell::Text(String::new()), |(_, c)| c.clone())
                    })
                    .collect()
            })
            .collect();
        Self { head, rows }
    }

    /// One object as `name | value` rows, flattened like [`Table::from_objects`]; arrays of
    /// objects are left out (give them their own table).
    pub fn key_values(v: &Value) -> Self {
        let mut out = Vec::new();
        flatten("", v, &mut out);
        let mut t = Self::new(&["name", "value"]);
        for (k, c) in out {
            t.row(vec![Cell::Text(k), c]);
        }
        t
    }

    fn html(&self, o: &mut String) {
        o.push_str("<table>\n<thead><tr>");
        for h in &self.head {
            let _ = write!(o, "<th>{}</th>", esc(h));
        }
        o.push_str("</tr></thead>\n<tbody>\n");
        for r in &self.rows {
            o.push_str("<tr>");
            for c in r {
                match c {
                    Cell::Text(s) => {
                        let _ = write!(o, "<td>{}</td>", esc(s));
                    }
                    Cell::Num(v) => {
                        let _ = write!(o, "<td class=\"n\">{}</td>", esc(&num(*v)));
                    }
                    Cell::Links(ls) => {
                        o.push_str("<td>");
                        for (i, (text, rel)) in ls.iter().enumerate() {
                            if i > 0 {
                                o.push(' ');
                            }
                            let _ = write!(o, "<a href=\"{}\">{}</a>", href(rel), esc(text));
                        }
                        o.push_str("</td>");
                    }
                }
            }
            o.push_str("</tr>\n");
        }
        o.push_str("</tbody>\n</table>\n");
    }

    fn links(&self) -> impl Iterator<Item = &str> {
        self.rows.iter().flatten().flat_map(|c| match c {
            Cell::Links(ls) => ls.iter().map(|(_, r)| r.as_str()).collect::<Vec<_>>(),
            _ => Vec::new(),
        })
    }
}

/// Scalars of `v` under dotted names; arrays of numbers (or strings) as one cell; arrays of
/// objects skipped.
fn flatten(prefix: &str, v: &Value, out: &mut Vec<(String, Cell)>) {
    let name = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match v {
        Value::Object(m) => {
            for (k, v) in m {
                flatten(&name(k), v, out);
            }
        }
        Value::Array(a) if a.iter().any(|x| x.is_object()) => {}
        Value::Array(a) if a.iter().any(|x| x.is_array()) => {
            for (i, x) in a.iter().enumerate() {
                flatten(&format!("{prefix}[{i}]"), x, out);
            }
        }
        Value::Array(a) => {
            let mut parts: Vec<String> = a.iter().take(LIST_MAX).map(scalar).collect();
            if a.len() > LIST_MAX {
                parts.push(format!("... ({} values in all)", a.len()));
            }
            out.push((prefix.to_string(), Cell::Text(parts.join(", "))));
        }
        Value::Number(n) => {
            let c = n.as_f64().map_or(Cell::Text(n.to_string()), Cell::Num);
            out.push((prefix.to_string(), c));
        }
        Value::Null => out.push((prefix.to_string(), Cell::Text(String::new()))),
        other => out.push((prefix.to_string(), Cell::Text(scalar(other)))),
    }
}

fn scalar(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Number(n) => n.as_f64().map_or(n.to_string(), num),
        Value::Null => String::new(),
        other => other.to_string(),
    }
}

/// Links to those of `files` (text, path relative to `dir`) that exist.
pub fn links(dir: &Path, files: &[(&str, String)]) -> Cell {
    Cell::Links(
        files
            .iter()
            .filter(|(_, rel)| dir.join(rel).is_file())
            .map(|(text, rel)| (text.to_string(), rel.clone()))
            .collect(),
    )
}

/// The arrays of objects inside `v` with their dotted names (not inside one another).
fn object_arrays<'a>(prefix: &str, v: &'a Value, out: &mut Vec<(String, &'a [Value])>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let name = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                object_arrays(&name, x, out);
            }
        }
        Value::Array(a) if a.iter().any(|x| x.is_object()) => out.push((prefix.into(), a)),
        _ => {}
    }
}

enum Block {
    Text(String),
    Pre(String),
    Table(Table),
    /// An SVG (or PNG) of the folder, shown.
    Plot(String),
    /// Plots behind a "show" line (many of them: loaded only when opened).
    Plots(String, Vec<String>),
}

/// A part of the page with its heading.
pub struct Section {
    title: String,
    open: bool,
    blocks: Vec<Block>,
}

impl Section {
    pub fn text(&mut self, s: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Text(s.into()));
        self
    }

    /// Preformatted text (what the command printed).
    pub fn pre(&mut self, s: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Pre(s.into()));
        self
    }

    pub fn table(&mut self, t: Table) -> &mut Self {
        if !t.is_empty() {
            self.blocks.push(Block::Table(t));
        }
        self
    }

    /// A plot of the folder (relative path), shown on the page.
    pub fn plot(&mut self, rel: impl Into<String>) -> &mut Self {
        self.blocks.push(Block::Plot(rel.into()));
        self
    }

    /// Plots behind a line the reader opens (`label`), loaded only then.
    pub fn plots_folded(&mut self, label: impl Into<String>, rels: Vec<String>) -> &mut Self {
        if !rels.is_empty() {
            self.blocks.push(Block::Plots(label.into(), rels));
        }
        self
    }

    /// Starts folded (a long section among many).
    pub fn folded(&mut self) -> &mut Self {
        self.open = false;
        self
    }

    fn links(&self) -> Vec<&str> {
        let mut v = Vec::new();
        for b in &self.blocks {
            match b {
                Block::Table(t) => v.extend(t.links()),
                Block::Plot(p) => v.push(p.as_str()),
                Block::Plots(_, ps) => v.extend(ps.iter().map(|p| p.as_str())),
                _ => {}
            }
        }
        v
    }

    fn html(&self, o: &mut String) {
        let _ = writeln!(
            o,
            "<details{}><summary><h2>{}</h2></summary>",
            if self.open { " open" } else { "" },
            esc(&self.title)
        );
        for b in &self.blocks {
            match b {
                Block::Text(s) => {
                    let _ = writeln!(o, "<p>{}</p>", esc(s));
                }
                Block::Pre(s) => {
                    let _ = writeln!(o, "<pre>{}</pre>", esc(s));
                }
                Block::Table(t) => t.html(o),
                Block::Plot(p) => plot_html(o, p),
                Block::Plots(label, ps) => {
                    let _ = writeln!(o, "<details><summary>{}</summary>", esc(label));
                    for p in ps {
                        plot_html(o, p);
                    }
                    o.push_str("</details>\n");
                }
            }
        }
        o.push_str("</details>\n");
    }
}

fn plot_html(o: &mut String, rel: &str) {
    let h = href(rel);
    let _ = writeln!(
        o,
        "<figure><a href=\"{h}\"><img src=\"{h}\" alt=\"{}\" loading=\"lazy\"></a><figcaption>{}</figcaption></figure>",
        esc(rel),
        esc(rel)
    );
}

/// A command's report, started before the command writes anything.
pub struct Report {
    title: String,
    command: String,
    started: SystemTime,
    sections: Vec<Section>,
}

impl Report {
    /// Notes the time (files written from now on are the run's) and the command line.
    pub fn start(title: &str) -> Self {
        let mut args = std::env::args();
        let exe = args
            .next()
            .map(|a| {
                Path::new(&a)
                    .file_stem()
                    .map_or(a.clone(), |s| s.to_string_lossy().into_owned())
            })
            .unwrap_or_else(|| "piezo".into());
        let command = std::iter::once(exe)
            .chain(args.map(|a| {
                if a.is_empty() || a.contains(|c: char| c.is_whitespace() || c == '\'') {
                    format!("'{}'", a.replace('\'', "'\\''"))
                } else {
                    a
                }
            }))
            .collect::<Vec<_>>()
            .join(" ");
        Self {
            title: title.into(),
            command,
            started: SystemTime::now(),
            sections: Vec::new(),
        }
    }

    /// A new section, open.
    pub fn section(&mut self, title: impl Into<String>) -> &mut Section {
        self.sections.push(Section {
            title: title.into(),
            open: true,
            blocks: Vec::new(),
        });
        self.sections.last_mut().expect("just pushed")
    }

    /// A JSON document as tables: its scalars (flattened) in a section `title`, each array
    /// of objects in a section of its own, named by its key (a few wide objects: one
    /// `name | value` table each).
    pub fn json(&mut self, title: &str, v: &Value) {
        self.section(title).table(Table::key_values(v));
        let mut arrays = Vec::new();
        object_arrays("", v, &mut arrays);
        for (name, rows) in arrays {
            let t = Table::from_objects(rows);
            let s = self.section(name);
            if rows.len() <= 4 && t.head.len() > 8 {
                for r in rows {
                    s.table(Table::key_values(r));
                }
            } else {
                s.table(t);
            }
        }
    }

    /// Writes `dir/index.html`: the sections, then every other file written since
    /// [`Report::start`] (below `dir`, sorted, the plots among them shown). Returns its path.
    pub fn write(mut self, dir: &Path) -> Result<PathBuf> {
        let written = files_since(dir, self.started.checked_sub(MTIME_SLACK))?;
        let linked: BTreeSet<String> = self
            .sections
            .iter()
            .flat_map(|s| s.links())
            .map(|s| s.to_string())
            .collect();
        let rest: Vec<&String> = written.iter().filter(|f| !linked.contains(*f)).collect();
        if !rest.is_empty() {
            let plots: Vec<String> = rest
                .iter()
                .filter(|f| f.ends_with(".svg") || f.ends_with(".png"))
                .map(|f| f.to_string())
                .collect();
            let mut t = Table::new(&["file", "size"]);
            for f in &rest {
                let size = std::fs::metadata(dir.join(f)).map_or(0, |m| m.len());
                t.row(vec![
                    Cell::Links(vec![(f.to_string(), f.to_string())]),
                    Cell::Text(size_text(size)),
                ]);
            }
            if !plots.is_empty() {
                let s = self.section("Plots");
                if plots.len() <= 12 {
                    for p in plots {
                        s.plot(p);
                    }
                } else {
                    s.plots_folded(format!("{} plots", plots.len()), plots);
                }
            }
            self.section("Files").table(t);
        }
        let mut o = String::new();
        let _ = write!(
            o,
            "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<h1>{}</h1>\n<p class=\"cmd\"><code>{}</code></p>\n<p class=\"note\">{} written; every one is linked below.</p>\n",
            esc(&self.title),
            esc(&self.title),
            esc(&self.command),
            match written.len() {
                1 => "1 file".to_string(),
                n => format!("{n} files"),
            },
        );
        for s in &self.sections {
            s.html(&mut o);
        }
        o.push_str("</body>\n</html>\n");
        let path = dir.join(INDEX);
        std::fs::write(&path, o).with_context(|| format!("cannot write {}", path.display()))?;
        Ok(path)
    }
}

fn size_text(n: u64) -> String {
    match n {
        n if n >= 1 << 20 => format!("{:.1} MB", n as f64 / (1u64 << 20) as f64),
        n if n >= 1 << 10 => format!("{:.1} kB", n as f64 / 1024.0),
        n => format!("{n} B"),
    }
}

/// Files below `dir` (relative, `/`-separated, sorted) modified at or after `since`,
/// `index.html` itself left out.
fn files_since(dir: &Path, since: Option<SystemTime>) -> Result<Vec<String>> {
    let mut out = Vec::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        let d = dir.join(&rel);
        for e in std::fs::read_dir(&d).with_context(|| format!("cannot list {}", d.display()))? {
            let e = e?;
            let r = rel.join(e.file_name());
            let meta = e.metadata()?;
            if meta.is_dir() {
                stack.push(r);
            } else if meta.is_file() && r != Path::new(INDEX) {
                let fresh = match (since, meta.modified()) {
                    (Some(s), Ok(m)) => m >= s,
                    _ => true,
                };
                if fresh {
                    let parts: Vec<String> = r
                        .components()
                        .map(|c| c.as_os_str().to_string_lossy().into_owned())
                        .collect();
                    out.push(parts.join("/"));
                }
            }
        }
    }
    out.sort();
    Ok(out)
}

const STYLE: &str = "
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #222; }
h1 { font-size: 1.4em; margin: 0 0 .3em; }
h2 { font-size: 1.1em; display: inline; }
summary { cursor: pointer; margin: .6em 0; }
details details { margin-left: 1em; }
.cmd code { background: #f3f3f3; padding: .2em .4em; }
.note { color: #666; }
table { border-collapse: collapse; margin: .5em 0 1em; }
th, td { border: 1px solid #ccc; padding: .15em .5em; text-align: left; }
th { background: #f3f3f3; }
td.n { text-align: right; font-variant-numeric: tabular-nums; }
pre { background: #f7f7f7; padding: .6em; white-space: pre-wrap; }
figure { display: inline-block; margin: .5em; vertical-align: top; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { color: #666; font-size: .9em; }
";

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn escapes_and_encodes() {
        assert_eq!(
            esc("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
        assert_eq!(href("sine_ff+pid.svg"), "sine_ff+pid.svg");
        assert_eq!(href("a b/c#d.csv"), "a%20b/c%23d.csv");
    }

    #[test]
    fn numbers_keep_four_digits() {
        assert_eq!(num(0.012345), "0.01235");
        assert_eq!(num(12.3456), "12.35");
        assert_eq!(num(3.0), "3");
        assert_eq!(num(1.5e-7), "1.500e-7");
        assert_eq!(num(f64::NAN), "NaN");
    }

    #[test]
    fn objects_become_columns() {
        let t = Table::from_objects(&[
            json!({"name": "a", "rmse": 0.5, "fit": {"k": 2.0}}),
            json!({"name": "b", "gain": [1.0, 2.0], "rows": [{"x": 1}]}),
        ]);
        assert_eq!(t.head, ["name", "fit.k", "rmse", "gain"]);
        assert_eq!(t.rows.len(), 2);
        assert!(matches!(&t.rows[1][0], Cell::Text(s) if s == "b"));
        assert!(matches!(&t.rows[1][3], Cell::Text(s) if s == "1, 2"));
        assert!(matches!(&t.rows[1][2], Cell::Text(s) if s.is_empty()));
    }

    /// Every file written after the start is linked, an older one is not, and the page
    /// escapes what it shows.
    #[test]
    fn links_every_file_written() {
        let dir = std::env::temp_dir().join(format!("piezo-report-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        let old = dir.join("old.csv");
        std::fs::write(&old, "x\n").unwrap();
        let f = std::fs::File::options().write(true).open(&old).unwrap();
        f.set_modified(SystemTime::now() - Duration::from_secs(3600))
            .unwrap();
        let mut r = Report::start("test <report>");
        std::fs::write(dir.join("a.svg"), "<svg/>").unwrap();
        std::fs::write(dir.join("sub/b c.csv"), "1\n").unwrap();
        r.section("one").plot("a.svg");
        let text = std::fs::read_to_string(r.write(&dir).unwrap()).unwrap();
        assert!(text.contains("<title>test &lt;report&gt;</title>"));
        assert!(text.contains("src=\"a.svg\""));
        assert!(text.contains("href=\"sub/b%20c.csv\""));
        assert!(!text.contains("old.csv"));
        assert!(text.contains("2 files written"), "{text}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
