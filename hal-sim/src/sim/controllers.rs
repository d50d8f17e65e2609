//! The controller registry: a name -> pipeline configuration (feedforward + feedback +
//! mode) for a given stage.
//!
//! To add a controller: write one `fn my_law<const N: usize>(s: &StageInfo) ->
//! Result<Controller<N>>` (or one per axis count) and add one [`Entry`] to [`registry`].
//! The builder sees the nominal stage ([`StageInfo`]): the scenario's parameters and a
//! linear calibration measured on the stage.

mod feedforward;
pub mod identified;
pub mod models;

use super::StageInfo;
use anyhow::Result;
use piezo_core::feedback::Feedback;
use piezo_core::feedforward::{Feedforward, LinearFf, MultiFeedforward};
use piezo_core::pipeline::Mode;
use piezo_core::registry::{self, Family as RegFamily, Law, LawKind};
use LawKind::*;
use RegFamily::{Cbw, Gbw};

/// The number type of the simulated firmware (the firmware's own).
pub type R = f32;

/// What a registry entry builds: the pipeline's compensator, laws and mode.
#[derive(Debug, Clone)]
pub struct Controller<const N: usize> {
    pub feedforward: MultiFeedforward<R, N>,
    pub feedback: [Feedback<R>; N],
    pub mode: Mode,
}

/// Builder for a 1-axis stage.
pub type Build1 = fn(&StageInfo) -> Result<Controller<1>>;
/// Builder for a 2-axis stage (`None`: the controller has no 2-axis form).
pub type Build2 = fn(&StageInfo) -> Result<Controller<2>>;

/// One registered controller.
#[derive(Debug, Clone, Copy)]
pub struct Entry {
    /// Name on the command line and in the tables (`--controller NAME`).
    pub name: &'static str,
    /// One line for `piezo sim --list`.
    pub about: &'static str,
    pub one_axis: Build1,
    pub two_axis: Option<Build2>,
}

/// Every controller, in table order.
pub fn registry() -> Vec<Entry> {
    let mut v = vec![
        Entry {
            name: law(OpenLoop, false, Cbw),
            about: "linear scaling of the reference (calibrated gain and offset), no model, no feedback",
            one_axis: open_loop::<1>,
            two_axis: Some(open_loop::<2>),
        },
        // FEEDFORWARD and FEEDBACK: add entries here.
        // FEEDBACK (000 Part III-IV laws, builders in `fb` below):
        Entry {
            name: law(Pid, false, Cbw),
            about: "PI on the position error, back-calculation anti-windup from the applied voltage, notch on the resonance",
            one_axis: |s| fb::build::<1>(s, Law::new(Pid, false, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(Pid, false, Cbw))),
        },
        Entry {
            name: law(Pid, true, Cbw),
            about: "linear feedforward + the same PI",
            one_axis: |s| fb::build::<1>(s, Law::new(Pid, true, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(Pid, true, Cbw))),
        },
        Entry {
            name: law(HgoRobust, false, Cbw),
            about: "HGO (000 eq. 6) + robust virtual-hysteresis law (000 eq. 7-8), notch",
            one_axis: |s| fb::build::<1>(s, Law::new(HgoRobust, false, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(HgoRobust, false, Cbw))),
        },
        Entry {
            name: law(HgoRobust, true, Cbw),
            about: "linear feedforward + HGO robust law (feedforward increments replace the law's own)",
            one_axis: |s| fb::build::<1>(s, Law::new(HgoRobust, true, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(HgoRobust, true, Cbw))),
        },
        Entry {
            name: law(Fts, false, Cbw),
            about: "HGO + finite-time virtual-hysteresis law (000 Part IV), CBW prediction model",
            one_axis: |s| fb::build::<1>(s, Law::new(Fts, false, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(Fts, false, Cbw))),
        },
        Entry {
            name: law(Fts, false, Gbw),
            about: "the finite-time law with the GBW (000 eq. 3) as observer and law model",
            one_axis: |s| fb::build::<1>(s, Law::new(Fts, false, Gbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(Fts, false, Gbw))),
        },
        Entry {
            name: law(Adrc, false, Cbw),
            about: "extended-state observer + ADRC as 000 eq. 10-11 (Delta holds the whole linear part; measured y in the law)",
            one_axis: |s| fb::build::<1>(s, Law::new(Adrc, false, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(Adrc, false, Cbw))),
        },
        Entry {
            name: law(Adrc, true, Cbw),
            about: "linear feedforward + the same ESO/ADRC on what it leaves",
            one_axis: |s| fb::build::<1>(s, Law::new(Adrc, true, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(Adrc, true, Cbw))),
        },
        Entry {
            name: law(AdrcLin, false, Cbw),
            about: "ESO/ADRC with the structure's a1, a2 known: the ESO estimates only -b0 h + delta_y",
            one_axis: |s| fb::build::<1>(s, Law::new(AdrcLin, false, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(AdrcLin, false, Cbw))),
        },
        Entry {
            name: law(Nmpc, false, Cbw),
            about: "HGO + NMPC with a CBW prediction model (000 Part IV), 10 kHz, horizon 8",
            one_axis: |s| fb::build::<1>(s, Law::new(Nmpc, false, Cbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(Nmpc, false, Cbw))),
        },
        Entry {
            name: law(Nmpc, false, Gbw),
            about: "HGO + NMPC with the GBW (000 eq. 3) as prediction model, as 000 Part IV",
            one_axis: |s| fb::build::<1>(s, Law::new(Nmpc, false, Gbw)),
            two_axis: Some(|s| fb::build::<2>(s, Law::new(Nmpc, false, Gbw))),
        },
    ];
    v.extend(feedforward::entries());
    v
}

/// A law's name in the core's registry ([`piezo_core::registry`]).
const fn law(kind: LawKind, feedforward: bool, family: RegFamily) -> &'static str {
    Law::new(kind, feedforward, family).name()
}

/// Looks a controller up by its registry name, or by a name `piezo sim` used before the
/// registry (with a note on stderr; accepted for one release).
pub fn find(name: &str) -> Option<Entry> {
    let canonical = registry::canonical(name);
    if canonical != name {
        eprintln!("note: controller {name} is now called {canonical} (the old name goes in the next release)");
    }
    registry().into_iter().find(|e| e.name == canonical)
}

/// The linear feedforward of the calibrated stage, per axis.
pub fn linear_ff<const N: usize>(s: &StageInfo) -> [Feedforward<R>; N] {
    core::array::from_fn(|_| {
        Feedforward::Linear(LinearFf {
            um_per_volt: s.linear.um_per_volt as R,
            offset_um: s.linear.offset_um as R,
        })
    })
}

/// Open loop: the pipeline's linear scaling only.
pub fn open_loop<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    Ok(Controller {
        feedforward: MultiFeedforward::PerAxis(linear_ff(s)),
        feedback: core::array::from_fn(|_| Feedback::OpenLoop),
        mode: Mode::OpenLoop,
    })
}

/// FEEDBACK's builders: the laws of 000 Part III-IV (`piezo_core::feedback`) tuned for the
/// nominal stage. Gains come from the stage description (amplifier bandwidth, resonance,
/// delay, sensor noise); the constants below were chosen on `sine-10hz` at 30 um amplitude
/// (see the FEEDBACK report) and are the same for every scenario.
pub mod fb {
    use super::models::prediction;
    use super::{linear_ff, Controller, R};
    use crate::sim::StageInfo;
    use anyhow::{anyhow, Result};
    use piezo_core::feedback::{Biquad, Feedback, Hgo, ObserverModel};
    use piezo_core::feedforward::MultiFeedforward;
    use piezo_core::hysteresis::ParamError;
    use piezo_core::pipeline::Mode;
    use piezo_core::registry::{AdrcGains, FtsGains, Law, LawKind, NmpcGains, PidGains, Tuning};
    use std::f64::consts::PI;

    /// Allowed RMS of the HGO's `h_hat` from sensor noise (um): with the default 5 nm sensor
    /// this gives `eps` near 60 us, with 10x noise the helper's cap `2/a` ([`Hgo::epsilon_for`]).
    pub const H_NOISE_BUDGET_UM: f64 = 0.0014;
    /// Closed-loop rates of the robust law (000 eq. 7-8), Hz.
    pub const LAMBDA1_HZ: f64 = 600.0;
    pub const LAMBDA2_HZ: f64 = 3000.0;
    /// The plain HGO robust law (no feedforward increments) on the re-centred default stage:
    /// a slower observer (budget 0.5 nm: the helper returns its cap `2/a`) with a faster
    /// outer rate tracks 0.041 % of stroke at 10 Hz where the settings above give 0.080 %;
    /// the feedforward and finite-time variants keep the settings above (they degrade with
    /// these).
    pub const PLAIN_H_NOISE_BUDGET_UM: f64 = 0.0005;
    pub const PLAIN_LAMBDA1_HZ: f64 = 800.0;
    /// Notch quality on the resonance (higher: less phase lag at the scan frequency).
    pub const NOTCH_Q: f64 = 4.0;

    fn perr(p: ParamError) -> anyhow::Error {
        anyhow!("{p}")
    }

    /// First-order pole (1/s) with the low-frequency lag of amplifier, structure,
    /// measurement delay and half a sample: the `-A` of 000 eq. (2), normalised.
    pub fn pole(s: &StageInfo) -> f64 {
        let st = &s.scenario.stage;
        let mut lag = 0.5 / s.loop_hz() + 1.0 / (2.0 * PI * st.amplifier.bandwidth_hz);
        if st.resonance.enabled {
            lag += 2.0 * st.resonance.zeta / (2.0 * PI * st.resonance.freq_hz);
        }
        if st.delay.enabled {
            lag += st.delay.seconds;
        }
        1.0 / lag
    }

    /// Sensor noise the observer is designed for (um RMS).
    fn noise_um(s: &StageInfo) -> f64 {
        let n = &s.scenario.stage.noise;
        if n.enabled {
            n.sigma_um
        } else {
            0.0
        }
    }

    /// Notch on the measured position at the stage resonance.
    pub fn notch(s: &StageInfo) -> Result<Option<Biquad<R>>> {
        let r = &s.scenario.stage.resonance;
        if !r.enabled {
            return Ok(None);
        }
        Biquad::notch(r.freq_hz as R, NOTCH_Q as R, s.loop_hz() as R)
            .map(Some)
            .map_err(perr)
    }

    fn wrap<const N: usize>(s: &StageInfo, mut law: Feedback<R>) -> Result<Controller<N>> {
        law.set_measurement_filter(notch(s)?);
        Ok(Controller {
            feedforward: MultiFeedforward::PerAxis(linear_ff(s)),
            feedback: core::array::from_fn(|_| law.clone()),
            mode: Mode::ClosedLoop,
        })
    }

    fn dt(s: &StageInfo) -> f64 {
        1.0 / s.loop_hz()
    }

    /// The gains of `law` for the stage `s` as the registry's [`Tuning`]; `model` is the
    /// law's prediction model (the HGO's `eps` follows from it and the sensor noise).
    pub fn tuning(s: &StageInfo, law: Law, model: Option<&ObserverModel<R>>) -> Result<Tuning<R>> {
        let a = pole(s);
        let plain = law.kind == LawKind::HgoRobust && !law.feedforward;
        let (l1_hz, budget) = if plain {
            (PLAIN_LAMBDA1_HZ, PLAIN_H_NOISE_BUDGET_UM)
        } else {
            (LAMBDA1_HZ, H_NOISE_BUDGET_UM)
        };
        let (l1, l2) = (2.0 * PI * l1_hz, 2.0 * PI * LAMBDA2_HZ);
        let hgo_eps_s = match model {
            Some(m) => Hgo::epsilon_for(*m, a as R, dt(s) as R, noise_um(s) as R, budget as R)
                .map_err(perr)?,
            None => 0.0,
        };
        // PI(D): integral action with crossover 250 Hz on the calibrated gain (the stage is
        // quasi-static below its resonance), proportional zero on the lag pole.
        let ki = 2.0 * PI * 250.0 / s.linear.um_per_volt;
        // ESO + ADRC (000 eq. 10-11) with the input gain `b = b0 d_p` of the structure's
        // second-order model; `adrc-lin` also gets its `a1, a2`, so that the ESO estimates
        // only `-b0 h + delta_y` (without feedforward that tracks 5x better at 10 Hz).
        let r = &s.scenario.stage.resonance;
        let (w2, a1) = if r.enabled {
            let w = 2.0 * PI * r.freq_hz;
            (w * w, 2.0 * r.zeta * w)
        } else {
            (a * a, 2.0 * a)
        };
        let (lo, hi) = s.volts_range();
        Ok(Tuning {
            pole_per_s: a as R,
            hgo_eps_s,
            lambda1: l1 as R,
            lambda2: l2 as R,
            // k sig(e)^0.8: the same rate as the exponential law at ~0.03 um error.
            fts: FtsGains {
                lambda1: (0.3 * l1) as R,
                lambda2: l2 as R,
                alpha1: 0.8,
                alpha2: 0.8,
                sat_um_per_s: 1e5,
            },
            pid: PidGains {
                kp: (ki / a) as R,
                ki: ki as R,
                kd: 0.0,
                tf_s: 1e-4,
                kb: 1.0,
            },
            adrc: AdrcGains {
                b: (s.linear.um_per_volt * w2) as R,
                a1: a1 as R,
                a2: w2 as R,
                eps_s: 2e-5,
                omega_c: (2.0 * PI * 600.0) as R,
            },
            // NMPC at a tenth of the loop rate, horizon 8 moves (0.8 ms at 100 kHz); the
            // prediction holds each move for 10 samples: a slower observer (eps 100 us)
            // keeps its noise out of the plan.
            nmpc: NmpcGains {
                decimation: 10,
                r: 1.0,
                iterations: 2,
                u_min: lo as R,
                u_max: hi as R,
                hgo_eps_s: 1e-4,
            },
        })
    }

    /// The registry's `law` for the stage `s`: its prediction model where it has an
    /// observer, [`tuning`], the notch on the resonance, the linear feedforward.
    pub fn build<const N: usize>(s: &StageInfo, law: Law) -> Result<Controller<N>> {
        let model = match law.kind {
            LawKind::HgoRobust | LawKind::Fts | LawKind::Nmpc => Some(prediction(s, law.family)?),
            _ => None,
        };
        let t = tuning(s, law, model.as_ref())?;
        wrap(s, law.build(model, &t, dt(s) as R).map_err(perr)?)
    }
}
