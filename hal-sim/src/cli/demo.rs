//! `piezo demo`: every hysteresis model driven by a decaying sine; each loop as CSV and SVG,
//! plus all loops in one grid `loops.svg`.
use anyhow::{Context, Result};
use piezo_core::hysteresis::{
    AbwAbs, AbwU, BwState, Cbw, Dahl, Dpi, Gbw, Hysteresis, Mbw002, MbwRlm, MultiBw, Pi, Ppi,
    RlmState, Wpmbw,
};
use piezo_core::linear::{Discretisation, Linear, Section};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::plot::{write_grid, Plot};
use crate::report::{self, Report, Table};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output folder for the CSV files, plots and index.html, the report linking them.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Sample rate (Hz).
    #[arg(long, default_value_t = 10_000.0)]
    pub rate_hz: f64,
}

/// Length of the fade-in of [`decaying_sine`] (s): its first quarter period.
const FADE_IN_S: f64 = 0.25;

/// A decaying sine from rest: `u(t) = amp * w(t) * e^(-t/tau) * sin(2 pi f t)`, 1 Hz, 6 s,
/// with the fade-in `w = sin^2(pi t / (2 T))` over the first quarter period `T`, so that
/// both the input and its rate start at 0 (the models start at rest). Without it the rate
/// steps from 0 to `2 pi amp` V/s at `t = 0`, and a rate-dependent model answers that step
/// with a step of its own: the 002 MBW's `p*u' + q*u'^3` jumped by 1.48 um at u = 0.
pub fn decaying_sine(amp: f64, rate_hz: f64) -> (Vec<f64>, Vec<f64>) {
    let n = (6.0 * rate_hz) as usize;
    let t: Vec<f64> = (0..n).map(|k| k as f64 / rate_hz).collect();
    let u = t
        .iter()
        .map(|&t| {
            let w = if t < FADE_IN_S {
                (std::f64::consts::FRAC_PI_2 * t / FADE_IN_S).sin().powi(2)
            } else {
                1.0
            };
            amp * w * (-t / 2.5).exp() * (2.0 * std::f64::consts::PI * t).sin()
        })
        .collect();
    (t, u)
}

/// 004 eq. (19): `u(t) = amp*e^(-0.21 t)*[sin(2 pi t + 1.5 pi) + 1]` (starts at 0, stays >= 0).
pub fn decaying_sine_004(amp: f64, t: &[f64]) -> Vec<f64> {
    t.iter()
        .map(|t| {
            amp * (-0.21 * t).exp()
                * ((2.0 * std::f64::consts::PI * t + 1.5 * std::f64::consts::PI).sin() + 1.0)
        })
        .collect()
}

/// Runs `model` over `u` from rest and returns its output.
pub fn run_model<M: Hysteresis<f64>>(model: &M, u: &[f64], dt: f64) -> Vec<f64> {
    let mut s = model.init(0.0);
    u.iter().map(|&u| model.step(&mut s, u, dt)).collect()
}

/// Runs a single-variable BW-type model and returns `(y, h)`.
fn run_bw<M: Hysteresis<f64, State = BwState<f64>>>(
    model: &M,
    u: &[f64],
    dt: f64,
) -> (Vec<f64>, Vec<f64>) {
    let mut s = model.init(0.0);
    u.iter()
        .map(|&u| {
            let y = model.step(&mut s, u, dt);
            (y, s.h)
        })
        .unzip()
}

/// One model's run: name, what the y axis is, input, output, extra CSV columns.
struct Loop {
    name: &'static str,
    ylabel: &'static str,
    u: Vec<f64>,
    y: Vec<f64>,
    extra: Vec<(&'static str, Vec<f64>)>,
}

impl Loop {
    /// A loop of output `y` on input `u`, no extra columns.
    fn of(name: &'static str, ylabel: &'static str, u: &[f64], y: Vec<f64>) -> Self {
        Self {
            name,
            ylabel,
            u: u.to_vec(),
            y,
            extra: vec![],
        }
    }

    /// A BW-type model's loop on input `u`, with its hysteresis variable `h`.
    fn bw<M: Hysteresis<f64, State = BwState<f64>>>(
        name: &'static str,
        ylabel: &'static str,
        model: &M,
        u: &[f64],
        dt: f64,
    ) -> Self {
        let (y, h) = run_bw(model, u, dt);
        Self {
            extra: vec![("h", h)],
            ..Self::of(name, ylabel, u, y)
        }
    }
}

fn write_csv(path: &Path, t: &[f64], l: &Loop) -> Result<()> {
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?,
    );
    // The record convention of `crate::record`: units in the header names where the loop
    // has them (time in s, input in V; the output in um, or unitless for mrad and
    // normalized loops).
    let y = if l.ylabel.ends_with("[um]") {
        "y_um"
    } else {
        "y"
    };
    write!(f, "t_s,u_V,{y}")?;
    for (name, _) in &l.extra {
        write!(f, ",{name}")?;
    }
    writeln!(f)?;
    for k in 0..t.len() {
        write!(f, "{},{},{}", t[k], l.u[k], l.y[k])?;
        for (_, col) in &l.extra {
            write!(f, ",{}", col[k])?;
        }
        writeln!(f)?;
    }
    f.flush()?;
    Ok(())
}

/// 002 table 1, MBW column, driven by `u` from rest.
fn mbw_002_loop(u: &[f64], dt: f64) -> Result<Loop> {
    let mbw = Mbw002::from_002(1.0998, -0.0656, 0.3922, -0.15, 1.0, -0.011, 0.0108, 3.68e-5)?;
    let mut s = mbw.init(0.0);
    let (mut y, mut h, mut rate) = (Vec::new(), Vec::new(), Vec::new());
    for &u in u {
        y.push(mbw.step(&mut s, u, dt));
        h.push(s.h);
        rate.push(s.du_dt);
    }
    Ok(Loop {
        name: "mbw_002",
        ylabel: "y [um]",
        u: u.to_vec(),
        y,
        extra: vec![("h", h), ("du_dt", rate)],
    })
}

pub fn run(args: Args) -> Result<()> {
    anyhow::ensure!(
        args.rate_hz.is_finite() && args.rate_hz >= 10.0,
        "--rate-hz must be at least 10 Hz, got {}",
        args.rate_hz
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut report = Report::start("piezo demo: hysteresis loops");
    let dt = 1.0 / args.rate_hz;
    let (t, u100) = decaying_sine(100.0, args.rate_hz);
    let (_, u5) = decaying_sine(5.0, args.rate_hz);
    let u004 = decaying_sine_004(5.45, &t);
    let mut loops = Vec::new();

    // 000 backup slide, set 1.
    let cbw = Cbw::with_n1(0.16, 0.07, 0.02, 0.01)?;
    loops.push(Loop::bw("cbw", "y [um]", &cbw, &u100, dt));

    // 000 eq. (3): A like set 1, B = 0.003, G = 0.02 (asymmetric equilibria 3.0 / 4.1 um);
    // 60 V keeps the sweep out of the run-away region the model guards (see `Gbw`).
    let gbw = Gbw::new(0.16, 1.0, 0.07, 0.003, 0.02, 1.0)?;
    let u60: Vec<f64> = u100.iter().map(|u| 0.6 * u).collect();
    loops.push(Loop::bw("gbw", "y [um]", &gbw, &u60, dt));

    // 000 eq. (4): stiffness like set 1's A_bw, saturation 3 um.
    let dahl = Dahl::new(0.16, 0.07, 3.0, 1.5)?;
    loops.push(Loop::bw("dahl", "y [um]", &dahl, &u100, dt));

    // 001 eq. (4-10): 8 backlash operators, thresholds 0..100 V, weights falling off.
    let r: [f64; 8] = core::array::from_fn(|i| 12.5 * i as f64 + 1.0);
    let w: [f64; 8] = core::array::from_fn(|i| 0.03 * 0.75f64.powi(i as i32));
    let pi = Pi::new(0.1, w, r)?;
    loops.push(Loop::of("pi", "y [um]", &u100, run_model(&pi, &u100, dt)));
    let ppi = Ppi::new(3e-6, 0.1, w, r)?;
    loops.push(Loop::of("ppi", "y [um]", &u100, run_model(&ppi, &u100, dt)));
    let w_dpi: [f64; 8] = w.map(|w| w + 0.1 / 8.0); // absorb w0 into the bank (eq. 10 has none)
    let dpi = Dpi::new(w_dpi, r, [1.0, 0.4, 0.4], [0.0, 3.0, 6.0])?;
    loops.push(Loop::of("dpi", "y [um]", &u100, run_model(&dpi, &u100, dt)));

    // 004 eq. (21) "traditional asymmetric BW" (= 001 eq. 3 in piezo form), 004's values.
    let abw_u = AbwU::new(0.9221, 0.3050, 0.5913, 0.1649, 1.7170, 0.0415)?;
    loops.push(Loop::bw("abw_u", "y [mrad]", &abw_u, &u5, dt));

    // 002 table 1, asymmetric BW column, mapped to piezo form.
    let abw_abs = AbwAbs::from_002(1.0986, -0.6715, 1.9231, -0.35, 1.0, 0.032)?;
    loops.push(Loop::bw("abw_abs", "y [um]", &abw_abs, &u5, dt));

    loops.push(mbw_002_loop(&u5, dt)?);

    // 004 fig. 5b (rho 0.5, lambda 0.4, mu 0.45) and the identified WPMBW, 004 eq. (19) input.
    let rlm = MbwRlm::new(0.5, 0.4, 0.45)?;
    loops.push(Loop::of("mbw_rlm", "w", &u004, run_model(&rlm, &u004, dt)));
    let wpmbw = Wpmbw::new(MbwRlm::new(0.6485, 0.7217, 0.7440)?, [0.9268, 0.0048])?;
    let run_rlm = |s: &mut RlmState<f64>, u: f64| (wpmbw.step(s, u, dt), s.w);
    let mut s = wpmbw.init(0.0);
    let (y, w): (Vec<f64>, Vec<f64>) = u004.iter().map(|&u| run_rlm(&mut s, u)).unzip();
    loops.push(Loop {
        name: "wpmbw",
        ylabel: "v [mrad]",
        u: u004.clone(),
        y: y.clone(),
        extra: vec![("w", w.clone())],
    });

    // Hammerstein (004 eq. 6-8): WPMBW then the stage's 2nd-order dynamics from 004's
    // m, b, k (wn = sqrt(k/m) = 554 rad/s, zeta = b/(2 sqrt(k m)) = 0.71), exact ZOH.
    let (m, b, k) = (0.1029, 81.3370, 3.1628e4);
    let lin = Linear::<f64, 1>::new(
        1.0,
        [Section::Second {
            wn: f64::sqrt(k / m),
            zeta: b / (2.0 * f64::sqrt(k * m)),
            zero: None,
        }],
        dt,
        Discretisation::Zoh,
    )?;
    let mut ls = lin.init(0.0);
    let yl: Vec<f64> = y.iter().map(|&v| lin.step(&mut ls, v)).collect();
    loops.push(Loop {
        name: "wpmbw_linear",
        ylabel: "y [mrad]",
        u: u004.clone(),
        y: yl,
        extra: vec![("w", w), ("v", y)],
    });

    // 003 eq. (4-7), 3 x 3, A/B/Gamma magnitudes after 003 eq. (22) (illustrative D);
    // U_x swept +-200 V as in 003's characterisation, U_y = U_z = 0.
    let multi = MultiBw::<f64, 3, 3>::new(
        [
            [0.18, 0.0054, -0.036],
            [-0.0345, 0.18, -0.0259],
            [0.01, -0.01, 0.031],
        ],
        [
            [0.0616, 0.0013, -0.0338],
            [-0.0026, 0.0658, -0.0259],
            [0.0111, -0.0364, 0.0160],
        ],
        [
            [0.0073, 0.0002, 0.0],
            [-0.0001, 0.0054, 0.0],
            [0.0004, 0.0, 0.0017],
        ],
        [
            [0.0016, 0.0, 0.0],
            [-0.0001, 0.0010, 0.0],
            [0.0001, 0.0, 0.0005],
        ],
    )?;
    let ux: Vec<f64> = u100.iter().map(|u| 2.0 * u).collect();
    let mut s = multi.init([0.0; 3]);
    let mut cols: [Vec<f64>; 6] = Default::default();
    for &u in &ux {
        let y = multi.step(&mut s, [u, 0.0, 0.0], dt);
        for i in 0..3 {
            cols[i].push(y[i]);
            cols[3 + i].push(s.h[i]);
        }
    }
    let [yx, yy, yz, hx, hy, hz] = cols;
    loops.push(Loop {
        name: "multi_bw_x",
        ylabel: "y_x [um]",
        u: ux.clone(),
        y: yx,
        extra: vec![
            ("y_y", yy.clone()),
            ("y_z", yz.clone()),
            ("h_x", hx),
            ("h_y", hy),
            ("h_z", hz),
        ],
    });

    let mut plots = Vec::new();
    let mut table = Table::new(&[
        "model", "output", "u min", "u max", "y min", "y max", "files",
    ]);
    let range = |v: &[f64]| {
        v.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            })
    };
    for l in &loops {
        let csv = args.out.join(format!("{}.csv", l.name));
        write_csv(&csv, &t, l)?;
        let xlabel = if l.name.starts_with("multi") {
            "U_x [V]"
        } else {
            "u [V]"
        };
        let mut plot = Plot::new(l.name, xlabel, l.ylabel).line(l.name, &l.u, &l.y);
        if l.name.starts_with("multi") {
            // the couplings on the same axes
            plot = plot.line("y_y", &l.u, &yy).line("y_z", &l.u, &yz);
        }
        let svg = args.out.join(format!("{}.svg", l.name));
        plot.write_svg(&svg)
            .with_context(|| format!("cannot write {}", svg.display()))?;
        plots.push(plot);
        println!("{:13} {} {}", l.name, csv.display(), svg.display());
        let ((u0, u1), (y0, y1)) = (range(&l.u), range(&l.y));
        table.row(vec![
            l.name.into(),
            l.ylabel.into(),
            u0.into(),
            u1.into(),
            y0.into(),
            y1.into(),
            report::links(
                &args.out,
                &[
                    ("plot", format!("{}.svg", l.name)),
                    ("csv", format!("{}.csv", l.name)),
                ],
            ),
        ]);
    }
    let svg = args.out.join("loops.svg");
    write_grid(&svg, &plots, 4).with_context(|| format!("cannot write {}", svg.display()))?;
    println!("plot: {}", svg.display());
    report
        .section("Loops")
        .text(format!(
            "Every hysteresis model driven from rest by a decaying sine, {} Hz sample rate; input u in V (multi_bw_x: U_x), output in the unit of its column.",
            args.rate_hz
        ))
        .table(table)
        .plot("loops.svg");
    println!("report: {}", report.write(&args.out)?.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The largest change of the MBW output between two samples, and the loop's height.
    fn mbw_steps(rate_hz: f64) -> (f64, f64) {
        let (_, u) = decaying_sine(5.0, rate_hz);
        let l = mbw_002_loop(&u, 1.0 / rate_hz).unwrap();
        let jump =
            l.y.windows(2)
                .map(|w| (w[1] - w[0]).abs())
                .fold(0.0, f64::max);
        let (lo, hi) =
            l.y.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &y| {
                    (a.min(y), b.max(y))
                });
        (jump, hi - lo)
    }

    /// The demo's input is continuous and so is its rate; then the MBW loop is continuous:
    /// its largest sample-to-sample step shrinks with the sample period (a jump would not).
    #[test]
    fn mbw_loop_is_continuous() {
        let (j10k, height) = mbw_steps(10_000.0);
        let (j100k, _) = mbw_steps(100_000.0);
        eprintln!(
            "largest step {j10k:.2e} um at 10 kHz, {j100k:.2e} um at 100 kHz ({height:.2} um loop)"
        );
        assert!(j10k < 2e-3 * height, "step {j10k} um of a {height} um loop");
        assert!(
            j100k < 0.2 * j10k,
            "{j100k} um at 100 kHz vs {j10k} um at 10 kHz"
        );
    }

    #[test]
    fn decaying_sine_starts_at_rest() {
        let (_, u) = decaying_sine(5.0, 10_000.0);
        assert_eq!(u[0], 0.0);
        assert!(
            (u[1] - u[0]).abs() * 10_000.0 < 1e-3,
            "rate {}",
            (u[1] - u[0]) * 1e4
        );
    }
}
