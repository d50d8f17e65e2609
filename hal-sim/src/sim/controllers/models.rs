//! The prediction models of the model-based feedback laws (HGO robust law, finite-time law,
//! NMPC): each law predicts with one hysteresis family, CBW (000 eq. 1; the plain names
//! `hgo-robust`, `fts`, `nmpc`) or GBW (000 eq. 3 with its CBW term; `fts-gbw`, `nmpc-gbw`,
//! `hgo-robust-gbw`).
//!
//! * GBW: identified from the stage's own open-loop record, as a user would
//!   ([`super::identified`]: `piezo fit --model gbw` on the record `piezo sim --controller
//!   open-loop --out DIR` writes), on every stage; `A, B_h, B, G` then times
//!   `1 + model_error`.
//! * CBW: the stage's own parameters when the stage runs CBW (`alpha, beta, gamma` times
//!   `1 + model_error`, `d` exact); on a stage of another family the least-squares CBW
//!   (`piezo fit --model cbw`, the same differential evolution + Levenberg-Marquardt) of the
//!   stage's hysteresis alone (`y = d*u - h`) over a quasi-static full-range sweep, then
//!   scaled by `1 + model_error`.

use crate::ident::fit::{fit_siso, models as fit_models, FitOptions};
use crate::scenario::{HysteresisCfg, HysteresisModel};
use crate::sim::StageInfo;
use anyhow::{anyhow, Context, Result};
use piezo_core::feedback::ObserverModel;
use piezo_core::hysteresis::{AbwAbs, Cbw, Dahl, Gbw, Hysteresis, Mbw002, ParamError};
use std::sync::Mutex;

use super::R;

/// Hysteresis family of a law's prediction model (the registry's).
pub use piezo_core::registry::Family;

fn perr(p: ParamError) -> anyhow::Error {
    anyhow!("{p}")
}

/// CBW parameters `(d, alpha, beta, gamma, n)`.
type CbwParams = (f64, f64, f64, f64, f64);

/// The law's prediction model for the stage `s`.
pub fn prediction(s: &StageInfo, family: Family) -> Result<ObserverModel<R>> {
    let h = s.hysteresis();
    let k = 1.0 + h.model_error;
    match (family, h.model) {
        (Family::Gbw, _) => {
            let m = identified_gbw(s)?;
            Ok(ObserverModel::Gbw(
                Gbw::with_beta_h(
                    m.d() as R,
                    1.0,
                    (m.a() * k) as R,
                    (m.beta_h() * k) as R,
                    (m.b() * k) as R,
                    (m.g() * k) as R,
                    1.0,
                )
                .map_err(perr)?,
            ))
        }
        (Family::Cbw, _) => {
            let (d, al, be, ga, n) = cbw_of(s)?;
            let (al, be, ga) = (al * k, be * k, ga * k);
            Ok(ObserverModel::Cbw(
                Cbw::new(d as R, al as R, be as R, ga as R, n as R).map_err(perr)?,
            ))
        }
    }
}

/// The GBW (`alpha = n = 1`) that `piezo fit --model gbw` identifies from the stage's
/// open-loop record (before `model_error`).
pub fn identified_gbw(s: &StageInfo) -> Result<Gbw<f64>> {
    let f = super::identified::identified(s, "gbw")?;
    anyhow::ensure!(
        f.sign > 0.0,
        "the GBW fit of {} has the wrong orientation (sign {})",
        s.scenario.name,
        f.sign
    );
    fit_models::gbw(&f.values()).map_err(perr)
}

/// The stage's CBW (before `model_error`): its own, or the least-squares fit.
fn cbw_of(s: &StageInfo) -> Result<CbwParams> {
    let h = s.hysteresis();
    Ok(match h.model {
        HysteresisModel::Cbw => (h.d, h.alpha, h.beta, h.gamma, h.n),
        // No hysteresis: a CBW with a negligible loop.
        HysteresisModel::None => (h.d, 1e-6, 1e-3, 0.0, 1.0),
        HysteresisModel::Gbw | HysteresisModel::Dahl | HysteresisModel::Mbw002 => {
            let (lo, hi) = s.volts_range();
            fitted_cbw(h, lo, hi)
                .with_context(|| format!("fitting a CBW to the {:?} stage", h.model))?
        }
    })
}

/// Fits already made in this process: (stage hysteresis and range, CBW).
static FITS: Mutex<Vec<(String, CbwParams)>> = Mutex::new(Vec::new());

/// The least-squares CBW (n = 1) of the hysteresis `h` over a sweep of `lo..hi` V.
pub fn fitted_cbw(h: &HysteresisCfg, lo: f64, hi: f64) -> Result<CbwParams> {
    let mut base = h.clone();
    base.model_error = 0.0;
    let key = format!("{base:?} {lo} {hi}");
    if let Some((_, p)) = lock_fits().iter().find(|(k, _)| *k == key) {
        return Ok(*p);
    }
    let (u, y) = quasi_static_loop(&base, lo, hi)?;
    let opts = FitOptions {
        generations: 150,
        ..FitOptions::default()
    };
    let f = fit_siso(fit_models::find("cbw")?, &u, &y, 1e-3, &opts)?;
    let p = f.values();
    anyhow::ensure!(
        f.sign > 0.0 && p.len() == 4,
        "the sweep does not look like a piezo loop"
    );
    let cbw = (p[0], p[1], p[2], p[3] * p[2], 1.0);
    lock_fits().push((key, cbw));
    Ok(cbw)
}

fn lock_fits() -> std::sync::MutexGuard<'static, Vec<(String, CbwParams)>> {
    // A panic elsewhere cannot leave the list half written (one push): use it anyway.
    FITS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Three raised-cosine sweeps `lo..hi` (1000 samples of 1 ms each) of the stage's
/// hysteresis model alone from rest at `lo` (where a fitted model starts too): input and
/// `y = d*u - h` (plus the rate terms of the 002 MBW).
pub fn quasi_static_loop(h: &HysteresisCfg, lo: f64, hi: f64) -> Result<(Vec<f64>, Vec<f64>)> {
    let n = 1000;
    let u: Vec<f64> = (0..3 * n)
        .map(|k| {
            let ph = std::f64::consts::TAU * k as f64 / n as f64;
            lo + (hi - lo) * 0.5 * (1.0 - ph.cos())
        })
        .collect();
    fn run<M: Hysteresis<f64>>(m: M, u: &[f64]) -> Vec<f64> {
        let mut s = m.init(u[0]);
        u.iter().map(|&v| m.step(&mut s, v, 1e-3)).collect()
    }
    let y = match h.model {
        HysteresisModel::Cbw => run(Cbw::new(h.d, h.alpha, h.beta, h.gamma, h.n)?, &u),
        HysteresisModel::Gbw => run(
            Gbw::with_beta_h(h.d, h.alpha, h.a, h.beta_h, h.beta, h.gamma, h.n)?,
            &u,
        ),
        HysteresisModel::Dahl => run(Dahl::new(h.d, h.alpha, h.hc, h.n)?, &u),
        HysteresisModel::Mbw002 => run(
            Mbw002::new(
                AbwAbs::new(h.d, h.alpha, h.beta, h.gamma, h.n, h.delta)?,
                h.p,
                h.q,
            )?,
            &u,
        ),
        HysteresisModel::None => u.iter().map(|v| h.d * v).collect(),
    };
    Ok((u, y))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CBW stage's own CBW comes back from the fit (the fit is not needed there, but it
    /// is what the other families get, so it must find a CBW when there is one).
    #[test]
    fn fit_recovers_a_cbw_stage() {
        let h = HysteresisCfg::default();
        let (d, al, be, ga, _) = fitted_cbw(&h, 0.0, 150.0).unwrap();
        for (got, want) in [(d, h.d), (al, h.alpha), (be, h.beta), (ga, h.gamma)] {
            assert!((got - want).abs() < 1e-3 * want.abs(), "{got} vs {want}");
        }
    }
}
