//! Hammerstein model: one rate-independent hysteresis model of the core per actuator
//! (`v_j = H_j(u_j)`) ahead of a multivariable modal state-space block (`y = G(q) v`).
//! Identified in steps: the linear block on the BLA first, then hysteresis and linear
//! block jointly by [`pem::refine`] on the periodic steady state of every record.

use super::frf::{bin_weight, period_spectra, PeriodicSpectra};
use super::model::{Modal, C64};
use super::pem::{self, LineStats, PemConfig};
use crate::fit::models::{self, ModelDef, Scales};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// One actuator's hysteresis: registry model and parameter values (model units).
#[derive(Debug, Clone)]
pub struct Front {
    pub def: &'static ModelDef,
    pub params: Vec<f64>,
}

impl Front {
    /// `v = H(u)` from the relaxed state at `u[0]`.
    pub fn apply(&self, u: &[f64], dt: f64) -> anyhow::Result<Vec<f64>> {
        let mut v = vec![0.0; u.len()];
        (self.def.simulate)(&self.params, u, dt, &mut v)
            .map_err(|e| anyhow::anyhow!("hysteresis `{}`: {e}", self.def.name))?;
        anyhow::ensure!(
            v.iter().all(|x| x.is_finite()),
            "hysteresis `{}` gave a non-finite output",
            self.def.name
        );
        Ok(v)
    }
}

/// A whole Hammerstein model; `fronts` empty means linear.
#[derive(Debug, Clone)]
pub struct Hammerstein {
    pub fronts: Vec<Front>,
    pub linear: Modal,
}

impl Hammerstein {
    /// Simulates from rest; `u[j]` is input `j`.
    pub fn simulate(&self, u: &[Vec<f64>], dt: f64) -> anyhow::Result<Vec<Vec<f64>>> {
        if self.fronts.is_empty() {
            return self.linear.simulate(u);
        }
        anyhow::ensure!(
            u.len() == self.fronts.len(),
            "the model has {} inputs, the record {}",
            self.fronts.len(),
            u.len()
        );
        let v = u
            .iter()
            .zip(&self.fronts)
            .map(|(x, f)| f.apply(x, dt))
            .collect::<anyhow::Result<Vec<_>>>()?;
        self.linear.simulate(&v)
    }
}

/// Search coordinates of a registry model: log10 for log-scaled parameters.
struct Coords {
    log: Vec<bool>,
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl Coords {
    fn of(def: &'static ModelDef, u: &[f64], dt: f64) -> Self {
        // Scaled as if the output were the input: a gain near one.
        let specs = (def.params)(&Scales::of(u, u, dt));
        let log: Vec<bool> = specs.iter().map(|s| s.log).collect();
        let to = |s: &models::ParamSpec, v: f64| {
            if s.log {
                v.max(f64::MIN_POSITIVE).log10()
            } else {
                v
            }
        };
        // Just inside the box: some models refuse its edges (CBW: gamma = -beta).
        let edge = |s: &models::ParamSpec| 1e-3 * (to(s, s.hi) - to(s, s.lo));
        let lo: Vec<f64> = specs.iter().map(|s| to(s, s.lo) + edge(s)).collect();
        let hi: Vec<f64> = specs.iter().map(|s| to(s, s.hi) - edge(s)).collect();
        Self { log, lo, hi }
    }
    fn params(&self, z: &[f64]) -> Vec<f64> {
        z.iter()
            .zip(&self.log)
            .map(|(v, l)| if *l { 10f64.powf(*v) } else { *v })
            .collect()
    }
}

/// One training record for the joint fit: its input over one period and the
/// period-averaged output spectrum.
pub struct Periodic {
    pub u: Vec<Vec<f64>>,
    pub y: Vec<Vec<C64>>,
}

impl Periodic {
    /// From a record's spectra and its samples (the last period's input).
    pub fn of(sp: &PeriodicSpectra, u: &[Vec<f64>]) -> Self {
        let n = sp.period;
        Self {
            u: u.iter().map(|x| x[x.len() - n..].to_vec()).collect(),
            y: sp.y.clone(),
        }
    }
}

/// Steady-state spectra of `H(u)` over one period (simulated over two).
fn front_spectrum(
    def: &'static ModelDef,
    p: &[f64],
    u: &[f64],
    dt: f64,
) -> anyhow::Result<Vec<C64>> {
    let n = u.len();
    let twice: Vec<f64> = u.iter().chain(u).copied().collect();
    let mut v = vec![0.0; 2 * n];
    (def.simulate)(p, &twice, dt, &mut v)
        .map_err(|e| anyhow::anyhow!("hysteresis `{}`: {e}", def.name))?;
    anyhow::ensure!(
        v.iter().all(|x| x.is_finite()),
        "hysteresis `{}` diverged",
        def.name
    );
    Ok(period_spectra(&v[n..], n).remove(0))
}

/// Where the joint refinement starts the hysteresis.
#[derive(Debug, Clone, Copy)]
pub enum Start<'a> {
    /// At this fraction (0..1) of each parameter's search box (in its search coordinate:
    /// log10 for log-scaled parameters), `linear` rescaled per input by the front's
    /// least-squares gain.
    Box(f64),
    /// At these parameters per input (clamped into the box), `linear` as given: the
    /// continuation of an earlier fit.
    Params(&'a [Vec<f64>]),
}

/// Joint identification of the hysteresis fronts and the linear block from `start`, the
/// linear model `linear` identified on the inputs themselves (`crate::ss::identify` tries
/// three starts).
pub fn identify_from(
    def: &'static ModelDef,
    recs: &[Periodic],
    dt: f64,
    linear: &Modal,
    cfg: &PemConfig,
    from: Start,
) -> anyhow::Result<(Hammerstein, f64)> {
    anyhow::ensure!(
        !def.dynamic,
        "`{}` has its own dynamics; the Hammerstein front end needs a rate-independent hysteresis model",
        def.name
    );
    let m = linear.inputs();
    anyhow::ensure!(!recs.is_empty(), "no records");
    let n = recs[0].u[0].len();
    let all_u: Vec<Vec<f64>> = (0..m)
        .map(|j| recs.iter().flat_map(|r| r.u[j].iter().copied()).collect())
        .collect();
    let coords: Vec<Coords> = all_u.iter().map(|u| Coords::of(def, u, dt)).collect();
    let k_per: Vec<usize> = coords.iter().map(|c| c.lo.len()).collect();
    let offsets: Vec<usize> = k_per
        .iter()
        .scan(0, |s, k| {
            let o = *s;
            *s += k;
            Some(o)
        })
        .collect();
    let theta0: Vec<f64> = match from {
        Start::Box(at) => {
            let at = at.clamp(0.0, 1.0);
            coords
                .iter()
                .flat_map(|c| c.lo.iter().zip(&c.hi).map(move |(a, b)| a + at * (b - a)))
                .collect()
        }
        Start::Params(ps) => {
            anyhow::ensure!(
                ps.len() == m && ps.iter().zip(&coords).all(|(p, c)| p.len() == c.lo.len()),
                "the start has {} hysteresis parameter sets for {m} inputs",
                ps.len()
            );
            ps.iter()
                .zip(&coords)
                .flat_map(|(p, c)| {
                    p.iter().enumerate().map(move |(i, v)| {
                        let z = if c.log[i] {
                            v.max(f64::MIN_POSITIVE).log10()
                        } else {
                            *v
                        };
                        z.clamp(c.lo[i], c.hi[i])
                    })
                })
                .collect()
        }
    };
    let lo: Vec<f64> = coords.iter().flat_map(|c| c.lo.iter().copied()).collect();
    let hi: Vec<f64> = coords.iter().flat_map(|c| c.hi.iter().copied()).collect();
    let nt = theta0.len();
    let bins = n / 2 + 1;
    let weights: Vec<f64> = (0..bins).map(|k| bin_weight(k, n)).collect();
    let fronts_at = |theta: &[f64]| -> Vec<Vec<f64>> {
        (0..m)
            .map(|j| coords[j].params(&theta[offsets[j]..offsets[j] + k_per[j]]))
            .collect()
    };
    // V[r][j][k] for a theta.
    let spectra = |theta: &[f64]| -> anyhow::Result<Vec<Vec<Vec<C64>>>> {
        let ps = fronts_at(theta);
        recs.par_iter()
            .map(|r| {
                (0..m)
                    .map(|j| front_spectrum(def, &ps[j], &r.u[j], dt))
                    .collect()
            })
            .collect()
    };
    let stats_fn = |theta: &[f64], derivs: bool| -> anyhow::Result<Vec<LineStats>> {
        let v = spectra(theta)?;
        // Forward differences per theta parameter: only its actuator's channel moves.
        let dv: Vec<(usize, Vec<Vec<C64>>)> = if derivs {
            (0..nt)
                .into_par_iter()
                .map(|b| {
                    let j = offsets.iter().rposition(|&o| o <= b).unwrap_or(0);
                    let h = 1e-6 * (hi[b] - lo[b]).max(1e-12);
                    let mut tp = theta.to_vec();
                    let h = if tp[b] + h > hi[b] { -h } else { h };
                    tp[b] += h;
                    let ps = fronts_at(&tp);
                    let d = recs
                        .iter()
                        .zip(&v)
                        .map(|(r, vr)| {
                            let s = front_spectrum(def, &ps[j], &r.u[j], dt)?;
                            Ok(s.iter().zip(&vr[j]).map(|(a, b0)| (a - b0) / h).collect())
                        })
                        .collect::<anyhow::Result<Vec<Vec<C64>>>>()?;
                    Ok((j, d))
                })
                .collect::<anyhow::Result<_>>()?
        } else {
            Vec::new()
        };
        let p = recs[0].y.len();
        let out = (0..bins)
            .into_par_iter()
            .map(|k| {
                let w = C64::new(weights[k], 0.0);
                let mut svv = DMatrix::<C64>::zeros(m, m);
                let mut syv = DMatrix::<C64>::zeros(p, m);
                let mut syy = 0.0;
                for (r, vr) in recs.iter().zip(&v) {
                    let vk = DMatrix::from_fn(m, 1, |j, _| vr[j][k]);
                    let yk = DMatrix::from_fn(p, 1, |o, _| r.y[o][k]);
                    svv += &vk * vk.adjoint();
                    syv += &yk * vk.adjoint();
                    syy += yk.norm_squared();
                }
                let col = |j: usize, x: C64| {
                    DMatrix::from_fn(m, 1, |i, _| if i == j { x } else { C64::new(0.0, 0.0) })
                };
                let mut sdv_v = Vec::with_capacity(dv.len());
                let mut sy_dv = Vec::with_capacity(dv.len());
                for (j, d) in &dv {
                    let mut a = DMatrix::<C64>::zeros(m, m);
                    let mut b = DMatrix::<C64>::zeros(p, m);
                    for (ri, (r, vr)) in recs.iter().zip(&v).enumerate() {
                        let dvk = col(*j, d[ri][k]);
                        let vk = DMatrix::from_fn(m, 1, |jj, _| vr[jj][k]);
                        let yk = DMatrix::from_fn(p, 1, |o, _| r.y[o][k]);
                        a += &dvk * vk.adjoint();
                        b += &yk * dvk.adjoint();
                    }
                    sdv_v.push(a * w);
                    sy_dv.push(b * w);
                }
                let mut sdv_dv = Vec::with_capacity(dv.len() * dv.len());
                for (ja, da) in &dv {
                    for (jb, db) in &dv {
                        let mut s = DMatrix::<C64>::zeros(m, m);
                        for ri in 0..recs.len() {
                            s[(*jb, *ja)] += db[ri][k] * da[ri][k].conj();
                        }
                        sdv_dv.push(s * w);
                    }
                }
                LineStats {
                    z: C64::from_polar(1.0, 2.0 * std::f64::consts::PI * k as f64 / n as f64),
                    svv: svv * w,
                    syv: syv * w,
                    syy: syy * weights[k],
                    sdv_v,
                    sy_dv,
                    sdv_dv,
                }
            })
            .collect();
        Ok(out)
    };
    // Start: the linear block rescaled per input by the front's least-squares gain (a
    // continuation keeps it as given).
    let mut start = linear.clone();
    let ps0 = fronts_at(&theta0);
    for j in 0..if matches!(from, Start::Box(_)) { m } else { 0 } {
        let mut v = vec![0.0; all_u[j].len()];
        (def.simulate)(&ps0[j], &all_u[j], dt, &mut v)
            .map_err(|e| anyhow::anyhow!("hysteresis `{}`: {e}", def.name))?;
        let uv: f64 = all_u[j].iter().zip(&v).map(|(a, b)| a * b).sum();
        let vv: f64 = v.iter().map(|b| b * b).sum();
        let k = if vv > 0.0 { uv / vv } else { 1.0 };
        for i in 0..start.b.nrows() {
            start.b[(i, j)] *= k;
        }
        for o in 0..start.d.nrows() {
            start.d[(o, j)] *= k;
        }
    }
    let r = pem::refine(&start, &theta0, (&lo, &hi), &stats_fn, cfg)?;
    let fronts = fronts_at(&r.theta)
        .into_iter()
        .map(|params| Front { def, params })
        .collect();
    Ok((
        Hammerstein {
            fronts,
            linear: r.model,
        },
        r.cost,
    ))
}
