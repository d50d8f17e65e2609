//! `piezo serial bode`: the stage's frequency response from its own record. The firmware's
//! own excitation (`wave multisine|prbs|chirp`) drives the stage in open loop (input the
//! applied voltage) or closed loop (input the reference); `record` captures input and
//! position; the H1 estimate over several captures gives magnitude, phase and coherence
//! per line; the resonance is the line that stands highest above its neighbours' trend,
//! and its half-power width gives the notch suggested for it.
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use piezo_core::command::{Command, RecCmd, TriggerCmd};
use piezo_core::pipeline::excitation::{MULTISINE_MAX, PRBS_ORDER_MAX, PRBS_ORDER_MIN};
use piezo_core::recorder::Signal;
use rustfft::num_complex::Complex64 as C64;
use rustfft::FftPlanner;

use crate::plot::{write_grid, Plot};
use crate::serial::Client;

use super::record::{self, RecordArgs};
use super::units::{f32_of, parse_hz, parse_um};

/// Open loop (applied voltage -> position, um/V) or closed loop (reference -> position).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LoopKind {
    Open,
    Closed,
}

/// The firmware's excitation the response is measured with.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Excitation {
    /// 32 equal harmonics, periodic in the record (no leakage: rectangular window).
    Multisine,
    /// Maximal-length PRBS at half the sample rate (Hann window).
    Prbs,
    /// Linear sweep from the record's resolution to --f-max over one record (Hann window).
    Chirp,
}

#[derive(clap::Args, Debug)]
pub struct BodeArgs {
    /// Open loop (`mode open-loop`, `ff linear`: u_volts -> y_um) or closed loop (--mode,
    /// --ff: ref_um -> y_um).
    #[arg(long = "loop", value_enum, default_value = "open")]
    pub loop_kind: LoopKind,
    #[arg(long, value_enum, default_value = "multisine")]
    pub excitation: Excitation,
    /// Peak deviation of the reference around --offset (PRBS: half its step).
    #[arg(long, default_value = "1um", value_parser = parse_um)]
    pub amplitude: f64,
    /// Operating point of the reference.
    #[arg(long, default_value = "10um", value_parser = parse_um, allow_hyphen_values = true)]
    pub offset: f64,
    /// Highest frequency of interest (default 3 kHz: 30 of the multisine's 32 harmonics at
    /// the resolution of a 1024-frame record at 100 kHz, 97.7 Hz).
    #[arg(long, value_parser = parse_hz)]
    pub f_max: Option<f64>,
    /// Feedback law of the closed loop.
    #[arg(long, default_value = "ff+hgo-robust")]
    pub mode: String,
    /// Feedforward compensator of the closed loop.
    #[arg(long, default_value = "ims-cbw")]
    pub ff: String,
    /// Captures averaged (H1; coherence needs at least 2).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub averages: u32,
    /// Set the suggested notch_hz / notch_q on the firmware.
    #[arg(long)]
    pub apply: bool,
    /// CSV file: f_hz,magnitude,phase_deg,coherence.
    #[arg(long)]
    pub out: PathBuf,
    /// SVG Bode plot (log frequency axis, magnitude in dB, phase, coherence).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Longest wait for each capture, in seconds of the firmware's time (as `record`).
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    pub wait_s: f64,
}

/// One line of the frequency response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Line {
    pub f_hz: f64,
    pub h: C64,
    pub coherence: f64,
}

/// The H1 estimate `H = sum Y U* / sum |U|^2` and coherence `|sum Y U*|^2 / (sum |U|^2 sum
/// |Y|^2)` over records of input `u` and output `y` at `sample_hz` (means removed,
/// `window`ed), at the bins `1..` below `f_max` where the input has power (above 1e-6 of
/// its strongest bin), every `step`-th bin (a multisine's lines).
pub fn h1(
    records: &[(Vec<f64>, Vec<f64>)],
    sample_hz: f64,
    f_max: f64,
    step: usize,
    hann: bool,
) -> Result<Vec<Line>> {
    let n = records.first().map_or(0, |r| r.0.len());
    if n < 8 || records.iter().any(|(u, y)| u.len() != n || y.len() != n) {
        bail!("records of at least 8 frames, all of one length, are needed");
    }
    let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
    let w: Vec<f64> = (0..n)
        .map(|i| {
            if hann {
                0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos()
            } else {
                1.0
            }
        })
        .collect();
    let spectrum = |x: &[f64]| {
        let mean = x.iter().sum::<f64>() / n as f64;
        let mut b: Vec<C64> = x
            .iter()
            .zip(&w)
            .map(|(v, w)| C64::new((v - mean) * w, 0.0))
            .collect();
        fft.process(&mut b);
        b
    };
    let bins = n / 2;
    let (mut syu, mut suu, mut syy) =
        (vec![C64::default(); bins], vec![0.0; bins], vec![0.0; bins]);
    for (u, y) in records {
        let (us, ys) = (spectrum(u), spectrum(y));
        for k in 1..bins {
            syu[k] += ys[k] * us[k].conj();
            suu[k] += us[k].norm_sqr();
            syy[k] += ys[k].norm_sqr();
        }
    }
    let df = sample_hz / n as f64;
    let strongest = suu.iter().cloned().fold(0.0, f64::max);
    let step = step.max(1);
    Ok((step..bins)
        .step_by(step)
        .filter(|&k| k as f64 * df <= f_max * (1.0 + 1e-9) && suu[k] > 1e-6 * strongest)
        .map(|k| Line {
            f_hz: k as f64 * df,
            h: syu[k] / suu[k],
            coherence: if syy[k] > 0.0 {
                syu[k].norm_sqr() / (suu[k] * syy[k])
            } else {
                0.0
            },
        })
        .collect())
}

/// A resonance found in a frequency response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resonance {
    pub f_hz: f64,
    /// Peak magnitude over the trend of its neighbours (the geometric mean of the magnitude
    /// at f/1.5 and 1.5 f, the band's edge line beyond it), in dB.
    pub prominence_db: f64,
    /// Centre over the half-power width of the peak.
    pub q: f64,
}

/// Magnitude at `f` by linear interpolation in log-log between the lines; outside them,
/// the first or last line's.
fn mag_at(lines: &[Line], f: f64) -> Option<f64> {
    let Some(i) = lines.iter().position(|l| l.f_hz >= f) else {
        return lines.last().map(|l| l.h.norm());
    };
    let b = lines[i];
    if i == 0 {
        return Some(b.h.norm());
    }
    let a = lines[i - 1];
    let t = (f.ln() - a.f_hz.ln()) / (b.f_hz.ln() - a.f_hz.ln());
    Some((a.h.norm().ln() * (1.0 - t) + b.h.norm().ln() * t).exp())
}

/// The resonance: of the local maxima with coherence >= 0.5, the one standing highest above
/// the trend of the magnitude at f/1.5 and 1.5 f (the band's edge line beyond it; at least
/// 3 dB), refined by a
/// parabola through log-magnitude at it and its two neighbours (uniform lines); its Q from
/// the half-power points (linear interpolation; a peak narrower than the lines gets the Q
/// of two lines' width, so the suggestion is never narrower than what was measured).
pub fn find_resonance(lines: &[Line]) -> Option<Resonance> {
    let mut best: Option<(usize, f64)> = None;
    for (i, l) in lines.iter().enumerate() {
        if l.coherence < 0.5 || i == 0 || i + 1 >= lines.len() {
            continue;
        }
        let (Some(lo), Some(hi)) = (mag_at(lines, l.f_hz / 1.5), mag_at(lines, l.f_hz * 1.5))
        else {
            continue;
        };
        let m = l.h.norm();
        if m < lines[i - 1].h.norm() || m < lines[i + 1].h.norm() {
            continue;
        }
        let ratio = m / (lo * hi).sqrt();
        if best.is_none_or(|(_, r)| ratio > r) {
            best = Some((i, ratio));
        }
    }
    let (i, ratio) = best?;
    if ratio < 10f64.powf(3.0 / 20.0) {
        return None;
    }
    let (a, b, c) = (lines[i - 1], lines[i], lines[i + 1]);
    let (la, lb, lc) = (a.h.norm().ln(), b.h.norm().ln(), c.h.norm().ln());
    let df = b.f_hz - a.f_hz;
    let den = la - 2.0 * lb + lc;
    let shift = if den < 0.0 {
        (0.5 * (la - lc) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    let f_hz = b.f_hz + shift * df;
    let peak = b.h.norm();
    let half = peak / std::f64::consts::SQRT_2;
    let cross = |range: &mut dyn Iterator<Item = usize>| -> Option<f64> {
        let mut prev = i;
        for j in range {
            let (p, q) = (lines[prev], lines[j]);
            if q.h.norm() <= half {
                let t = (p.h.norm() - half) / (p.h.norm() - q.h.norm());
                return Some(p.f_hz + t * (q.f_hz - p.f_hz));
            }
            prev = j;
        }
        None
    };
    let lo = cross(&mut (0..i).rev());
    let hi = cross(&mut (i + 1..lines.len()));
    let width = match (lo, hi) {
        (Some(l), Some(h)) => (h - l).max(2.0 * df),
        _ => 2.0 * df,
    };
    Some(Resonance {
        f_hz,
        prominence_db: 20.0 * ratio.log10(),
        q: f_hz / width,
    })
}

/// The notch the firmware accepts for a resonance: `notch_hz` the peak, `notch_q` its Q
/// within the firmware's range (0.5 to 50).
pub fn suggest_notch(r: &Resonance) -> (f64, f64) {
    (r.f_hz, r.q.clamp(0.5, 50.0))
}

/// Writes `f_hz,magnitude,phase_deg,coherence` (phase unwrapped) with `#` lines.
pub fn write_csv(path: &Path, lines: &[Line], what: &str, unit: &str) -> Result<()> {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(s, "# piezo serial bode: {what}");
    let _ = writeln!(
        s,
        "# units: f_hz [Hz], magnitude [{unit}], phase_deg [deg], coherence [1]"
    );
    let _ = writeln!(s, "f_hz,magnitude,phase_deg,coherence");
    for (l, p) in lines.iter().zip(unwrapped_deg(lines)) {
        let _ = writeln!(s, "{},{:e},{p:.3},{:.5}", l.f_hz, l.h.norm(), l.coherence);
    }
    if let Some(dir) = path.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)?;
        }
    }
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

/// Phase in degrees, unwrapped along frequency.
fn unwrapped_deg(lines: &[Line]) -> Vec<f64> {
    let mut out = Vec::with_capacity(lines.len());
    let mut prev: Option<f64> = None;
    for l in lines {
        let mut p = l.h.arg().to_degrees();
        if let Some(q) = prev {
            p -= 360.0 * ((p - q) / 360.0).round();
        }
        out.push(p);
        prev = Some(p);
    }
    out
}

/// Magnitude (dB), phase and coherence against a log frequency axis.
pub fn write_svg(path: &Path, lines: &[Line], what: &str, unit: &str) -> Result<()> {
    let f: Vec<f64> = lines.iter().map(|l| l.f_hz).collect();
    let db: Vec<f64> = lines.iter().map(|l| 20.0 * l.h.norm().log10()).collect();
    let coh: Vec<f64> = lines.iter().map(|l| l.coherence).collect();
    let plots = [
        Plot::new(
            &format!("Bode: {what}"),
            "f [Hz]",
            &format!("|H| [dB {unit}]"),
        )
        .log_x()
        .line("magnitude", &f, &db),
        Plot::new("phase", "f [Hz]", "phase [deg]").log_x().line(
            "phase",
            &f,
            &unwrapped_deg(lines),
        ),
        Plot::new("coherence", "f [Hz]", "coherence [1]")
            .log_x()
            .line("coherence", &f, &coh),
    ];
    write_grid(path, &plots, 1).with_context(|| format!("writing {}", path.display()))
}

/// The excitation command for records of `frames` frames at `sample_hz` up to `f_max`, and
/// the bin step of its lines (multisine: every k-th bin; others: every bin). Realization
/// `r` of a multisine has random phases of seed `r + 1` (a PRBS its seed): averaged over
/// realizations, the H1 estimate is the best linear approximation, and the nonlinear
/// distortion (hysteresis, the IMS) shows as coherence below 1 instead of as a wrong line.
fn excitation(
    a: &BodeArgs,
    sample_hz: f64,
    frames: usize,
    f_max: f64,
    r: u32,
) -> (Command<'static>, usize) {
    let df = sample_hz / frames as f64;
    match a.excitation {
        Excitation::Multisine => {
            // f0 = k df with k a power of two (it divides the record), 32 harmonics reach
            // f_max.
            let mut k = 1usize;
            while (k as f64) * df * MULTISINE_MAX as f64 <= f_max * 0.999 && k < frames / 64 {
                k *= 2;
            }
            let f0 = k as f64 * df;
            let harmonics = ((f_max / f0).floor() as usize).clamp(1, MULTISINE_MAX) as u8;
            (
                Command::WaveMultisine {
                    amp_um: f32_of(a.amplitude),
                    f0_hz: f32_of(f0),
                    harmonics,
                    offset_um: f32_of(a.offset),
                    seed: r + 1,
                },
                k,
            )
        }
        Excitation::Prbs => {
            // One bit per two samples; a period at least as long as the record.
            let bits = frames / 2;
            let mut order = PRBS_ORDER_MIN;
            while (1usize << order) - 1 < bits && order < PRBS_ORDER_MAX {
                order += 1;
            }
            (
                Command::WavePrbs {
                    low_um: f32_of(a.offset - a.amplitude),
                    high_um: f32_of(a.offset + a.amplitude),
                    order,
                    bit_hz: f32_of(sample_hz / 2.0),
                    seed: r + 1,
                },
                1,
            )
        }
        Excitation::Chirp => (
            Command::WaveChirp {
                amp_um: f32_of(a.amplitude),
                f0_hz: f32_of(df),
                f1_hz: f32_of(f_max),
                duration_s: f32_of(frames as f64 / sample_hz),
                offset_um: f32_of(a.offset),
            },
            1,
        ),
    }
}

fn record_args(a: &BodeArgs, signals: [&str; 2], out: &Path) -> RecordArgs {
    RecordArgs {
        signals: signals.map(String::from).to_vec(),
        xy: false,
        every: 1,
        trigger: "now".into(),
        pre: 0,
        wait_s: a.wait_s,
        wall_cap_s: 600.0,
        no_arm: false,
        frames: None,
        text: false,
        out: out.to_path_buf(),
        svg: None,
    }
}

/// Waits until the firmware has run `periods` more control periods (its `stats`).
fn settle(c: &mut Client, periods: u64) -> Result<()> {
    let mut last = c.stats()?.samples;
    let mut waited = 0u64;
    while waited < periods {
        std::thread::sleep(std::time::Duration::from_millis(5));
        let now = c.stats()?.samples;
        waited += u64::from(if now >= last { now - last } else { now });
        last = now;
    }
    Ok(())
}

/// A measured frequency response.
#[derive(Debug, Clone)]
pub struct Measured {
    pub lines: Vec<Line>,
    /// `open loop, u_volts -> y_um` or `closed loop, ref_um -> y_um`.
    pub what: &'static str,
    /// Unit of the magnitude (`um/V`, `um/um`).
    pub unit: &'static str,
}

impl Measured {
    /// Phase in degrees, unwrapped along frequency.
    pub fn phase_deg(&self) -> Vec<f64> {
        unwrapped_deg(&self.lines)
    }
}

/// `bode`: excite, record, estimate, find the resonance, write CSV and SVG.
pub fn run(c: &mut Client, a: &BodeArgs, out: &mut impl Write) -> Result<()> {
    let Measured { lines, what, unit } = measure(c, a, out)?;
    write_csv(&a.out, &lines, what, unit)?;
    writeln!(out, "wrote {} ({} lines)", a.out.display(), lines.len())?;
    if let Some(svg) = &a.svg {
        write_svg(svg, &lines, what, unit)?;
        writeln!(out, "wrote {}", svg.display())?;
    }
    match find_resonance(&lines) {
        Some(r) => {
            let (hz, q) = suggest_notch(&r);
            writeln!(
                out,
                "resonance: {:.1} Hz, {:.1} dB above its neighbours, Q {:.2}",
                r.f_hz, r.prominence_db, r.q
            )?;
            writeln!(out, "suggested notch: notch_hz {hz:.1} notch_q {q:.2}")?;
            if a.apply {
                for (name, v) in [("notch_hz", hz), ("notch_q", q)] {
                    let r = c.send(&Command::Set(name, f32_of(v)))?;
                    writeln!(out, "{}", r.reply_line())?;
                }
            }
        }
        None => writeln!(
            out,
            "resonance: none found (no line 3 dB above its neighbours)"
        )?,
    }
    Ok(())
}

/// Excites, records and estimates (the progress on `out`); leaves the stage holding
/// `--offset` in the loop measured. Writes no file (`a.out` is not used).
pub fn measure(c: &mut Client, a: &BodeArgs, out: &mut impl Write) -> Result<Measured> {
    if !(a.amplitude.is_finite() && a.amplitude > 0.0) {
        bail!("--amplitude must be positive");
    }
    let sample_hz = c.get("sample_hz")?;
    let (signals, what, unit) = match a.loop_kind {
        LoopKind::Open => {
            c.send(&Command::Feedforward("linear"))?;
            c.send(&Command::Mode("open-loop"))?;
            (["u_volts", "y_um"], "open loop, u_volts -> y_um", "um/V")
        }
        LoopKind::Closed => {
            c.send(&Command::Feedforward(&a.ff))?;
            c.send(&Command::Mode(&a.mode))?;
            (["ref_um", "y_um"], "closed loop, ref_um -> y_um", "um/um")
        }
    };
    c.send(&Command::WaveHold(f32_of(a.offset)))?;
    // The recorder's length: one capture of the hold (its frames are not read).
    let probe = record_args(a, signals, &a.out);
    let sel: Vec<Signal> = signals
        .iter()
        .filter_map(|s| Signal::from_name(s))
        .collect();
    c.send(&Command::Rec(RecCmd::Stop))?;
    c.rec_select(&sel)?;
    c.send(&Command::Rec(RecCmd::Trigger(TriggerCmd::Now)))?;
    c.send(&Command::Rec(RecCmd::Divider(Some(1))))?;
    c.send(&Command::Rec(RecCmd::Arm))?;
    let frames = record::wait_for_capture(c, &probe, sample_hz)?;
    let f_max = a.f_max.unwrap_or(3000.0).min(0.45 * sample_hz);
    if frames < 64 || f_max <= sample_hz / frames as f64 {
        bail!("a record of {frames} frames at {sample_hz} Hz cannot resolve up to {f_max} Hz");
    }
    writeln!(
        out,
        "{what}: {} captures of {frames} frames at {sample_hz} Hz ({:.3} Hz resolution)",
        a.averages,
        sample_hz / frames as f64
    )?;
    let mut records = Vec::new();
    let mut step = 1;
    for r in 0..a.averages {
        let (cmd, k) = excitation(a, sample_hz, frames, f_max, r);
        step = k;
        let reply = c.send(&cmd)?;
        writeln!(out, "{}", reply.reply_line())?;
        // Steady state first: one record length of the firmware's own time.
        settle(c, frames as u64)?;
        let rec = record::record(c, &record_args(a, signals, &a.out))?;
        let (Some(u), Some(y)) = (rec.column(signals[0]), rec.column(signals[1])) else {
            bail!("the capture lacks {} or {}", signals[0], signals[1]);
        };
        writeln!(out, "capture {}/{}: {} frames", r + 1, a.averages, u.len())?;
        records.push((u, y));
    }
    c.send(&Command::WaveHold(f32_of(a.offset)))?;
    let hann = a.excitation != Excitation::Multisine;
    let lines = h1(&records, sample_hz, f_max, step, hann)?;
    Ok(Measured { lines, what, unit })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A second-order mode behind a first-order lag, simulated by the bilinear transform
    /// at `fs` and driven by `u`.
    fn simulate(u: &[f64], fs: f64, f_r: f64, zeta: f64) -> Vec<f64> {
        let w = 2.0 * std::f64::consts::PI * f_r;
        let k = w / (w / (2.0 * fs)).tan();
        let d = k * k + 2.0 * zeta * w * k + w * w;
        let b = [w * w / d, 2.0 * w * w / d, w * w / d];
        let a = [
            (2.0 * w * w - 2.0 * k * k) / d,
            (k * k - 2.0 * zeta * w * k + w * w) / d,
        ];
        let lag = 1.0 - (-2.0 * std::f64::consts::PI * 500.0 / fs).exp();
        let (mut x, mut s) = (0.0, [0.0; 4]);
        u.iter()
            .map(|&v| {
                x += lag * (0.16 * v - x);
                let y = b[0] * x + b[1] * s[0] + b[2] * s[1] - a[0] * s[2] - a[1] * s[3];
                s = [x, s[0], y, s[2]];
                y
            })
            .collect()
    }

    /// `len` samples of a multisine of period `n`: harmonics `k, 2k, ...` of `1/n`.
    fn multisine(len: usize, n: usize, k: usize, harmonics: usize) -> Vec<f64> {
        (0..len)
            .map(|i| {
                (1..=harmonics)
                    .map(|h| {
                        let ph = std::f64::consts::PI * (h * (h - 1)) as f64 / harmonics as f64;
                        (2.0 * std::f64::consts::PI * (h * k * i) as f64 / n as f64 + ph).cos()
                    })
                    .sum()
            })
            .collect()
    }

    #[test]
    fn h1_of_a_simulated_mode_finds_its_resonance_and_q() {
        let (fs, n, f_r, zeta) = (100_000.0, 4096, 2_500.0, 0.05);
        // Steady state: simulate a long periodic input, keep the last records.
        let u = multisine(n * 6, n, 1, 128);
        let y = simulate(&u, fs, f_r, zeta);
        let recs: Vec<(Vec<f64>, Vec<f64>)> = (2..6)
            .map(|r| {
                (
                    u[r * n..(r + 1) * n].to_vec(),
                    y[r * n..(r + 1) * n].to_vec(),
                )
            })
            .collect();
        let lines = h1(&recs, fs, 3200.0 * 1.6, 1, false).unwrap();
        assert!(
            lines.iter().all(|l| l.coherence > 0.99),
            "periodic: coherence 1"
        );
        let r = find_resonance(&lines).expect("a resonance");
        // The peak of |H| sits at f_r sqrt(1 - 2 zeta^2) (the lag moves it a little lower).
        assert!((r.f_hz - f_r).abs() < 0.02 * f_r, "{r:?}");
        // Q of the mode 1/(2 zeta) = 10; the lag's slope skews the half-power points.
        assert!((7.0..13.0).contains(&r.q), "{r:?}");
        assert!(r.prominence_db > 10.0, "{r:?}");
        let (hz, q) = suggest_notch(&r);
        assert_eq!(hz, r.f_hz);
        assert!((0.5..=50.0).contains(&q));
    }

    #[test]
    fn a_smooth_response_has_no_resonance_and_noise_lowers_coherence() {
        let (fs, n) = (100_000.0, 2048);
        let u = multisine(n, n, 1, 64);
        // First-order lag only (an overdamped mode far above the band).
        let y = simulate(&u, fs, 40_000.0, 1.0);
        let lines = h1(&[(u.clone(), y.clone())], fs, 3000.0, 1, false).unwrap();
        assert!(find_resonance(&lines).is_none());
        // Output noise uncorrelated between records: coherence drops below 1.
        let noisy: Vec<(Vec<f64>, Vec<f64>)> = (0..4)
            .map(|r| {
                let y: Vec<f64> = y
                    .iter()
                    .enumerate()
                    .map(|(i, v)| {
                        v + 0.5 * (((i * 7919 + r * 104_729) % 1000) as f64 / 500.0 - 1.0)
                    })
                    .collect();
                (u.clone(), y)
            })
            .collect();
        let lines = h1(&noisy, fs, 3000.0, 1, true).unwrap();
        assert!(lines.iter().any(|l| l.coherence < 0.9));
        assert!(h1(&[(vec![0.0; 4], vec![0.0; 4])], fs, 1.0, 1, false).is_err());
    }

    #[test]
    fn csv_and_svg_are_written() {
        let lines = vec![
            Line {
                f_hz: 100.0,
                h: C64::new(1.0, 0.0),
                coherence: 1.0,
            },
            Line {
                f_hz: 200.0,
                h: C64::new(0.0, -2.0),
                coherence: 0.9,
            },
        ];
        let dir = std::env::temp_dir().join(format!("bode-test-{}", std::process::id()));
        write_csv(&dir.join("b.csv"), &lines, "test", "um/V").unwrap();
        write_svg(&dir.join("b.svg"), &lines, "test", "um/V").unwrap();
        let csv = std::fs::read_to_string(dir.join("b.csv")).unwrap();
        assert!(
            csv.contains("f_hz,magnitude,phase_deg,coherence\n100,1e0,0.000,1.00000\n"),
            "{csv}"
        );
        assert!(csv.contains("200,2e0,-90.000,0.90000"), "{csv}");
        std::fs::remove_dir_all(dir).ok();
    }
}
