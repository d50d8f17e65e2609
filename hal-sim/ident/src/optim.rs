//! Global (differential evolution, particle swarm) and local (Levenberg-Marquardt) optimisers
//! for identification, and golden-section search on one coordinate ([`golden`]).
//!
//! All work inside a box `lo <= x <= hi`. DE or PSO ([`Optimizer`]) is the global search
//! (002 uses PSO with an RMSE fitness, 002 eq. (6)-(7); [`pso`]); LM then polishes on the
//! residual vector (the RMSE of 004 eq. (23) is its norm). Costs and
//! residuals are plain closures; the population and the Jacobian columns are evaluated in
//! parallel with rayon. Runs are reproducible for a given seed (the random numbers are drawn
//! serially, only the evaluations are parallel).

// `!(x > y)` keeps NaN out; intended.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rayon::prelude::*;

use crate::numeric::{solve_spd, Rng};

pub mod pso;
pub use pso::{particle_swarm, PsoConfig};

/// The global search of a fit (`piezo fit --optimizer`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Optimizer {
    /// Differential evolution ([`differential_evolution`]).
    #[default]
    De,
    /// Particle swarm, the method of 002 sec. 3 ([`particle_swarm`]).
    Pso,
}

/// Settings of a global search, shared by DE and PSO.
#[derive(Debug, Clone, Default)]
pub struct SearchConfig {
    pub optimizer: Optimizer,
    /// DE population / PSO swarm size (0: `max(15, 10 * dim)` for both).
    pub population: usize,
    /// DE generations / PSO iterations: with equal sizes, the same evaluation budget.
    pub generations: usize,
    pub seed: u64,
    /// Label for progress lines on stderr (None: silent).
    pub progress: Option<String>,
}

/// Runs the chosen global search over the box (see [`differential_evolution`] and
/// [`particle_swarm`]; each keeps its other settings at their defaults).
pub fn global_search<F>(
    cost: F,
    lo: &[f64],
    hi: &[f64],
    seeds: &[Vec<f64>],
    cfg: &SearchConfig,
) -> anyhow::Result<Optimum>
where
    F: Fn(&[f64]) -> f64 + Sync,
{
    match cfg.optimizer {
        Optimizer::De => {
            let de = DeConfig {
                population: cfg.population,
                generations: cfg.generations,
                seed: cfg.seed,
                progress: cfg.progress.clone(),
                ..Default::default()
            };
            differential_evolution(cost, lo, hi, seeds, &de)
        }
        Optimizer::Pso => {
            let pso = PsoConfig {
                particles: cfg.population,
                iterations: cfg.generations,
                seed: cfg.seed,
                progress: cfg.progress.clone(),
                ..Default::default()
            };
            particle_swarm(cost, lo, hi, seeds, &pso)
        }
    }
}

/// Checks a box and a start point; the message names what is wrong.
pub fn check_bounds(lo: &[f64], hi: &[f64]) -> anyhow::Result<()> {
    anyhow::ensure!(!lo.is_empty(), "no parameters to optimise");
    anyhow::ensure!(
        lo.len() == hi.len(),
        "bounds have {} lower and {} upper values",
        lo.len(),
        hi.len()
    );
    for (i, (l, h)) in lo.iter().zip(hi).enumerate() {
        anyhow::ensure!(
            l.is_finite() && h.is_finite() && l <= h,
            "parameter {i}: bounds [{l}, {h}] are not a finite interval"
        );
    }
    Ok(())
}

/// Result of an optimisation.
#[derive(Debug, Clone, PartialEq)]
pub struct Optimum {
    /// Best point found (inside the bounds).
    pub x: Vec<f64>,
    /// Its cost (DE: the cost closure; LM: sum of squared residuals).
    pub cost: f64,
    /// Cost evaluations (LM: residual-vector evaluations).
    pub evals: usize,
    /// Generations (DE) or iterations (LM) done.
    pub iterations: usize,
}

/// Differential evolution settings (DE/current-to-pbest/1/bin-like: rand/1 with a pull to the best).
#[derive(Debug, Clone)]
pub struct DeConfig {
    /// Population size; 0 chooses `max(15, 10 * dim)`.
    pub population: usize,
    pub generations: usize,
    /// Differential weight.
    pub f: f64,
    /// Crossover probability.
    pub cr: f64,
    pub seed: u64,
    /// Stop when the population's cost spread is below `tol * |best| + abs_tol`.
    pub tol: f64,
    pub abs_tol: f64,
    /// Label for progress lines on stderr (None: silent).
    pub progress: Option<String>,
}

impl Default for DeConfig {
    fn default() -> Self {
        Self {
            population: 0,
            generations: 200,
            f: 0.7,
            cr: 0.9,
            seed: 1,
            tol: 1e-8,
            abs_tol: 0.0,
            progress: None,
        }
    }
}

/// Non-finite costs rank last.
#[inline]
fn sane(c: f64) -> f64 {
    if c.is_nan() {
        f64::INFINITY
    } else {
        c
    }
}

/// Minimises `cost` over the box `[lo, hi]` by differential evolution. Extra start points
/// in `seeds` (clamped into the box) replace the first random members.
pub fn differential_evolution<F>(
    cost: F,
    lo: &[f64],
    hi: &[f64],
    seeds: &[Vec<f64>],
    cfg: &DeConfig,
) -> anyhow::Result<Optimum>
where
    F: Fn(&[f64]) -> f64 + Sync,
{
    check_bounds(lo, hi)?;
    let dim = lo.len();
    let np = population_size(cfg.population, dim, 4);
    let mut rng = Rng::new(cfg.seed);
    let mut pop = initial_points(&mut rng, np, lo, hi, seeds);
    let mut costs = costs_of(&cost, &pop);
    let mut evals = np;
    let mut gen = 0;
    let report_every = (cfg.generations / 10).max(1);
    while gen < cfg.generations {
        let best = argmin(&costs);
        let (cmin, cmax) = costs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &c| {
                (a.min(c), b.max(c))
            });
        if cmax.is_finite() && cmax - cmin <= cfg.tol * cmin.abs() + cfg.abs_tol {
            break;
        }
        // Trial vectors: rand/1 with dither on F, plus a pull to the best member.
        let trials: Vec<Vec<f64>> = (0..np)
            .map(|i| {
                let (a, b, c) = three_others(&mut rng, np, i);
                let f = cfg.f * (0.8 + 0.4 * rng.uniform());
                let jr = rng.below(dim);
                (0..dim)
                    .map(|j| {
                        if j == jr || rng.uniform() < cfg.cr {
                            let v = pop[a][j]
                                + f * (pop[b][j] - pop[c][j])
                                + 0.5 * f * (pop[best][j] - pop[a][j]);
                            // Bounce back inside between the parent and the violated bound.
                            if v < lo[j] {
                                lo[j] + rng.uniform() * (pop[i][j] - lo[j])
                            } else if v > hi[j] {
                                hi[j] - rng.uniform() * (hi[j] - pop[i][j])
                            } else {
                                v
                            }
                        } else {
                            pop[i][j]
                        }
                    })
                    .collect()
            })
            .collect();
        let tc = costs_of(&cost, &trials);
        evals += np;
        for (i, (x, c)) in trials.into_iter().zip(tc).enumerate() {
            if c <= costs[i] {
                pop[i] = x;
                costs[i] = c;
            }
        }
        gen += 1;
        if gen % report_every == 0 {
            progress(&cfg.progress, "DE generation", gen, cfg.generations, || {
                costs[argmin(&costs)]
            });
        }
    }
    let best = argmin(&costs);
    Ok(Optimum {
        x: pop.swap_remove(best),
        cost: costs[best],
        evals,
        iterations: gen,
    })
}

/// A population of `requested` members, or `max(15, 10 * dim)` for 0; at least `min`.
fn population_size(requested: usize, dim: usize, min: usize) -> usize {
    if requested == 0 {
        (10 * dim).max(15)
    } else {
        requested.max(min)
    }
}

/// `n` start points: the `seeds` of the right dimension (clamped into the box) first, then
/// uniform random points of the box.
fn initial_points(
    rng: &mut Rng,
    n: usize,
    lo: &[f64],
    hi: &[f64],
    seeds: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    let dim = lo.len();
    (0..n)
        .map(|i| match seeds.get(i) {
            Some(s) if s.len() == dim => clamp(s, lo, hi),
            _ => (0..dim)
                .map(|j| lo[j] + rng.uniform() * (hi[j] - lo[j]))
                .collect(),
        })
        .collect()
}

/// The costs of `points`, evaluated in parallel (non-finite ones rank last).
fn costs_of<F>(cost: &F, points: &[Vec<f64>]) -> Vec<f64>
where
    F: Fn(&[f64]) -> f64 + Sync,
{
    points.par_iter().map(|x| sane(cost(x))).collect()
}

/// A progress line on stderr under `label` (none without one).
fn progress(label: &Option<String>, what: &str, done: usize, total: usize, best: impl Fn() -> f64) {
    if let Some(label) = label {
        eprintln!("{label}: {what} {done}/{total}: best cost {:.6e}", best());
    }
}

fn argmin(c: &[f64]) -> usize {
    let mut k = 0;
    for (i, v) in c.iter().enumerate() {
        if *v < c[k] {
            k = i;
        }
    }
    k
}

fn three_others(rng: &mut Rng, n: usize, i: usize) -> (usize, usize, usize) {
    let mut pick = |not: &[usize]| loop {
        let k = rng.below(n);
        if !not.contains(&k) {
            break k;
        }
    };
    let a = pick(&[i]);
    let b = pick(&[i, a]);
    let c = pick(&[i, a, b]);
    (a, b, c)
}

fn clamp(x: &[f64], lo: &[f64], hi: &[f64]) -> Vec<f64> {
    x.iter()
        .zip(lo.iter().zip(hi))
        .map(|(v, (l, h))| {
            if v.is_nan() {
                0.5 * (l + h)
            } else {
                v.clamp(*l, *h)
            }
        })
        .collect()
}

/// Levenberg-Marquardt settings.
#[derive(Debug, Clone)]
pub struct LmConfig {
    pub max_iterations: usize,
    /// Stop when one accepted step lowers the cost by less than `ftol` (relative).
    pub ftol: f64,
    /// Stop when the step is smaller than `xtol` relative to `|x| + xtol`.
    pub xtol: f64,
    /// Initial damping (relative to the diagonal of `J^T J`).
    pub lambda0: f64,
    /// Finite-difference step relative to `|x_j|` (floored by 1e-6 of the bound width).
    pub fd_step: f64,
    pub progress: Option<String>,
}

impl Default for LmConfig {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            ftol: 1e-10,
            xtol: 1e-10,
            lambda0: 1e-3,
            fd_step: 1e-7,
            progress: None,
        }
    }
}

fn sumsq(r: &[f64]) -> f64 {
    let s: f64 = r.iter().map(|v| v * v).sum();
    if s.is_nan() {
        f64::INFINITY
    } else {
        s
    }
}

/// Minimises `sum(r(x)^2)` over the box from `x0` by Levenberg-Marquardt with a forward
/// finite-difference Jacobian (columns in parallel). `residuals(x, r)` fills `r` (length `m`).
/// Steps are clamped into the box; a parameter pinned at a bound stays free to move back.
pub fn levenberg_marquardt<R>(
    residuals: R,
    m: usize,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    cfg: &LmConfig,
) -> anyhow::Result<Optimum>
where
    R: Fn(&[f64], &mut [f64]) + Sync,
{
    check_bounds(lo, hi)?;
    let n = lo.len();
    anyhow::ensure!(
        x0.len() == n,
        "start point has {} values, bounds have {n}",
        x0.len()
    );
    anyhow::ensure!(m > 0, "no residuals");
    let mut x = clamp(x0, lo, hi);
    let mut r = vec![0.0; m];
    residuals(&x, &mut r);
    let mut cost = sumsq(&r);
    anyhow::ensure!(
        cost.is_finite(),
        "residuals at the start point are not finite"
    );
    let mut evals = 1;
    let mut lambda = cfg.lambda0;
    let mut it = 0;
    let mut trial_r = vec![0.0; m];
    while it < cfg.max_iterations {
        it += 1;
        // Jacobian columns by forward differences, one residual evaluation each.
        let cols: Vec<(Vec<f64>, f64)> = (0..n)
            .into_par_iter()
            .map(|j| {
                let width = hi[j] - lo[j];
                if width == 0.0 {
                    return (vec![0.0; m], 0.0); // fixed parameter
                }
                let mut h = cfg.fd_step * x[j].abs().max(1e-6 * width).max(1e-300);
                if x[j] + h > hi[j] {
                    h = -h; // step inward at the upper bound
                }
                let mut xp = x.clone();
                xp[j] += h;
                let mut rp = vec![0.0; m];
                residuals(&xp, &mut rp);
                let h = xp[j] - x[j];
                for (p, r0) in rp.iter_mut().zip(&r) {
                    *p = if h != 0.0 { (*p - r0) / h } else { 0.0 };
                }
                (rp, h)
            })
            .collect();
        evals += n;
        // Normal equations A = J^T J, g = J^T r.
        let mut a = vec![0.0; n * n];
        let mut g = vec![0.0; n];
        for i in 0..n {
            let ci = &cols[i].0;
            g[i] = dot(ci, &r);
            for k in 0..=i {
                let v = dot(ci, &cols[k].0);
                a[i * n + k] = v;
                a[k * n + i] = v;
            }
        }
        if a.iter().chain(&g).any(|v| !v.is_finite()) {
            break;
        }
        // Parameters pinned at a bound with the descent pointing outward leave the step
        // (active set): clamping their step would spoil the others' direction.
        for j in 0..n {
            let pinned =
                hi[j] == lo[j] || (x[j] <= lo[j] && g[j] > 0.0) || (x[j] >= hi[j] && g[j] < 0.0);
            if pinned {
                for k in 0..n {
                    a[j * n + k] = 0.0;
                    a[k * n + j] = 0.0;
                }
                a[j * n + j] = 1.0;
                g[j] = 0.0;
            }
        }
        let mut improved = false;
        let mut small_step = false;
        for _ in 0..30 {
            let mut damped = a.clone();
            for i in 0..n {
                let d = a[i * n + i];
                damped[i * n + i] = d + lambda * d.max(1e-12 * (1.0 + d));
            }
            let Some(dx) = solve_spd(&damped, &g, n) else {
                lambda *= 10.0;
                continue;
            };
            let xn: Vec<f64> = (0..n).map(|i| (x[i] - dx[i]).clamp(lo[i], hi[i])).collect();
            let step: f64 = (0..n)
                .map(|i| ((xn[i] - x[i]) / (x[i].abs() + cfg.xtol)).powi(2))
                .sum::<f64>()
                .sqrt();
            residuals(&xn, &mut trial_r);
            evals += 1;
            let c = sumsq(&trial_r);
            if c < cost {
                let rel = (cost - c) / cost.max(f64::MIN_POSITIVE);
                x = xn;
                std::mem::swap(&mut r, &mut trial_r);
                cost = c;
                lambda = (lambda / 3.0).max(1e-12);
                improved = true;
                small_step = rel < cfg.ftol || step < cfg.xtol;
                break;
            }
            if step < cfg.xtol {
                small_step = true;
                break;
            }
            lambda *= 4.0;
            if lambda > 1e16 {
                break;
            }
        }
        if let Some(label) = &cfg.progress {
            eprintln!("{label}: LM iteration {it}: cost {cost:.6e} (lambda {lambda:.1e})");
        }
        if !improved || small_step {
            break;
        }
    }
    Ok(Optimum {
        x,
        cost,
        evals,
        iterations: it,
    })
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Minimises `f` on `[a, b]` by golden-section search with `evals` evaluations (at least
/// two); returns the best point evaluated and its value. Non-finite values count as worse
/// than any finite.
pub fn golden(f: &mut dyn FnMut(f64) -> f64, a: f64, b: f64, evals: usize) -> (f64, f64) {
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let mut eval = |x: f64| {
        let v = f(x);
        if v.is_finite() {
            v
        } else {
            f64::INFINITY
        }
    };
    let (mut a, mut b) = (a, b);
    let (mut c, mut d) = (b - r * (b - a), a + r * (b - a));
    let (mut fc, mut fd) = (eval(c), eval(d));
    for _ in 2..evals.max(2) {
        if fc <= fd {
            (b, d, fd) = (d, c, fc);
            c = b - r * (b - a);
            fc = eval(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + r * (b - a);
            fd = eval(d);
        }
    }
    if fc <= fd {
        (c, fc)
    } else {
        (d, fd)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rosenbrock(x: &[f64]) -> f64 {
        x.windows(2)
            .map(|w| 100.0 * (w[1] - w[0] * w[0]).powi(2) + (1.0 - w[0]).powi(2))
            .sum()
    }

    #[test]
    fn de_finds_rosenbrock_minimum() {
        let cfg = DeConfig {
            generations: 1500,
            tol: 1e-14,
            ..Default::default()
        };
        let o = differential_evolution(rosenbrock, &[-5.0; 3], &[5.0; 3], &[], &cfg).unwrap();
        assert!(o.cost < 1e-6, "{o:?}");
        for v in &o.x {
            assert!((v - 1.0).abs() < 1e-2, "{o:?}");
        }
    }

    #[test]
    fn de_escapes_local_minima_of_rastrigin() {
        let rastrigin = |x: &[f64]| {
            x.iter()
                .map(|v| v * v - 10.0 * (2.0 * std::f64::consts::PI * v).cos() + 10.0)
                .sum::<f64>()
        };
        let cfg = DeConfig {
            generations: 600,
            // Separable function: low crossover explores one coordinate at a time.
            cr: 0.2,
            seed: 3,
            ..Default::default()
        };
        let o = differential_evolution(rastrigin, &[-5.12; 4], &[5.12; 4], &[], &cfg).unwrap();
        assert!(o.cost < 1e-3, "{o:?}");
    }

    #[test]
    fn de_is_reproducible_and_respects_bounds() {
        let cfg = DeConfig {
            generations: 50,
            ..Default::default()
        };
        // Minimum outside the box: the answer is on the bound.
        let f = |x: &[f64]| (x[0] - 3.0).powi(2) + (x[1] + 1.0).powi(2);
        let a = differential_evolution(f, &[0.0, 0.0], &[2.0, 1.0], &[], &cfg).unwrap();
        let b = differential_evolution(f, &[0.0, 0.0], &[2.0, 1.0], &[], &cfg).unwrap();
        assert_eq!(a, b);
        assert!((a.x[0] - 2.0).abs() < 1e-3 && a.x[1].abs() < 1e-3, "{a:?}");
        assert!(a.x[0] <= 2.0 && a.x[1] >= 0.0);
    }

    #[test]
    fn de_survives_nan_costs() {
        let f = |x: &[f64]| {
            if x[0] < 0.0 {
                f64::NAN
            } else {
                (x[0] - 0.5).powi(2)
            }
        };
        let o = differential_evolution(f, &[-1.0], &[1.0], &[], &DeConfig::default()).unwrap();
        assert!((o.x[0] - 0.5).abs() < 1e-3, "{o:?}");
    }

    #[test]
    fn lm_solves_rosenbrock_from_far() {
        let res = |x: &[f64], r: &mut [f64]| {
            r[0] = 10.0 * (x[1] - x[0] * x[0]);
            r[1] = 1.0 - x[0];
        };
        let o = levenberg_marquardt(
            res,
            2,
            &[-1.2, 1.0],
            &[-5.0, -5.0],
            &[5.0, 5.0],
            &LmConfig::default(),
        )
        .unwrap();
        assert!(o.cost < 1e-16, "{o:?}");
        assert!((o.x[0] - 1.0).abs() < 1e-7 && (o.x[1] - 1.0).abs() < 1e-7);
    }

    #[test]
    fn lm_fits_exponential_with_badly_scaled_parameters() {
        // y = a * exp(-b t) + c with a ~ 1e4, b ~ 1e-2, c ~ 1e-3.
        let t: Vec<f64> = (0..200).map(|i| i as f64).collect();
        let truth = [2.5e4, 1.7e-2, 3e-3];
        let y: Vec<f64> = t
            .iter()
            .map(|t| truth[0] * (-truth[1] * t).exp() + truth[2])
            .collect();
        let res = |x: &[f64], r: &mut [f64]| {
            for ((ri, ti), yi) in r.iter_mut().zip(&t).zip(&y) {
                *ri = x[0] * (-x[1] * ti).exp() + x[2] - yi;
            }
        };
        let o = levenberg_marquardt(
            res,
            t.len(),
            &[1e4, 5e-2, 0.0],
            &[0.0, 0.0, -1.0],
            &[1e5, 1.0, 1.0],
            &LmConfig::default(),
        )
        .unwrap();
        for (v, w) in o.x.iter().zip(&truth) {
            assert!((v - w).abs() <= 1e-6 * w.abs().max(1e-3), "{o:?}");
        }
    }

    #[test]
    fn lm_moves_free_parameters_when_one_is_pinned() {
        // Unconstrained optimum (2, 1); with x0 <= 1 the optimum is (1, 1).
        let res = |x: &[f64], r: &mut [f64]| {
            r[0] = x[0] + x[1] - 3.0;
            r[1] = x[0] - x[1] - 1.0 + 0.5 * (x[0] - 1.0);
        };
        let o = levenberg_marquardt(
            res,
            2,
            &[0.0, 5.0],
            &[-5.0; 2],
            &[1.0, 5.0],
            &LmConfig::default(),
        )
        .unwrap();
        let want = {
            // x0 = 1: minimise (x1 - 2)^2 + (x1)^2 -> x1 = 1.
            [1.0, 1.0]
        };
        assert!(
            (o.x[0] - want[0]).abs() < 1e-9 && (o.x[1] - want[1]).abs() < 1e-6,
            "{o:?}"
        );
    }

    #[test]
    fn lm_stops_at_bound() {
        let res = |x: &[f64], r: &mut [f64]| r[0] = x[0] - 3.0;
        let o = levenberg_marquardt(res, 1, &[0.0], &[-1.0], &[1.0], &LmConfig::default()).unwrap();
        assert_eq!(o.x[0], 1.0);
    }

    #[test]
    fn bad_bounds_are_named() {
        let e = differential_evolution(|_| 0.0, &[1.0], &[0.0], &[], &DeConfig::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("parameter 0"), "{e}");
        let e = levenberg_marquardt(
            |_, _| {},
            1,
            &[0.0, 1.0],
            &[0.0],
            &[1.0],
            &LmConfig::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("start point"), "{e}");
    }

    #[test]
    fn golden_finds_the_minimum_of_a_parabola_inside_its_bracket() {
        let mut n = 0;
        let (x, v) = golden(
            &mut |x| {
                n += 1;
                (x - 0.3) * (x - 0.3) + 2.0
            },
            -1.0,
            1.0,
            30,
        );
        assert_eq!(n, 30);
        assert!((x - 0.3).abs() < 1e-5, "{x}");
        assert!((v - 2.0).abs() < 1e-9);
        // NaN is worse than anything finite; the bracket's end is approached.
        let (x, _) = golden(&mut |x| if x > 0.9 { f64::NAN } else { -x }, 0.0, 1.0, 40);
        assert!((0.85..=0.9).contains(&x), "{x}");
    }
}
