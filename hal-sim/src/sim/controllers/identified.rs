//! Models identified from the stage's own record, the way a user identifies them: run the
//! scenario open loop (`piezo sim --controller open-loop --out DIR` writes this record as
//! `DIR/<scenario>_open-loop_record.csv`, axis 0), then `piezo fit --model NAME --train`
//! that file with the default options. [`identified`] does both in process (same record,
//! same fit) and keeps the result for the rest of the process. [`identified_multibw`] is
//! `piezo fit --model cbw` on the record of every axis (003's multivariable Bouc-Wen).

use crate::ident::fit::{fit_siso, models as fit_models, FitOptions, Fitted};
use crate::ident::multibw::{self, MultiBwFit};
use crate::sim::{run_calibrated, StageInfo};
use anyhow::{Context, Result};
use std::sync::Mutex;

use super::Entry;

/// Fits made in this process: (scenario, model name) and the fit.
static FITS: Mutex<Vec<(String, Fitted)>> = Mutex::new(Vec::new());

/// Fits of 003's multivariable Bouc-Wen made in this process: (scenario, fit).
static MULTI_FITS: Mutex<Vec<(String, MultiBwFit)>> = Mutex::new(Vec::new());

/// The open-loop run of the scenario as a `piezo fit` record (axis 0: applied piezo volts
/// in, measured position out), as `piezo sim --out` writes it.
pub fn open_loop_record(s: &StageInfo) -> Result<crate::record::Record> {
    open_loop_axes(s, Some(0))
}

/// [`open_loop_record`] with every axis (`None`) or one.
fn open_loop_axes(s: &StageInfo, axis: Option<usize>) -> Result<crate::record::Record> {
    let entry = Entry {
        name: "open-loop",
        about: "",
        one_axis: super::open_loop::<1>,
        two_axis: Some(super::open_loop::<2>),
    };
    let (_, rec) = run_calibrated(s.scenario, &entry, &s.linear, true)?;
    let rec = rec.context("the open-loop run kept no record")?;
    rec.fit_record(axis)
}

/// `piezo fit --model cbw` (default options) on the open-loop record of every axis of a
/// multi-axis scenario: 003's multivariable Bouc-Wen, its two steps and the joint refinement
/// ([`multibw::identify`]).
pub fn identified_multibw(s: &StageInfo) -> Result<MultiBwFit> {
    cached(&MULTI_FITS, format!("{:?}", s.scenario), || {
        let rec = open_loop_axes(s, None)?;
        multibw::identify(&rec, &FitOptions::default()).with_context(|| {
            format!(
                "identifying the multivariable Bouc-Wen on the open-loop record of {}",
                s.scenario.name
            )
        })
    })
}

/// `piezo fit --model name` (default options) on [`open_loop_record`].
pub fn identified(s: &StageInfo, name: &str) -> Result<Fitted> {
    cached(&FITS, format!("{:?} {name}", s.scenario), || {
        let rec = open_loop_record(s)?;
        fit_siso(
            fit_models::find(name)?,
            &rec.u[0],
            &rec.y[0],
            rec.dt(),
            &FitOptions::default(),
        )
        .with_context(|| {
            format!(
                "identifying {name} on the open-loop record of {}",
                s.scenario.name
            )
        })
    })
}

/// The fit kept under `key`, or `fit()` kept there.
fn cached<T: Clone>(
    cache: &Mutex<Vec<(String, T)>>,
    key: String,
    fit: impl FnOnce() -> Result<T>,
) -> Result<T> {
    // One push per fit: a panic elsewhere cannot leave the list half written.
    let lock = || cache.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, f)) = lock().iter().find(|(k, _)| *k == key) {
        return Ok(f.clone());
    }
    let f = fit()?;
    lock().push((key, f.clone()));
    Ok(f)
}
