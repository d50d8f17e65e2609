//! The stage effects beyond the Hammerstein chain: rate-dependent hysteresis, start-up
//! creep, backlash, amplitude-dependent resonance and a nonlinear sensor. Their equations and
//! parameters are documented on their scenario sections ([`crate::scenario::RateHysteresis`],
//! [`crate::scenario::StartupCreep`], [`crate::scenario::Backlash`],
//! [`crate::scenario::AmplitudeDynamics`], [`crate::scenario::SensorNonlinearity`]).
//!
//! Where they act in the chain: amplifier -> hysteresis -> **rate dependence** -> asymmetric
//! term -> **start-up creep** -> creep -> **backlash** -> coupling -> structure (**amplitude
//! dependent**) -> drift -> delay -> **sensor** -> noise. A stage with any of them on runs the
//! general path (`Stage::advance_general`); the one-step fast path never sees them, so their
//! cost is zero when they are off.

use crate::scenario::StageConfig;

/// Table entries of the amplitude-dependent resonance over `rho` in `[0, 1]`.
const AMP_TABLE: usize = 64;

/// Exact transition matrix of the structure `x'' + 2 zeta w x' + w^2 x = w^2 u` over a step
/// `h`, and the lag `2 zeta / w` of its ramp response.
pub(super) fn resonance_ad(freq_hz: f64, zeta: f64, h: f64) -> ([[f64; 2]; 2], f64) {
    let w = 2.0 * std::f64::consts::PI * freq_hz;
    let s = zeta * w;
    let wd = w * (1.0 - zeta * zeta).sqrt();
    let e = (-s * h).exp();
    let (sn, cs) = (wd * h).sin_cos();
    (
        [
            [e * (cs + s / wd * sn), e * sn / wd],
            [-e * w * w / wd * sn, e * (cs - s / wd * sn)],
        ],
        2.0 * zeta / w,
    )
}

#[derive(Debug, Clone)]
struct Rate {
    widen: f64,
    gain_drop: f64,
    rate_ref: f64,
    /// `1 - exp(-h/tau)`: the low-pass per internal step.
    a: f64,
    inv_h: f64,
    d: f64,
}

#[derive(Debug, Clone)]
struct Startup {
    depth: f64,
    travel_v: f64,
    /// `1 - exp(-h/rest_tau)`.
    b: f64,
}

/// The amplitude-dependent resonance: transition matrices and lags tabulated over `rho`.
#[derive(Debug, Clone)]
pub(super) struct AmpDynamics {
    table: Vec<([[f64; 2]; 2], f64)>,
    inv_w0: f64,
    lag0: f64,
    level_um: f64,
}

#[derive(Debug, Clone)]
struct Sensor {
    center: f64,
    half: f64,
    q: f64,
    c: f64,
}

/// The effects switched on in a stage (shared by its axes).
#[derive(Debug, Clone)]
pub(super) struct Effects {
    rate: Option<Rate>,
    startup: Option<Startup>,
    /// Half the play width (um).
    backlash_half_um: Option<f64>,
    pub(super) amp: Option<AmpDynamics>,
    sensor: Option<Sensor>,
}

/// Per-axis state of the effects.
#[derive(Debug, Clone, Default)]
pub(super) struct AxisFx {
    /// Low-passed input rate (V/s) and input (V).
    rate_vps: f64,
    vbar: f64,
    /// Input at the last internal step.
    v_last: f64,
    /// Start-up deficit and the rest position it is measured from.
    deficit: f64,
    anchor: f64,
    /// Output of the play.
    play_um: f64,
    /// The structure's input slope over the last step (um/s).
    slope: f64,
}

impl Effects {
    /// The effects of `cfg` for an internal step `h`; `None` when all are off.
    pub(super) fn new(cfg: &StageConfig, h: f64) -> Option<Self> {
        if !cfg.any_effect() {
            return None;
        }
        let r = &cfg.rate_hysteresis;
        let s = &cfg.startup_creep;
        let a = &cfg.amplitude_dynamics;
        let n = &cfg.sensor_nonlinearity;
        let res = &cfg.resonance;
        Some(Self {
            rate: r.enabled.then(|| Rate {
                widen: r.widen,
                gain_drop: r.gain_drop,
                rate_ref: r.rate_ref_v_per_s,
                a: -(-h / r.tau_s).exp_m1(),
                inv_h: 1.0 / h,
                d: cfg.hysteresis.d,
            }),
            startup: s.enabled.then(|| Startup {
                depth: s.depth,
                travel_v: s.travel_v,
                b: -(-h / s.rest_tau_s).exp_m1(),
            }),
            backlash_half_um: cfg.backlash.enabled.then_some(0.5 * cfg.backlash.width_um),
            amp: (a.enabled && res.enabled).then(|| AmpDynamics {
                table: (0..=AMP_TABLE)
                    .map(|k| {
                        let rho = k as f64 / AMP_TABLE as f64;
                        let f = res.freq_hz * (1.0 + a.freq_shift * rho);
                        let z = (res.zeta * (1.0 + a.zeta_scale * rho)).clamp(1e-4, 0.95);
                        resonance_ad(f, z, h)
                    })
                    .collect(),
                inv_w0: 1.0 / (2.0 * std::f64::consts::PI * res.freq_hz),
                lag0: 2.0 * res.zeta / (2.0 * std::f64::consts::PI * res.freq_hz),
                level_um: a.level_um,
            }),
            sensor: n.enabled.then_some(Sensor {
                center: n.center_um,
                half: n.half_range_um,
                q: n.quadratic,
                c: n.cubic,
            }),
        })
    }

    /// At rest at input `v` with static output `ys` (the stage rested long: full start-up
    /// deficit).
    pub(super) fn settle(&self, st: &mut AxisFx, v: f64, y: f64) {
        *st = AxisFx {
            vbar: v,
            v_last: v,
            deficit: self.startup.as_ref().map_or(0.0, |s| s.depth),
            anchor: y,
            ..AxisFx::default()
        };
    }

    /// The play's output at rest.
    pub(super) fn settle_play(&self, st: &mut AxisFx, y: f64) {
        st.play_um = y;
    }

    /// The hysteresis output `ys` at input `v` with the rate dependence.
    #[inline]
    pub(super) fn rate(&self, st: &mut AxisFx, v: f64, ys: f64) -> f64 {
        let Some(r) = &self.rate else {
            return ys;
        };
        let rate = (v - st.v_last).abs() * r.inv_h;
        st.rate_vps += r.a * (rate - st.rate_vps);
        st.vbar += r.a * (v - st.vbar);
        let rho = st.rate_vps / (st.rate_vps + r.rate_ref);
        let h = r.d * v - ys;
        ys - rho * (r.widen * h + r.gain_drop * r.d * (v - st.vbar))
    }

    /// The static output `y` (hysteresis and asymmetric term) at input `v` with the start-up
    /// deficit; ends the input-side step (remembers `v`).
    #[inline]
    pub(super) fn startup(&self, st: &mut AxisFx, v: f64, y: f64) -> f64 {
        let dv = (v - st.v_last).abs();
        st.v_last = v;
        let Some(s) = &self.startup else {
            return y;
        };
        st.deficit = st.deficit * (-dv / s.travel_v).exp() + s.b * (s.depth - st.deficit);
        st.anchor += s.b * (y - st.anchor);
        st.anchor + (1.0 - st.deficit) * (y - st.anchor)
    }

    /// The actuator's displacement `y` through the play.
    #[inline]
    pub(super) fn backlash(&self, st: &mut AxisFx, y: f64) -> f64 {
        match self.backlash_half_um {
            Some(half) => {
                st.play_um = st.play_um.clamp(y - half, y + half);
                st.play_um
            }
            None => y,
        }
    }

    /// What the sensor reads at position `x`.
    #[inline]
    pub(super) fn sensor(&self, x: f64) -> f64 {
        match &self.sensor {
            Some(s) => {
                let e = (x - s.center) / s.half;
                x + s.half * e * e * (s.q + s.c * e)
            }
            None => x,
        }
    }
}

impl AmpDynamics {
    /// The transition matrix and lag for the structure's state `(x, v)` with input at `u`:
    /// its free oscillation amplitude (about the ramp it follows) picks the table entry.
    #[inline]
    pub(super) fn select(
        &self,
        st: &mut AxisFx,
        x: f64,
        v: f64,
        u: f64,
        slope: f64,
    ) -> ([[f64; 2]; 2], f64) {
        let dx = x - (u - self.lag0 * st.slope);
        let dv = (v - st.slope) * self.inv_w0;
        st.slope = slope;
        let amp = (dx * dx + dv * dv).sqrt();
        let pos = amp / (amp + self.level_um) * AMP_TABLE as f64;
        let k = (pos as usize).min(AMP_TABLE - 1);
        let f = (pos - k as f64).clamp(0.0, 1.0);
        let (a0, l0) = self.table[k];
        let (a1, l1) = self.table[k + 1];
        let mut ad = [[0.0; 2]; 2];
        for i in 0..2 {
            for j in 0..2 {
                ad[i][j] = a0[i][j] + f * (a1[i][j] - a0[i][j]);
            }
        }
        (ad, l0 + f * (l1 - l0))
    }
}
