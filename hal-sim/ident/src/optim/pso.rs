//! Particle swarm optimisation, the identification method of 002 (sec. 3: the RMSE fitness
//! of 002 eq. (6) minimised over the model parameters, eq. (7)).
//!
//! 002 ran a Matlab PSO toolbox and gives no update law; this is the standard global-best
//! swarm with the constriction coefficients of Clerc and Kennedy (2002), inertia
//! `w = 0.7298` and acceleration `c1 = c2 = 1.49618`:
//! `v <- w*v + c1*r1*(pbest - x) + c2*r2*(gbest - x)`, `x <- x + v`, each velocity
//! component limited to the box width, positions kept in the box by reflection. It stops
//! after `iterations`, or when the best cost has not improved by more than
//! `tol * |best| + abs_tol` for `stall` iterations (004 sec. 4.2 stopped its PSO the same
//! way, after 250 epochs without a change above 1e-25).

use super::{argmin, check_bounds, costs_of, initial_points, population_size, progress, Optimum};
use crate::numeric::Rng;

/// Particle swarm settings.
#[derive(Debug, Clone)]
pub struct PsoConfig {
    /// Swarm size; 0 chooses `max(15, 10 * dim)` (the DE default, so both spend the same
    /// evaluations per iteration).
    pub particles: usize,
    pub iterations: usize,
    /// Inertia weight.
    pub inertia: f64,
    /// Pull towards the particle's own best (cognitive).
    pub c_self: f64,
    /// Pull towards the swarm's best (social).
    pub c_social: f64,
    pub seed: u64,
    /// Stall test: relative and absolute improvement that counts.
    pub tol: f64,
    pub abs_tol: f64,
    /// Iterations without such an improvement before stopping (0: never stop early).
    pub stall: usize,
    /// Label for progress lines on stderr (None: silent).
    pub progress: Option<String>,
}

impl Default for PsoConfig {
    fn default() -> Self {
        Self {
            particles: 0,
            iterations: 200,
            inertia: 0.7298,
            c_self: 1.49618,
            c_social: 1.49618,
            seed: 1,
            tol: 1e-10,
            abs_tol: 0.0,
            stall: 100,
            progress: None,
        }
    }
}

/// Minimises `cost` over the box `[lo, hi]` by particle swarm optimisation. Extra start
/// points in `seeds` (clamped into the box) replace the first random particles. Costs are
/// evaluated in parallel; the random numbers are drawn serially, so a seed reproduces a run.
pub fn particle_swarm<F>(
    cost: F,
    lo: &[f64],
    hi: &[f64],
    seeds: &[Vec<f64>],
    cfg: &PsoConfig,
) -> anyhow::Result<Optimum>
where
    F: Fn(&[f64]) -> f64 + Sync,
{
    check_bounds(lo, hi)?;
    anyhow::ensure!(
        [cfg.inertia, cfg.c_self, cfg.c_social]
            .iter()
            .all(|v| v.is_finite() && *v >= 0.0),
        "PSO: inertia and acceleration coefficients must be finite and >= 0"
    );
    let dim = lo.len();
    let np = population_size(cfg.particles, dim, 2);
    let width: Vec<f64> = lo.iter().zip(hi).map(|(l, h)| h - l).collect();
    let mut rng = Rng::new(cfg.seed);
    let mut x = initial_points(&mut rng, np, lo, hi, seeds);
    // Initial velocities: a random fraction of the box, either direction.
    let mut v: Vec<Vec<f64>> = (0..np)
        .map(|_| {
            (0..dim)
                .map(|j| (rng.uniform() - 0.5) * 0.2 * width[j])
                .collect()
        })
        .collect();
    let mut cost_x = costs_of(&cost, &x);
    let mut pbest = x.clone();
    let mut pcost = cost_x.clone();
    let mut g = argmin(&pcost);
    let mut evals = np;
    let mut it = 0;
    let mut since_improved = 0;
    let report_every = (cfg.iterations / 10).max(1);
    while it < cfg.iterations {
        let gbest = pbest[g].clone();
        for (xi, (vi, pi)) in x.iter_mut().zip(v.iter_mut().zip(&pbest)) {
            for j in 0..dim {
                let (r1, r2) = (rng.uniform(), rng.uniform());
                let vj = cfg.inertia * vi[j]
                    + cfg.c_self * r1 * (pi[j] - xi[j])
                    + cfg.c_social * r2 * (gbest[j] - xi[j]);
                let vj = vj.clamp(-width[j], width[j]);
                let mut p = xi[j] + vj;
                // Reflect at a violated bound and reverse the component (the width limit
                // keeps one reflection enough).
                vi[j] = vj;
                if p < lo[j] {
                    p = (2.0 * lo[j] - p).min(hi[j]);
                    vi[j] = -vj;
                } else if p > hi[j] {
                    p = (2.0 * hi[j] - p).max(lo[j]);
                    vi[j] = -vj;
                }
                xi[j] = if p.is_finite() {
                    p
                } else {
                    0.5 * (lo[j] + hi[j])
                };
            }
        }
        cost_x = costs_of(&cost, &x);
        evals += np;
        let before = pcost[g];
        for (i, c) in cost_x.iter().enumerate() {
            if *c < pcost[i] {
                pcost[i] = *c;
                pbest[i].clone_from(&x[i]);
            }
        }
        g = argmin(&pcost);
        it += 1;
        let gained = before - pcost[g];
        if gained > cfg.tol * pcost[g].abs() + cfg.abs_tol || !before.is_finite() {
            since_improved = 0;
        } else {
            since_improved += 1;
        }
        if it % report_every == 0 {
            progress(&cfg.progress, "PSO iteration", it, cfg.iterations, || {
                pcost[g]
            });
        }
        if cfg.stall > 0 && since_improved >= cfg.stall {
            break;
        }
    }
    Ok(Optimum {
        x: pbest.swap_remove(g),
        cost: pcost[g],
        evals,
        iterations: it,
    })
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
    fn pso_finds_sphere_and_rosenbrock_minima() {
        let sphere = |x: &[f64]| x.iter().map(|v| (v - 0.3).powi(2)).sum::<f64>();
        let o = particle_swarm(sphere, &[-5.0; 4], &[5.0; 4], &[], &PsoConfig::default()).unwrap();
        assert!(o.cost < 1e-10, "{o:?}");
        let cfg = PsoConfig {
            iterations: 2000,
            stall: 0,
            ..Default::default()
        };
        let o = particle_swarm(rosenbrock, &[-5.0; 2], &[5.0; 2], &[], &cfg).unwrap();
        assert!(o.cost < 1e-8, "{o:?}");
        for v in &o.x {
            assert!((v - 1.0).abs() < 1e-3, "{o:?}");
        }
    }

    #[test]
    fn pso_is_reproducible_respects_bounds_and_survives_nan() {
        let f = |x: &[f64]| {
            if x[1] > 0.9 {
                f64::NAN
            } else {
                (x[0] - 3.0).powi(2) + (x[1] + 1.0).powi(2)
            }
        };
        let cfg = PsoConfig {
            iterations: 100,
            ..Default::default()
        };
        let a = particle_swarm(f, &[0.0, 0.0], &[2.0, 1.0], &[], &cfg).unwrap();
        let b = particle_swarm(f, &[0.0, 0.0], &[2.0, 1.0], &[], &cfg).unwrap();
        assert_eq!(a, b);
        // Minimum outside the box: on the bound.
        assert!((a.x[0] - 2.0).abs() < 1e-6 && a.x[1].abs() < 1e-6, "{a:?}");
        let c = particle_swarm(
            f,
            &[0.0, 0.0],
            &[2.0, 1.0],
            &[],
            &PsoConfig {
                seed: 9,
                ..cfg.clone()
            },
        )
        .unwrap();
        assert_ne!(a.evals, 0);
        assert!(c.x[0] <= 2.0 && c.x[1] >= 0.0);
    }

    #[test]
    fn pso_stops_when_stalled() {
        let cfg = PsoConfig {
            iterations: 10_000,
            stall: 20,
            abs_tol: 1e-9,
            ..Default::default()
        };
        let o = particle_swarm(|x| x[0].abs(), &[-1.0], &[1.0], &[], &cfg).unwrap();
        assert!(o.iterations < 10_000, "{o:?}");
        assert!(o.cost < 1e-3, "{o:?}");
    }

    #[test]
    fn bad_coefficients_are_named() {
        let cfg = PsoConfig {
            inertia: f64::NAN,
            ..Default::default()
        };
        let e = particle_swarm(|_| 0.0, &[0.0], &[1.0], &[], &cfg)
            .unwrap_err()
            .to_string();
        assert!(e.contains("PSO"), "{e}");
    }
}
