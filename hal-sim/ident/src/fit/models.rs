//! The model registry: every identifiable model of the core, with data-scaled bounds.
//!
//! Each entry maps a parameter vector to a core model and simulates it with a monomorphised
//! loop (one dynamic call per simulation, none per sample). Bounds come from the record's
//! scales so one registry serves volts-and-micrometres and newtons-and-metres alike.

use piezo_core::hysteresis::structural::{Hold, Integrator, StructuralBw};
use piezo_core::hysteresis::{
    AbwAbs, AbwU, Cbw, Dahl, Dpi, Gbw, Hysteresis, Mbw002, MbwRlm, ParamError, Pi, Ppi, Wpmbw,
};

/// Number of backlash operators of the PI family fits.
pub const PI_OPERATORS: usize = 10;
/// Number of dead-zone operators of the DPI fit.
pub const DPI_DEAD_ZONES: usize = 3;

/// One parameter: name, search box, and whether the search runs in log space.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSpec {
    pub name: String,
    pub lo: f64,
    pub hi: f64,
    /// Search `log10(x)` (both bounds > 0): for scales spanning decades.
    pub log: bool,
}

impl ParamSpec {
    pub fn lin(name: &str, lo: f64, hi: f64) -> Self {
        Self {
            name: name.into(),
            lo: lo.min(hi),
            hi: hi.max(lo),
            log: false,
        }
    }
    pub fn log(name: &str, lo: f64, hi: f64) -> Self {
        Self {
            name: name.into(),
            lo: lo.min(hi),
            hi: hi.max(lo),
            log: true,
        }
    }
}

/// Scales of a training record that set the search boxes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scales {
    /// Input range `max(u) - min(u)`.
    pub u_range: f64,
    /// Largest `|u|`.
    pub u_abs: f64,
    /// Output range.
    pub y_range: f64,
    pub y_min: f64,
    pub y_max: f64,
    /// `|y_range / u_range|`, the order of the gain.
    pub slope: f64,
    /// Mean `|du/dt| / u_range` (1/s), the order of the input rate.
    pub rate: f64,
}

impl Scales {
    pub fn of(u: &[f64], y: &[f64], dt: f64) -> Self {
        let range = |v: &[f64]| {
            v.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                })
        };
        let (u0, u1) = range(u);
        let (y0, y1) = range(y);
        let u_range = (u1 - u0).max(1e-12);
        let y_range = (y1 - y0).max(1e-12);
        let mean_rate = u.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>()
            / (dt * (u.len().max(2) - 1) as f64);
        Self {
            u_range,
            u_abs: u0.abs().max(u1.abs()).max(1e-12),
            y_range,
            y_min: y0,
            y_max: y1,
            slope: y_range / u_range,
            rate: (mean_rate / u_range).max(1e-9),
        }
    }
}

/// Simulates a parameter vector on an input; fills `y` (same length as `u`).
pub type SimFn = fn(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError>;

/// A registered model.
pub struct ModelDef {
    pub name: &'static str,
    pub about: &'static str,
    /// Parameters (without the output offset, which the fit adds for static models).
    pub params: fn(&Scales) -> Vec<ParamSpec>,
    pub simulate: SimFn,
    /// Integrated in time (inertia): simulated from rest on an upsampled input, no offset.
    pub dynamic: bool,
}

/// Runs `m` from its relaxed state at `u[0]` (the first output is at zero increment).
#[inline]
pub fn run<M: Hysteresis<f64>>(m: &M, u: &[f64], dt: f64, y: &mut [f64]) {
    let Some(&u0) = u.first() else { return };
    let mut s = m.init(u0);
    let mut it = y.iter_mut().zip(u);
    if let Some((y0, &u0)) = it.next() {
        *y0 = m.step(&mut s, u0, 0.0);
    }
    for (yi, &ui) in it {
        *yi = m.step(&mut s, ui, dt);
    }
}

/// The Bouc-Wen family's common box: the gain `d`, the loop's slope `slope` (of the
/// gain's order) and its saturation `sat` (of `1 / u_range`), then the model's `rest`.
fn bw_specs(s: &Scales, slope: &str, sat: &str, rest: ParamSpec) -> Vec<ParamSpec> {
    vec![
        ParamSpec::lin("d", 0.0, 3.0 * s.slope),
        ParamSpec::log(slope, 1e-3 * s.slope, 3.0 * s.slope),
        ParamSpec::log(sat, 1e-3 / s.u_range, 1e3 / s.u_range),
        rest,
    ]
}

fn cbw_specs(s: &Scales) -> Vec<ParamSpec> {
    // gamma = g * beta keeps 004 eq. (3) (|gamma| <= beta) inside the box.
    bw_specs(s, "alpha", "beta", ParamSpec::lin("gamma/beta", -1.0, 1.0))
}

fn cbw(p: &[f64]) -> Result<Cbw<f64>, ParamError> {
    Cbw::with_n1(p[0], p[1], p[2], p[3] * p[2])
}

fn sim_cbw(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&cbw(p)?, u, dt, y);
    Ok(())
}

fn cbw_n_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = cbw_specs(s);
    v.push(ParamSpec::lin("n", 1.0, 4.0));
    v
}

/// 001 eq. (2) with the exponent form of [`Cbw`]: `beta*|u'|*|h|^(n-1)*h` (001 prints
/// `|h|^n*h`, inconsistent with its eq. 3; see the `Cbw` doc).
fn sim_cbw_n(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    // beta, gamma are searched in the n = 1 box (their unit is 1/(V um^(n-1)) for n > 1).
    let m = Cbw::new(p[0], p[1], p[2], p[3] * p[2], p[4])?;
    run(&m, u, dt, y);
    Ok(())
}

/// The GBW the laws predict with (`fts-gbw`, `nmpc-gbw`): 000 eq. (3) with its CBW term
/// ([`Gbw::with_beta_h`]), `alpha = n = 1`. `G = g*B_h` with `g` in CBW's `gamma/beta` box and
/// `B = b*(B_h + G)`, `|b| < 1`, keep both equilibria bounded. `A, B_h, G` are the firmware's
/// `cbw_alpha, cbw_beta, cbw_gamma`, `B` its `gbw_b`.
fn gbw_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = bw_specs(s, "A", "B_h", ParamSpec::lin("G/B_h", -1.0, 1.0));
    v.push(ParamSpec::lin("B/(B_h+G)", -0.99, 0.99));
    v
}

/// `gbw_specs`' vector as the model.
pub fn gbw(p: &[f64]) -> Result<Gbw<f64>, ParamError> {
    let g = p[3] * p[2];
    Gbw::with_beta_h(p[0], 1.0, p[1], p[2], p[4] * (p[2] + g), g, 1.0)
}

fn sim_gbw(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&gbw(p)?, u, dt, y);
    Ok(())
}

/// 000 eq. (3) as printed ([`Gbw::new`], `B_h = 0`): it keeps no loop under a periodic input
/// (see `Gbw`), so it is not the model of the laws.
fn gbw_printed_specs(s: &Scales) -> Vec<ParamSpec> {
    bw_specs(s, "A", "G", ParamSpec::lin("B/G", -0.99, 0.99))
}

fn sim_gbw_printed(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    // alpha is redundant with A, B, G for a fit; fixed at 1.
    run(
        &Gbw::new(p[0], 1.0, p[1], p[3] * p[2], p[2], 1.0)?,
        u,
        dt,
        y,
    );
    Ok(())
}

fn dahl_specs(s: &Scales) -> Vec<ParamSpec> {
    vec![
        ParamSpec::lin("d", 0.0, 3.0 * s.slope),
        ParamSpec::log("sigma0", 1e-3 * s.slope, 10.0 * s.slope),
        ParamSpec::log("hc", 1e-3 * s.y_range, 3.0 * s.y_range),
        ParamSpec::lin("i", 0.2, 5.0),
    ]
}

fn sim_dahl(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&Dahl::new(p[0], p[1], p[2], p[3])?, u, dt, y);
    Ok(())
}

fn abw_u_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = cbw_specs(s);
    v.push(ParamSpec::lin(
        "delta",
        -3.0 * s.slope * s.rate,
        3.0 * s.slope * s.rate,
    ));
    v
}

fn sim_abw_u(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(
        &AbwU::new(p[0], p[1], p[2], p[3] * p[2], 1.0, p[4])?,
        u,
        dt,
        y,
    );
    Ok(())
}

fn abw_abs_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = cbw_specs(s);
    // delta = a * alpha keeps alpha > |delta|.
    v.push(ParamSpec::lin("delta/alpha", -0.99, 0.99));
    v
}

fn abw_abs(p: &[f64]) -> Result<AbwAbs<f64>, ParamError> {
    AbwAbs::new(p[0], p[1], p[2], p[3] * p[2], 1.0, p[4] * p[1])
}

fn sim_abw_abs(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&abw_abs(p)?, u, dt, y);
    Ok(())
}

fn mbw002_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = abw_abs_specs(s);
    let rate = s.rate * s.u_range; // V/s
    v.push(ParamSpec::lin("p", -s.y_range / rate, s.y_range / rate));
    v.push(ParamSpec::lin(
        "q",
        -s.y_range / rate.powi(3),
        s.y_range / rate.powi(3),
    ));
    v
}

fn sim_mbw002(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&Mbw002::new(abw_abs(p)?, p[5], p[6])?, u, dt, y);
    Ok(())
}

fn rlm_specs(s: &Scales) -> Vec<ParamSpec> {
    vec![
        ParamSpec::log("rho", 1e-2 * s.slope, 10.0 * s.slope),
        // mu ~ 1 / (rho * y_range), lambda = rho * mu * (1 + l) keeps 004 eq. (14).
        ParamSpec::log("mu*rho*y_range", 1e-2, 1e3),
        ParamSpec::log("l", 1e-3, 1e3),
    ]
}

fn rlm(p: &[f64], s_y: f64) -> Result<MbwRlm<f64>, ParamError> {
    let mu = p[1] / (p[0] * s_y);
    MbwRlm::new(p[0], p[0] * mu * (1.0 + p[2]), mu)
}

// The RLM parameterisation needs the output range; it is carried as the last parameter
// (fixed, zero-width box) so the simulate function stays a plain `fn`.
fn rlm_specs_full(s: &Scales) -> Vec<ParamSpec> {
    let mut v = rlm_specs(s);
    v.push(ParamSpec::lin("y_range (fixed)", s.y_range, s.y_range));
    v
}

fn sim_rlm(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&rlm(p, p[3])?, u, dt, y);
    Ok(())
}

fn wpmbw_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = rlm_specs_full(s);
    v.push(ParamSpec::lin("c1", 0.0, 3.0));
    v.push(ParamSpec::lin("c2", -3.0 / s.y_range, 3.0 / s.y_range));
    v.push(ParamSpec::lin(
        "c3",
        -3.0 / s.y_range.powi(2),
        3.0 / s.y_range.powi(2),
    ));
    v
}

/// `wpmbw_specs`' vector as the model.
pub fn wpmbw(p: &[f64]) -> Result<Wpmbw<f64, 3>, ParamError> {
    Wpmbw::new(rlm(p, p[3])?, [p[4], p[5], p[6]])
}

fn sim_wpmbw(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&wpmbw(p)?, u, dt, y);
    Ok(())
}

/// PI thresholds evenly over half the input range (the widest play a sweep opens): the
/// thresholds of the `pi`, `ppi` and `dpi` fits, from their fixed `u_range` parameter.
pub fn pi_thresholds(u_range: f64) -> [f64; PI_OPERATORS] {
    core::array::from_fn(|i| (i as f64 + 0.5) / PI_OPERATORS as f64 * 0.5 * u_range)
}

fn pi_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = vec![ParamSpec::lin("w0", -3.0 * s.slope, 3.0 * s.slope)];
    for i in 0..PI_OPERATORS {
        v.push(ParamSpec::lin(
            &format!("w{}", i + 1),
            -3.0 * s.slope,
            3.0 * s.slope,
        ));
    }
    v.push(ParamSpec::lin("u_range (fixed)", s.u_range, s.u_range));
    v
}

/// `pi_specs`' vector as the model.
pub fn pi(p: &[f64]) -> Result<Pi<f64, PI_OPERATORS>, ParamError> {
    let w: [f64; PI_OPERATORS] = core::array::from_fn(|i| p[1 + i]);
    Pi::new(p[0], w, pi_thresholds(p[1 + PI_OPERATORS]))
}

fn sim_pi(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&pi(p)?, u, dt, y);
    Ok(())
}

fn ppi_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = vec![ParamSpec::lin(
        "c1",
        -3.0 * s.slope / s.u_abs.powi(2),
        3.0 * s.slope / s.u_abs.powi(2),
    )];
    v.extend(pi_specs(s));
    v[1].name = "c2".into();
    v
}

/// `ppi_specs`' vector as the model.
pub fn ppi(p: &[f64]) -> Result<Ppi<f64, PI_OPERATORS>, ParamError> {
    let w: [f64; PI_OPERATORS] = core::array::from_fn(|i| p[2 + i]);
    Ppi::new(p[0], p[1], w, pi_thresholds(p[2 + PI_OPERATORS]))
}

fn sim_ppi(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&ppi(p)?, u, dt, y);
    Ok(())
}

fn dpi_specs(s: &Scales) -> Vec<ParamSpec> {
    let mut v = Vec::new();
    for i in 0..PI_OPERATORS {
        v.push(ParamSpec::lin(
            &format!("w{}", i + 1),
            -3.0 * s.slope,
            3.0 * s.slope,
        ));
    }
    for k in 0..DPI_DEAD_ZONES {
        v.push(ParamSpec::lin(&format!("ws{}", k + 1), -3.0, 3.0));
    }
    v.push(ParamSpec::lin("u_range (fixed)", s.u_range, s.u_range));
    v.push(ParamSpec::lin("y_range (fixed)", s.y_range, s.y_range));
    v
}

/// `dpi_specs`' vector as the model.
pub fn dpi(p: &[f64]) -> Result<Dpi<f64, PI_OPERATORS, DPI_DEAD_ZONES>, ParamError> {
    let n = PI_OPERATORS;
    let w: [f64; PI_OPERATORS] = core::array::from_fn(|i| p[i]);
    let ws: [f64; DPI_DEAD_ZONES] = core::array::from_fn(|k| p[n + k]);
    let r = pi_thresholds(p[n + DPI_DEAD_ZONES]);
    Dpi::new(w, r, ws, dpi_dead_zones(p[n + DPI_DEAD_ZONES + 1]))
}

fn sim_dpi(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    run(&dpi(p)?, u, dt, y);
    Ok(())
}

/// Dead-zone thresholds of the `dpi` fit from its fixed `y_range` parameter: 0, 1/3, 2/3 of
/// the output range (one-sided, 001 eq. 9).
pub fn dpi_dead_zones(y_range: f64) -> [f64; DPI_DEAD_ZONES] {
    core::array::from_fn(|k| k as f64 / DPI_DEAD_ZONES as f64 * y_range)
}

/// Structural BW parameters: `[m, c, k, alpha, beta*gamma, beta*delta, nu]` (beta = 1; only
/// the products enter the equations). Wide boxes: the benchmark treats them as unknown.
fn structural_specs(_s: &Scales) -> Vec<ParamSpec> {
    vec![
        ParamSpec::log("m", 1e-2, 1e2),
        ParamSpec::log("c", 1e-2, 1e4),
        ParamSpec::log("k", 1e2, 1e7),
        ParamSpec::log("alpha", 1e2, 1e7),
        ParamSpec::lin("beta*gamma", -1e4, 1e4),
        ParamSpec::lin("beta*delta", -1e4, 1e4),
        ParamSpec::lin("nu", 1.0, 3.0),
    ]
}

/// The structural model for a parameter vector, `substeps` RK4 steps per input sample.
pub fn structural(p: &[f64], substeps: usize) -> Result<StructuralBw<f64>, ParamError> {
    StructuralBw::new(
        p[0],
        p[1],
        p[2],
        p[3],
        1.0,
        p[4],
        p[5],
        p[6],
        substeps,
        Hold::First,
    )
}

fn sim_structural(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    // The caller upsamples the input; one RK4 step per (upsampled) sample.
    run_structural(&structural(p, 1)?, u, dt, y);
    Ok(())
}

fn sim_structural_newmark(p: &[f64], u: &[f64], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    let m = structural(p, 1)?.with_integrator(Integrator::Newmark);
    run_structural(&m, u, dt, y);
    Ok(())
}

fn run_structural(m: &StructuralBw<f64>, u: &[f64], dt: f64, y: &mut [f64]) {
    // From rest at the first input sample; the first output is the initial condition.
    let mut s = m.init(u.first().copied().unwrap_or(0.0));
    if let Some(y0) = y.first_mut() {
        *y0 = 0.0;
    }
    for (yi, &ui) in y.iter_mut().zip(u).skip(1) {
        *yi = m.step(&mut s, ui, dt);
    }
}

impl core::fmt::Debug for ModelDef {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "ModelDef({})", self.name)
    }
}

fn gain_specs(s: &Scales) -> Vec<ParamSpec> {
    vec![ParamSpec::lin("gain", 0.0, 3.0 * s.slope)]
}

fn sim_gain(p: &[f64], u: &[f64], _dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    for (yi, ui) in y.iter_mut().zip(u) {
        *yi = p[0] * ui;
    }
    Ok(())
}

/// Every model `piezo fit --model` knows.
pub static MODELS: &[ModelDef] = &[
    ModelDef {
        name: "gain",
        about: "static gain (with --linear: the linear part alone, step 1 of 004 sec. 4.2)",
        params: gain_specs,
        simulate: sim_gain,
        dynamic: false,
    },
    ModelDef {
        name: "cbw",
        about: "classical Bouc-Wen, n = 1 (000 eq. 1-2)",
        params: cbw_specs,
        simulate: sim_cbw,
        dynamic: false,
    },
    ModelDef {
        name: "cbw-n",
        about: "classical Bouc-Wen with exponent n (001 eq. 2 with |h|^(n-1)*h in the beta term, as its eq. 3)",
        params: cbw_n_specs,
        simulate: sim_cbw_n,
        dynamic: false,
    },
    ModelDef {
        name: "gbw",
        about: "generalized Bouc-Wen with its CBW term B_h, n = 1 (000 eq. 3; the model of fts-gbw, nmpc-gbw)",
        params: gbw_specs,
        simulate: sim_gbw,
        dynamic: false,
    },
    ModelDef {
        name: "gbw-printed",
        about: "generalized Bouc-Wen as 000 eq. (3) prints it (no B_h term; keeps no loop), n = 1",
        params: gbw_printed_specs,
        simulate: sim_gbw_printed,
        dynamic: false,
    },
    ModelDef {
        name: "dahl",
        about: "Dahl (000 eq. 4)",
        params: dahl_specs,
        simulate: sim_dahl,
        dynamic: false,
    },
    ModelDef {
        name: "abw-u",
        about: "asymmetric Bouc-Wen with delta*u*sgn(u') (001 eq. 3)",
        params: abw_u_specs,
        simulate: sim_abw_u,
        dynamic: false,
    },
    ModelDef {
        name: "abw-abs",
        about: "asymmetric Bouc-Wen with delta*|u'| (002 eq. 3)",
        params: abw_abs_specs,
        simulate: sim_abw_abs,
        dynamic: false,
    },
    ModelDef {
        name: "mbw002",
        about: "modified Bouc-Wen with p*u' + q*u'^3 (002 eq. 4-5)",
        params: mbw002_specs,
        simulate: sim_mbw002,
        dynamic: false,
    },
    ModelDef {
        name: "mbw-rlm",
        about: "modified Bouc-Wen in rho, lambda, mu (004 eq. 4-6)",
        params: rlm_specs_full,
        simulate: sim_rlm,
        dynamic: false,
    },
    ModelDef {
        name: "wpmbw",
        about: "weighted polynomial MBW, L = 3 (004 eq. 7)",
        params: wpmbw_specs,
        simulate: sim_wpmbw,
        dynamic: false,
    },
    ModelDef {
        name: "pi",
        about: "Prandtl-Ishlinskii, 10 backlash operators (001 eq. 4-5)",
        params: pi_specs,
        simulate: sim_pi,
        dynamic: false,
    },
    ModelDef {
        name: "ppi",
        about: "PI with cubic polynomial, 10 operators (001 eq. 6-7)",
        params: ppi_specs,
        simulate: sim_ppi,
        dynamic: false,
    },
    ModelDef {
        name: "dpi",
        about: "PI with 3 one-sided dead zones, 10 operators (001 eq. 8-10)",
        params: dpi_specs,
        simulate: sim_dpi,
        dynamic: false,
    },
    ModelDef {
        name: "structural-bw",
        about: "structural Bouc-Wen oscillator, force in, displacement out (003 eq. 1; Bouc-Wen benchmark)",
        params: structural_specs,
        simulate: sim_structural,
        dynamic: true,
    },
    ModelDef {
        name: "structural-bw-newmark",
        about: "structural Bouc-Wen integrated by Newmark average acceleration, as the benchmark generator",
        params: structural_specs,
        simulate: sim_structural_newmark,
        dynamic: true,
    },
];

/// The model called `name`, or an error listing the known names.
pub fn find(name: &str) -> anyhow::Result<&'static ModelDef> {
    MODELS.iter().find(|m| m.name == name).ok_or_else(|| {
        anyhow::anyhow!(
            "unknown model `{name}`; known models: {}",
            MODELS.iter().map(|m| m.name).collect::<Vec<_>>().join(", ")
        )
    })
}
