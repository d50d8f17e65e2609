//! Model fitting from records (`piezo fit`): model registry, global search then local
//! refinement, metrics.
//!
//! Procedure (002 sec. 3 uses PSO on the RMSE of 002 eq. (6)-(7); differential evolution,
//! the default, or PSO ([`FitOptions::optimizer`]) plays that part, then Levenberg-Marquardt
//! polishes):
//! 1. global search by DE or PSO over data-scaled boxes (log space for scales), on a decimated
//!    copy of the record for static (rate-independent) models, or on its first samples at a
//!    coarse integration rate for dynamic ones;
//! 2. LM on the full record (dynamic models: input upsampled by a band-limited
//!    interpolator, one RK4 step per upsampled sample).
//!
//! Static models are fitted as `y = offset + sign * M(u)`: `sign` is the sign of the
//! least-squares slope of `y` on `u` (so loops of either orientation fit), `offset` is
//! solved in closed form at every evaluation. Dynamic models start from rest, no offset.
//!
//! Metrics: RMSE (004 eq. 23), MPME (004 eq. 22), RE (002 eq. 14).

pub mod models;
pub mod resample;

use crate::optim::{global_search, levenberg_marquardt, LmConfig, Optimizer, SearchConfig};
use models::{ModelDef, ParamSpec, Scales};
use piezo_core::hysteresis::ParamError;
use resample::{upsample, Edge};
use serde::Serialize;

/// Fit quality of a simulated output against the measured one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Metrics {
    /// 004 eq. (23), in output units.
    pub rmse: f64,
    /// 004 eq. (22): max |error| over the output range, percent.
    pub mpme_pct: f64,
    /// 002 eq. (14): error norm over output norm, percent.
    pub re_pct: f64,
    /// Largest |error|, output units.
    pub max_abs: f64,
    pub samples: usize,
}

/// Metrics of `model` against `measured` (equal lengths; extra samples ignored).
pub fn metrics(measured: &[f64], model: &[f64]) -> Metrics {
    let n = measured.len().min(model.len());
    let (mut se, mut sy, mut emax) = (0.0, 0.0, 0.0f64);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (y, m) in measured.iter().zip(model) {
        let e = y - m;
        se += e * e;
        sy += y * y;
        emax = emax.max(e.abs());
        lo = lo.min(*y);
        hi = hi.max(*y);
    }
    let nf = n.max(1) as f64;
    Metrics {
        rmse: (se / nf).sqrt(),
        mpme_pct: 100.0 * emax / (hi - lo),
        re_pct: 100.0 * (se / sy).sqrt(),
        max_abs: emax,
        samples: n,
    }
}

/// Settings of one fit.
#[derive(Debug, Clone)]
pub struct FitOptions {
    /// Global search: differential evolution or particle swarm (002 sec. 3).
    pub optimizer: Optimizer,
    /// DE generations / PSO iterations (0: skip the global search and start LM from the
    /// box centres).
    pub generations: usize,
    /// DE population / PSO swarm (0: 10 per parameter, at least 15).
    pub population: usize,
    pub seed: u64,
    /// Static models: the global search runs on at most this many samples (decimated).
    pub de_samples: usize,
    /// Dynamic models: samples from the start of the record used by the global search.
    pub de_prefix: usize,
    /// Dynamic models: input upsampling during the global search.
    pub de_upsample: usize,
    /// Dynamic models: input upsampling for LM and simulation (the benchmark's 20).
    pub upsample: usize,
    pub lm_iterations: usize,
    /// Hammerstein: second-order sections of linear dynamics after the hysteresis
    /// (004 eq. 8), unity DC gain; 0 for none.
    pub linear_sections: usize,
    /// Hammerstein two-step (004 sec. 4.2): the linear part identified beforehand
    /// (`(f_hz, zeta)` per section), kept fixed while the hysteresis is fitted.
    pub linear_fixed: Option<Vec<(f64, f64)>>,
    /// Static models: hold the output offset at this value instead of solving it in closed
    /// form (`None`, the default): for a model that goes where there is no offset (the
    /// firmware's CBW, `piezo serial identify`).
    pub fixed_offset: Option<f64>,
    /// Samples at the start of the training record that run the model (bring its state
    /// up to date) but are not scored: a record cut from a running excitation starts with
    /// a hysteresis state the model, started from rest, does not have (0: score all).
    pub warmup: usize,
    /// Print progress on stderr.
    pub progress: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            optimizer: Optimizer::De,
            generations: 300,
            population: 0,
            seed: 1,
            de_samples: 4000,
            de_prefix: 4096,
            de_upsample: 2,
            upsample: 20,
            lm_iterations: 60,
            linear_sections: 0,
            linear_fixed: None,
            fixed_offset: None,
            warmup: 0,
            progress: false,
        }
    }
}

/// An identified single-input single-output model.
#[derive(Debug, Clone, Serialize)]
pub struct Fitted {
    pub model: String,
    /// Parameter names and values in model units.
    pub params: Vec<(String, f64)>,
    /// Output sign applied to the model (static models).
    pub sign: f64,
    /// Output offset (static models; 0 for dynamic).
    pub offset: f64,
    /// Input upsampling used when simulating (dynamic models).
    pub upsample: usize,
    /// Hammerstein linear part: `(f_hz, zeta)` per second-order section (unity DC gain).
    pub linear: Vec<(f64, f64)>,
    /// The global search that started the local refinement (None: none ran).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub search: Option<SearchReport>,
    #[serde(skip)]
    def: &'static ModelDef,
}

/// What the global search of a fit reached (its RMSE on the reduced problem it searched).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SearchReport {
    pub optimizer: Optimizer,
    /// Fitness 002 eq. (6): RMSE on the search's reduced record.
    pub rmse: f64,
    pub evals: usize,
    /// Generations / iterations run.
    pub iterations: usize,
    /// Wall-clock time of the search.
    pub seconds: f64,
}

/// Search-space coordinate to parameter value.
fn to_param(spec: &ParamSpec, z: f64) -> f64 {
    if spec.log {
        10f64.powf(z)
    } else {
        z
    }
}

fn search_box(specs: &[ParamSpec]) -> (Vec<f64>, Vec<f64>) {
    specs
        .iter()
        .map(|s| {
            if s.log {
                (
                    s.lo.max(f64::MIN_POSITIVE).log10(),
                    s.hi.max(f64::MIN_POSITIVE).log10(),
                )
            } else {
                (s.lo, s.hi)
            }
        })
        .unzip()
}

/// Least-squares slope sign of `y` on `u` (+1 when flat).
fn slope_sign(u: &[f64], y: &[f64]) -> f64 {
    let n = u.len().max(1) as f64;
    let mu = u.iter().sum::<f64>() / n;
    let my = y.iter().sum::<f64>() / n;
    let cov: f64 = u.iter().zip(y).map(|(a, b)| (a - mu) * (b - my)).sum();
    if cov < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// One training problem: input (possibly upsampled), target, how to map a search point
/// to an output.
struct Problem<'a> {
    def: &'static ModelDef,
    specs: &'a [ParamSpec],
    u: Vec<f64>,
    y: Vec<f64>,
    dt: f64,
    /// Output every `stride` simulated samples (upsampled dynamic models).
    stride: usize,
    sign: f64,
    /// Number of model parameters in `specs` (the rest are linear-part parameters).
    n_model: usize,
    /// Fixed linear part (two-step), used when `specs` has no linear parameters.
    linear_fixed: Vec<(f64, f64)>,
    /// Static models: the output offset held here instead of solved ([`FitOptions`]).
    fixed_offset: Option<f64>,
    /// Leading outputs that are simulated but not scored ([`FitOptions::warmup`]).
    skip: usize,
}

impl Problem<'_> {
    fn params(&self, z: &[f64]) -> Vec<f64> {
        self.specs
            .iter()
            .zip(z)
            .map(|(s, z)| to_param(s, *z))
            .collect()
    }

    /// The linear sections for parameter vector `p` (model units).
    fn linear(&self, p: &[f64]) -> Vec<(f64, f64)> {
        let free = &p[self.n_model.min(p.len())..];
        if free.is_empty() {
            self.linear_fixed.clone()
        } else {
            free.chunks_exact(2).map(|c| (c[0], c[1])).collect()
        }
    }

    /// Residuals `model - measured` (offset solved in closed form for static models);
    /// returns the offset, or None when the parameters are rejected or the output blows up.
    fn residuals(&self, z: &[f64], r: &mut [f64]) -> Option<f64> {
        let p = self.params(z);
        let mut sim = vec![0.0; self.u.len()];
        (self.def.simulate)(&p[..self.n_model], &self.u, self.dt, &mut sim).ok()?;
        apply_linear(&self.linear(&p), self.dt, &mut sim).ok()?;
        for (ri, yi) in r
            .iter_mut()
            .zip(sim.iter().step_by(self.stride).skip(self.skip))
        {
            *ri = self.sign * yi;
        }
        let y = &self.y[self.skip..];
        let offset = if self.def.dynamic {
            0.0
        } else if let Some(o) = self.fixed_offset {
            o
        } else {
            y.iter().zip(r.iter()).map(|(y, m)| y - m).sum::<f64>() / y.len() as f64
        };
        let mut ok = true;
        for (ri, yi) in r.iter_mut().zip(y) {
            *ri += offset - yi;
            ok &= ri.is_finite();
        }
        ok.then_some(offset)
    }

    fn cost(&self, z: &[f64]) -> f64 {
        let mut r = vec![0.0; self.y.len() - self.skip];
        match self.residuals(z, &mut r) {
            Some(_) => (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt(),
            None => f64::INFINITY,
        }
    }
}

/// Prepares a dynamic model's input: upsampled by `factor`, time step divided.
fn upsampled(u: &[f64], dt: f64, factor: usize, edge: Edge) -> (Vec<f64>, f64) {
    let f = factor.max(1);
    (upsample(u, f, edge), dt / f as f64)
}

/// Identifies `def` from `u -> y` sampled every `dt` seconds.
pub fn fit_siso(
    def: &'static ModelDef,
    u: &[f64],
    y: &[f64],
    dt: f64,
    opts: &FitOptions,
) -> anyhow::Result<Fitted> {
    anyhow::ensure!(
        u.len() == y.len(),
        "input has {} samples, output {}",
        u.len(),
        y.len()
    );
    anyhow::ensure!(
        u.len() >= 10,
        "{} samples are too few to fit a model",
        u.len()
    );
    anyhow::ensure!(
        opts.warmup + 10 <= u.len(),
        "a warm-up of {} samples leaves fewer than 10 of {} to fit on",
        opts.warmup,
        u.len()
    );
    anyhow::ensure!(
        dt > 0.0 && dt.is_finite(),
        "sample period {dt} s is not positive"
    );
    let scales = Scales::of(u, y, dt);
    let mut specs = (def.params)(&scales);
    let n_model = specs.len();
    anyhow::ensure!(
        !(def.dynamic && (opts.linear_sections > 0 || opts.linear_fixed.is_some())),
        "`{}` has its own dynamics; a Hammerstein linear part does not apply",
        def.name
    );
    anyhow::ensure!(
        opts.linear_sections <= 2,
        "at most 2 linear sections, {} asked",
        opts.linear_sections
    );
    let linear_fixed = opts.linear_fixed.clone().unwrap_or_default();
    if linear_fixed.is_empty() {
        for k in 1..=opts.linear_sections {
            specs.push(ParamSpec::log(&format!("f{k}_hz"), 1e-3 / dt, 0.45 / dt));
            specs.push(ParamSpec::log(&format!("zeta{k}"), 0.02, 3.0));
        }
    }
    let (lo, hi) = search_box(&specs);
    let sign = if def.dynamic { 1.0 } else { slope_sign(u, y) };
    let label = opts.progress.then(|| format!("fit {}", def.name));
    let t0 = std::time::Instant::now();

    // 1. Global search on a reduced problem.
    let coarse = if def.dynamic {
        let n = opts.de_prefix.clamp(10, u.len());
        let (uu, dtu) = upsampled(&u[..n], dt, opts.de_upsample, Edge::Hold);
        Problem {
            def,
            specs: &specs,
            u: uu,
            y: y[..n].to_vec(),
            dt: dtu,
            stride: opts.de_upsample.max(1),
            sign,
            n_model,
            linear_fixed: linear_fixed.clone(),
            fixed_offset: opts.fixed_offset,
            skip: opts.warmup.min(n.saturating_sub(10)),
        }
    } else {
        let k = u.len().div_ceil(opts.de_samples.max(10));
        Problem {
            def,
            specs: &specs,
            u: u.iter().step_by(k).copied().collect(),
            y: y.iter().step_by(k).copied().collect(),
            dt: dt * k as f64,
            stride: 1,
            sign,
            n_model,
            linear_fixed: linear_fixed.clone(),
            fixed_offset: opts.fixed_offset,
            skip: opts.warmup / k,
        }
    };
    let centre: Vec<f64> = lo.iter().zip(&hi).map(|(a, b)| 0.5 * (a + b)).collect();
    let mut search = None;
    let z0 = if opts.generations > 0 {
        let cfg = SearchConfig {
            optimizer: opts.optimizer,
            population: opts.population,
            generations: opts.generations,
            seed: opts.seed,
            progress: label.clone(),
        };
        let t_search = std::time::Instant::now();
        let best = global_search(|z| coarse.cost(z), &lo, &hi, &[centre], &cfg)?;
        if let Some(l) = &label {
            eprintln!(
                "{l}: global search ({:?}) RMSE {:.4e} after {} evaluations",
                opts.optimizer, best.cost, best.evals
            );
        }
        search = Some(SearchReport {
            optimizer: opts.optimizer,
            rmse: best.cost,
            evals: best.evals,
            iterations: best.iterations,
            seconds: t_search.elapsed().as_secs_f64(),
        });
        best.x
    } else {
        centre
    };

    // 2. Local refinement on the full record.
    let full = if def.dynamic {
        let (uu, dtu) = upsampled(u, dt, opts.upsample, Edge::Hold);
        Problem {
            def,
            specs: &specs,
            u: uu,
            y: y.to_vec(),
            dt: dtu,
            stride: opts.upsample.max(1),
            sign,
            n_model,
            linear_fixed: linear_fixed.clone(),
            fixed_offset: opts.fixed_offset,
            skip: opts.warmup,
        }
    } else {
        Problem {
            def,
            specs: &specs,
            u: u.to_vec(),
            y: y.to_vec(),
            dt,
            stride: 1,
            sign,
            n_model,
            linear_fixed: linear_fixed.clone(),
            fixed_offset: opts.fixed_offset,
            skip: opts.warmup,
        }
    };
    let lm = LmConfig {
        max_iterations: opts.lm_iterations,
        progress: label.clone(),
        ..Default::default()
    };
    let m = full.y.len() - full.skip;
    let z = if full.cost(&z0).is_finite() && opts.lm_iterations > 0 {
        levenberg_marquardt(
            |z, r| {
                if full.residuals(z, r).is_none() {
                    r.fill(f64::INFINITY);
                }
            },
            m,
            &z0,
            &lo,
            &hi,
            &lm,
        )?
        .x
    } else {
        z0
    };
    if let Some(l) = &label {
        eprintln!("{l}: done in {:.1} s", t0.elapsed().as_secs_f64());
    }
    let mut r = vec![0.0; m];
    let offset = full.residuals(&z, &mut r).ok_or_else(|| {
        anyhow::anyhow!(
            "no parameter set of `{}` gave a finite simulation of this record",
            def.name
        )
    })?;
    let p = full.params(&z);
    Ok(Fitted {
        model: def.name.into(),
        params: specs[..n_model]
            .iter()
            .zip(&p)
            .map(|(s, v)| (s.name.clone(), *v))
            .collect(),
        sign,
        offset,
        upsample: if def.dynamic { opts.upsample.max(1) } else { 1 },
        linear: full.linear(&p),
        search,
        def,
    })
}

impl Fitted {
    /// Rebuilds a fitted model from its registry name and parameter values.
    pub fn from_params(
        def: &'static ModelDef,
        values: &[f64],
        sign: f64,
        offset: f64,
        upsample: usize,
    ) -> anyhow::Result<Self> {
        let specs = (def.params)(&Scales::of(&[0.0, 1.0], &[0.0, 1.0], 1.0));
        anyhow::ensure!(
            specs.len() == values.len(),
            "model `{}` has {} parameters, {} given",
            def.name,
            specs.len(),
            values.len()
        );
        Ok(Self {
            model: def.name.into(),
            params: specs
                .into_iter()
                .map(|s| s.name)
                .zip(values.iter().copied())
                .collect(),
            sign,
            offset,
            upsample: upsample.max(1),
            linear: Vec::new(),
            search: None,
            def,
        })
    }

    pub fn values(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.1).collect()
    }

    /// Simulates the model on `u` (sampled every `dt`) from its initial state. `edge` says
    /// how a dynamic model's input continues beyond the record for the interpolator.
    pub fn simulate(&self, u: &[f64], dt: f64, edge: Edge) -> anyhow::Result<Vec<f64>> {
        let p = self.values();
        let (uu, dtu, stride) = if self.def.dynamic {
            let (uu, d) = upsampled(u, dt, self.upsample, edge);
            (uu, d, self.upsample)
        } else {
            (u.to_vec(), dt, 1)
        };
        let mut sim = vec![0.0; uu.len()];
        (self.def.simulate)(&p, &uu, dtu, &mut sim)
            .map_err(|e| anyhow::anyhow!("model `{}`: {e}", self.model))?;
        apply_linear(&self.linear, dtu, &mut sim)
            .map_err(|e| anyhow::anyhow!("model `{}` linear part: {e}", self.model))?;
        Ok(sim
            .iter()
            .step_by(stride)
            .map(|v| self.offset + self.sign * v)
            .collect())
    }

    /// Simulates a record that is one period of a periodic steady state: the input is
    /// repeated `warmup` extra periods first and the last period is returned.
    pub fn simulate_periodic(&self, u: &[f64], dt: f64, warmup: usize) -> anyhow::Result<Vec<f64>> {
        let n = u.len();
        let reps: Vec<f64> = u.iter().copied().cycle().take(n * (warmup + 1)).collect();
        let y = self.simulate(&reps, dt, Edge::Periodic)?;
        Ok(y[n * warmup..].to_vec())
    }
}

/// Filters `y` in place through unity-gain second-order sections `(f_hz, zeta)`
/// (004 eq. 8, ZOH-exact), from steady state at the first sample.
pub fn apply_linear(sections: &[(f64, f64)], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
    use piezo_core::linear::{Discretisation, Linear, Section};
    fn run<const S: usize>(secs: [Section; S], dt: f64, y: &mut [f64]) -> Result<(), ParamError> {
        let l = Linear::<f64, S>::new(1.0, secs, dt, Discretisation::Zoh)?;
        let mut s = l.init(y.first().copied().unwrap_or(0.0));
        for v in y.iter_mut() {
            *v = l.step(&mut s, *v);
        }
        Ok(())
    }
    let sec = |&(f, z): &(f64, f64)| Section::poles_hz(f, z);
    match sections {
        [] => Ok(()),
        [a] => run([sec(a)], dt, y),
        [a, b] => run([sec(a), sec(b)], dt, y),
        _ => Err(ParamError("linear: at most 2 sections in a fit")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_follow_the_seed_definitions() {
        let y = [0.0, 1.0, 2.0, 3.0];
        let m = [0.0, 1.0, 2.0, 2.0];
        let k = metrics(&y, &m);
        assert!((k.rmse - 0.5).abs() < 1e-12);
        assert!((k.mpme_pct - 100.0 / 3.0).abs() < 1e-12);
        assert!((k.re_pct - 100.0 * (1.0f64 / 14.0).sqrt()).abs() < 1e-12);
    }

    fn sine_input(n: usize, fs: f64) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let t = i as f64 / fs;
                50.0 + 45.0 * (t * (1.0 + 0.3 * t)).sin() * (1.0 - 0.2 * t / (n as f64 / fs))
            })
            .collect()
    }

    #[test]
    fn recovers_cbw_parameters_from_simulated_record() {
        let fs = 200.0;
        let u = sine_input(2000, fs);
        let truth = models::find("cbw").unwrap();
        // d, alpha, beta, gamma/beta: 000 backup slide set 1 (gamma = 0.01 = 0.5 * beta).
        let gen = Fitted::from_params(truth, &[0.16, 0.07, 0.02, 0.5], 1.0, 3.0, 1).unwrap();
        let y = gen.simulate(&u, 1.0 / fs, Edge::Hold).unwrap();
        let opts = FitOptions {
            generations: 60,
            ..Default::default()
        };
        let f = fit_siso(truth, &u, &y, 1.0 / fs, &opts).unwrap();
        let m = metrics(&y, &f.simulate(&u, 1.0 / fs, Edge::Hold).unwrap());
        assert!(m.rmse < 1e-6, "{m:?} {f:?}");
        for (got, want) in f.values().iter().zip([0.16, 0.07, 0.02, 0.5]) {
            assert!((got - want).abs() < 1e-4 * want.abs().max(1.0), "{f:?}");
        }
        assert!((f.offset - 3.0).abs() < 1e-6);
        // Offset held: the fit keeps it and still finds the model (0.5 um off: the
        // parameters take what they can of it, the RMSE shows the rest).
        let held = FitOptions {
            fixed_offset: Some(3.0),
            ..opts.clone()
        };
        let f = fit_siso(truth, &u, &y, 1.0 / fs, &held).unwrap();
        assert_eq!(f.offset, 3.0);
        assert!(
            f.values()
                .iter()
                .zip([0.16, 0.07, 0.02, 0.5])
                .all(|(g, w)| (g - w).abs() < 1e-3),
            "{f:?}"
        );
        let off = FitOptions {
            fixed_offset: Some(2.5),
            ..opts
        };
        let f = fit_siso(truth, &u, &y, 1.0 / fs, &off).unwrap();
        assert_eq!(f.offset, 2.5);
        let m = metrics(&y, &f.simulate(&u, 1.0 / fs, Edge::Hold).unwrap());
        assert!(
            m.rmse > 1e-3,
            "a held offset 0.5 um off cannot fit exactly: {m:?}"
        );
    }

    #[test]
    fn a_warm_up_is_run_but_not_scored() {
        // The record starts with the loop's state far from rest (the model's start), and
        // holds the offset at 0: scored from the start the fit is pulled off, with the
        // first 1.5 periods as warm-up it finds the model.
        let fs = 200.0;
        let truth = models::find("cbw").unwrap();
        let want = [0.16, 0.07, 0.02, 0.5];
        let gen = Fitted::from_params(truth, &want, 1.0, 0.0, 1).unwrap();
        let whole = sine_input(2000, fs);
        let y_whole = gen.simulate(&whole, 1.0 / fs, Edge::Hold).unwrap();
        // Cut where the state is far from rest.
        let cut = 2000 - 700;
        let (u, y) = (&whole[cut..], &y_whole[cut..]);
        let base = FitOptions {
            generations: 60,
            fixed_offset: Some(0.0),
            ..Default::default()
        };
        let err = |f: &Fitted| {
            f.values()
                .iter()
                .zip(want)
                .map(|(g, w)| ((g - w) / w).abs())
                .fold(0.0, f64::max)
        };
        let cold = fit_siso(truth, u, y, 1.0 / fs, &base).unwrap();
        let warm = fit_siso(
            truth,
            u,
            y,
            1.0 / fs,
            &FitOptions {
                warmup: 300,
                ..base.clone()
            },
        )
        .unwrap();
        assert!(err(&warm) < 0.2 * err(&cold), "warm {warm:?} cold {cold:?}");
        assert!(fit_siso(
            truth,
            u,
            y,
            1.0 / fs,
            &FitOptions {
                warmup: 695,
                ..base
            }
        )
        .is_err());
    }

    #[test]
    fn pso_alone_recovers_cbw_parameters() {
        // 002 sec. 3: particle swarm on the RMSE fitness (eq. 6), no LM polish.
        let fs = 200.0;
        let u = sine_input(2000, fs);
        let truth = models::find("cbw").unwrap();
        let want = [0.16, 0.07, 0.02, 0.5];
        let gen = Fitted::from_params(truth, &want, 1.0, 3.0, 1).unwrap();
        let y = gen.simulate(&u, 1.0 / fs, Edge::Hold).unwrap();
        let opts = FitOptions {
            optimizer: Optimizer::Pso,
            generations: 300,
            lm_iterations: 0,
            ..Default::default()
        };
        let f = fit_siso(truth, &u, &y, 1.0 / fs, &opts).unwrap();
        let g = f.search.unwrap();
        assert_eq!(g.optimizer, Optimizer::Pso);
        let m = metrics(&y, &f.simulate(&u, 1.0 / fs, Edge::Hold).unwrap());
        eprintln!("PSO: {m:?} {f:?}");
        assert!(m.rmse < 1e-4 * 20.0, "{m:?} {f:?}");
        for (got, want) in f.values().iter().zip(want) {
            assert!((got - want).abs() < 1e-3 * want, "{f:?}");
        }
    }

    #[test]
    fn every_model_fits_a_measured_loop_better_than_a_line() {
        let path = crate::record::data_dir().join("backlash-micromanipulator/model_1Hz.csv");
        let Ok(rec) = crate::record::Record::read(&path) else {
            eprintln!("skipped: {} not found", path.display());
            return;
        };
        let rec = rec.slice(0, 1000);
        let (u, y) = (&rec.u[0], &rec.y[0]);
        // Straight line fit as the baseline.
        let n = u.len() as f64;
        let (mu, my) = (u.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
        let b = u
            .iter()
            .zip(y)
            .map(|(a, c)| (a - mu) * (c - my))
            .sum::<f64>()
            / u.iter().map(|a| (a - mu).powi(2)).sum::<f64>();
        let line: Vec<f64> = u.iter().map(|a| my + b * (a - mu)).collect();
        let base = metrics(y, &line).rmse;
        let opts = FitOptions {
            generations: 20,
            lm_iterations: 10,
            de_samples: 300,
            ..Default::default()
        };
        // The exactly-updated models (the RK4-integrated cbw-n, mbw-rlm and wpmbw are slow
        // in the dev profile; gbw-printed is left out: literal 000 eq. (3) holds h on a full
        // loop, see Gbw's doc, so it cannot beat a line on a measured loop).
        for name in [
            "cbw", "gbw", "dahl", "abw-u", "abw-abs", "mbw002", "pi", "ppi", "dpi",
        ] {
            let def = models::find(name).unwrap();
            let f = fit_siso(def, u, y, rec.dt(), &opts).unwrap();
            let m = metrics(y, &f.simulate(u, rec.dt(), Edge::Hold).unwrap());
            assert!(
                m.rmse < 0.8 * base,
                "{}: {} vs line {base}",
                def.name,
                m.rmse
            );
        }
    }
}
