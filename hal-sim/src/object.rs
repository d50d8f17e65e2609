//! Deformable object pushed by the stage (000 Part V), and the runs on it: force estimation
//! without a force sensor, object identification, and barrier-Lyapunov force control (their
//! `piezo sim` scenarios are in [`crate::manipulation`]).
//!
//! Object: nonlinear viscoelastic, a cubic spring in parallel with a damper, in contact only
//! beyond a gap: with `delta = y - gap`,
//! `F = psi[y] = max(0, k1 delta + k3 delta^3 + c delta')` for `delta > 0`, else 0
//! (it can push, never pull). The force is simulated, never given to the estimator.
//!
//! Stage: CBW hysteresis (000 eq. 1) and second-order mechanics loaded by the object,
//! `m y'' + c_s y' + k y = k (d u - h) - F`, integrated with RK4 on sub-steps.

use anyhow::Result;
use piezo_core::hysteresis::{BwState, Cbw, Hysteresis};
use piezo_core::manipulation::{BlfForce, ForceEso, StageDynamics, VoltageInput};
use serde::Serialize;

use crate::numeric::{lowpass, lowpass_n, rms, Rng};

/// Nonlinear viscoelastic object.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Object {
    /// Stage position where contact starts (um).
    pub gap_um: f64,
    /// Linear stiffness (mN/um).
    pub k1: f64,
    /// Cubic stiffness (mN/um^3).
    pub k3: f64,
    /// Damping (mN s/um).
    pub c: f64,
}

impl Object {
    /// Soft object used by the scenarios.
    pub fn default_soft() -> Self {
        Self {
            gap_um: 4.0,
            k1: 40.0,
            k3: 4.0,
            c: 0.1,
        }
    }

    /// Interaction force (mN) at stage position `y_um` moving at `v` (um/s).
    pub fn force(&self, y_um: f64, v: f64) -> f64 {
        let d = y_um - self.gap_um;
        if d > 0.0 {
            (self.k1 * d + self.k3 * d * d * d + self.c * v).max(0.0)
        } else {
            0.0
        }
    }
}

/// The simulated actuator pushing on the object.
#[derive(Debug, Clone, Copy)]
pub struct Plant {
    pub cbw: Cbw<f64>,
    pub stage: StageDynamics<f64>,
    pub object: Object,
    pub substeps: usize,
}

/// Plant state: position, velocity, hysteresis, last voltage.
#[derive(Debug, Clone, Copy)]
pub struct PlantState {
    pub y: f64,
    pub v: f64,
    pub hs: BwState<f64>,
    /// Interaction force at the end of the last step (mN).
    pub force: f64,
}

/// Stage of the scenarios: CBW parameter set 1 of 000 (backup slide), 800 Hz, 200 mN/um.
pub fn default_plant() -> Plant {
    Plant {
        cbw: Cbw::with_n1(0.16, 0.07, 0.02, 0.01).expect("000 set 1 is valid"),
        stage: StageDynamics {
            natural_hz: 800.0,
            damping_ratio: 0.15,
            stiffness_mn_per_um: 200.0,
        },
        object: Object::default_soft(),
        substeps: 20,
    }
}

impl Plant {
    pub fn init(&self) -> PlantState {
        PlantState {
            y: 0.0,
            v: 0.0,
            hs: self.cbw.init(0.0),
            force: 0.0,
        }
    }

    /// Advances one sample of `dt` with the voltage moving linearly to `u`.
    pub fn step(&self, s: &mut PlantState, u: f64, dt: f64) {
        let n = self.substeps.max(1);
        let h = dt / n as f64;
        let w = self.stage.omega();
        let w2 = w * w;
        let tzw = 2.0 * self.stage.damping_ratio * w;
        let a_per_mn = w2 / self.stage.stiffness_mn_per_um;
        let u0 = s.hs.u;
        for i in 1..=n {
            let ui = u0 + (u - u0) * i as f64 / n as f64;
            let v_in = self.cbw.step(&mut s.hs, ui, h);
            let f = |x: [f64; 2]| {
                let force = self.object.force(x[0], x[1]);
                [x[1], w2 * (v_in - x[0]) - tzw * x[1] - a_per_mn * force]
            };
            let x = rk4_2([s.y, s.v], h, f);
            s.y = x[0];
            s.v = x[1];
        }
        s.force = self.object.force(s.y, s.v);
    }
}

fn rk4_2(x: [f64; 2], h: f64, f: impl Fn([f64; 2]) -> [f64; 2]) -> [f64; 2] {
    let k1 = f(x);
    let k2 = f([x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1]]);
    let k3 = f([x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1]]);
    let k4 = f([x[0] + h * k3[0], x[1] + h * k3[1]]);
    [
        x[0] + h / 6.0 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]),
        x[1] + h / 6.0 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]),
    ]
}

/// Noise on every channel (standard deviations).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Noise {
    /// Position sensor (um).
    pub y_um: f64,
    /// Voltage measurement (V).
    pub u_volts: f64,
    /// Force sensor (mN), used only where the force is measured.
    pub f_mn: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Self {
            y_um: 0.005,
            u_volts: 0.02,
            f_mn: 0.3,
        }
    }
}

/// Settings shared by the manipulation scenarios.
#[derive(Debug, Clone, Copy)]
pub struct ManipConfig {
    pub rate_hz: f64,
    pub plant: Plant,
    pub noise: Noise,
    /// Force observer bandwidth (Hz), voltage prefilter (Hz) and play half-width (V).
    pub observer_hz: f64,
    pub u_filter_hz: f64,
    pub u_play_volts: f64,
    pub u_max: f64,
    pub slew_volts_per_s: f64,
    pub seed: u64,
}

impl Default for ManipConfig {
    fn default() -> Self {
        Self {
            rate_hz: 10_000.0,
            plant: default_plant(),
            noise: Noise::default(),
            observer_hz: 400.0,
            u_filter_hz: 0.0,
            u_play_volts: 0.06,
            u_max: 150.0,
            slew_volts_per_s: 20_000.0,
            seed: 1,
        }
    }
}

impl ManipConfig {
    fn eso(&self) -> Result<ForceEso<f64>> {
        Ok(ForceEso::new(
            self.plant.cbw,
            self.plant.stage,
            self.observer_hz,
            VoltageInput::new(self.u_filter_hz, self.u_play_volts, 1.0 / self.rate_hz)?,
            self.rate_hz,
        )?)
    }
}

/// Traces of one run (one entry per sample).
#[derive(Debug, Clone, Default)]
pub struct Traces {
    pub t: Vec<f64>,
    pub y_ref: Vec<f64>,
    pub y: Vec<f64>,
    pub y_meas: Vec<f64>,
    pub u: Vec<f64>,
    pub u_meas: Vec<f64>,
    pub force: Vec<f64>,
    pub force_hat: Vec<f64>,
    pub force_ref: Vec<f64>,
    pub saturated: usize,
}

/// Voltage limits: range and slew; counts samples where either binds.
fn limit(u: f64, prev: f64, cfg: &ManipConfig, sat: &mut usize) -> f64 {
    let step = cfg.slew_volts_per_s / cfg.rate_hz;
    let lo = (prev - step).max(0.0);
    let hi = (prev + step).min(cfg.u_max);
    let out = u.clamp_to_range(lo, hi);
    if out != u {
        *sat += 1;
    }
    out
}

trait ClampNan {
    fn clamp_to_range(self, lo: f64, hi: f64) -> f64;
}
impl ClampNan for f64 {
    fn clamp_to_range(self, lo: f64, hi: f64) -> f64 {
        if self.is_nan() {
            lo
        } else {
            self.clamp(lo, hi)
        }
    }
}

/// Indentation reference (um): from 0 into contact, then a two-tone indentation that also
/// leaves the object briefly (so the contact point is seen).
pub fn indentation_ref(t: f64, gap_um: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let cyc = gap_um + 1.5 - 1.5 * (tau * 2.0 * t).cos() + 0.35 * (tau * 13.0 * t).sin();
    let start = gap_um - 0.35;
    if t < 0.25 {
        // Smooth approach from 0 to the start of the cycle.
        let s = t / 0.25;
        start * s * s * (3.0 - 2.0 * s)
    } else {
        start + (cyc - start) * ((t - 0.25) / 0.1).min(1.0)
    }
}

/// Position loop for the characterisation: linear feedforward (core `LinearFf`) plus an
/// integral of the measured error, with back-calculation so the limits never wind it up.
#[derive(Debug, Clone, Copy)]
pub struct PositionPi {
    pub ff: piezo_core::feedforward::LinearFf<f64>,
    pub kp: f64,
    pub ki: f64,
    pub integ: f64,
    /// Feedforward + proportional part of the last command.
    pub last_fp: f64,
}

impl PositionPi {
    pub fn update(&mut self, y_ref: f64, y_meas: f64, dt: f64) -> f64 {
        let e = y_ref - y_meas;
        self.last_fp = self.ff.compensate(y_ref) + self.kp * e;
        self.integ += self.ki * e * dt;
        self.last_fp + self.integ
    }

    /// The voltage actually applied after the limits.
    pub fn applied(&mut self, u: f64) {
        let i = u - self.last_fp;
        if i.is_finite() {
            self.integ = i;
        }
    }
}

/// Position-controlled indentation with the force estimated by the ESO (no force sensor).
pub fn indentation(cfg: &ManipConfig, duration_s: f64) -> Result<Traces> {
    anyhow::ensure!(
        duration_s.is_finite() && duration_s > 0.5,
        "indentation: duration must exceed 0.5 s, got {duration_s}"
    );
    let dt = 1.0 / cfg.rate_hz;
    let n = (duration_s * cfg.rate_hz) as usize;
    let eso = cfg.eso()?;
    let plant = &cfg.plant;
    let mut ps = plant.init();
    let mut es = eso.init(0.0, 0.0);
    let mut rng = Rng::new(cfg.seed);
    let mut pi = PositionPi {
        ff: piezo_core::feedforward::LinearFf {
            um_per_volt: plant.cbw.d(),
            offset_um: 0.0,
        },
        kp: 0.0,
        ki: 2500.0,
        integ: 0.0,
        last_fp: 0.0,
    };
    let mut tr = Traces::default();
    let mut u = 0.0;
    let mut y_meas = 0.0;
    for k in 0..n {
        let t = k as f64 * dt;
        let y_ref = indentation_ref(t, plant.object.gap_um);
        let cmd = pi.update(y_ref, y_meas, dt);
        u = limit(cmd, u, cfg, &mut tr.saturated);
        pi.applied(u);
        plant.step(&mut ps, u, dt);
        y_meas = ps.y + rng.normal(cfg.noise.y_um);
        let u_meas = u + rng.normal(cfg.noise.u_volts);
        let f_hat = eso.update(&mut es, y_meas, u_meas);
        tr.t.push(t);
        tr.y_ref.push(y_ref);
        tr.y.push(ps.y);
        tr.y_meas.push(y_meas);
        tr.u.push(u);
        tr.u_meas.push(u_meas);
        tr.force.push(ps.force);
        tr.force_hat.push(f_hat);
    }
    Ok(tr)
}

/// Identified object (least squares, linear in `k1, k3, c`; the gap by a 1-D search).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ObjectFit {
    pub gap_um: f64,
    pub k1: f64,
    pub k3: f64,
    pub c: f64,
    /// RMS of the force residual (mN).
    pub residual_rms_mn: f64,
}

/// Zero-phase one-pole smoothing (forward then backward), cutoff `fc` Hz.
fn smooth(x: &[f64], fc: f64, dt: f64) -> Vec<f64> {
    let tau_s = 1.0 / (std::f64::consts::TAU * fc);
    let mut y = lowpass(x, tau_s, dt);
    y.reverse();
    let mut y = lowpass(&y, tau_s, dt);
    y.reverse();
    y
}

/// Fits `F^ = G[k1 delta + k3 delta^3 + c delta']` (G the ESO's force transfer) to the
/// estimated force and measured position of a run, from sample `skip` on.
pub fn identify(tr: &Traces, observer_hz: f64, rate_hz: f64, skip: usize) -> Result<ObjectFit> {
    let n = tr.y_meas.len();
    anyhow::ensure!(
        n > skip + 100,
        "identify: need more than {} samples",
        skip + 100
    );
    let dt = 1.0 / rate_hz;
    // G = w^3/(s+w)^3, the ESO's force transfer, applied to the regressors so the fit is
    // not biased by the lag.
    let g = |x: &[f64]| lowpass_n(x, 1.0 / (std::f64::consts::TAU * observer_hz), dt, 3);
    let y = smooth(&tr.y_meas, 500.0, dt);
    let mut v = vec![0.0; n];
    for i in 1..n - 1 {
        v[i] = (y[i + 1] - y[i - 1]) / (2.0 * dt);
    }
    let target = &tr.force_hat[skip..];
    let fit_at = |gap: f64| -> Option<(f64, [f64; 3])> {
        let d: Vec<f64> = y.iter().map(|y| (y - gap).max(0.0)).collect();
        let r1 = g(&d);
        let r3 = g(&d.iter().map(|d| d * d * d).collect::<Vec<_>>());
        let rc = g(&d
            .iter()
            .zip(&v)
            .map(|(d, v)| if *d > 0.0 { *v } else { 0.0 })
            .collect::<Vec<_>>());
        let cols = [&r1[skip..], &r3[skip..], &rc[skip..]];
        let mut ata = [[0.0; 3]; 3];
        let mut atb = [0.0; 3];
        for (i, f) in target.iter().enumerate() {
            let row = [cols[0][i], cols[1][i], cols[2][i]];
            for a in 0..3 {
                atb[a] += row[a] * f;
                for b in 0..3 {
                    ata[a][b] += row[a] * row[b];
                }
            }
        }
        let p = piezo_core::manipulation::linalg::solve(ata, atb)?;
        let res = rms(target
            .iter()
            .enumerate()
            .map(|(i, f)| f - (p[0] * cols[0][i] + p[1] * cols[1][i] + p[2] * cols[2][i])));
        Some((res, p))
    };
    // Coarse grid over the travelled range, then golden-section refinement.
    let lo = y[skip..].iter().copied().fold(f64::INFINITY, f64::min);
    let hi = y[skip..].iter().copied().fold(f64::NEG_INFINITY, f64::max);
    anyhow::ensure!(hi > lo, "identify: the position does not move");
    let grid = 60;
    let mut best = (f64::INFINITY, lo);
    for i in 0..=grid {
        let g = lo + (hi - lo) * i as f64 / grid as f64;
        if let Some((r, _)) = fit_at(g) {
            if r < best.0 {
                best = (r, g);
            }
        }
    }
    let step = (hi - lo) / grid as f64;
    let (gap, _) = crate::ident::optim::golden(
        &mut |g| fit_at(g).map_or(f64::INFINITY, |r| r.0),
        best.1 - step,
        best.1 + step,
        32,
    );
    let (res, p) = fit_at(gap).ok_or_else(|| anyhow::anyhow!("identify: singular regression"))?;
    Ok(ObjectFit {
        gap_um: gap,
        k1: p[0],
        k3: p[1],
        c: p[2],
        residual_rms_mn: res,
    })
}

/// Desired force profile (mN) for the BLF scenario, from `f0` at `t0`: a smooth ramp to
/// 60 mN, a hold, then a 3 Hz sine of 30 mN around 60 mN. Returns `(F_d, F_d')`.
pub fn force_ref(t: f64, t0: f64, f0: f64) -> (f64, f64) {
    let tau = std::f64::consts::TAU;
    let s = t - t0;
    if s < 0.0 {
        return (f0, 0.0);
    }
    let ramp = 0.2;
    if s < ramp {
        let r = s / ramp;
        let shape = r * r * (3.0 - 2.0 * r);
        let dshape = 6.0 * r * (1.0 - r) / ramp;
        return (f0 + (60.0 - f0) * shape, (60.0 - f0) * dshape);
    }
    if s < ramp + 0.2 {
        return (60.0, 0.0);
    }
    let p = s - ramp - 0.2;
    (
        60.0 + 30.0 * (tau * 3.0 * p).sin(),
        30.0 * tau * 3.0 * (tau * 3.0 * p).cos(),
    )
}

/// BLF force-control settings.
#[derive(Debug, Clone, Copy)]
pub struct BlfConfig {
    pub kb_mn: f64,
    pub lambda: f64,
    pub b_hat: f64,
    pub rate_limit: f64,
    /// Force (mN) that marks contact and starts force control.
    pub contact_mn: f64,
}

impl Default for BlfConfig {
    fn default() -> Self {
        Self {
            kb_mn: 3.0,
            lambda: 90.0,
            b_hat: 6.0,
            rate_limit: 1500.0,
            contact_mn: 2.0,
        }
    }
}

/// Approach (voltage ramp) until contact, then BLF force tracking. The law is fed the force
/// sensor (`estimated = false`, noisy) or the ESO estimate (`estimated = true`).
/// `force_ref` holds NaN before force control starts.
pub fn blf_force(
    cfg: &ManipConfig,
    bcfg: &BlfConfig,
    estimated: bool,
    duration_s: f64,
) -> Result<Traces> {
    let dt = 1.0 / cfg.rate_hz;
    let n = (duration_s * cfg.rate_hz) as usize;
    let eso = cfg.eso()?;
    let law = BlfForce::new(
        bcfg.kb_mn,
        bcfg.lambda,
        bcfg.b_hat,
        bcfg.rate_limit,
        0.0,
        cfg.u_max,
        cfg.rate_hz,
    )?;
    let plant = &cfg.plant;
    let mut ps = plant.init();
    let mut es = eso.init(0.0, 0.0);
    let mut rng = Rng::new(cfg.seed.wrapping_add(17));
    let mut tr = Traces::default();
    let mut u = 0.0;
    let mut f_fb = 0.0;
    let mut start: Option<(f64, f64)> = None;
    let mut bs = law.init(0.0);
    for k in 0..n {
        let t = k as f64 * dt;
        let cmd = match start {
            None => {
                if f_fb > bcfg.contact_mn && t > 0.01 {
                    start = Some((t, f_fb));
                    bs = law.init(u);
                    u
                } else {
                    u + 100.0 * dt // approach at 100 V/s
                }
            }
            Some(_) => u,
        };
        let (fd, dfd) = match start {
            Some((t0, f0)) => force_ref(t, t0, f0),
            None => (f64::NAN, 0.0),
        };
        let cmd = if start.is_some() {
            law.update(&mut bs, f_fb, fd, dfd)
        } else {
            cmd
        };
        u = limit(cmd, u, cfg, &mut tr.saturated);
        plant.step(&mut ps, u, dt);
        let y_meas = ps.y + rng.normal(cfg.noise.y_um);
        let u_meas = u + rng.normal(cfg.noise.u_volts);
        let f_meas = ps.force + rng.normal(cfg.noise.f_mn);
        let f_hat = eso.update(&mut es, y_meas, u_meas);
        f_fb = if estimated { f_hat } else { f_meas };
        tr.t.push(t);
        tr.y_ref.push(f64::NAN);
        tr.y.push(ps.y);
        tr.y_meas.push(y_meas);
        tr.u.push(u);
        tr.u_meas.push(u_meas);
        tr.force.push(ps.force);
        tr.force_hat.push(if estimated { f_hat } else { f_meas });
        tr.force_ref.push(fd);
    }
    Ok(tr)
}

/// Force-control errors over the force-control phase: (max |F - F_d| true, max |F_fb - F_d|
/// fed back, rms true).
pub fn blf_errors(tr: &Traces) -> (f64, f64, f64) {
    let idx: Vec<usize> = (0..tr.t.len())
        .filter(|&i| tr.force_ref[i].is_finite())
        .collect();
    let max_true = idx
        .iter()
        .map(|&i| (tr.force[i] - tr.force_ref[i]).abs())
        .fold(0.0, f64::max);
    let max_fb = idx
        .iter()
        .map(|&i| (tr.force_hat[i] - tr.force_ref[i]).abs())
        .fold(0.0, f64::max);
    let rms_true = rms(idx.iter().map(|&i| tr.force[i] - tr.force_ref[i]));
    (max_true, max_fb, rms_true)
}

/// Force estimation errors after `skip` samples: (rms, max, peak force).
pub fn force_errors(tr: &Traces, skip: usize) -> (f64, f64, f64) {
    let e = || tr.force.iter().zip(&tr.force_hat).skip(skip);
    let rms_e = rms(e().map(|(f, h)| h - f));
    let max_e = e().map(|(f, h)| (h - f).abs()).fold(0.0, f64::max);
    let peak = tr.force.iter().copied().fold(0.0, f64::max);
    (rms_e, max_e, peak)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_pushes_only_in_contact() {
        let o = Object::default_soft();
        assert_eq!(o.force(3.0, 100.0), 0.0);
        assert!((o.force(5.0, 0.0) - 44.0).abs() < 1e-12);
        assert_eq!(o.force(4.1, -1e6), 0.0);
    }

    #[test]
    fn free_stage_settles_at_d_u_minus_h() {
        let p = default_plant();
        let mut s = p.init();
        for _ in 0..2000 {
            p.step(&mut s, 10.0, 1e-4);
        }
        // Below the gap (4 um): free; y = d u - h.
        let want = 0.16 * 10.0 - s.hs.h;
        assert!((s.y - want).abs() < 1e-6, "{} vs {want}", s.y);
        assert_eq!(s.force, 0.0);
    }
}
