//! The simulated actuator, a Hammerstein chain per axis:
//!
//! DAC volts -> high-voltage amplifier (gain, rails, slew limit `I/C`, first-order
//! bandwidth) -> hysteresis (a model of `piezo_core::hysteresis` plus an asymmetric static
//! term) -> creep (first-order elements) -> axis coupling -> structural dynamics (one lightly
//! damped resonance, external force through the stiffness) -> thermal drift -> pure delay
//! -> sensor noise.
//!
//! Integration runs at `substeps` times the loop rate (default: one step per loop period).
//! The slew-limited amplifier is solved exactly; the hysteresis model is stepped once per
//! loop period to the amplifier's end voltage (it is rate-independent) and interpolated in
//! voltage inside it; creep and structure are discretised exactly for an input that moves
//! linearly over one internal step (first-order hold, ramp-invariant), so the error comes
//! only from the curvature of their inputs inside a step. A delay that is not a whole
//! number of internal steps is interpolated linearly.
//!
//! What real stages show besides this chain (rate-dependent hysteresis, start-up creep after
//! a long rest, backlash, amplitude-dependent resonance, a nonlinear sensor) is in
//! [`effects`], each switched and parameterised by its scenario section
//! (`[stage.rate_hysteresis]`, ...; [`crate::scenario::RateHysteresis`] and its siblings
//! give the equations). All are off by default and cost nothing then.

pub mod identified;

use crate::scenario::{HysteresisModel, Scenario, StageConfig};
use anyhow::{Context, Result};
use piezo_core::hysteresis::{AbwAbs, BwState, Cbw, Dahl, Gbw, Hysteresis, Mbw002, MbwState};
use std::f64::consts::PI;

mod effects;
use crate::numeric::Rng;
use effects::{resonance_ad, AxisFx, Effects};

/// The static (rate-independent) part of one axis.
#[derive(Debug, Clone)]
enum Static {
    Linear {
        d: f64,
        u: f64,
    },
    /// CBW with `n = 1` (the default): its exact step, inlined.
    Cbw1(Cbw<f64>, BwState<f64>),
    Cbw(Cbw<f64>, BwState<f64>),
    Gbw(Gbw<f64>, BwState<f64>),
    Dahl(Dahl<f64>, BwState<f64>),
    /// Rate dependent: `dt` is the loop period (the model's `u'` over one model step).
    Mbw(Mbw002<f64>, MbwState<f64>),
}

impl Static {
    #[inline]
    fn step(&mut self, u: f64, dt: f64) -> f64 {
        match self {
            Static::Linear { d, u: last } => {
                *last = u;
                *d * u
            }
            Static::Cbw1(m, s) => m.step_n1(s, u),
            Static::Cbw(m, s) => m.step(s, u, dt),
            Static::Gbw(m, s) => m.step(s, u, dt),
            Static::Dahl(m, s) => m.step(s, u, dt),
            Static::Mbw(m, s) => m.step(s, u, dt),
        }
    }
}

/// Amplifier state and constants for one internal step.
#[derive(Debug, Clone)]
struct Amp {
    gain: f64,
    offset: f64,
    rail_min: f64,
    rail_max: f64,
    tau: f64,
    /// `exp(-h/tau)`
    decay: f64,
    slew: f64,
    h: f64,
    v: f64,
}

impl Amp {
    /// Exact solution of `v' = clamp((target - v)/tau, -slew, slew)` over one step.
    #[inline]
    fn step(&mut self, dac_volts: f64) -> f64 {
        let target = (self.gain * dac_volts + self.offset).clamp(self.rail_min, self.rail_max);
        let e = target - self.v;
        let knee = self.slew * self.tau; // |e| above which the slew limit is active
        let mut rest = self.h;
        let mut v = self.v;
        if e.abs() > knee {
            let t1 = (e.abs() - knee) / self.slew;
            if t1 >= rest {
                self.v = v + e.signum() * self.slew * rest;
                return self.v;
            }
            v += e.signum() * self.slew * t1;
            rest -= t1;
        }
        let decay = if rest == self.h {
            self.decay
        } else {
            (-rest / self.tau).exp()
        };
        self.v = target + (v - target) * decay;
        self.v
    }
}

/// One creep element's exact update over an internal step `h` for a linear input
/// (ramp-invariant discretisation of `c' = (g*y - c)/tau`): `[e, b0, b1]` of
/// `c' = e*c + b0*y0 + b1*y1`.
fn creep_fh(gain: f64, tau: f64, h: f64) -> [f64; 3] {
    // c(h) = e*c0 + g*[(1 - r)*y1 + (r - e)*y0], e = exp(-h/tau), r = tau/h*(1 - e)
    let one_minus_e = -(-h / tau).exp_m1();
    let e = 1.0 - one_minus_e;
    let r = tau / h * one_minus_e;
    [e, gain * (r - e), gain * (1.0 - r)]
}

/// Creep elements per block: the update runs on fixed-size blocks (vectorised); unused
/// places are zero elements (`e = b0 = b1 = 0`, so their state stays 0 and adds 0).
const CREEP_LANES: usize = 4;

/// The creep elements of one axis, in blocks of [`CREEP_LANES`].
#[derive(Debug, Clone)]
struct Creep {
    /// Per block: `e`, `b0`, `b1` of each element.
    fh: Vec<[[f64; CREEP_LANES]; 3]>,
    /// Per block: the element states.
    c: Vec<[f64; CREEP_LANES]>,
}

impl Creep {
    fn new(gains: &[f64], taus: &[f64], h: f64) -> Self {
        let n = gains.len().min(taus.len());
        let blocks = n.div_ceil(CREEP_LANES);
        let mut fh = vec![[[0.0; CREEP_LANES]; 3]; blocks];
        for (i, (&g, &t)) in gains.iter().zip(taus).enumerate() {
            let k = creep_fh(g, t, h);
            for (row, kk) in fh[i / CREEP_LANES].iter_mut().zip(k) {
                row[i % CREEP_LANES] = kk;
            }
        }
        Self {
            fh,
            c: vec![[0.0; CREEP_LANES]; blocks],
        }
    }

    /// One step for an input moving linearly from `y0` to `y`; returns `y + sum c`
    /// (summed in element order).
    #[inline(always)]
    fn step(&mut self, y0: f64, y: f64) -> f64 {
        let mut yc = y;
        for (c, [e, b0, b1]) in self.c.iter_mut().zip(&self.fh) {
            for j in 0..CREEP_LANES {
                c[j] = e[j] * c[j] + b0[j] * y0 + b1[j] * y;
            }
            for cj in c.iter() {
                yc += *cj;
            }
        }
        yc
    }

    /// The step split at its input `y`: updates the states and returns `p` with
    /// `y + sum c = (1 + sum b1) * y + p`, where `p = sum (e*c + b0*y0)` depends on the old
    /// states only (so `y` enters through one multiply-add).
    #[inline(always)]
    fn step_split(&mut self, y0: f64, y: f64) -> f64 {
        let mut p = 0.0;
        for (c, [e, b0, b1]) in self.c.iter_mut().zip(&self.fh) {
            for j in 0..CREEP_LANES {
                let old = e[j] * c[j] + b0[j] * y0;
                c[j] = old + b1[j] * y;
                p += old;
            }
        }
        p
    }

    /// `1 + sum b1`: the gain from the new input to [`Self::step`]'s output.
    fn gain(&self) -> f64 {
        1.0 + self.fh.iter().flat_map(|[_, _, b1]| b1).sum::<f64>()
    }

    /// At rest for the constant input `y`; returns `y + sum c`.
    fn settle(&mut self, gains: &[f64], y: f64) -> f64 {
        for (i, g) in gains.iter().enumerate() {
            if let Some(c) = self.c.get_mut(i / CREEP_LANES) {
                c[i % CREEP_LANES] = g * y;
            }
        }
        y + gains.iter().map(|g| g * y).sum::<f64>()
    }
}

/// The structure's exact step as an affine function of its new input `w` (ramp from the
/// last input `u`): `x' = kx*w + mx_u*u + a00*(x - u) + a01*v` and likewise for `v'`, so
/// the new input enters through one multiply-add (the loop's latency chain).
#[derive(Debug, Clone, Copy)]
struct StructureAffine {
    kx: f64,
    kv: f64,
    /// The `u` coefficients besides the `(x - u)` terms.
    mx: f64,
    mv: f64,
    a: [[f64; 2]; 2],
}

impl StructureAffine {
    fn new(ad: &Option<([[f64; 2]; 2], f64)>, inv_h: f64) -> Self {
        match ad {
            // s = (w - u)/h, x' = w - L*s + a00*(x - u + L*s) + a01*(v - s),
            // v' = s + a10*(x - u + L*s) + a11*(v - s)
            Some((a, lag)) => {
                let mx = inv_h * (a[0][0] * lag - lag - a[0][1]);
                let mv = inv_h * (1.0 + a[1][0] * lag - a[1][1]);
                Self {
                    kx: 1.0 + mx,
                    kv: mv,
                    mx: -mx,
                    mv: -mv,
                    a: *a,
                }
            }
            // Structure off: x' = w, v' = 0.
            None => Self {
                kx: 1.0,
                kv: 0.0,
                mx: 0.0,
                mv: 0.0,
                a: [[0.0; 2]; 2],
            },
        }
    }
}

/// Everything of one axis.
#[derive(Debug, Clone)]
struct Axis {
    amp: Amp,
    stat: Static,
    asym: f64,
    creep_gain: Vec<f64>,
    /// Exact first-order-hold update of each creep element over one internal step:
    /// `c' = e*c + b0*y0 + b1*y1` for an input moving linearly from `y0` to `y1`.
    creep: Creep,
    /// [`Creep::gain`].
    creep_k: f64,
    /// Input of the creep elements at the end of the last step.
    y_in: f64,
    /// Output of the static part + creep (before coupling).
    y_hc: f64,
    /// Hysteresis model output at the amplifier voltage `v_stat`.
    y_stat: f64,
    v_stat: f64,
    /// Hysteresis output at the end of the current loop period, and its voltage.
    y_end: f64,
    v_end: f64,
    /// Amplifier voltage at each internal step of the current loop period.
    v_traj: [f64; MAX_SUBSTEPS],
    /// Input of the structure at the end of the last step.
    u_struct: f64,
    /// Structural state: position, velocity.
    x: f64,
    v: f64,
    /// State of the effects beyond the Hammerstein chain ([`effects`]).
    fx: AxisFx,
}

impl Axis {
    /// Static output `ys` at amplifier voltage `v` -> (rate dependence) -> quadratic term ->
    /// (start-up creep) -> creep -> (backlash); sets `y_hc`.
    #[inline(always)]
    fn hammerstein(&mut self, v: f64, ys: f64, fx: Option<&Effects>) {
        let y = match fx {
            None => ys + self.asym * v * v,
            Some(fx) => {
                let ys = fx.rate(&mut self.fx, v, ys);
                fx.startup(&mut self.fx, v, ys + self.asym * v * v)
            }
        };
        let y0 = self.y_in;
        self.y_in = y;
        self.y_hc = self.creep.step(y0, y);
        if let Some(fx) = fx {
            self.y_hc = fx.backlash(&mut self.fx, self.y_hc);
        }
    }

    /// One internal step of the structure to the new input. Exact for an input moving
    /// linearly over the step: the ramp response follows the input with velocity `s` and lag
    /// `2 zeta / w * s`; the rest decays freely.
    #[inline(always)]
    fn structure(&mut self, input: f64, ad: &Option<([[f64; 2]; 2], f64)>, inv_h: f64) {
        match ad {
            Some((ad, lag)) => {
                let s = (input - self.u_struct) * inv_h;
                let lag = lag * s;
                let (dx, dv) = (self.x - (self.u_struct - lag), self.v - s);
                self.x = input - lag + ad[0][0] * dx + ad[0][1] * dv;
                self.v = s + ad[1][0] * dx + ad[1][1] * dv;
            }
            None => {
                self.x = input;
                self.v = 0.0;
            }
        }
        self.u_struct = input;
    }
}

/// The simulated stage.
#[derive(Debug, Clone)]
pub struct Stage {
    axes: Vec<Axis>,
    /// Internal step (s) and its inverse.
    h: f64,
    inv_h: f64,
    substeps: usize,
    /// Exact transition matrix of the structure over `h`, and `2 zeta / w` (the lag of
    /// its ramp response); `None`: structure off.
    ad: Option<([[f64; 2]; 2], f64)>,
    /// [`Self::ad`] as an affine map of the structure's new input (the one-step path).
    affine: StructureAffine,
    coupling: Option<Vec<Vec<f64>>>,
    force: Option<(f64, f64, f64, f64)>, // (um at full force, at_s, freq_hz, stiffness)
    drift: Option<(f64, f64, f64)>,      // (um, tau_s, rate)
    /// Exponential part of the drift now, and its decay per internal step.
    drift_exp_um: f64,
    /// [`Self::drift_um`] now.
    drift_now_um: f64,
    drift_decay: f64,
    noise_sigma_um: f64,
    /// Delay line of positions at the internal rate, per axis (length a power of two).
    delay: Vec<Vec<f64>>,
    delay_pos: usize,
    /// The delay in internal steps: whole part and fraction (linear interpolation).
    delay_steps: usize,
    delay_frac: f64,
    rng: Rng,
    t: f64,
    steps: u64,
    exact_hysteresis: bool,
    zero_um: f64,
    /// The effects beyond the Hammerstein chain that are on; `None` (all off) keeps the
    /// one-step fast path.
    fx: Option<Box<Effects>>,
    /// [`Self::advance_one`] applies: one internal step, no coupling, no exact hysteresis,
    /// no effects (one test per sample).
    one_step: bool,
    /// An identified model in place of hysteresis, creep and structure
    /// (`piezo sim --stage fit.json`).
    identified: Option<Box<identified::IdentifiedPlant>>,
}

/// Most internal steps per loop period.
pub const MAX_SUBSTEPS: usize = 64;

impl Stage {
    /// The stage of `scenario` integrated with `substeps` steps per loop period.
    pub fn new(scenario: &Scenario) -> Result<Self> {
        Self::with_substeps(scenario, scenario.run.substeps)
    }

    pub fn with_substeps(scenario: &Scenario, substeps: usize) -> Result<Self> {
        let cfg: &StageConfig = &scenario.stage;
        anyhow::ensure!(
            (1..=MAX_SUBSTEPS).contains(&substeps),
            "substeps must be in 1..={MAX_SUBSTEPS}"
        );
        let h = 1.0 / (scenario.run.loop_hz * substeps as f64);
        let a = &cfg.amplifier;
        let tau = 1.0 / (2.0 * PI * a.bandwidth_hz);
        let hy = &cfg.hysteresis;
        let mut axes = Vec::new();
        for _ in 0..cfg.axes {
            let stat = match hy.model {
                HysteresisModel::None => Static::Linear { d: hy.d, u: 0.0 },
                HysteresisModel::Cbw => {
                    let m = Cbw::new(hy.d, hy.alpha, hy.beta, hy.gamma, hy.n)
                        .context("stage.hysteresis (cbw)")?;
                    if m.n() == 1.0 {
                        Static::Cbw1(m, m.init(0.0))
                    } else {
                        Static::Cbw(m, m.init(0.0))
                    }
                }
                HysteresisModel::Gbw => {
                    let m =
                        Gbw::with_beta_h(hy.d, hy.alpha, hy.a, hy.beta_h, hy.beta, hy.gamma, hy.n)
                            .context("stage.hysteresis (gbw)")?;
                    Static::Gbw(m, m.init(0.0))
                }
                HysteresisModel::Dahl => {
                    let m = Dahl::new(hy.d, hy.alpha, hy.hc, hy.n)
                        .context("stage.hysteresis (dahl)")?;
                    Static::Dahl(m, m.init(0.0))
                }
                HysteresisModel::Mbw002 => {
                    let abw = AbwAbs::new(hy.d, hy.alpha, hy.beta, hy.gamma, hy.n, hy.delta);
                    let m = Mbw002::new(abw.context("stage.hysteresis (mbw002)")?, hy.p, hy.q)
                        .context("stage.hysteresis (mbw002)")?;
                    Static::Mbw(m, m.init(0.0))
                }
            };
            let (gains, taus) = if cfg.creep.enabled {
                (cfg.creep.gains.clone(), cfg.creep.taus_s.clone())
            } else {
                (vec![], vec![])
            };
            let v0 = (a.offset_volts).clamp(a.rail_min_volts, a.rail_max_volts);
            axes.push(Axis {
                amp: Amp {
                    gain: a.gain,
                    offset: a.offset_volts,
                    rail_min: a.rail_min_volts,
                    rail_max: a.rail_max_volts,
                    tau,
                    decay: (-h / tau).exp(),
                    slew: a.current_limit_a / a.capacitance_f,
                    h,
                    v: v0,
                },
                stat,
                asym: hy.asym_um_per_v2,
                creep_k: Creep::new(&gains, &taus, h).gain(),
                creep: Creep::new(&gains, &taus, h),
                y_in: 0.0,
                creep_gain: gains,
                y_hc: 0.0,
                y_stat: 0.0,
                v_stat: 0.0,
                y_end: 0.0,
                v_end: 0.0,
                v_traj: [0.0; MAX_SUBSTEPS],
                u_struct: 0.0,
                x: 0.0,
                v: 0.0,
                fx: AxisFx::default(),
            });
        }
        let ad = cfg
            .resonance
            .enabled
            .then(|| resonance_ad(cfg.resonance.freq_hz, cfg.resonance.zeta, h));
        let f = &cfg.force;
        let delay = if cfg.delay.enabled {
            cfg.delay.seconds / h
        } else {
            0.0
        };
        // Whole steps; a fraction within rounding of a whole step counts as whole.
        let near = delay.round();
        let (delay_steps, delay_frac) = if (delay - near).abs() < 1e-9 * near.max(1.0) {
            (near as usize, 0.0)
        } else {
            (delay.floor() as usize, delay - delay.floor())
        };
        let mut st = Self {
            delay: vec![vec![0.0; (delay_steps + 2).next_power_of_two()]; cfg.axes],
            delay_pos: 0,
            delay_steps,
            delay_frac,
            axes,
            h,
            inv_h: 1.0 / h,
            substeps,
            affine: StructureAffine::new(&ad, 1.0 / h),
            ad,
            coupling: cfg.coupling.enabled.then(|| cfg.coupling.matrix.clone()),
            force: f.enabled.then_some((
                f.newtons / f.stiffness_n_per_um,
                f.at_s,
                f.freq_hz,
                f.stiffness_n_per_um,
            )),
            drift_exp_um: 0.0,
            drift_now_um: 0.0,
            drift_decay: (-h / cfg.drift.tau_s).exp(),
            drift: cfg.drift.enabled.then_some((
                cfg.drift.um,
                cfg.drift.tau_s,
                cfg.drift.rate_um_per_s,
            )),
            noise_sigma_um: if cfg.noise.enabled {
                cfg.noise.sigma_um
            } else {
                0.0
            },
            rng: Rng::new(scenario.run.seed ^ 0x5EED),
            t: 0.0,
            steps: 0,
            exact_hysteresis: false,
            zero_um: cfg.zero_um,
            fx: Effects::new(cfg, h).map(Box::new),
            one_step: false,
            identified: cfg
                .identified
                .as_ref()
                .map(|c| identified::IdentifiedPlant::load(c, cfg.axes).map(Box::new))
                .transpose()?,
        };
        st.set_exact_hysteresis(false);
        st.drift_now_um = st.drift_calc_um();
        // Rest at the amplifier's output for 0 V in.
        let zero = vec![0.0; st.axes.len()];
        st.settle(&zero);
        Ok(st)
    }

    /// Puts every state at rest for the constant DAC voltages `dac_volts`.
    fn settle(&mut self, dac_volts: &[f64]) {
        for (ax, &u) in self.axes.iter_mut().zip(dac_volts) {
            ax.amp.v = (ax.amp.gain * u + ax.amp.offset).clamp(ax.amp.rail_min, ax.amp.rail_max);
            ax.y_stat = ax.stat.step(ax.amp.v, self.h);
            ax.v_stat = ax.amp.v;
            let y = ax.y_stat + ax.asym * ax.amp.v * ax.amp.v;
            ax.y_in = y;
            ax.y_hc = ax.creep.settle(&ax.creep_gain, y);
            if let Some(fx) = &self.fx {
                fx.settle(&mut ax.fx, ax.amp.v, y);
                fx.settle_play(&mut ax.fx, ax.y_hc);
            }
            ax.x = ax.y_hc;
            ax.u_struct = ax.y_hc;
            ax.v = 0.0;
        }
        if let Some(p) = &mut self.identified {
            let volts: Vec<f64> = self.axes.iter().map(|a| a.amp.v).collect();
            p.settle(&volts);
            for (i, ax) in self.axes.iter_mut().enumerate() {
                ax.x = p.position_um(i);
            }
        }
        let off = self.drift_um();
        let fx = self.fx.as_deref();
        for (line, ax) in self.delay.iter_mut().zip(&self.axes) {
            let read = fx.map_or(ax.x + off, |f| f.sensor(ax.x + off));
            line.iter_mut().for_each(|p| *p = read);
        }
    }

    pub fn axes(&self) -> usize {
        self.axes.len()
    }

    /// Simulated time (s).
    pub fn time_s(&self) -> f64 {
        self.t
    }

    /// Internal integration step (s).
    pub fn step_s(&self) -> f64 {
        self.h
    }

    /// Amplifier output (V) of `axis`.
    pub fn piezo_volts(&self, axis: usize) -> f64 {
        self.axes.get(axis).map_or(f64::NAN, |a| a.amp.v)
    }

    /// True position (um) of `axis` now (no delay, no noise, with drift).
    pub fn position_um(&self, axis: usize) -> f64 {
        self.axes.get(axis).map_or(f64::NAN, |a| a.x) + self.drift_um()
    }

    /// Sensor zero plus thermal drift (um) now (kept by [`Self::advance_time`]).
    #[inline(always)]
    fn drift_um(&self) -> f64 {
        self.drift_now_um
    }

    fn drift_calc_um(&self) -> f64 {
        self.zero_um
            + match self.drift {
                Some((_, _, rate)) => self.drift_exp_um + rate * self.t,
                None => 0.0,
            }
    }

    /// What the position sensor reads now (um): delayed position, drift, noise.
    #[inline]
    pub fn sensor_um(&mut self, axis: usize) -> f64 {
        let Some(line) = self.delay.get(axis) else {
            return f64::NAN;
        };
        let mask = line.len() - 1; // a power of two
        let at = |back: usize| {
            line.get(self.delay_pos.wrapping_sub(back) & mask)
                .copied()
                .unwrap_or(f64::NAN)
        };
        let mut old = at(self.delay_steps);
        if self.delay_frac != 0.0 {
            old += (at(self.delay_steps + 1) - old) * self.delay_frac;
        }
        let noise = if self.noise_sigma_um > 0.0 {
            self.noise_sigma_um * self.rng.gauss()
        } else {
            0.0
        };
        old + noise
    }

    /// Advances one loop period with the DAC output voltages held.
    #[inline]
    pub fn advance(&mut self, dac_volts: &[f64]) {
        if self.identified.is_some() {
            self.advance_identified(dac_volts);
        } else if self.one_step {
            self.advance_one(dac_volts);
        } else {
            self.advance_slow(dac_volts);
        }
    }

    /// [`Self::advance`] with several internal steps, coupling or the exact hysteresis (a
    /// function of its own: its setup would otherwise run on the fast path too).
    #[inline(never)]
    fn advance_slow(&mut self, dac_volts: &[f64]) {
        if self.exact_hysteresis {
            for _ in 0..self.substeps {
                self.step_internal(dac_volts, None);
            }
            return;
        }
        // With the DAC held the amplifier output moves monotonically over the period, and
        // the hysteresis models are rate-independent: one exact model step to the end
        // voltage, and linear interpolation in voltage inside the period (error ~
        // curvature * dv^2 / 8, about 1e-6 um at full speed).
        self.advance_general(dac_volts);
    }

    /// [`Self::advance`] with one internal step per period and no coupling: every block of
    /// an axis in one pass, the same discretisation as [`Self::advance_general`] with the
    /// linear blocks (creep, structure) written as affine maps of their new input, so that
    /// the chain from the hysteresis output to the position is four multiply-adds instead
    /// of the blocks in series (the loop's latency; the results agree to rounding).
    #[inline]
    fn advance_one(&mut self, dac_volts: &[f64]) {
        let f_um = self.force_um();
        let h = self.h;
        self.advance_time();
        let drift = self.drift_um();
        let st = self.affine;
        for ((ax, &u), line) in self.axes.iter_mut().zip(dac_volts).zip(&mut self.delay) {
            let v = ax.amp.step(u);
            // The default model first, where the compiler can inline it.
            let ys = match &mut ax.stat {
                Static::Cbw1(m, s) => m.step_n1(s, v),
                other => other.step(v, h),
            };
            (ax.v_end, ax.y_end, ax.v_stat, ax.y_stat) = (v, ys, v, ys);
            // The old states' parts first, off the chain.
            let (u0, x0, v0) = (ax.u_struct, ax.x, ax.v);
            let qx = st.mx * u0 + st.a[0][0] * (x0 - u0) + st.a[0][1] * v0;
            let qv = st.mv * u0 + st.a[1][0] * (x0 - u0) + st.a[1][1] * v0;
            let y = ys + ax.asym * v * v;
            let p = ax.creep.step_split(ax.y_in, y);
            ax.y_in = y;
            ax.y_hc = ax.creep_k * y + p;
            let w = ax.creep_k * y + (p + f_um);
            ax.x = st.kx * w + qx;
            ax.v = st.kv * w + qv;
            ax.u_struct = w;
            let mask = line.len() - 1; // a power of two
            if let Some(p) = line.get_mut(self.delay_pos & mask) {
                *p = ax.x + drift;
            }
        }
    }

    /// Time, drift and the delay line's write position, one internal step on.
    #[inline(always)]
    fn advance_time(&mut self) {
        self.steps += 1;
        // Through i64: one instruction on x86-64 (u64 -> f64 takes several); exact below 2^53.
        self.t = self.steps as i64 as f64 * self.h;
        if let Some((um, _, _)) = self.drift {
            // um * (1 - exp(-t/tau)), advanced without an exp per step.
            self.drift_exp_um = um - (um - self.drift_exp_um) * self.drift_decay;
        }
        self.drift_now_um = self.drift_calc_um();
        self.delay_pos = self.delay_pos.wrapping_add(1);
    }

    fn advance_general(&mut self, dac_volts: &[f64]) {
        let h_loop = self.h * self.substeps as f64;
        for (ax, &u) in self.axes.iter_mut().zip(dac_volts) {
            for v in ax.v_traj.iter_mut().take(self.substeps) {
                *v = ax.amp.step(u);
            }
            ax.v_end = ax.amp.v;
            ax.y_end = ax.stat.step(ax.v_end, h_loop);
        }
        for j in 0..self.substeps {
            self.step_internal(dac_volts, Some(j));
        }
        for ax in self.axes.iter_mut() {
            ax.v_stat = ax.v_end;
            ax.y_stat = ax.y_end;
        }
    }

    /// Steps the hysteresis model at every internal step instead of once per loop period
    /// (reference runs; slower).
    pub fn set_exact_hysteresis(&mut self, exact: bool) {
        self.exact_hysteresis = exact;
        self.one_step = self.substeps == 1
            && self.coupling.is_none()
            && !self.exact_hysteresis
            && self.fx.is_none();
    }

    fn force_um(&self) -> f64 {
        match self.force {
            Some((um, at, f, _)) if self.t >= at => {
                if f > 0.0 {
                    um * (2.0 * PI * f * (self.t - at)).sin()
                } else {
                    um
                }
            }
            _ => 0.0,
        }
    }

    #[inline]
    /// One internal step; `Some(j)`: the amplifier was already advanced (step `j` of the
    /// period) and the hysteresis is interpolated.
    fn step_internal(&mut self, dac_volts: &[f64], j: Option<usize>) {
        let h = self.h;
        let fx = self.fx.as_deref();
        for (ax, &u) in self.axes.iter_mut().zip(dac_volts) {
            let (v, ys) = match j {
                None => {
                    let v = ax.amp.step(u);
                    ax.y_stat = ax.stat.step(v, h);
                    ax.v_stat = v;
                    (v, ax.y_stat)
                }
                Some(j) if j + 1 < self.substeps => {
                    let v = ax.v_traj.get(j).copied().unwrap_or(ax.v_end);
                    let dv = ax.v_end - ax.v_stat;
                    let ys = if dv != 0.0 {
                        ax.y_stat + (ax.y_end - ax.y_stat) * ((v - ax.v_stat) / dv)
                    } else {
                        ax.y_end
                    };
                    (v, ys)
                }
                // The last step of the period ends at the model's own end point.
                Some(_) => (ax.v_end, ax.y_end),
            };
            ax.hammerstein(v, ys, fx);
        }
        let f_um = self.force_um();
        let n = self.axes.len();
        for i in 0..n {
            let mut input = self.axes[i].y_hc + f_um;
            if let Some(row) = self.coupling.as_ref().and_then(|m| m.get(i)) {
                for (j, (c, ax)) in row.iter().zip(&self.axes).enumerate() {
                    if j != i {
                        input += c * ax.y_hc;
                    }
                }
            }
            let amp = fx.and_then(|f| f.amp.as_ref());
            if let Some(ax) = self.axes.get_mut(i) {
                match amp {
                    Some(amp) => {
                        let slope = (input - ax.u_struct) * self.inv_h;
                        let ad = amp.select(&mut ax.fx, ax.x, ax.v, ax.u_struct, slope);
                        ax.structure(input, &Some(ad), self.inv_h);
                    }
                    None => ax.structure(input, &self.ad, self.inv_h),
                }
            }
        }
        self.advance_time();
        let drift = self.drift_um();
        let fx = self.fx.as_deref();
        for (line, ax) in self.delay.iter_mut().zip(&self.axes) {
            let mask = line.len() - 1; // a power of two
            if let Some(p) = line.get_mut(self.delay_pos & mask) {
                *p = fx.map_or(ax.x + drift, |f| f.sensor(ax.x + drift));
            }
        }
    }
}

#[cfg(test)]
mod tests;
