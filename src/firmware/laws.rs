//! The feedback laws and feedforward compensators of the core, by name, built from the
//! [`Params`].

use super::params::Params;
use super::target::{c, R};
use crate::command::Error;
use crate::feedback::{
    hgo, Adrc, AdrcConfig, Convergence, Feedback, Hgo, Nmpc, NmpcConfig, ObserverModel, Pid,
    PidConfig, Robust, RobustConfig,
};
use crate::feedforward::{Feedforward, Ims, ImsLoop};

/// Names of the feedback laws `mode` accepts (the bench iterates over them); they are the
/// laws' own [`Feedback::name`]s.
/// The `-gbw` laws predict with [`Params::gbw_model`] (000 Part IV), the others with the CBW.
pub const LAWS: [&str; 13] = [
    "open-loop",
    "pid",
    "ff+pid",
    "hgo-robust",
    "ff+hgo-robust",
    "fts",
    "ff+fts",
    "fts-gbw",
    "adrc",
    "ff+adrc",
    "nmpc",
    "ff+nmpc",
    "nmpc-gbw",
];

/// Names of the feedforward compensators `ff` accepts.
pub const FFS: [&str; 3] = ["linear", "ims-cbw", "ims-cbw-delayed"];

/// Stage the laws are tuned for: CBW set 1 of the 000 backup slide, first-order linear part
/// with pole [`STAGE_POLE_PER_S`], range 0..150 V.
pub const STAGE_POLE_PER_S: f64 = 2.0 * core::f64::consts::PI * 500.0;

/// Every consumer accepts the values of `p`: the core's constructors decide (CBW bounds,
/// IMS invertibility, HGO gains, robust and PID gains, open-loop scaling), so any law and
/// compensator can be selected afterwards.
#[inline(never)]
pub fn validate(p: &Params, sample_hz: R) -> Result<(), Error> {
    let ok = ff_with("ims-cbw", p, sample_hz).is_some()
        && law_with("hgo-robust", p, sample_hz).is_some()
        && law_with("fts-gbw", p, sample_hz).is_some()
        && law_with("pid", p, sample_hz).is_some()
        && p.notch(sample_hz).is_ok()
        && p.linear().is_valid();
    if ok {
        Ok(())
    } else {
        Err(Error::OutOfRange)
    }
}

/// The feedback laws of the core, by name, with the default [`Params`] (host tests).
pub fn law_by_name(name: &str, sample_hz: R) -> Option<Feedback<R>> {
    law_with(name, &Params::default(), sample_hz)
}

/// The feedback laws of the core, by name, with the model and gains of `p`, and the notch
/// of `p` ([`Params::notch`]) on the law's measurement.
pub fn law_with(name: &str, p: &Params, sample_hz: R) -> Option<Feedback<R>> {
    let notch = p.notch(sample_hz).ok()?;
    let mut fb = law_unfiltered(name, p, sample_hz)?;
    if notch.is_some() {
        fb.set_measurement_filter(notch);
    }
    Some(fb)
}

/// [`law_with`] without the notch.
fn law_unfiltered(name: &str, p: &Params, sample_hz: R) -> Option<Feedback<R>> {
    let dt_s = c(1.0) / sample_hz;
    let (ff, base) = match name.strip_prefix("ff+") {
        Some(b) => (true, b),
        None => (false, name),
    };
    // Only `fts-gbw` and `nmpc-gbw` of the GBW laws are in [`LAWS`].
    let (gbw, base) = match base.strip_suffix("-gbw") {
        Some(b @ ("fts" | "nmpc")) if !ff => (true, b),
        Some(_) => return None,
        None => (false, base),
    };
    let model = if gbw {
        ObserverModel::Gbw(p.gbw_model()?)
    } else {
        ObserverModel::Cbw(p.model()?)
    };
    let hgo = || {
        Hgo::new(
            model,
            c(STAGE_POLE_PER_S),
            p.hgo_eps_s,
            c(hgo::K1),
            c(hgo::K2),
            dt_s,
        )
        .ok()
    };
    let robust = |convergence| {
        Robust::new(
            hgo()?,
            RobustConfig {
                lambda1: p.lambda1,
                lambda2: p.lambda2,
                feedforward: ff,
                convergence,
            },
        )
        .ok()
        .map(Feedback::Robust)
    };
    match base {
        "open-loop" if !ff => Some(Feedback::OpenLoop),
        "pid" => Pid::new(PidConfig {
            kp: p.pid_kp,
            ki: p.pid_ki,
            kd: c(0.0),
            tf_s: c(1e-4),
            kb: c(1.0),
            feedforward: ff,
            dt_s,
        })
        .ok()
        .map(Feedback::Pid),
        "hgo-robust" => robust(Convergence::Exponential),
        "fts" => robust(Convergence::FiniteTime {
            alpha1: c(0.8),
            alpha2: c(0.8),
            sat_um_per_s: c(1e4),
        }),
        "adrc" => Adrc::new(AdrcConfig {
            // Plain ADRC: the ESO estimates the whole linear part.
            a1: c(0.0),
            a2: c(0.0),
            b: c(0.16 * STAGE_POLE_PER_S * STAGE_POLE_PER_S),
            eps_s: c(2e-4),
            omega_c: c(2_000.0),
            feedforward: ff,
            dt_s,
        })
        .ok()
        .map(Feedback::Adrc),
        "nmpc" => Nmpc::new(
            hgo()?,
            NmpcConfig {
                decimation: 10,
                r: c(1e-3),
                iterations: 2,
                u_min: c(0.0),
                u_max: c(150.0),
                feedforward: ff,
            },
        )
        .ok()
        .map(Feedback::Nmpc),
        _ => None,
    }
}

/// The feedforward compensators, by name, with the default [`Params`] (host tests).
pub fn ff_by_name(name: &str, sample_hz: R) -> Option<Feedforward<R>> {
    ff_with(name, &Params::default(), sample_hz)
}

/// The feedforward compensators, by name: linear scaling, or IMS around the CBW model of
/// `p` (0..150 V).
pub fn ff_with(name: &str, p: &Params, sample_hz: R) -> Option<Feedforward<R>> {
    let ims = |closure| {
        let model = p.model()?;
        Ims::new(model, closure, c(0.0), c(150.0), c(1.0) / sample_hz)
            .ok()
            .map(Feedforward::ImsCbw)
    };
    match name {
        "linear" => Some(Feedforward::Linear(p.linear())),
        "ims-cbw" => ims(ImsLoop::Solved),
        "ims-cbw-delayed" => ims(ImsLoop::Delayed),
        _ => None,
    }
}
