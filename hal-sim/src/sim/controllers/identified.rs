//! Models identified from the stage's own record, the way a user identifies them: run the
//! scenario open loop (`piezo sim --controller open-loop --out DIR` writes this record as
//! `DIR/<scenario>_open-loop_record.csv`, axis 0), then `piezo fit --model NAME --train`
//! that file with the default options. [`identified`] does both in process (same record,
//! same fit) and keeps the result for the rest of the process.

use crate::ident::fit::{fit_siso, models as fit_models, FitOptions, Fitted};
use crate::sim::{run_calibrated, StageInfo};
use anyhow::{Context, Result};
use std::sync::Mutex;

use super::Entry;

/// Fits made in this process: (scenario, model name) and the fit.
static FITS: Mutex<Vec<(String, Fitted)>> = Mutex::new(Vec::new());

/// The open-loop run of the scenario as a `piezo fit` record (axis 0: applied piezo volts
/// in, measured position out), as `piezo sim --out` writes it.
pub fn open_loop_record(s: &StageInfo) -> Result<crate::record::Record> {
    let entry = Entry {
        name: "open-loop",
        about: "",
        one_axis: super::open_loop::<1>,
        two_axis: Some(super::open_loop::<2>),
    };
    let (_, rec) = run_calibrated(s.scenario, &entry, &s.linear, true)?;
    let rec = rec.context("the open-loop run kept no record")?;
    rec.fit_record(Some(0))
}

/// `piezo fit --model name` (default options) on [`open_loop_record`].
pub fn identified(s: &StageInfo, name: &str) -> Result<Fitted> {
    let key = format!("{:?} {name}", s.scenario);
    if let Some((_, f)) = lock().iter().find(|(k, _)| *k == key) {
        return Ok(f.clone());
    }
    let rec = open_loop_record(s)?;
    let f = fit_siso(
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
    })?;
    lock().push((key, f.clone()));
    Ok(f)
}

fn lock() -> std::sync::MutexGuard<'static, Vec<(String, Fitted)>> {
    // One push per fit: a panic elsewhere cannot leave the list half written.
    FITS.lock().unwrap_or_else(|e| e.into_inner())
}
