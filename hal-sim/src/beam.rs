//! Distributed-parameter actuator (000 Part V, eq. 9): a cantilever Euler-Bernoulli beam
//! `EI y'''' + rho A_s y_tt = q(x, t)`, clamped at `x = 0`, free at `x = L`, loaded by the
//! piezo along its length, `q(x, t) = q0 v(t)` with `v = d u - h` (CBW, 000 eq. 1).
//!
//! Modal discretisation: `y(x, t) = sum_i phi_i(x) eta_i(t)` with the cantilever mode shapes
//! `phi_i = cosh(b_i x) - cos(b_i x) - s_i (sinh(b_i x) - sin(b_i x))` (`b_i L` = 1.875, 4.694,
//! 7.855, 10.996; `int phi_i^2 = L`), so
//! `eta_i'' + 2 zeta w_i eta_i' + w_i^2 eta_i = q0 int(phi_i) v / L` and `w_i ~ b_i^2`.
//! `q0` is chosen so that the static tip deflection equals `v`.
//!
//! The simulated beam has [`SIM_MODES`] modes and its own CBW parameters; the observers are
//! built on the first two modes and the nominal CBW (model truncation and parameter error
//! are both real here). Sensor at the tip, objective at `x_c != L`.

use anyhow::Result;
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};
use piezo_core::manipulation::beam::ModalModel;
use piezo_core::manipulation::{Hgo, Nno, NnoConfig, VoltageInput};
use serde::Serialize;

use crate::numeric::Rng;

/// Modes of the simulated beam.
pub const SIM_MODES: usize = 4;
/// Modes of the observers' model.
pub const OBS_MODES: usize = 2;
/// Hidden units of the NNO.
pub const NNO_HIDDEN: usize = 8;

const BETA_L: [f64; SIM_MODES] = [1.875_104_07, 4.694_091_13, 7.854_757_44, 10.995_540_73];

/// Cantilever mode shape `i` at `x` (in units of `L`).
pub fn mode_shape(i: usize, x: f64) -> f64 {
    let b = BETA_L[i];
    let s = (b.cosh() + b.cos()) / (b.sinh() + b.sin());
    let bx = b * x;
    bx.cosh() - bx.cos() - s * (bx.sinh() - bx.sin())
}

/// `int_0^1 phi_i dx` (in units of `L`): `2 s_i / b_i`.
fn mode_integral(i: usize) -> f64 {
    let b = BETA_L[i];
    let s = (b.cosh() + b.cos()) / (b.sinh() + b.sin());
    2.0 * s / b
}

/// Beam settings.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct BeamConfig {
    pub rate_hz: f64,
    /// First natural frequency (Hz); the others follow `(b_i / b_1)^2`.
    pub f1_hz: f64,
    pub damping_ratio: f64,
    /// Control point (in units of `L`).
    pub x_c: f64,
    /// Tip sensor noise (um) and voltage measurement noise (V).
    pub noise_y_um: f64,
    pub noise_u_volts: f64,
    pub u_play_volts: f64,
    /// HGO: error poles at `-1/eps`, given as `1/(2 pi eps)` (Hz).
    pub hgo_hz: f64,
    /// NNO settings.
    pub nno_observer_hz: f64,
    pub nno_learning_rate: f64,
    pub nno_e_mod: f64,
    /// Plant CBW differs from the observers' (000 set 2 vs set 1) when true.
    pub mismatch: bool,
    /// The observers' beam model against the plant's: first natural frequency and damping
    /// ratio scaled by these (1, 1: the plant's own; the truncation to two modes stays).
    pub model_f1_scale: f64,
    pub model_damping_scale: f64,
    /// The observers are denied the hysteresis model: they get a CBW whose loop is 1 % of
    /// the nominal one's (`alpha` / 100), so the HGO's state `h` and the NNO's network must
    /// account for the hysteresis.
    pub deny_hysteresis: bool,
    pub duration_s: f64,
    pub seed: u64,
}

impl Default for BeamConfig {
    fn default() -> Self {
        Self {
            rate_hz: 10_000.0,
            f1_hz: 100.0,
            damping_ratio: 0.02,
            x_c: 0.5,
            noise_y_um: 0.005,
            noise_u_volts: 0.02,
            u_play_volts: 0.06,
            // Best of a sweep (150/300/600 Hz) on the mismatched plant.
            hgo_hz: 600.0,
            // Best with learning of a sweep (300/600/1000 Hz x eta 0..1e4).
            nno_observer_hz: 300.0,
            nno_learning_rate: 1000.0,
            nno_e_mod: 1.0,
            mismatch: true,
            model_f1_scale: 1.0,
            model_damping_scale: 1.0,
            deny_hysteresis: false,
            duration_s: 1.5,
            seed: 5,
        }
    }
}

/// The simulated beam.
#[derive(Debug, Clone)]
pub struct BeamPlant {
    pub cbw: Cbw<f64>,
    omega: [f64; SIM_MODES],
    gain: [f64; SIM_MODES],
    zeta: f64,
    substeps: usize,
}

/// Modal state of the simulated beam.
#[derive(Debug, Clone, Copy)]
pub struct BeamState {
    pub eta: [f64; SIM_MODES],
    pub deta: [f64; SIM_MODES],
    pub hs: BwState<f64>,
}

/// `q0` with a static tip deflection of `v` over `modes` modes, and the modal gains.
fn modal_gains(f1_hz: f64, modes: usize) -> ([f64; SIM_MODES], [f64; SIM_MODES]) {
    let mut omega = [0.0; SIM_MODES];
    let mut g = [0.0; SIM_MODES];
    for i in 0..SIM_MODES {
        omega[i] = std::f64::consts::TAU * f1_hz * (BETA_L[i] / BETA_L[0]).powi(2);
        g[i] = mode_integral(i);
    }
    let tip: f64 = (0..modes)
        .map(|i| mode_shape(i, 1.0) * g[i] / (omega[i] * omega[i]))
        .sum();
    for gi in g.iter_mut() {
        *gi /= tip;
    }
    (omega, g)
}

impl BeamPlant {
    pub fn new(cfg: &BeamConfig) -> Result<Self> {
        anyhow::ensure!(
            cfg.f1_hz.is_finite() && cfg.f1_hz > 0.0,
            "beam: f1_hz must be positive, got {}",
            cfg.f1_hz
        );
        anyhow::ensure!(
            cfg.x_c > 0.0 && cfg.x_c < 1.0,
            "beam: the control point x_c must lie inside (0, L), got {}",
            cfg.x_c
        );
        let cbw = if cfg.mismatch {
            Cbw::with_n1(0.16, 0.09, 0.03, 0.015)?
        } else {
            nominal_cbw()
        };
        let (omega, gain) = modal_gains(cfg.f1_hz, SIM_MODES);
        let wmax = omega[SIM_MODES - 1] / cfg.rate_hz;
        Ok(Self {
            cbw,
            omega,
            gain,
            zeta: cfg.damping_ratio,
            substeps: (wmax / 0.1).ceil().max(1.0) as usize,
        })
    }

    pub fn init(&self) -> BeamState {
        BeamState {
            eta: [0.0; SIM_MODES],
            deta: [0.0; SIM_MODES],
            hs: self.cbw.init(0.0),
        }
    }

    /// One sample with the voltage moving linearly to `u`.
    pub fn step(&self, s: &mut BeamState, u: f64, dt: f64) {
        let n = self.substeps;
        let h = dt / n as f64;
        let u0 = s.hs.u;
        for k in 1..=n {
            let v = self
                .cbw
                .step(&mut s.hs, u0 + (u - u0) * k as f64 / n as f64, h);
            for i in 0..SIM_MODES {
                let (w, g) = (self.omega[i], self.gain[i]);
                let z = self.zeta;
                let f = |x: [f64; 2]| [x[1], g * v - w * w * x[0] - 2.0 * z * w * x[1]];
                let x = [s.eta[i], s.deta[i]];
                let k1 = f(x);
                let k2 = f([x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1]]);
                let k3 = f([x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1]]);
                let k4 = f([x[0] + h * k3[0], x[1] + h * k3[1]]);
                s.eta[i] += h / 6.0 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]);
                s.deta[i] += h / 6.0 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]);
            }
        }
    }

    /// Deflection at `x` (units of `L`), um.
    pub fn deflection(&self, s: &BeamState, x: f64) -> f64 {
        (0..SIM_MODES).map(|i| mode_shape(i, x) * s.eta[i]).sum()
    }
}

/// CBW parameter set 1 of 000 (the observers' model).
pub fn nominal_cbw() -> Cbw<f64> {
    Cbw::with_n1(0.16, 0.07, 0.02, 0.01).expect("000 set 1 is valid")
}

/// The hysteresis model the observers get: [`nominal_cbw`], or (denied) one with 1 % of its
/// loop.
pub fn observer_cbw(cfg: &BeamConfig) -> Result<Cbw<f64>> {
    Ok(if cfg.deny_hysteresis {
        Cbw::with_n1(0.16, 0.0007, 0.02, 0.01)?
    } else {
        nominal_cbw()
    })
}

/// The observers' two-mode model (same `q0` as the plant: truncation is a model error;
/// `model_f1_scale` and `model_damping_scale` add a beam mismatch).
pub fn observer_model(cfg: &BeamConfig) -> ModalModel<f64, { 2 * OBS_MODES }> {
    let (omega, g) = modal_gains(cfg.f1_hz * cfg.model_f1_scale, SIM_MODES);
    let zeta = cfg.damping_ratio * cfg.model_damping_scale;
    let mut m = ModalModel {
        a: [[0.0; 2 * OBS_MODES]; 2 * OBS_MODES],
        b: [0.0; 2 * OBS_MODES],
        c_tip: [0.0; 2 * OBS_MODES],
        c_out: [0.0; 2 * OBS_MODES],
    };
    for i in 0..OBS_MODES {
        let w = omega[i];
        m.a[2 * i][2 * i + 1] = 1.0;
        m.a[2 * i + 1][2 * i] = -w * w;
        m.a[2 * i + 1][2 * i + 1] = -2.0 * zeta * w;
        m.b[2 * i + 1] = g[i];
        m.c_tip[2 * i] = mode_shape(i, 1.0);
        m.c_out[2 * i] = mode_shape(i, cfg.x_c);
    }
    m
}

/// Voltage that drives the beam: a slow large sine and a faster small one near mode 1.
pub fn beam_input(t: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let ramp = (t / 0.05).min(1.0);
    ramp * (60.0 + 45.0 * (tau * 4.0 * t).sin() + 8.0 * (tau * 55.0 * t).sin())
}

/// One set of conditions for the HGO-against-NNO comparison: sensor noise, the observers'
/// beam model against the plant's, the hysteresis model denied or given.
#[derive(Debug, Clone, Copy)]
pub struct BeamCondition {
    pub name: &'static str,
    pub noise_y_um: f64,
    pub model_f1_scale: f64,
    pub model_damping_scale: f64,
    pub deny_hysteresis: bool,
}

impl BeamCondition {
    pub fn apply(&self, cfg: &BeamConfig) -> BeamConfig {
        BeamConfig {
            noise_y_um: self.noise_y_um,
            model_f1_scale: self.model_f1_scale,
            model_damping_scale: self.model_damping_scale,
            deny_hysteresis: self.deny_hysteresis,
            ..*cfg
        }
    }
}

/// What 000 Part V leaves open about its comparison (sensor at the tip, estimate at
/// `x_c = L/2`, CBW mismatch as in the `beam` scenario), varied where a neural observer
/// could be ahead: more sensor noise (a high-gain observer amplifies it), a wrong beam model
/// (first mode 20 % low, damping doubled), the hysteresis model denied, and all at once.
pub const BEAM_CONDITIONS: [BeamCondition; 5] = [
    BeamCondition {
        name: "nominal",
        noise_y_um: 0.005,
        model_f1_scale: 1.0,
        model_damping_scale: 1.0,
        deny_hysteresis: false,
    },
    BeamCondition {
        name: "noise-50nm",
        noise_y_um: 0.05,
        model_f1_scale: 1.0,
        model_damping_scale: 1.0,
        deny_hysteresis: false,
    },
    BeamCondition {
        name: "model-off",
        noise_y_um: 0.005,
        model_f1_scale: 0.8,
        model_damping_scale: 2.0,
        deny_hysteresis: false,
    },
    BeamCondition {
        name: "hysteresis-denied",
        noise_y_um: 0.005,
        model_f1_scale: 1.0,
        model_damping_scale: 1.0,
        deny_hysteresis: true,
    },
    BeamCondition {
        name: "all-three-100nm",
        noise_y_um: 0.1,
        model_f1_scale: 0.8,
        model_damping_scale: 2.0,
        deny_hysteresis: true,
    },
];

/// Each observer's best rms error (um) over the same sweep, and its settings.
#[derive(Debug, Clone, Copy)]
pub struct BestOfSweep {
    pub hgo_um: f64,
    pub hgo_hz: f64,
    pub nno_um: f64,
    pub nno_hz: f64,
    pub nno_eta: f64,
    /// The NNO's observer without learning at the NNO's best bandwidth.
    pub luenberger_um: f64,
}

/// Observer bandwidths (Hz) and NNO learning rates of the sweep: the same grid for both.
pub const SWEEP_HZ: [f64; 4] = [75.0, 150.0, 300.0, 600.0];
pub const SWEEP_ETA: [f64; 3] = [300.0, 1000.0, 3000.0];

/// Runs `cfg` over [`SWEEP_HZ`] x [`SWEEP_ETA`]: the HGO's error poles and the NNO's
/// observer at each bandwidth, the NNO at each learning rate; each observer's best.
pub fn best_of_sweep(cfg: &BeamConfig) -> Result<BestOfSweep> {
    let mut b = BestOfSweep {
        hgo_um: f64::INFINITY,
        hgo_hz: 0.0,
        nno_um: f64::INFINITY,
        nno_hz: 0.0,
        nno_eta: 0.0,
        luenberger_um: f64::INFINITY,
    };
    for hz in SWEEP_HZ {
        for (k, eta) in SWEEP_ETA.into_iter().enumerate() {
            let c = BeamConfig {
                hgo_hz: hz,
                nno_observer_hz: hz,
                nno_learning_rate: eta,
                ..*cfg
            };
            let r = run_beam(&c)?;
            let h = est_errors(&r, &r.hgo).0;
            if k == 0 && h < b.hgo_um {
                (b.hgo_um, b.hgo_hz) = (h, hz);
            }
            let n = est_errors(&r, &r.nno).0;
            if n < b.nno_um {
                (b.nno_um, b.nno_hz, b.nno_eta) = (n, hz, eta);
                b.luenberger_um = est_errors(&r, &r.luenberger).0;
            }
        }
    }
    Ok(b)
}

/// Traces and errors of one beam run.
#[derive(Debug, Clone, Default)]
pub struct BeamRun {
    pub t: Vec<f64>,
    pub y_c: Vec<f64>,
    pub y_tip: Vec<f64>,
    /// Control-point estimates: HGO, NNO, NNO without learning (same Luenberger gain).
    pub hgo: Vec<f64>,
    pub nno: Vec<f64>,
    pub luenberger: Vec<f64>,
    /// Sample where the error statistics start.
    pub skip: usize,
}

/// Error statistics (um) of one estimate after the warm-up: (rms, max).
pub fn est_errors(run: &BeamRun, est: &[f64]) -> (f64, f64) {
    let e: Vec<f64> = est[run.skip..]
        .iter()
        .zip(&run.y_c[run.skip..])
        .map(|(a, b)| a - b)
        .collect();
    let rms = (e.iter().map(|x| x * x).sum::<f64>() / e.len().max(1) as f64).sqrt();
    let max = e.iter().map(|x| x.abs()).fold(0.0, f64::max);
    (rms, max)
}

/// Runs the beam with the HGO, the NNO and the NNO without learning side by side on the same
/// noisy measurements.
pub fn run_beam(cfg: &BeamConfig) -> Result<BeamRun> {
    anyhow::ensure!(
        cfg.duration_s.is_finite() && cfg.duration_s > 0.4,
        "beam: duration must exceed 0.4 s, got {}",
        cfg.duration_s
    );
    let plant = BeamPlant::new(cfg)?;
    let model = observer_model(cfg);
    let dt = 1.0 / cfg.rate_hz;
    let input = VoltageInput::new(0.0, cfg.u_play_volts, dt)?;
    let obs_cbw = observer_cbw(cfg)?;
    let hgo: Hgo<f64, { 2 * OBS_MODES + 1 }> = Hgo::new(
        &model,
        obs_cbw,
        1.0 / (std::f64::consts::TAU * cfg.hgo_hz),
        input,
        cfg.rate_hz,
    )?;
    let nno_cfg = NnoConfig {
        learning_rate: cfg.nno_learning_rate,
        e_mod: cfg.nno_e_mod,
        w_max: 1.0,
        observer_hz: cfg.nno_observer_hz,
        y_scale_um: 10.0,
        u_scale_volts: 100.0,
        du_scale: 500.0,
        seed: 12345,
    };
    let nno: Nno<f64, { 2 * OBS_MODES }, NNO_HIDDEN> =
        Nno::new(&model, obs_cbw, nno_cfg, input, cfg.rate_hz)?;
    let lue: Nno<f64, { 2 * OBS_MODES }, NNO_HIDDEN> = Nno::new(
        &model,
        obs_cbw,
        NnoConfig {
            learning_rate: 0.0,
            ..nno_cfg
        },
        input,
        cfg.rate_hz,
    )?;
    let mut ps = plant.init();
    let mut hs = hgo.init(0.0);
    let mut ns = nno.init(0.0);
    let mut ls = lue.init(0.0);
    let mut rng = Rng::new(cfg.seed);
    let n = (cfg.duration_s * cfg.rate_hz) as usize;
    let mut run = BeamRun {
        skip: (0.3 * cfg.rate_hz) as usize,
        ..Default::default()
    };
    for k in 0..n {
        let t = k as f64 * dt;
        let u = beam_input(t);
        plant.step(&mut ps, u, dt);
        let y_tip = plant.deflection(&ps, 1.0);
        let y_meas = y_tip + rng.normal(cfg.noise_y_um);
        let u_meas = u + rng.normal(cfg.noise_u_volts);
        run.t.push(t);
        run.y_c.push(plant.deflection(&ps, cfg.x_c));
        run.y_tip.push(y_tip);
        run.hgo.push(hgo.update(&mut hs, y_meas, u_meas));
        run.nno.push(nno.update(&mut ns, y_meas, u_meas));
        run.luenberger.push(lue.update(&mut ls, y_meas, u_meas));
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mode_shapes_are_normalised_and_clamped() {
        for i in 0..SIM_MODES {
            assert!(mode_shape(i, 0.0).abs() < 1e-12);
            assert!((mode_shape(i, 1.0).abs() - 2.0).abs() < 1e-6);
            let n = 20_000;
            let int: f64 = (0..n)
                .map(|k| mode_shape(i, (k as f64 + 0.5) / n as f64).powi(2))
                .sum::<f64>()
                / n as f64;
            assert!((int - 1.0).abs() < 1e-4, "mode {i}: {int}");
        }
    }

    #[test]
    fn static_tip_deflection_is_v() {
        let cfg = BeamConfig {
            mismatch: false,
            ..Default::default()
        };
        let p = BeamPlant::new(&cfg).unwrap();
        let mut s = p.init();
        for _ in 0..20_000 {
            p.step(&mut s, 20.0, 1e-4);
        }
        let v = 0.16 * 20.0 - s.hs.h;
        assert!((p.deflection(&s, 1.0) - v).abs() < 1e-3 * v);
        assert!(
            p.deflection(&s, 0.5) < 0.5 * v,
            "mid-span deflects less than the tip"
        );
    }
}
