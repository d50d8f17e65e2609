//! The one controller registry: every feedback law and feedforward kind by name, with one
//! spelling used by the firmware (`mode`, `ff`), `piezo sim --controller`, `piezo serial`
//! and the docs, and the feedback laws built from a model, a [`Tuning`] and the sample
//! period.
//!
//! Names: a law is its kind (`pid`, `hgo-robust`, ...), prefixed `ff+` when it adds the
//! feedforward voltage, suffixed `-gbw` when it predicts with the GBW (000 eq. 3) instead of
//! the CBW. The names `piezo sim` used before this registry are accepted as [`ALIASES`]
//! for one release.

use crate::feedback::{
    Adrc, AdrcConfig, Convergence, Feedback, Hgo, Nmpc, NmpcConfig, ObserverModel, Pid, PidConfig,
    Robust, RobustConfig,
};
use crate::hysteresis::ParamError;
use crate::real::Real;

/// Kind of feedback law.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LawKind {
    /// No feedback.
    OpenLoop,
    /// PID baseline.
    Pid,
    /// HGO (000 eq. 6) + robust virtual-hysteresis law (000 eq. 7-8).
    HgoRobust,
    /// HGO + the finite-time variant of the robust law (000 Part IV).
    Fts,
    /// ESO + ADRC (000 eq. 10-11), the ESO estimating the whole linear part.
    Adrc,
    /// ESO + ADRC with the structure's `a1, a2` known.
    AdrcLin,
    /// HGO + NMPC with the hysteresis model as predictor (000 Part IV).
    Nmpc,
}

/// Prediction model family of the observer-based laws.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// Classical Bouc-Wen (000 eq. 1).
    Cbw,
    /// Generalized Bouc-Wen (000 eq. 3).
    Gbw,
}

/// One feedback law: its kind, whether it adds the feedforward voltage, its model family.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Law {
    pub kind: LawKind,
    pub feedforward: bool,
    pub family: Family,
}

const fn law(kind: LawKind, feedforward: bool, family: Family) -> Law {
    Law::new(kind, feedforward, family)
}

use Family::{Cbw, Gbw};
use LawKind::*;

/// Every law and its name, in table order.
pub const LAW_NAMES: [(Law, &str); 19] = [
    (law(OpenLoop, false, Cbw), "open-loop"),
    (law(Pid, false, Cbw), "pid"),
    (law(Pid, true, Cbw), "ff+pid"),
    (law(HgoRobust, false, Cbw), "hgo-robust"),
    (law(HgoRobust, true, Cbw), "ff+hgo-robust"),
    (law(HgoRobust, false, Gbw), "hgo-robust-gbw"),
    (law(HgoRobust, true, Gbw), "ff+hgo-robust-gbw"),
    (law(Fts, false, Cbw), "fts"),
    (law(Fts, true, Cbw), "ff+fts"),
    (law(Fts, false, Gbw), "fts-gbw"),
    (law(Fts, true, Gbw), "ff+fts-gbw"),
    (law(Adrc, false, Cbw), "adrc"),
    (law(Adrc, true, Cbw), "ff+adrc"),
    (law(AdrcLin, false, Cbw), "adrc-lin"),
    (law(AdrcLin, true, Cbw), "ff+adrc-lin"),
    (law(Nmpc, false, Cbw), "nmpc"),
    (law(Nmpc, true, Cbw), "ff+nmpc"),
    (law(Nmpc, false, Gbw), "nmpc-gbw"),
    (law(Nmpc, true, Gbw), "ff+nmpc-gbw"),
];

/// Kind of feedforward compensator (its names: [`FF_NAMES`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FfKind {
    /// Linear scaling of the reference (calibrated gain and offset).
    Linear,
    /// IMS around the CBW model, algebraic loop solved (001/004).
    ImsCbw,
    /// IMS with the one-sample-delayed `h` (004 sec. 4.4).
    ImsCbwDelayed,
    /// IMS with every model parameter 20 % off (a model-error study, `piezo sim` only).
    ImsCbwOff20,
    /// IMS on the hysteresis model alone (`piezo sim` only).
    ImsCbwBare,
    /// 002's feedforward without inversion (eq. 8-12).
    Mbw,
    /// 004's direct WPMBW inverse.
    Wpmbw,
    /// Exact Prandtl-Ishlinskii inverse.
    PiInverse,
    /// Play-type PI (PPI) inverse by bounded solve.
    PpiInverse,
    /// Exact DPI inverse.
    DpiInverse,
    /// Multivariable IMS (003 eq. 16).
    MultiIms,
}

/// Every feedforward kind and its name, in table order.
pub const FF_NAMES: [(FfKind, &str); 11] = [
    (FfKind::Linear, "linear"),
    (FfKind::ImsCbw, "ims-cbw"),
    (FfKind::ImsCbwDelayed, "ims-cbw-delayed"),
    (FfKind::ImsCbwOff20, "ims-cbw-off20"),
    (FfKind::ImsCbwBare, "ims-cbw-bare"),
    (FfKind::Mbw, "mbw"),
    (FfKind::Wpmbw, "wpmbw"),
    (FfKind::PiInverse, "pi-inverse"),
    (FfKind::PpiInverse, "ppi-inverse"),
    (FfKind::DpiInverse, "dpi-inverse"),
    (FfKind::MultiIms, "multi-ims"),
];

/// Names `piezo sim` used before this registry (old, new): accepted for one release, with a
/// note on stderr (`piezo sim`).
pub const ALIASES: [(&str, &str); 10] = [
    ("ff-ims", "ims-cbw"),
    ("ff-ims-delayed", "ims-cbw-delayed"),
    ("ff-ims-off20", "ims-cbw-off20"),
    ("ff-ims-bare", "ims-cbw-bare"),
    ("ff-mbw", "mbw"),
    ("ff-wpmbw", "wpmbw"),
    ("ff-pi", "pi-inverse"),
    ("ff-ppi", "ppi-inverse"),
    ("ff-dpi", "dpi-inverse"),
    ("ff-multi-ims", "multi-ims"),
];

/// The current name for `name`: itself, or what its alias stands for.
pub fn canonical(name: &str) -> &str {
    let mut i = 0;
    while i < ALIASES.len() {
        if ALIASES[i].0.as_bytes() == name.as_bytes() {
            return ALIASES[i].1;
        }
        i += 1;
    }
    name
}

/// A controller of `piezo sim` or the firmware: a feedback law (with the linear
/// feedforward) or a feedforward compensator alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Controller {
    Law(Law),
    Ff(FfKind),
}

impl Controller {
    /// The controller of `name` (a law's or a feedforward kind's name, or an alias).
    pub fn from_name(name: &str) -> Option<Self> {
        let name = canonical(name);
        Law::from_name(name)
            .map(Controller::Law)
            .or_else(|| FfKind::from_name(name).map(Controller::Ff))
    }

    pub const fn name(self) -> &'static str {
        match self {
            Controller::Law(l) => l.name(),
            Controller::Ff(f) => f.name(),
        }
    }
}

impl Law {
    pub const fn new(kind: LawKind, feedforward: bool, family: Family) -> Self {
        Self {
            kind,
            feedforward,
            family,
        }
    }

    /// The law's one name ([`LAW_NAMES`]).
    pub const fn name(self) -> &'static str {
        let mut i = 0;
        while i < LAW_NAMES.len() {
            let l = LAW_NAMES[i].0;
            if l.kind as u8 == self.kind as u8
                && l.feedforward == self.feedforward
                && l.family as u8 == self.family as u8
            {
                return LAW_NAMES[i].1;
            }
            i += 1;
        }
        // Only combinations of the table are constructed by `from_name`; a hand-built
        // other one (a GBW PID, say) has no name.
        "?"
    }

    /// The law named `name` (not an alias).
    pub fn from_name(name: &str) -> Option<Self> {
        LAW_NAMES.iter().find(|(_, n)| *n == name).map(|(l, _)| *l)
    }

    /// Whether the law observes with a hysteresis model (HGO): it needs one to be built.
    pub const fn needs_model(self) -> bool {
        matches!(self.kind, LawKind::HgoRobust | LawKind::Fts | LawKind::Nmpc)
    }

    /// Builds the law with the gains of `tuning`, sampled every `dt_s`; the observer-based
    /// laws ([`Law::needs_model`]) predict with `model`, which must be of [`Law::family`].
    /// The measurement filter (notch) is the caller's.
    pub fn build<R: Real>(
        self,
        model: Option<ObserverModel<R>>,
        tuning: &Tuning<R>,
        dt_s: R,
    ) -> Result<Feedback<R>, ParamError> {
        if self.name() == "?" {
            return Err(ParamError("registry: no such law"));
        }
        let hgo = |eps_s| match (self.family, model) {
            (Family::Cbw, Some(m @ ObserverModel::Cbw(_)))
            | (Family::Gbw, Some(m @ ObserverModel::Gbw(_))) => {
                Hgo::with_eps(m, tuning.pole_per_s, eps_s, dt_s)
            }
            _ => Err(ParamError(
                "registry: the law needs a prediction model of its family",
            )),
        };
        let ff = self.feedforward;
        let robust = |lambda1, lambda2, convergence| -> Result<Feedback<R>, ParamError> {
            let cfg = RobustConfig {
                lambda1,
                lambda2,
                feedforward: ff,
                convergence,
            };
            Ok(Feedback::Robust(Robust::new(hgo(tuning.hgo_eps_s)?, cfg)?))
        };
        let adrc = |a1, a2| -> Result<Feedback<R>, ParamError> {
            let a = &tuning.adrc;
            Ok(Feedback::Adrc(Adrc::new(AdrcConfig {
                b: a.b,
                a1,
                a2,
                eps_s: a.eps_s,
                omega_c: a.omega_c,
                feedforward: ff,
                dt_s,
            })?))
        };
        match self.kind {
            LawKind::OpenLoop => Ok(Feedback::OpenLoop),
            LawKind::Pid => {
                let p = &tuning.pid;
                Ok(Feedback::Pid(Pid::new(PidConfig {
                    kp: p.kp,
                    ki: p.ki,
                    kd: p.kd,
                    tf_s: p.tf_s,
                    kb: p.kb,
                    feedforward: ff,
                    dt_s,
                })?))
            }
            LawKind::HgoRobust => robust(tuning.lambda1, tuning.lambda2, Convergence::Exponential),
            LawKind::Fts => {
                let f = &tuning.fts;
                let convergence = Convergence::FiniteTime {
                    alpha1: f.alpha1,
                    alpha2: f.alpha2,
                    sat_um_per_s: f.sat_um_per_s,
                };
                robust(f.lambda1, f.lambda2, convergence)
            }
            LawKind::Adrc => adrc(R::ZERO, R::ZERO),
            LawKind::AdrcLin => adrc(tuning.adrc.a1, tuning.adrc.a2),
            LawKind::Nmpc => {
                let n = &tuning.nmpc;
                Ok(Feedback::Nmpc(Nmpc::new(
                    hgo(n.hgo_eps_s)?,
                    NmpcConfig {
                        decimation: n.decimation,
                        r: n.r,
                        iterations: n.iterations,
                        u_min: n.u_min,
                        u_max: n.u_max,
                        feedforward: ff,
                    },
                )?))
            }
        }
    }
}

/// Each built law knows its registry entry (kept here, not in `feedback`, so that the
/// registry depends on the laws and not the other way round).
impl<T: Real> Feedback<T> {
    /// The law in the controller registry ([`crate::registry`]).
    pub fn law(&self) -> Law {
        let gbw = |m: &ObserverModel<T>| match m {
            ObserverModel::Gbw(_) => Family::Gbw,
            _ => Family::Cbw,
        };
        let (kind, feedforward, family) = match self {
            Feedback::OpenLoop => (LawKind::OpenLoop, false, Family::Cbw),
            Feedback::Pid(l) => (LawKind::Pid, l.config().feedforward, Family::Cbw),
            Feedback::Robust(l) => {
                let kind = match l.config().convergence {
                    Convergence::Exponential => LawKind::HgoRobust,
                    Convergence::FiniteTime { .. } => LawKind::Fts,
                };
                (kind, l.config().feedforward, gbw(l.observer().model()))
            }
            Feedback::Adrc(l) => {
                let c = l.config();
                let known = c.a1 != T::ZERO || c.a2 != T::ZERO;
                let kind = if known {
                    LawKind::AdrcLin
                } else {
                    LawKind::Adrc
                };
                (kind, c.feedforward, Family::Cbw)
            }
            Feedback::Nmpc(l) => (
                LawKind::Nmpc,
                l.config().feedforward,
                gbw(l.observer().model()),
            ),
        };
        Law {
            kind,
            feedforward,
            family,
        }
    }

    /// Short name for tables and logs: the registry's ([`Law::name`]).
    pub fn name(&self) -> &'static str {
        self.law().name()
    }
}

impl FfKind {
    /// The kind's one name ([`FF_NAMES`]).
    pub const fn name(self) -> &'static str {
        let mut i = 0;
        while i < FF_NAMES.len() {
            if FF_NAMES[i].0 as u8 == self as u8 {
                return FF_NAMES[i].1;
            }
            i += 1;
        }
        "?"
    }

    /// The kind named `name` (not an alias).
    pub fn from_name(name: &str) -> Option<Self> {
        FF_NAMES.iter().find(|(_, n)| *n == name).map(|(k, _)| *k)
    }
}

/// Gains of every law, as the firmware's parameters or `piezo sim`'s stage-derived tuning
/// give them. Rates in 1/s, times in s, voltages in V, positions in um.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tuning<R> {
    /// The linear part's pole `-A` the HGO assumes (1/s).
    pub pole_per_s: R,
    /// HGO `epsilon` of the robust and finite-time laws (s).
    pub hgo_eps_s: R,
    /// Robust law rates `lambda_1`, `lambda_2` (000 eq. 7-8).
    pub lambda1: R,
    pub lambda2: R,
    pub fts: FtsGains<R>,
    pub pid: PidGains<R>,
    pub adrc: AdrcGains<R>,
    pub nmpc: NmpcGains<R>,
}

/// Finite-time law (000 Part IV): rates, exponents and the rate bound near zero error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FtsGains<R> {
    pub lambda1: R,
    pub lambda2: R,
    pub alpha1: R,
    pub alpha2: R,
    pub sat_um_per_s: R,
}

/// PID gains (V/um, V/(um s), V s/um), derivative filter and back-calculation gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PidGains<R> {
    pub kp: R,
    pub ki: R,
    pub kd: R,
    pub tf_s: R,
    pub kb: R,
}

/// ESO/ADRC: input gain `b` (um/(s^2 V)), the structure's `a1, a2` (used by `adrc-lin`
/// only), observer `eps` and controller bandwidth (rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdrcGains<R> {
    pub b: R,
    pub a1: R,
    pub a2: R,
    pub eps_s: R,
    pub omega_c: R,
}

/// NMPC: decimation, input weight, iterations, input range and its own HGO `epsilon`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NmpcGains<R> {
    pub decimation: u32,
    pub r: R,
    pub iterations: u32,
    pub u_min: R,
    pub u_max: R,
    pub hgo_eps_s: R,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_round_trips_and_is_unique() {
        for (l, n) in LAW_NAMES {
            assert_eq!(l.name(), n);
            assert_eq!(Law::from_name(n), Some(l));
            assert_eq!(Controller::from_name(n), Some(Controller::Law(l)));
        }
        for (k, n) in FF_NAMES {
            assert_eq!(k.name(), n);
            assert_eq!(Controller::from_name(n), Some(Controller::Ff(k)));
        }
        let mut names: heapless::Vec<&str, 40> = heapless::Vec::new();
        for n in LAW_NAMES
            .iter()
            .map(|x| x.1)
            .chain(FF_NAMES.iter().map(|x| x.1))
        {
            assert!(!names.contains(&n), "{n} twice");
            names.push(n).unwrap();
        }
        for (old, new) in ALIASES {
            assert!(!names.contains(&old), "alias {old} shadows a name");
            assert_eq!(
                Controller::from_name(old).map(Controller::name),
                Some(new),
                "{old}"
            );
        }
        assert_eq!(Controller::from_name("no-such-law"), None);
    }
}
