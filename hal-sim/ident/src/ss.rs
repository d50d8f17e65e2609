//! Multivariable linear identification and Hammerstein models of real stages
//! (`piezo fit --model ss | hammerstein-ss`): nonparametric BLA ([`frf`]), frequency-domain
//! subspace ([`subspace`]), output-error refinement ([`pem`]) of a modal state-space
//! model ([`model`]), hysteresis fronts per actuator ([`hammerstein`]).

pub mod extended;
pub mod fitting;
pub mod frf;
pub mod hammerstein;
pub mod lfr;
pub mod model;
pub mod pem;
pub mod saved;
pub mod scheduled;
pub mod score;
pub mod subspace;

use crate::fit::models::ModelDef;
use crate::record::Record;
use frf::{FrfData, PeriodicSpectra};
use hammerstein::{Hammerstein, Periodic};
use model::Modal;
use pem::{LineStats, PemConfig};

/// Largest ratio of [`Modal::modal_gain_bound`] to the measured response's peak accepted
/// from the automatic order choice: a real stage's modes add up to a few times its peak
/// (2-66 for the well-conditioned candidates on hal-sim's hysteretic stage, whose
/// cancelling ones began at 1.8e4).
pub const MAX_CANCELLATION: f64 = 1e3;

/// Largest Frobenius norm of the measured response over its lines.
fn peak_gain(d: &frf::FrfData) -> f64 {
    d.g.iter().map(|g| g.norm()).fold(0.0, f64::max)
}

/// Settings of `identify`.
#[derive(Debug, Clone)]
pub struct SsOptions {
    /// Model order; `None` chooses it by validation on held-back records.
    pub order: Option<usize>,
    /// Orders tried by the automatic choice.
    pub candidates: Vec<usize>,
    /// Hysteresis per actuator (rate-independent registry model), or none (linear).
    pub hysteresis: Option<&'static ModelDef>,
    /// Iterations of the linear refinement and of the joint one.
    pub iterations: usize,
    pub joint_iterations: usize,
    /// Welch segment of non-periodic records (samples).
    pub segment: usize,
    /// Amplitude schedule (local model per level) with this running-RMS time constant (s).
    pub schedule: Option<f64>,
    pub progress: bool,
}

impl Default for SsOptions {
    fn default() -> Self {
        Self {
            order: None,
            candidates: (1..=20).map(|k| 2 * k).collect(),
            hysteresis: None,
            iterations: 40,
            joint_iterations: 30,
            segment: 1024,
            schedule: None,
            progress: false,
        }
    }
}

/// Outcome of `identify`.
#[derive(Debug, Clone)]
pub struct SsFit {
    pub model: Hammerstein,
    pub order: usize,
    pub fs_hz: f64,
    /// Samples per period of the periodic records (0: non-periodic).
    pub period: usize,
    /// Automatic order choice: `(order, validation RMS)` of every candidate.
    pub order_scan: Vec<(usize, f64)>,
    /// The linear part's [`Modal::modal_gain_bound`] over the measured response's peak:
    /// above [`MAX_CANCELLATION`] its modes cancel.
    pub modes_to_peak: f64,
    /// RMS output error of the linear model on the training records (periodic steady
    /// state, mean over records and outputs of the mean square, then root).
    pub linear_rms: f64,
    pub hammerstein_rms: Option<f64>,
    /// The amplitude schedule (local models per level; `model.linear` stays the model of
    /// all records).
    pub schedule: Option<scheduled::Schedule>,
    /// RMS output error of the scheduled model, each level's BLA against the model at
    /// that level (steady state, excited lines).
    pub scheduled_rms: Option<f64>,
}

fn progress(on: bool, msg: impl FnOnce() -> String) {
    if on {
        eprintln!("{}", msg());
    }
}

/// Frequency data of every record (BLA of the periodic ones, H1 of the others).
fn frequency_data(
    recs: &[Record],
    opts: &SsOptions,
) -> anyhow::Result<(FrfData, Vec<PeriodicSpectra>)> {
    let periods: Vec<usize> = recs.iter().map(frf::detect_period).collect();
    let periodic = periods.iter().zip(recs).all(|(&n, r)| n < r.len());
    if periodic {
        anyhow::ensure!(
            periods.iter().all(|&n| n == periods[0]),
            "the periodic records have different periods ({periods:?} samples)"
        );
        let sp = recs
            .iter()
            .map(|r| PeriodicSpectra::of(r, periods[0]))
            .collect::<anyhow::Result<Vec<_>>>()?;
        Ok((frf::bla(&sp)?.data, sp))
    } else {
        let mut all: Option<FrfData> = None;
        for r in recs {
            let d = frf::h1_welch(r, opts.segment.min(r.len()))?;
            all = Some(match all {
                None => d,
                Some(mut a) => {
                    anyhow::ensure!(a.n == d.n, "records too short for one Welch segment length");
                    a.bins.extend(d.bins);
                    a.g.extend(d.g);
                    a.f.extend(d.f);
                    a
                }
            });
        }
        Ok((
            all.ok_or_else(|| anyhow::anyhow!("no records"))?,
            Vec::new(),
        ))
    }
}

/// Subspace estimate refined by the output-error fit on `data`.
fn linear_model(
    data: &FrfData,
    order: usize,
    iterations: usize,
    label: Option<String>,
) -> anyhow::Result<(Modal, f64)> {
    let init = subspace::identify(data, order)?;
    let stats = LineStats::from_frf(data);
    let cfg = PemConfig {
        iterations,
        progress: label,
        ..Default::default()
    };
    let r = pem::refine(&init, &[], (&[], &[]), &|_, _| Ok(stats.clone()), &cfg)?;
    Ok((r.model, r.cost))
}

/// Identifies one model for all `recs` (same inputs, outputs and sample rate).
pub fn identify(recs: &[Record], opts: &SsOptions) -> anyhow::Result<SsFit> {
    anyhow::ensure!(!recs.is_empty(), "no training records");
    let (m, p) = (recs[0].u.len(), recs[0].y.len());
    let fs = recs[0].sample_rate_hz();
    for (i, r) in recs.iter().enumerate() {
        anyhow::ensure!(
            r.u.len() == m && r.y.len() == p,
            "training record {} has {} inputs / {} outputs, the first {m} / {p}",
            i + 1,
            r.u.len(),
            r.y.len()
        );
        anyhow::ensure!(
            (r.sample_rate_hz() / fs - 1.0).abs() < 1e-3,
            "training record {} is sampled at {:.6} Hz, the first at {fs:.6} Hz",
            i + 1,
            r.sample_rate_hz()
        );
    }
    let (data, spectra) = frequency_data(recs, opts)?;
    let period = spectra.first().map_or(0, |s| s.period);
    progress(opts.progress, || {
        format!(
            "frequency response: {} lines, {:.1}..{:.1} Hz, {} records",
            data.bins.len(),
            data.freq_hz(0),
            data.freq_hz(data.bins.len() - 1),
            recs.len()
        )
    });
    let records = (recs.len() * p) as f64;
    let mut order_scan = Vec::new();
    let order = match opts.order {
        Some(n) => n,
        None => {
            // Every fourth record held back (all of them when there is one record: then
            // every fourth line); subspace + least squares per candidate order.
            anyhow::ensure!(!opts.candidates.is_empty(), "no candidate orders");
            let (fit_d, val_d, val_n) = if spectra.len() >= 4 {
                let (a, b): (Vec<_>, Vec<_>) = spectra
                    .iter()
                    .cloned()
                    .enumerate()
                    .partition(|(i, _)| i % 4 != 3);
                let strip = |v: Vec<(usize, PeriodicSpectra)>| {
                    v.into_iter().map(|x| x.1).collect::<Vec<_>>()
                };
                let (a, b) = (strip(a), strip(b));
                let nb = b.len();
                (frf::bla(&a)?.data, val_stats_periodic(&b), (nb * p) as f64)
            } else {
                let val = LineStats::from_frf(&data.subset(|i| i % 4 == 3));
                (data.subset(|i| i % 4 != 3), val, (recs.len() * p) as f64)
            };
            // A candidate whose modes cancel is refused: on strongly hysteretic records
            // (hal-sim's stage, nonlinear distortion 0.6 um) the scan's noisy minimum was a
            // 32-state model with input gains of 5e21 that fitted worse than 8 states.
            let peak = peak_gain(&fit_d);
            for &n in &opts.candidates {
                let (c, ratio) = match subspace::identify(&fit_d, n) {
                    Ok(mdl) => {
                        let ratio = mdl.modal_gain_bound() / peak;
                        let c = if ratio <= MAX_CANCELLATION {
                            (pem::cost(&mdl, &val_d) / val_n).sqrt()
                        } else {
                            f64::INFINITY
                        };
                        (c, ratio)
                    }
                    Err(_) => (f64::INFINITY, f64::NAN),
                };
                progress(opts.progress, || {
                    format!(
                        "order {n}: validation RMS {c:.4e} (modes' gains {ratio:.1e} x the peak)"
                    )
                });
                order_scan.push((n, c));
            }
            // The smallest order within 2 % of the best: beyond the true order the
            // validation error only wanders with the noise.
            let best = order_scan.iter().map(|x| x.1).fold(f64::INFINITY, f64::min);
            anyhow::ensure!(best.is_finite(), "no candidate order gave a model");
            let n = order_scan
                .iter()
                .find(|x| x.1 <= 1.02 * best)
                .map_or(opts.candidates[0], |x| x.0);
            progress(opts.progress, || format!("order {n} chosen"));
            n
        }
    };
    let (linear, lin_cost) = linear_model(
        &data,
        order,
        opts.iterations,
        opts.progress.then(|| format!("linear order {order}")),
    )?;
    // The reduced cost misses what no linear model explains; report the full one.
    let linear_rms = if spectra.is_empty() {
        (lin_cost / records).sqrt()
    } else {
        (pem::cost(&linear, &val_stats_periodic(&spectra)) / records).sqrt()
    };
    progress(opts.progress, || {
        format!("linear model: RMS output error {linear_rms:.4e} on the training records")
    });
    let mut fit = SsFit {
        model: Hammerstein {
            fronts: Vec::new(),
            linear: linear.clone(),
        },
        order,
        fs_hz: fs,
        period,
        order_scan,
        modes_to_peak: linear.modal_gain_bound() / peak_gain(&data),
        linear_rms,
        hammerstein_rms: None,
        schedule: None,
        scheduled_rms: None,
    };
    if let Some(tau_s) = opts.schedule {
        // `model.linear` stays the model of all records (`piezo sim --stage`) and is one
        // start of every local refinement.
        anyhow::ensure!(
            opts.hysteresis.is_none(),
            "the amplitude schedule and a hysteresis front are not combined"
        );
        let cfg = PemConfig {
            iterations: opts.iterations,
            progress: opts.progress.then(|| format!("local order {order}")),
            ..Default::default()
        };
        let (sched, c) = scheduled::identify(recs, &spectra, &linear, tau_s, &cfg)?;
        let rms = (c / records).sqrt();
        progress(opts.progress, || {
            format!("scheduled model: RMS output error {rms:.4e} at the BLA lines")
        });
        fit.schedule = Some(sched);
        fit.scheduled_rms = Some(rms);
    }
    if let Some(def) = opts.hysteresis {
        anyhow::ensure!(
            !spectra.is_empty(),
            "the Hammerstein fit needs periodic records (multisines of whole periods)"
        );
        let cfg = PemConfig {
            iterations: opts.joint_iterations,
            progress: opts
                .progress
                .then(|| format!("hammerstein {} + order {order}", def.name)),
            ..Default::default()
        };
        let (h, c) = hammerstein_starts(&linear, &spectra, recs, def, &cfg, None)?;
        let rms = (c / records).sqrt();
        progress(opts.progress, || {
            format!("hammerstein model: RMS output error {rms:.4e} on the training records")
        });
        fit.model = h;
        fit.hammerstein_rms = Some(rms);
    }
    Ok(fit)
}

/// A hysteresis `def` ahead of each input of `linear`, refined jointly with it on the
/// periodic records `recs` (`iterations` of the joint refinement): the Hammerstein fit of
/// [`identify`] from a given linear part, or with `fronts` (their parameters, one set per
/// input) the continuation of an earlier one. Returns the model and its training RMS
/// output error.
pub fn hammerstein_around(
    linear: &Modal,
    recs: &[Record],
    def: &'static ModelDef,
    iterations: usize,
    fronts: Option<&[Vec<f64>]>,
) -> anyhow::Result<(Hammerstein, f64)> {
    let (_, spectra) = frequency_data(recs, &SsOptions::default())?;
    anyhow::ensure!(
        !spectra.is_empty(),
        "the Hammerstein fit needs periodic records (multisines of whole periods)"
    );
    let cfg = PemConfig {
        iterations,
        ..Default::default()
    };
    let (h, c) = hammerstein_starts(linear, &spectra, recs, def, &cfg, fronts)?;
    Ok((h, (c / (recs.len() * linear.outputs()) as f64).sqrt()))
}

/// The joint Hammerstein refinement of [`identify`] and [`hammerstein_around`] on the
/// periodic `spectra` of `recs`: from three starts (the middle of the hysteresis' search box,
/// a quarter and three quarters of it; from the middle alone it stalled on strongly
/// hysteretic records, 1-2 % gain where the hysteresis is the main effect), or from
/// `fronts`' parameters; the lowest training cost kept. Returns the model and that cost.
fn hammerstein_starts(
    linear: &Modal,
    spectra: &[PeriodicSpectra],
    recs: &[Record],
    def: &'static ModelDef,
    cfg: &PemConfig,
    fronts: Option<&[Vec<f64>]>,
) -> anyhow::Result<(Hammerstein, f64)> {
    let per: Vec<Periodic> = spectra
        .iter()
        .zip(recs)
        .map(|(s, r)| Periodic::of(s, &r.u))
        .collect();
    let dt = 1.0 / anyhow::Context::context(recs.first(), "no records")?.sample_rate_hz();
    let starts: Vec<hammerstein::Start> = match fronts {
        Some(p) => vec![hammerstein::Start::Params(p)],
        None => [0.5, 0.25, 0.75].map(hammerstein::Start::Box).to_vec(),
    };
    let mut best: Option<(Hammerstein, f64)> = None;
    let mut last_err = None;
    for from in starts {
        match hammerstein::identify_from(def, &per, dt, linear, cfg, from) {
            Ok((h, c)) if c.is_finite() && best.as_ref().is_none_or(|b| c < b.1) => {
                best = Some((h, c))
            }
            Ok(_) => {}
            Err(e) => last_err = Some(e),
        }
    }
    match (best, last_err) {
        (Some(b), _) => Ok(b),
        (None, Some(e)) => Err(e.context("the Hammerstein fit failed from every start")),
        (None, None) => anyhow::bail!("the Hammerstein fit gave no finite cost from any start"),
    }
}

/// Statistics of periodic records for the full output-error cost of a linear model.
fn val_stats_periodic(sp: &[PeriodicSpectra]) -> Vec<LineStats> {
    let (n, m, p) = (sp[0].period, sp[0].u.len(), sp[0].y.len());
    (0..=n / 2)
        .map(|k| {
            let w = frf::bin_weight(k, n);
            let mut svv = nalgebra::DMatrix::zeros(m, m);
            let mut syv = nalgebra::DMatrix::zeros(p, m);
            let mut syy = 0.0;
            for s in sp {
                let u = nalgebra::DMatrix::from_fn(m, 1, |j, _| s.u[j][k]);
                let y = nalgebra::DMatrix::from_fn(p, 1, |o, _| s.y[o][k]);
                svv += &u * u.adjoint();
                syv += &y * u.adjoint();
                syy += y.norm_squared();
            }
            let wc = model::C64::new(w, 0.0);
            LineStats {
                z: model::C64::from_polar(1.0, 2.0 * std::f64::consts::PI * k as f64 / n as f64),
                svv: svv * wc,
                syv: syv * wc,
                syy: syy * w,
                sdv_v: Vec::new(),
                sy_dv: Vec::new(),
                sdv_dv: Vec::new(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ss::extended::{Core, Model};
    use crate::ss::hammerstein::Front;
    use crate::ss::model::Block;
    use nalgebra::DMatrix;

    /// Periodic records of a CBW ahead of a three-state plant (steady state, two periods of
    /// a random-phase multisine per record).
    fn records() -> Vec<Record> {
        let plant = Model {
            delay: 0,
            fronts: vec![Front {
                def: crate::fit::models::find("cbw").unwrap(),
                params: vec![1.0, 0.6, 3.0, 0.5],
            }],
            core: Core::Linear(Modal {
                blocks: vec![Block::Pair(0.9, 0.3), Block::Real(0.6)],
                b: DMatrix::from_row_slice(3, 1, &[0.2, -0.1, 0.4]),
                c: DMatrix::from_row_slice(1, 3, &[1.0, 0.3, 0.5]),
                d: DMatrix::from_row_slice(1, 1, &[0.02]),
            }),
            creep: None,
            drift: None,
        };
        let (n, fs) = (512, 1000.0);
        (1..=4u64)
            .map(|seed| {
                let one = crate::numeric::random_phase_period(n, 60, seed);
                let u: Vec<f64> = (0..3 * n).map(|k| one[k % n]).collect();
                let y = plant.simulate(std::slice::from_ref(&u), 1.0 / fs).unwrap();
                let t = (0..2 * n).map(|k| k as f64 / fs).collect();
                Record::new(t, vec![u[n..].to_vec()], vec![y[0][n..].to_vec()]).unwrap()
            })
            .collect()
    }

    #[test]
    fn the_hammerstein_fit_takes_in_the_input_hysteresis() {
        let recs = records();
        let fit = identify(
            &recs,
            &SsOptions {
                order: Some(3),
                hysteresis: Some(crate::fit::models::find("cbw").unwrap()),
                iterations: 30,
                joint_iterations: 30,
                ..Default::default()
            },
        )
        .unwrap();
        let h = fit.hammerstein_rms.unwrap();
        assert_eq!(fit.model.fronts.len(), 1);
        assert!(
            h < 0.2 * fit.linear_rms,
            "Hammerstein {h:.3e} against linear {:.3e}",
            fit.linear_rms
        );
    }
}
