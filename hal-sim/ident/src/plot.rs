//! Minimal SVG line plots: no fonts, no system libraries, readable in any browser.
//!
//! ```no_run
//! use piezo_ident::plot::Plot;
//! let x = [0.0, 1.0, 2.0];
//! Plot::new("loop", "u [V]", "y [um]").line("model", &x, &[0.0, 1.0, 4.0]).write_svg("out/loop.svg").unwrap();
//! ```

use std::fmt::Write as _;
use std::path::Path;

const COLORS: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];
/// Points kept per series; longer series are decimated by stride.
const MAX_POINTS: usize = 4000;
const W: f64 = 640.0;
const H: f64 = 420.0;
const ML: f64 = 70.0;
const MR: f64 = 20.0;
const MT: f64 = 34.0;
const MB: f64 = 52.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    Line,
    Points,
}

#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub style: Style,
}

/// One chart: title, axis labels with units, any number of series.
#[derive(Debug, Clone)]
pub struct Plot {
    pub title: String,
    pub xlabel: String,
    pub ylabel: String,
    pub series: Vec<Series>,
    /// Logarithmic x axis (decade ticks; points at x <= 0 are left out).
    pub log_x: bool,
}

impl Plot {
    pub fn new(title: &str, xlabel: &str, ylabel: &str) -> Self {
        Self {
            title: title.into(),
            xlabel: xlabel.into(),
            ylabel: ylabel.into(),
            series: Vec::new(),
            log_x: false,
        }
    }

    /// A logarithmic x axis (a Bode plot's frequency): ticks at 1, 2 and 5 per decade.
    pub fn log_x(mut self) -> Self {
        self.log_x = true;
        self
    }

    /// Where `x` sits on the x axis: itself, or its log10 on a log axis (NaN for x <= 0).
    fn xpos(&self, x: f64) -> f64 {
        if !self.log_x {
            x
        } else if x > 0.0 {
            x.log10()
        } else {
            f64::NAN
        }
    }

    /// Adds a line series (x and y of equal length; extra points are ignored).
    pub fn line(mut self, label: &str, x: &[f64], y: &[f64]) -> Self {
        self.push(label, x, y, Style::Line);
        self
    }

    /// Adds a scatter series.
    pub fn points(mut self, label: &str, x: &[f64], y: &[f64]) -> Self {
        self.push(label, x, y, Style::Points);
        self
    }

    fn push(&mut self, label: &str, x: &[f64], y: &[f64], style: Style) {
        let n = x.len().min(y.len());
        let stride = n.div_ceil(MAX_POINTS).max(1);
        let (xs, ys) = (0..n)
            .step_by(stride)
            .filter(|&i| x[i].is_finite() && y[i].is_finite())
            .map(|i| (x[i], y[i]))
            .unzip();
        self.series.push(Series {
            label: label.into(),
            x: xs,
            y: ys,
            style,
        });
    }

    /// Writes the plot as a standalone SVG file, creating parent folders.
    pub fn write_svg(&self, path: impl AsRef<Path>) -> std::io::Result<()> {
        write_file(path.as_ref(), &svg_grid(std::slice::from_ref(self), 1))
    }

    /// Renders this plot into `out` with its top-left corner at `(ox, oy)`.
    fn render(&self, out: &mut String, ox: f64, oy: f64) {
        let (x0, x1) = range(
            self.series
                .iter()
                .flat_map(|s| s.x.iter().map(|&x| self.xpos(x)))
                .filter(|x| x.is_finite()),
        );
        let (y0, y1) = range(self.series.iter().flat_map(|s| s.y.iter().copied()));
        let pw = W - ML - MR;
        let ph = H - MT - MB;
        let sx = |x: f64| ox + ML + (self.xpos(x) - x0) / (x1 - x0) * pw;
        let xticks = if self.log_x {
            log_ticks(x0, x1)
        } else {
            ticks(x0, x1)
        };
        let sy = |y: f64| oy + MT + (1.0 - (y - y0) / (y1 - y0)) * ph;
        let _ = write!(
            out,
            r##"<rect x="{:.1}" y="{:.1}" width="{pw:.1}" height="{ph:.1}" fill="white" stroke="#444"/>"##,
            ox + ML,
            oy + MT
        );
        let _ = write!(
            out,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="15" font-weight="bold">{}</text>"#,
            ox + W / 2.0,
            oy + 22.0,
            esc(&self.title)
        );
        for t in xticks {
            let x = sx(t);
            let _ = write!(
                out,
                r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle" font-size="11">{}</text>"##,
                oy + MT,
                oy + MT + ph,
                oy + MT + ph + 15.0,
                fmt_tick(t)
            );
        }
        for t in ticks(y0, y1) {
            let y = sy(t);
            let _ = write!(
                out,
                r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end" font-size="11">{}</text>"##,
                ox + ML,
                ox + ML + pw,
                ox + ML - 5.0,
                y + 4.0,
                fmt_tick(t)
            );
        }
        let _ = write!(
            out,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="13">{}</text>"#,
            ox + ML + pw / 2.0,
            oy + H - 12.0,
            esc(&self.xlabel)
        );
        let _ = write!(
            out,
            r#"<text transform="translate({:.1},{:.1}) rotate(-90)" text-anchor="middle" font-size="13">{}</text>"#,
            ox + 16.0,
            oy + MT + ph / 2.0,
            esc(&self.ylabel)
        );
        for (i, s) in self.series.iter().enumerate() {
            let c = COLORS[i % COLORS.len()];
            match s.style {
                Style::Line => {
                    let mut d = String::new();
                    let on_axis =
                        s.x.iter()
                            .zip(&s.y)
                            .filter(|(x, _)| self.xpos(**x).is_finite());
                    for (k, (x, y)) in on_axis.enumerate() {
                        let _ = write!(
                            d,
                            "{}{:.2},{:.2}",
                            if k == 0 { "M" } else { " L" },
                            sx(*x),
                            sy(*y)
                        );
                    }
                    let _ = write!(
                        out,
                        r#"<path d="{d}" fill="none" stroke="{c}" stroke-width="1.3"/>"#
                    );
                }
                Style::Points => {
                    for (x, y) in s.x.iter().zip(&s.y) {
                        if !self.xpos(*x).is_finite() {
                            continue;
                        }
                        let _ = write!(
                            out,
                            r#"<circle cx="{:.2}" cy="{:.2}" r="1.6" fill="{c}"/>"#,
                            sx(*x),
                            sy(*y)
                        );
                    }
                }
            }
            let ly = oy + MT + 14.0 + 15.0 * i as f64;
            let lx = ox + ML + 10.0;
            let _ = write!(
                out,
                r#"<line x1="{lx:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{c}" stroke-width="3"/><text x="{:.1}" y="{ly:.1}" font-size="11">{}</text>"#,
                ly - 4.0,
                lx + 18.0,
                ly - 4.0,
                lx + 23.0,
                esc(&s.label)
            );
        }
    }
}

/// Several plots on one page, `cols` per row.
pub fn svg_grid(plots: &[Plot], cols: usize) -> String {
    let cols = cols.max(1);
    let rows = plots.len().div_ceil(cols).max(1);
    let mut out = String::new();
    let _ = write!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" font-family="sans-serif"><rect width="100%" height="100%" fill="white"/>"#,
        W * cols.min(plots.len().max(1)) as f64,
        H * rows as f64
    );
    for (i, p) in plots.iter().enumerate() {
        p.render(&mut out, W * (i % cols) as f64, H * (i / cols) as f64);
    }
    out.push_str("</svg>\n");
    out
}

/// Writes several plots on one SVG page.
pub fn write_grid(path: impl AsRef<Path>, plots: &[Plot], cols: usize) -> std::io::Result<()> {
    write_file(path.as_ref(), &svg_grid(plots, cols))
}

fn write_file(path: &Path, text: &str) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)?;
        }
    }
    std::fs::write(path, text)
}

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo <= f64::EPSILON * hi.abs().max(1.0) {
        let pad = hi.abs().max(1.0) * 0.05;
        return (lo - pad, hi + pad);
    }
    let pad = (hi - lo) * 0.04;
    (lo - pad, hi + pad)
}

fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let raw = (hi - lo) / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw * 0.999)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut v = Vec::new();
    while t <= hi && v.len() < 20 {
        v.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        t += step;
    }
    v
}

/// Ticks of a log axis spanning log10 values `lo..hi`: 1, 2 and 5 of every decade (only
/// the decades when it spans more than three), as values (not logs).
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut v = Vec::new();
    let steps: &[f64] = if hi - lo > 3.0 {
        &[1.0]
    } else {
        &[1.0, 2.0, 5.0]
    };
    let mut d = lo.floor();
    while d <= hi.ceil() && v.len() < 40 {
        for m in steps {
            let t = m * 10f64.powf(d);
            if (lo - 1e-9..=hi + 1e-9).contains(&t.log10()) {
                v.push(t);
            }
        }
        d += 1.0;
    }
    v
}

fn fmt_tick(t: f64) -> String {
    let a = t.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{t:.1e}")
    } else {
        let s = format!("{t:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_has_every_series_and_escapes_text() {
        let p = Plot::new("a<b", "u [V]", "y [um]")
            .line("one", &[0.0, 1.0], &[0.0, 2.0])
            .points("two", &[0.5], &[f64::NAN]);
        let s = svg_grid(&[p], 1);
        assert!(s.contains("a&lt;b"));
        assert!(s.contains(">one<") && s.contains(">two<"));
        assert!(s.starts_with("<svg") && s.trim_end().ends_with("</svg>"));
    }

    #[test]
    fn log_axis_places_decades_evenly_and_drops_nonpositive_x() {
        let p = Plot::new("bode", "f [Hz]", "|H| [dB]").log_x().line(
            "h",
            &[0.0, 10.0, 100.0, 1000.0],
            &[1.0, 2.0, 3.0, 4.0],
        );
        let s = svg_grid(&[p], 1);
        // Three points on the axis (x = 0 left out), equally spaced in x.
        let d = s
            .split("<path d=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap();
        let xs: Vec<f64> = d
            .split(['M', 'L'])
            .filter_map(|p| p.trim().split(',').next()?.parse().ok())
            .collect();
        assert_eq!(xs.len(), 3, "{d}");
        assert!(((xs[1] - xs[0]) - (xs[2] - xs[1])).abs() < 0.05, "{xs:?}");
        assert_eq!(
            log_ticks(1.0, 3.0),
            vec![10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0]
        );
        assert_eq!(log_ticks(0.0, 4.5), vec![1.0, 10.0, 100.0, 1000.0, 10000.0]);
    }

    #[test]
    fn ticks_cover_range_with_round_steps() {
        let t = ticks(-0.13, 1.07);
        assert!(t.len() >= 4 && t.len() <= 13, "{t:?}");
        assert!(t.iter().all(|v| (-0.13..=1.07).contains(v)));
    }
}
