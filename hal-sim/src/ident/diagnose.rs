//! Model discovery (`piezo diagnose`): base CBW fit, candidate causes, residual signatures, iterative extension.
//!
//! 1. Fit the base model, the classical Bouc-Wen `y = d*u - h + y0` (000 eq. 1-2), one per
//!    output, each driven by its own input, on the training record.
//! 2. For every cause not yet in the model, fit the model extended by that cause (starting
//!    from the current fit, global stage on decimated data, then a local polish on all of
//!    it), and measure it on the validation record, which had a different excitation.
//! 3. Accept the cause with the largest validated gain if that gain is real: at least
//!    [`MIN_GAIN`] of the current validation RMSE, and the cause's signature (what the
//!    residual correlates with, [`evidence`]) explains at least [`MIN_R2`] of the residual.
//! 4. Repeat from 2 with the extended model until nothing passes: two causes present at
//!    once are both found, and clean data answers `none`.
//!
//! Errors are RMSE (004 eq. 23); all parameters are fitted on the training record only.

pub mod evidence;
pub mod model;
pub mod plots;
pub mod search;
mod signals;

use rayon::prelude::*;
use serde::Serialize;
use serde_json::{json, Value};

use crate::numeric::rmse_all;
pub use evidence::Evidence;
use model::{creep_taus, fit_linear, Coords};
pub use model::{Cause, Causes, OutputModel, Scales, Shape};
pub use signals::Signals;

/// Smallest relative gain on the validation record that counts as real.
pub const MIN_GAIN: f64 = 0.03;
/// Smallest fraction of the residual variance the cause's signature must explain.
pub const MIN_R2: f64 = 0.02;
/// Smallest RMSE reduction that counts, relative to the span of the measured output: a
/// gain below 0.002 % of the range (2 nm on 100 um, below a capacitive sensor's noise) is
/// numerical, whatever its relative size.
pub const MIN_ABS_GAIN: f64 = 2e-5;
/// At most this many causes are added.
pub const MAX_ROUNDS: usize = 4;

/// Search effort.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// At most this many samples in the global stage (decimated training record).
    pub coarse_samples: usize,
    /// The polish runs on the training record decimated to at most this many samples, but
    /// never below [`Options::medium_rate_hz`] (unless the record is slower).
    pub medium_samples: usize,
    pub medium_rate_hz: f64,
    /// Nelder-Mead evaluations in the global stage: `base + per_dim * dim`, per start.
    pub global_evals: (usize, usize),
    /// Nelder-Mead evaluations of the polish: `base + per_dim * dim`.
    pub local_evals: (usize, usize),
}

impl Default for Options {
    fn default() -> Self {
        Self {
            coarse_samples: 5_000,
            medium_samples: 25_000,
            medium_rate_hz: 2_000.0,
            global_evals: (30, 20),
            local_evals: (8, 4),
        }
    }
}

/// The training record at three resolutions: global search, polish, final least squares.
struct Tiers<'a> {
    full: &'a Signals,
    medium: Signals,
    coarse: Signals,
}

impl<'a> Tiers<'a> {
    fn new(full: &'a Signals, opt: &Options) -> Self {
        let n = full.len();
        let coarse = n.div_ceil(opt.coarse_samples.max(100)).max(1);
        let by_rate = (1.0 / (full.dt() * opt.medium_rate_hz)).floor().max(1.0) as usize;
        let medium = n.div_ceil(opt.medium_samples.max(100)).clamp(1, by_rate);
        Self {
            full,
            medium: full.decimate(medium),
            coarse: full.decimate(coarse),
        }
    }
}

/// A fitted model: one [`OutputModel`] per output, all with the same causes.
#[derive(Debug, Clone)]
pub struct Fitted {
    pub causes: Causes,
    pub outputs: Vec<OutputModel>,
    pub scales: Vec<Scales>,
    pub taus: Vec<f64>,
    pub rmse_train: f64,
}

impl Fitted {
    /// Model outputs on the scored samples of `data` (after its warm-up), one vector per
    /// output.
    pub fn predict(&self, data: &Signals) -> Vec<Vec<f64>> {
        (0..self.outputs.len())
            .into_par_iter()
            .map(|i| {
                let mut y = model::predict(
                    data,
                    i,
                    self.causes,
                    &self.outputs[i],
                    &self.scales[i],
                    &self.taus,
                );
                y.drain(..data.warmup.min(y.len()));
                y
            })
            .collect()
    }

    /// Parameters as JSON, per output.
    pub fn params(&self) -> Value {
        let per: Vec<Value> = self
            .outputs
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let s = &m.shape;
                let mut o = serde_json::Map::new();
                o.insert("output".into(), json!(format!("y{}", i + 1)));
                let mut put = |k: &str, v: f64| {
                    o.insert(k.into(), json!(v));
                };
                put("beta", s.beta);
                put("gamma", s.gamma);
                for (name, c) in m.names.iter().zip(&m.coef) {
                    put(name, *c);
                }
                let c = self.causes;
                if c.has(Cause::Delay) {
                    put("delay_s", s.delay_s);
                }
                if c.has(Cause::Saturation) {
                    put("rail_lo_v", s.rail_lo_v);
                    put("rail_hi_v", s.rail_hi_v);
                }
                if c.has(Cause::SlewLimit) {
                    put("slew_v_per_s", s.slew_v_per_s);
                }
                if c.has(Cause::Dynamics) {
                    put("wn_hz", s.wn_hz);
                    put("zeta", s.zeta);
                }
                if c.has(Cause::Creep) {
                    put("creep_taus_s", f64::NAN);
                    o.insert("creep_taus_s".into(), json!(self.taus));
                }
                Value::Object(o)
            })
            .collect();
        Value::Array(per)
    }
}

/// A fitted extension, its validation prediction and RMSE.
type Tried = (Fitted, Vec<Vec<f64>>, f64);

/// One tried extension.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    pub cause: Cause,
    pub round: usize,
    pub rmse_train: f64,
    pub rmse_valid: f64,
    /// `1 - rmse_valid / (current model's rmse_valid)`.
    pub gain: f64,
    pub evidence: Evidence,
    pub significant: bool,
}

/// One accepted cause.
#[derive(Debug, Clone, Serialize)]
pub struct Finding {
    pub cause: Cause,
    pub round: usize,
    pub rmse_valid_before: f64,
    pub rmse_valid: f64,
    pub gain: f64,
    pub evidence: Evidence,
}

/// Everything `diagnose` found.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    pub base: Fitted,
    pub base_valid: f64,
    pub extended: Fitted,
    pub extended_valid: f64,
    pub findings: Vec<Finding>,
    pub candidates: Vec<Candidate>,
    pub noise_rms: f64,
    /// Causes found, then dropped by the backward check (a later cause made them redundant).
    pub dropped: Vec<Cause>,
}

impl Diagnosis {
    pub fn cause(&self) -> &'static str {
        self.findings.first().map_or("none", |f| f.cause.name())
    }

    pub fn gain(&self) -> f64 {
        1.0 - self.extended_valid / self.base_valid
    }

    /// The JSON report (stable contract: `base`, `causes`, `cause`, `extended`, `gain`,
    /// `candidates`; the rest is extra detail).
    pub fn json(&self) -> Value {
        let model = |f: &Fitted, valid: f64| {
            json!({
                "model": f.causes.label(),
                "rmse_train": f.rmse_train,
                "rmse_valid": valid,
                "params": f.params(),
            })
        };
        json!({
            "base": model(&self.base, self.base_valid),
            "causes": self.findings.iter().map(|f| f.cause.name()).collect::<Vec<_>>(),
            "cause": self.cause(),
            "extended": model(&self.extended, self.extended_valid),
            "gain": self.gain(),
            "candidates": self.candidates.iter().map(|c| json!({
                "cause": c.cause.name(),
                "round": c.round,
                "rmse_valid": c.rmse_valid,
                "rmse_train": c.rmse_train,
                "gain": c.gain,
                "evidence_r2": c.evidence.r2,
                "significant": c.significant,
            })).collect::<Vec<_>>(),
            "findings": self.findings,
            "noise_rms": self.noise_rms,
            "dropped": self.dropped.iter().map(|c| c.name()).collect::<Vec<_>>(),
            "rule": {"min_gain": MIN_GAIN, "min_abs_gain_of_span": MIN_ABS_GAIN, "min_evidence_r2": MIN_R2},
        })
    }
}

/// CBW shapes every fit also starts from: `ln((beta + gamma) * span)`, `ln((beta - gamma) /
/// (beta + gamma))`.
const SHAPE_GRID: [(f64, f64); 6] = [
    (0.5, -1.0),
    (0.5, 0.0),
    (2.0, -1.0),
    (2.0, 0.0),
    (3.5, -1.0),
    (3.5, 0.0),
];

/// Starting shapes for adding `cause` to a model whose output has `shape`.
fn starts(cause: Option<Cause>, shape: &Shape, scales: &Scales) -> Vec<Shape> {
    let mut v = Vec::new();
    let span = scales.span();
    match cause {
        None | Some(Cause::Asymmetry | Cause::Creep | Cause::CrossCoupling | Cause::Drift) => {
            v.push(*shape)
        }
        Some(Cause::Delay) => {
            for ms in [0.3, 1.0, 3.0, 10.0, 30.0] {
                v.push(Shape {
                    delay_s: ms * 1e-3,
                    ..*shape
                });
            }
        }
        Some(Cause::Saturation) => {
            for (lo, hi) in [
                (0.0, 0.02),
                (0.0, 0.07),
                (0.0, 0.2),
                (0.02, 0.0),
                (0.07, 0.0),
                (0.2, 0.0),
                (0.03, 0.03),
                (0.1, 0.1),
            ] {
                v.push(Shape {
                    rail_lo_v: scales.u_lo + lo * span,
                    rail_hi_v: scales.u_hi - hi * span,
                    ..*shape
                });
            }
        }
        Some(Cause::SlewLimit) => {
            for f in [0.8, 0.5, 0.25, 0.1, 0.03] {
                v.push(Shape {
                    slew_v_per_s: f * scales.rate_max,
                    ..*shape
                });
            }
        }
        Some(Cause::Dynamics) => {
            for hz in [3.0, 10.0, 30.0, 100.0, 300.0, 1000.0] {
                if hz < 0.4 / scales.dt {
                    for zeta in [0.15, 0.7] {
                        v.push(Shape {
                            wn_hz: hz,
                            zeta,
                            ..*shape
                        });
                    }
                }
            }
        }
    }
    v
}

/// Fits output `i` with `causes`, from the best of `starts`.
#[allow(clippy::too_many_arguments)]
fn fit_output(
    tiers: &Tiers,
    i: usize,
    causes: Causes,
    starts: &[Shape],
    scales: &Scales,
    taus: &[f64],
    opt: &Options,
) -> (OutputModel, f64) {
    let coords = Coords {
        causes,
        scales: *scales,
    };
    let dim = coords.dim();
    let cost_on = |data: &Signals, x: &[f64]| {
        let (shape, excess) = coords.shape_and_excess(x);
        fit_linear(data, i, causes, &shape, scales, taus).1 * (1.0 + excess)
    };
    let (coarse, medium) = (&tiers.coarse, &tiers.medium);
    // Rank the starts, keep two (one when only the CBW shape is searched).
    let mut ranked: Vec<(Vec<f64>, f64)> = starts
        .iter()
        .map(|s| {
            let x = coords.coords(s);
            let c = cost_on(coarse, &x);
            (x, c)
        })
        .collect();
    ranked.sort_by(|a, b| a.1.total_cmp(&b.1));
    // The best extension setting again with fresh CBW shapes: the current shape may sit in
    // a corner the missing cause pushed it into.
    if let Some((x, _)) = ranked.first().cloned() {
        for (a, r) in SHAPE_GRID {
            let mut x = x.clone();
            x[0] = a;
            x[1] = r;
            let c = cost_on(coarse, &x);
            ranked.push((x, c));
        }
        ranked.sort_by(|a, b| a.1.total_cmp(&b.1));
    }
    ranked.truncate(if dim > 2 { 2 } else { 1 });
    let steps = coords.steps();
    // Only the CBW shape to search (the extension is linear): a short search suffices.
    let global = if dim > 2 {
        opt.global_evals.0 + opt.global_evals.1 * dim
    } else {
        opt.global_evals.0
    };
    // The starts run in parallel (the other core is idle while the control fits).
    let best = ranked
        .par_iter()
        .map(|(x0, _)| {
            let (x, _) = search::nelder_mead(&mut |x| cost_on(coarse, x), x0, &steps, global, 1e-7);
            // A restart with fresh steps: a collapsed simplex is the usual Nelder-Mead failure.
            search::nelder_mead(&mut |x| cost_on(coarse, x), &x, &steps, global / 3, 1e-7)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1));
    let x = best.map_or_else(|| coords.coords(&starts[0]), |b| b.0);
    let fine_steps: Vec<f64> = steps.iter().map(|s| 0.1 * s).collect();
    let local = opt.local_evals.0 + opt.local_evals.1 * dim;
    let (x, _) = search::nelder_mead(&mut |x| cost_on(medium, x), &x, &fine_steps, local, 1e-9);
    fit_linear(tiers.full, i, causes, &coords.shape(&x), scales, taus)
}

/// The base fit: a grid over the CBW shape, then the same search as the extensions.
fn fit_base(tiers: &Tiers, opt: &Options) -> Fitted {
    let full = tiers.full;
    let taus = creep_taus(full.dt() * full.len() as f64, full.dt());
    let n_out = full.y.len();
    let scales: Vec<Scales> = (0..n_out)
        .map(|i| Scales::of(&full.t, &full.u[model::own_input(i, full.u.len())]))
        .collect();
    let outputs: Vec<(OutputModel, f64)> = (0..n_out)
        .into_par_iter()
        .map(|i| {
            let coords = Coords {
                causes: Causes::default(),
                scales: scales[i],
            };
            let mut grid = Vec::new();
            for a in [0.0, 1.0, 2.0, 3.5, 5.0] {
                for r in [-3.0, -1.0, 0.0, 1.0] {
                    grid.push(coords.shape(&[a, r]));
                }
            }
            fit_output(tiers, i, Causes::default(), &grid, &scales[i], &taus, opt)
        })
        .collect();
    assemble(Causes::default(), outputs, scales, taus, full)
}

fn assemble(
    causes: Causes,
    outputs: Vec<(OutputModel, f64)>,
    scales: Vec<Scales>,
    taus: Vec<f64>,
    full: &Signals,
) -> Fitted {
    let n: f64 = full.len() as f64 * outputs.len() as f64;
    let mse: f64 = outputs
        .iter()
        .map(|(_, e)| e * e * full.len() as f64)
        .sum::<f64>()
        / n.max(1.0);
    Fitted {
        causes,
        outputs: outputs.into_iter().map(|(m, _)| m).collect(),
        scales,
        taus,
        rmse_train: mse.sqrt(),
    }
}

/// Extends `current` by `cause` and refits every output from its current shape.
fn extend(current: &Fitted, cause: Option<Cause>, tiers: &Tiers, opt: &Options) -> Fitted {
    let causes = cause.map_or(current.causes, |c| current.causes.with(c));
    let mut scales = current.scales.clone();
    if cause == Some(Cause::Creep) {
        // Creep of the current model's static displacement `d*v - alpha*g`.
        for (s, m) in scales.iter_mut().zip(&current.outputs) {
            let coef = |n: &str| m.names.iter().position(|x| x == n).map(|k| m.coef[k]);
            if let (Some(d), Some(a)) = (coef("d"), coef("alpha")) {
                let rho = a / d;
                s.creep_rho = if rho.is_finite() {
                    rho.clamp(-2.0, 2.0)
                } else {
                    0.0
                };
            }
        }
    }
    let outputs: Vec<(OutputModel, f64)> = (0..current.outputs.len())
        .into_par_iter()
        .map(|i| {
            let st = starts(cause, &current.outputs[i].shape, &scales[i]);
            fit_output(tiers, i, causes, &st, &scales[i], &current.taus, opt)
        })
        .collect();
    assemble(causes, outputs, scales, current.taus.clone(), tiers.full)
}

/// `current` refitted without `cause`, from its current shapes.
fn reduce(current: &Fitted, cause: Cause, tiers: &Tiers, opt: &Options) -> Fitted {
    let causes = current.causes.without(cause);
    let outputs: Vec<(OutputModel, f64)> = (0..current.outputs.len())
        .into_par_iter()
        .map(|i| {
            let st = [neutral(current.outputs[i].shape, cause)];
            fit_output(
                tiers,
                i,
                causes,
                &st,
                &current.scales[i],
                &current.taus,
                opt,
            )
        })
        .collect();
    assemble(
        causes,
        outputs,
        current.scales.clone(),
        current.taus.clone(),
        tiers.full,
    )
}

/// `shape` without the input-side or dynamic extension of `cause`.
fn neutral(mut shape: Shape, cause: Cause) -> Shape {
    match cause {
        Cause::Delay => shape.delay_s = 0.0,
        Cause::Saturation => {
            shape.rail_lo_v = f64::NEG_INFINITY;
            shape.rail_hi_v = f64::INFINITY;
        }
        Cause::SlewLimit => shape.slew_v_per_s = f64::INFINITY,
        Cause::Dynamics => {
            shape.wn_hz = f64::INFINITY;
            shape.zeta = 1.0;
        }
        Cause::Asymmetry | Cause::Creep | Cause::CrossCoupling | Cause::Drift => {}
    }
    shape
}

/// Coefficient-name prefix of the linear terms of `cause` (none for input-side causes).
fn coef_prefix(cause: Cause) -> Option<&'static str> {
    match cause {
        Cause::Asymmetry => Some("asym_"),
        Cause::Creep => Some("creep_"),
        Cause::CrossCoupling => Some("couple_"),
        Cause::Drift => Some("drift_"),
        _ => None,
    }
}

/// `f` with `cause` switched off and nothing refitted: its prediction shows what the cause's
/// extension contributes.
fn switched_off(f: &Fitted, cause: Cause) -> Fitted {
    let mut g = f.clone();
    for m in g.outputs.iter_mut() {
        m.shape = neutral(m.shape, cause);
        if let Some(p) = coef_prefix(cause) {
            for (name, c) in m.names.iter().zip(m.coef.iter_mut()) {
                if name.starts_with(p) {
                    *c = 0.0;
                }
            }
        }
    }
    g
}

/// `f` (fitted with `causes` plus `cause`) with `cause` switched off and the linear part
/// refitted on the training record.
fn ablate(f: &Fitted, causes: Causes, cause: Cause, tiers: &Tiers) -> Fitted {
    let outputs: Vec<(OutputModel, f64)> = (0..f.outputs.len())
        .map(|i| {
            let shape = neutral(f.outputs[i].shape, cause);
            fit_linear(tiers.full, i, causes, &shape, &f.scales[i], &f.taus)
        })
        .collect();
    assemble(
        causes,
        outputs,
        f.scales.clone(),
        f.taus.clone(),
        tiers.full,
    )
}

/// Evidence for `cause` in the residual of `y_model` on `valid`; the output with the
/// strongest signature speaks.
fn evidence_for(valid: &Signals, cause: Cause, y_model: &[Vec<f64>], fitted: &Fitted) -> Evidence {
    (0..valid.y.len())
        .map(|i| {
            let r: Vec<f64> = valid.y[i]
                .iter()
                .zip(&y_model[i])
                .map(|(a, b)| a - b)
                .collect();
            evidence::evidence(valid, i, cause, &r, &y_model[i], &fitted.outputs[i].shape)
        })
        .max_by(|a, b| a.r2.total_cmp(&b.r2))
        .unwrap_or(Evidence {
            signal: String::new(),
            r2: 0.0,
            text: String::new(),
        })
}

/// Causes that apply to records with these channels.
fn applicable(train: &Signals) -> Vec<Cause> {
    Cause::ALL
        .into_iter()
        .filter(|c| *c != Cause::CrossCoupling || train.u.len() > 1)
        .collect()
}

/// Checks that train and valid describe the same system.
fn check_pair(train: &Signals, valid: &Signals) -> anyhow::Result<()> {
    anyhow::ensure!(
        train.u.len() == valid.u.len() && train.y.len() == valid.y.len(),
        "train has {} inputs/{} outputs but valid has {}/{}",
        train.u.len(),
        train.y.len(),
        valid.u.len(),
        valid.y.len()
    );
    for (k, u) in train.u.iter().enumerate() {
        let (lo, hi) = model::min_max(u);
        anyhow::ensure!(
            hi > lo,
            "train input u{} is constant: nothing to identify",
            k + 1
        );
    }
    Ok(())
}

/// Runs the discovery on a training and a validation record.
///
/// `valid` may start with warm-up samples (see [`Signals::warmup`]); only the rest is scored.
pub fn diagnose(train: &Signals, valid: &Signals, opt: &Options) -> anyhow::Result<Diagnosis> {
    check_pair(train, valid)?;
    let scored = valid.scored();
    let tiers = Tiers::new(train, opt);
    let mut base = fit_base(&tiers, opt);
    let base_pred = base.predict(valid);
    let mut base_valid = rmse_all(&scored.y, &base_pred);
    anyhow::ensure!(
        base_valid.is_finite(),
        "base model diverged on the validation record"
    );
    let noise_rms = {
        let s: f64 = scored
            .y
            .iter()
            .map(|y| evidence::noise_rms(y).powi(2))
            .sum();
        (s / scored.y.len() as f64).sqrt()
    };
    let y_span = scored
        .y
        .iter()
        .map(|y| {
            let (lo, hi) = model::min_max(y);
            hi - lo
        })
        .fold(0.0, f64::max);
    let mut current = base.clone();
    let mut current_valid = base_valid;
    let mut findings = Vec::new();
    let mut candidates = Vec::new();
    for round in 1..=MAX_ROUNDS {
        let todo: Vec<Cause> = applicable(train)
            .into_iter()
            .filter(|c| !current.causes.has(*c))
            .collect();
        if todo.is_empty() {
            break;
        }
        // The current causes refitted by the same search are the control: a cause must gain
        // more than what a longer search alone gives.
        let runs: Vec<Option<Cause>> = std::iter::once(None)
            .chain(todo.iter().copied().map(Some))
            .collect();
        let mut tried: Vec<(Fitted, Vec<Vec<f64>>, f64)> = runs
            .par_iter()
            .map(|&c| {
                let f = extend(&current, c, &tiers, opt);
                let pred = f.predict(valid);
                let e = rmse_all(&scored.y, &pred);
                (f, pred, e)
            })
            .collect();
        let control = tried.remove(0);
        // Each candidate without its cause (its refitted CBW shape, the cause's extension
        // switched off, linear part refitted on train): a better fit of the current model that
        // the candidate's search found. Gains are then measured against the best of these, so
        // a cause never takes credit for a better converged hysteresis.
        let ablated: Vec<Fitted> = tried
            .par_iter()
            .zip(&todo)
            .map(|((f, _, _), &c)| ablate(f, current.causes, c, &tiers))
            .collect();
        let best_same = std::iter::once(control.0.clone())
            .chain(ablated)
            .min_by(|a, b| a.rmse_train.total_cmp(&b.rmse_train))
            .expect("control is always there");
        let control = if best_same.rmse_train < control.0.rmse_train {
            let pred = best_same.predict(valid);
            let e = rmse_all(&scored.y, &pred);
            (best_same, pred, e)
        } else {
            control
        };
        if control.0.rmse_train < current.rmse_train && control.2.is_finite() {
            (current, _, current_valid) = control;
            if findings.is_empty() {
                // Still the base model, only better converged.
                base = current.clone();
                base_valid = current_valid;
            }
        }
        // Every candidate is fitted: its evidence is measured in its own frame (below), and
        // a cause can show in the training record only.
        let (tried, mut evidence): (Vec<Tried>, Vec<Evidence>) = tried
            .into_iter()
            .zip(&todo)
            .map(|((f, p, e), &c)| {
                // The residual the candidate's own extension removes: the candidate with
                // its cause switched off (everything else as fitted). On both records: a
                // cause can distort the training fit (and so the validation) while showing
                // little in the validation record itself.
                let off = switched_off(&f, c);
                let ev_valid = evidence_for(&scored, c, &off.predict(valid), &f);
                let mut ev_train = evidence_for(train, c, &off.predict(train), &f);
                let ev = if ev_train.r2 > ev_valid.r2 {
                    ev_train.text.push_str(" (training record)");
                    ev_train
                } else {
                    ev_valid
                };
                ((f, p, e), ev)
            })
            .unzip();
        let mut best: Option<usize> = None;
        for (k, (t, ev)) in tried.iter().zip(&evidence).enumerate() {
            let (rmse_train, e) = (t.0.rmse_train, t.2);
            let gain = 1.0 - e / current_valid;
            let significant = gain.is_finite()
                && gain >= MIN_GAIN
                && current_valid - e >= MIN_ABS_GAIN * y_span
                && ev.r2 >= MIN_R2;
            candidates.push(Candidate {
                cause: todo[k],
                round,
                rmse_train,
                rmse_valid: e,
                gain,
                evidence: ev.clone(),
                significant,
            });
            if significant && best.is_none_or(|b: usize| e < tried[b].2) {
                best = Some(k);
            }
        }
        let Some(b) = best else { break };
        let Some((f, _, e)) = tried.into_iter().nth(b) else {
            break;
        };
        let ev = evidence.swap_remove(b);
        findings.push(Finding {
            cause: todo[b],
            round,
            rmse_valid_before: current_valid,
            rmse_valid: e,
            gain: 1.0 - e / current_valid,
            evidence: ev,
        });
        current = f;
        current_valid = e;
    }
    // Backward check: a cause found early can be made redundant by a later one (dynamics
    // standing in for a delay before the asymmetry was modelled). Refit without each found
    // cause; drop the cheapest to lose while losing it costs less than the rule for a gain.
    let mut dropped = Vec::new();
    while findings.len() > 1 {
        let tried: Vec<(usize, Fitted, f64)> = findings
            .par_iter()
            .enumerate()
            .map(|(k, fd)| {
                let f = reduce(&current, fd.cause, &tiers, opt);
                let e = rmse_all(&scored.y, &f.predict(valid));
                (k, f, e)
            })
            .collect();
        let Some((k, f, e)) = tried.into_iter().min_by(|a, b| a.2.total_cmp(&b.2)) else {
            break;
        };
        let gain = 1.0 - current_valid / e;
        if !e.is_finite() || (gain >= MIN_GAIN && e - current_valid >= MIN_ABS_GAIN * y_span) {
            break;
        }
        dropped.push(findings.remove(k).cause);
        current = f;
        current_valid = e;
    }
    Ok(Diagnosis {
        dropped,
        base,
        base_valid,
        extended: current,
        extended_valid: current_valid,
        findings,
        candidates,
        noise_rms,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use piezo_core::hysteresis::{Cbw, Hysteresis};

    fn record(seed: u64, n: usize, dt: f64, lag: bool) -> Signals {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let f = 1.0 + seed as f64 * 0.3;
        let u: Vec<f64> = t
            .iter()
            .map(|t| {
                50.0 + 40.0 * (2.0 * std::f64::consts::PI * f * t).sin()
                    + 10.0 * (2.0 * std::f64::consts::PI * 3.7 * f * t).sin()
            })
            .collect();
        let m = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
        let mut s = m.init(u[0]);
        let mut y: Vec<f64> = u.iter().map(|&u| m.step(&mut s, u, dt)).collect();
        if lag {
            model::dynamics(&mut y, 15.0, 0.6, dt);
        }
        Signals::new(t, vec![u], vec![y]).unwrap()
    }

    #[test]
    fn clean_cbw_is_none_and_lag_is_dynamics() {
        let opt = Options::default();
        let d = diagnose(
            &record(1, 4000, 1e-3, false),
            &record(2, 4000, 1e-3, false),
            &opt,
        )
        .unwrap();
        assert!(d.base_valid < 1e-3, "{}", d.base_valid);
        assert_eq!(d.cause(), "none", "{:#}", d.json());
        let d = diagnose(
            &record(1, 4000, 1e-3, true),
            &record(2, 4000, 1e-3, true),
            &opt,
        )
        .unwrap();
        assert_eq!(d.cause(), "dynamics", "{:#}", d.json());
        assert!(d.gain() > 0.5);
    }

    #[test]
    fn rejects_bad_pairs() {
        let a = record(1, 100, 1e-3, false);
        let mut b = a.clone();
        b.y.push(b.y[0].clone());
        b.u.push(b.u[0].clone());
        assert!(diagnose(&a, &b, &Options::default()).is_err());
        assert!(Signals::new(vec![0.0; 10], vec![vec![0.0; 10]], vec![vec![0.0; 10]]).is_err());
    }
}
