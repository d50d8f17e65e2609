//! The feedback laws and feedforward compensators of the core, by name, built from the
//! [`Params`].

use super::params::Params;
use super::target::{c, NMPC_DEFERRED, R};
use crate::command::Error;
use crate::feedback::{Feedback, ObserverModel};
use crate::feedforward::{Feedforward, Ims, ImsLoop};
use crate::registry::{
    AdrcGains, Family, FfKind, FtsGains, Law, LawKind, NmpcGains, PidGains, Tuning,
};

/// The feedback laws `mode` accepts (the bench iterates over them), from the registry.
/// The `-gbw` laws predict with [`Params::gbw_model`] (000 Part IV), the others with the CBW.
pub const FIRMWARE_LAWS: [Law; 13] = {
    use Family::{Cbw, Gbw};
    use LawKind::*;
    const fn l(kind: LawKind, feedforward: bool, family: Family) -> Law {
        Law::new(kind, feedforward, family)
    }
    [
        l(OpenLoop, false, Cbw),
        l(Pid, false, Cbw),
        l(Pid, true, Cbw),
        l(HgoRobust, false, Cbw),
        l(HgoRobust, true, Cbw),
        l(Fts, false, Cbw),
        l(Fts, true, Cbw),
        l(Fts, false, Gbw),
        l(Adrc, false, Cbw),
        l(Adrc, true, Cbw),
        l(Nmpc, false, Cbw),
        l(Nmpc, true, Cbw),
        l(Nmpc, false, Gbw),
    ]
};

/// Names of [`FIRMWARE_LAWS`] (the registry's spelling).
pub const LAWS: [&str; 13] = {
    let mut n = [""; 13];
    let mut i = 0;
    while i < n.len() {
        n[i] = FIRMWARE_LAWS[i].name();
        i += 1;
    }
    n
};

/// The feedforward compensators `ff` accepts.
pub const FIRMWARE_FFS: [FfKind; 3] = [FfKind::Linear, FfKind::ImsCbw, FfKind::ImsCbwDelayed];

/// Names of [`FIRMWARE_FFS`].
pub const FFS: [&str; 3] = [
    FIRMWARE_FFS[0].name(),
    FIRMWARE_FFS[1].name(),
    FIRMWARE_FFS[2].name(),
];

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

/// The firmware's gains for the laws: the [`Params`] where the user sets them, fixed
/// choices for the rest (tuned on the stage of [`STAGE_POLE_PER_S`]).
pub fn tuning(p: &Params) -> Tuning<R> {
    let pole = c(STAGE_POLE_PER_S);
    Tuning {
        pole_per_s: pole,
        hgo_eps_s: p.hgo_eps_s,
        lambda1: p.lambda1,
        lambda2: p.lambda2,
        fts: FtsGains {
            lambda1: p.lambda1,
            lambda2: p.lambda2,
            alpha1: c(0.8),
            alpha2: c(0.8),
            sat_um_per_s: c(1e4),
        },
        pid: PidGains {
            kp: p.pid_kp,
            ki: p.pid_ki,
            kd: c(0.0),
            tf_s: c(1e-4),
            kb: c(1.0),
        },
        // Plain ADRC: the ESO estimates the whole linear part (a1 = a2 = 0).
        adrc: AdrcGains {
            b: c(0.16 * STAGE_POLE_PER_S * STAGE_POLE_PER_S),
            a1: c(0.0),
            a2: c(0.0),
            eps_s: c(2e-4),
            omega_c: c(2_000.0),
        },
        nmpc: NmpcGains {
            decimation: NMPC_DECIMATION,
            r: c(1e-3),
            iterations: 2,
            u_min: c(0.0),
            u_max: c(150.0),
            hgo_eps_s: p.hgo_eps_s,
        },
    }
}

/// Control periods per NMPC move: the solve runs once per this many periods (deferred on
/// the boards: [`super::solve_nmpc`]).
pub const NMPC_DECIMATION: u32 = 10;

/// The feedback laws of [`LAWS`], by name, with the model and gains of `p`, and the notch
/// of `p` ([`Params::notch`]) on the law's measurement.
pub fn law_with(name: &str, p: &Params, sample_hz: R) -> Option<Feedback<R>> {
    let notch = p.notch(sample_hz).ok()?;
    let mut fb = law_unfiltered(name, p, sample_hz)?;
    if notch.is_some() {
        fb.set_measurement_filter(notch);
    }
    if let Feedback::Nmpc(n) = &mut fb {
        n.set_deferred(NMPC_DEFERRED);
    }
    Some(fb)
}

/// [`law_with`] without the notch.
fn law_unfiltered(name: &str, p: &Params, sample_hz: R) -> Option<Feedback<R>> {
    let law = *FIRMWARE_LAWS.iter().find(|l| l.name() == name)?;
    let model = match law.family {
        Family::Cbw => ObserverModel::Cbw(p.model()?),
        Family::Gbw => ObserverModel::Gbw(p.gbw_model()?),
    };
    let model = Some(model);
    law.build(model, &tuning(p), c(1.0) / sample_hz).ok()
}

/// The feedforward compensators, by name, with the default [`Params`] (host tests).
pub fn ff_by_name(name: &str, sample_hz: R) -> Option<Feedforward<R>> {
    ff_with(name, &Params::default(), sample_hz)
}

/// The feedforward compensators, by name: linear scaling, or IMS around the CBW model of
/// `p` (0..150 V). The solved IMS takes one point per sample ([`Ims::with_one_point`]).
pub fn ff_with(name: &str, p: &Params, sample_hz: R) -> Option<Feedforward<R>> {
    let ims = |closure| {
        let model = p.model()?;
        let ims = Ims::new(model, closure, c(0.0), c(150.0), c(1.0) / sample_hz).ok()?;
        Some(Feedforward::ImsCbw(if closure == ImsLoop::Solved {
            ims.with_one_point()
        } else {
            ims
        }))
    };
    match *FIRMWARE_FFS.iter().find(|f| f.name() == name)? {
        FfKind::Linear => Some(Feedforward::Linear(p.linear())),
        FfKind::ImsCbw => ims(ImsLoop::Solved),
        FfKind::ImsCbwDelayed => ims(ImsLoop::Delayed),
        _ => None,
    }
}
