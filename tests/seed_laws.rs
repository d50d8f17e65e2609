//! The defining properties of the 000 Part IV laws, each on its own model:
//! * finite-time control: on a noise-free plant that is the law's own model, the tracking
//!   error enters a band around zero within the time computed from the gains (and not much
//!   earlier), and stays;
//! * NMPC: the plan the solver returns costs (its own cost, written out here independently)
//!   no more than the optimum an exhaustive grid search finds, on horizons of 2 and 3 moves.

use piezo_core::feedback::{
    Convergence, Hgo, HgoState, Nmpc, NmpcConfig, ObserverModel, Robust, RobustConfig,
};
use piezo_core::hysteresis::{Cbw, Gbw};
use piezo_core::signals::{LoopSignals, Setpoint};

const DT: f64 = 1e-5;
/// Linear pole (1/s): the simulated stage's lag is of this order.
const A: f64 = 2.0e4;

fn cbw() -> ObserverModel<f64> {
    ObserverModel::Cbw(Cbw::with_n1(0.93, 0.3, 0.012, 0.004).unwrap())
}

/// The asymmetric GBW of `piezo sim`'s `gbw-asymmetric-10hz`.
fn gbw() -> ObserverModel<f64> {
    ObserverModel::Gbw(Gbw::with_beta_h(0.93, 1.0, 0.3, 0.012, 0.006, 0.004, 1.0).unwrap())
}

/// The plant: the model's hysteresis and the first-order linear part, discretised exactly
/// (what the observer predicts, so it is exact here and the error is the law's alone).
struct Plant {
    m: ObserverModel<f64>,
    h: f64,
    u: f64,
    x: f64,
}

impl Plant {
    fn step(&mut self, u: f64) {
        self.h = self.m.advance_h(self.h, self.u, u - self.u);
        self.u = u;
        let ad = (-A * DT).exp();
        self.x = ad * self.x + (1.0 - ad) * (self.m.d() * u - self.h);
    }
}

/// Time for `e' = -k sig(e)^alpha` with `|e'| <= sat` to bring `|e0|` to zero: the saturated
/// part at rate `sat` down to `e_s = (sat/k)^(1/alpha)`, then `e_s^(1-alpha)/(k(1-alpha))`.
fn settling_time(e0: f64, k: f64, alpha: f64, sat: f64) -> f64 {
    let e_s = (sat / k).powf(1.0 / alpha);
    let (t_sat, e1) = if e0.abs() > e_s {
        ((e0.abs() - e_s) / sat, e_s)
    } else {
        (0.0, e0.abs())
    };
    t_sat + e1.powf(1.0 - alpha) / (k * (1.0 - alpha))
}

#[test]
fn finite_time_error_reaches_its_band_in_the_computed_time() {
    // Exponents other than 1/2, so that `alpha` and `1 - alpha` cannot be confused.
    let (l1, a1, l2, a2, sat) = (1000.0, 0.6, 2.0e4, 0.7, 2000.0);
    let step_um = 10.0;
    for (name, m) in [("fts", cbw()), ("fts-gbw", gbw())] {
        let mut law = Robust::new(
            Hgo::with_eps(m, A, 1e-4, DT).unwrap(),
            RobustConfig {
                lambda1: l1,
                lambda2: l2,
                feedforward: false,
                convergence: Convergence::FiniteTime {
                    alpha1: a1,
                    alpha2: a2,
                    sat_um_per_s: sat,
                },
            },
        )
        .unwrap();
        // Virgin ascent to 60 V, then at rest.
        let mut p = Plant {
            m,
            h: 0.0,
            u: 0.0,
            x: 0.0,
        };
        for k in 1..=7000 {
            p.step((k as f64 * 0.01).min(60.0));
        }
        let y0 = p.x;
        let io = |y_d: f64, p: &Plant| LoopSignals::hold(y_d, p.x, 0.0, p.u);
        law.update(&io(y0, &p)); // primes the observer at rest
        let y_d = y0 + step_um;
        // The outer error settles in T1; the inner one starts at most at the saturated
        // virtual-control step `sat*dt/gd` (um) and settles in T2; two samples of latency.
        let gd = 1.0 - (-A * DT).exp();
        let t1 = settling_time(step_um, l1, a1, sat);
        let t2 = settling_time(sat * DT / gd, l2, a2, f64::INFINITY);
        let t_bound = t1 + t2 + 2.0 * DT;
        let band_um = 1e-4;
        let n_bound = (t_bound / DT).ceil() as usize;
        let mut first_in = None;
        let mut worst_after = 0.0f64;
        for k in 0..3 * n_bound {
            let u = law.update(&io(y_d, &p));
            assert!(
                u.is_finite() && (0.0..=150.0).contains(&u),
                "{name}: u = {u}"
            );
            p.step(u);
            let e = (p.x - y_d).abs();
            if e <= band_um && first_in.is_none() {
                first_in = Some(k + 1);
            }
            if k + 1 >= n_bound {
                worst_after = worst_after.max(e);
            }
        }
        let t_in = first_in.map(|k| k as f64 * DT);
        eprintln!(
            "{name}: |e| <= {band_um} um after {:?} ms, bound {:.3} ms (T1 {:.3}, T2 {:.3}); \
             largest |e| after the bound {worst_after:.2e} um",
            t_in.map(|t| t * 1e3),
            t_bound * 1e3,
            t1 * 1e3,
            t2 * 1e3
        );
        assert!(
            worst_after <= band_um,
            "{name}: |e| = {worst_after} um after the bound {t_bound} s"
        );
        // And not much before: the time is the law's own (a law with another exponent or
        // saturation, or an asymptotic one, arrives elsewhere).
        let t_in = t_in.unwrap_or(f64::INFINITY);
        assert!(
            t_in >= 0.97 * t1,
            "{name}: in the band at {t_in} s, T1 = {t1} s"
        );
    }
}

/// The NMPC's cost, written out from its definition (not through `Nmpc::cost`): the model's
/// exact hysteresis step and the exact linear step at the MPC period from the observer's
/// estimates, and the input penalty against the previous move or the feedforward.
fn cost<const H: usize>(
    m: &ObserverModel<f64>,
    obs: &HgoState<f64>,
    cfg: &NmpcConfig<f64>,
    io: &LoopSignals<f64>,
    plan: &[f64; H],
) -> f64 {
    let t_mpc = DT * cfg.decimation as f64;
    let ad = (-A * t_mpc).exp();
    let (mut x, mut h, mut u0) = (obs.x, obs.h, io.u_applied);
    let mut j = 0.0;
    for (k, &u) in plan.iter().enumerate() {
        h = m.advance_h(h, u0, u - u0);
        x = ad * x + (1.0 - ad) * (m.d() * u - h - obs.d);
        let t = t_mpc * (k + 1) as f64;
        let sp = &io.setpoint;
        let r = sp.y_um + sp.dy * t + 0.5 * sp.ddy * t * t;
        let du = if cfg.feedforward { u - io.u_ff } else { u - u0 };
        j += (x - r).powi(2) + cfg.r * du * du;
        u0 = u;
    }
    j
}

/// Exhaustive search of `f` over `[lo, hi]^H`: a grid, then finer grids around the best.
fn brute_force<const H: usize>(f: impl Fn(&[f64; H]) -> f64, lo: f64, hi: f64) -> ([f64; H], f64) {
    let mut best = ([lo; H], f64::INFINITY);
    let (mut a, mut b, mut steps) = ([lo; H], [hi; H], if H == 2 { 300 } else { 60 });
    for _ in 0..6 {
        let mut idx = [0usize; H];
        loop {
            let p: [f64; H] =
                core::array::from_fn(|i| a[i] + (b[i] - a[i]) * idx[i] as f64 / steps as f64);
            let c = f(&p);
            if c < best.1 {
                best = (p, c);
            }
            let mut i = 0;
            while i < H {
                idx[i] += 1;
                if idx[i] <= steps {
                    break;
                }
                idx[i] = 0;
                i += 1;
            }
            if i == H {
                break;
            }
        }
        for i in 0..H {
            let w = 2.0 * (b[i] - a[i]) / steps as f64;
            a[i] = (best.0[i] - w).max(lo);
            b[i] = (best.0[i] + w).min(hi);
        }
        steps = 20;
    }
    best
}

/// One solve of an `H`-move NMPC from a state on the loop, against the exhaustive optimum.
fn nmpc_case<const H: usize>(m: ObserverModel<f64>, feedforward: bool, r: f64, step_um: f64) {
    let cfg = NmpcConfig {
        decimation: 10,
        r,
        iterations: 4,
        u_min: 0.0,
        u_max: 150.0,
        feedforward,
    };
    let mut law: Nmpc<f64, H> = Nmpc::new(Hgo::with_eps(m, A, 1e-4, DT).unwrap(), cfg).unwrap();
    // A plant on the descending branch at 70 V, the law primed there.
    let mut p = Plant {
        m,
        h: 0.0,
        u: 0.0,
        x: 0.0,
    };
    for k in 1..=12_000 {
        let k = k as f64;
        let u = if k <= 9000.0 {
            k * 0.01
        } else {
            (90.0 - (k - 9000.0) * 0.01).max(70.0)
        };
        p.step(u);
    }
    let io = |p: &Plant, y_d: f64| LoopSignals {
        setpoint: Setpoint {
            y_um: y_d,
            dy: 3000.0,
            ddy: 0.0,
        },
        y_um: p.x,
        u_ff: p.u + 2.0,
        u_applied: p.u,
    };
    law.update(&io(&p, p.x));
    // Nine samples at rest, the tenth solves with the reference `step_um` away.
    let y_d = p.x + step_um;
    for _ in 0..9 {
        law.update(&io(&p, y_d));
    }
    let sig = io(&p, y_d);
    law.update(&sig);
    let obs = law.state().obs;
    let own = |plan: &[f64; H]| cost(&m, &obs, &cfg, &sig, plan);
    let solver = own(&law.state().plan);
    assert!(
        (law.cost(&law.state().plan, &sig) - solver).abs() <= 1e-9 * solver.max(1.0),
        "Nmpc::cost is the cost written out here"
    );
    let (best_plan, best) = brute_force(own, cfg.u_min, cfg.u_max);
    eprintln!(
        "H = {H}, ff {feedforward}, r {r}, step {step_um} um: solver {solver:.6e} at {:?}, \
         exhaustive {best:.6e} at {best_plan:?}",
        law.state().plan
    );
    assert!(
        solver <= best * (1.0 + 1e-3) + 1e-9,
        "H = {H}: solver cost {solver} above the optimum {best}"
    );
}

#[test]
fn nmpc_solution_matches_exhaustive_search_on_short_horizons() {
    for m in [cbw(), gbw()] {
        for (ff, r, step) in [(false, 1e-3, 2.0), (false, 1e-2, -5.0), (true, 1e-3, 4.0)] {
            nmpc_case::<2>(m, ff, r, step);
            nmpc_case::<3>(m, ff, r, step);
        }
    }
}
