//! Nonlinear MPC with the HGO's hysteresis model as prediction model (CBW for `nmpc`, GBW
//! for `nmpc-gbw`, 000 eq. 3 with its CBW term), on the HGO's estimates (000 Part IV,
//! "Model Predictive Control with Hysteresis").
//!
//! At every `decimation`-th sample it minimises, over a fixed horizon of `H` moves
//! ([`HORIZON`] = 8 in the firmware and `piezo sim`) held for `decimation` samples each,
//! `sum_k (y[k+1] - y_d[k+1])^2 + r * sum_k (u[k] - u_ref[k])^2`
//! where `u_ref` is the previous move (increment penalty) or, with `feedforward`, the
//! feedforward voltage (the lecture's `R ||u_k||^2` measured from the feedforward, which
//! keeps the steady state unbiased). The prediction runs the observer's model: exact
//! input-domain hysteresis update from `(x_hat, h_hat)` and the exact discretisation of the
//! linear part at the MPC period. The reference is previewed by the Taylor polynomial of
//! the setpoint (`y_d + y_d' t + y_d'' t^2/2`).
//!
//! Solver: projected Gauss-Newton, a fixed number of iterations (at most
//! [`MAX_ITERATIONS`]), warm-started from the shifted previous plan. The Jacobian keeps the
//! local slope of every move (`dv/du = d_p - slope(h, s)`) propagated through the linear
//! part, and drops the hysteresis memory (`d h[k] / d u[j]`, `k > j + 1`); the model
//! prediction itself is exact. Moves are projected into `[u_min, u_max]`. Everything is
//! fixed-size arrays: no allocation, bounded work (`iterations * (H model steps +
//! H^3/6 Cholesky)`). [`Nmpc::cost`] evaluates that cost for any plan (the tests check the
//! solver against an exhaustive search of it on short horizons).
//!
//! Deferred ([`Nmpc::set_deferred`], the boards at 100 kHz): the solve leaves the control
//! step. At an MPC boundary the step shifts its plan (the one a solver delivered for the
//! last boundary, else its own), applies the plan's first move and posts an [`NmpcJob`]: the
//! estimates and signals of this boundary with that first move fixed. A lower-priority task
//! copies the law and the job ([`Nmpc::job`]), solves ([`Nmpc::solve_job`]: the same
//! Gauss-Newton, the first move held) and hands the plan back ([`Nmpc::deliver`]) before the
//! next boundary, where the step applies its second move. A solver that is late or gone
//! leaves the step on its last plan, shifted (the last move held).

// Dense matrix code reads best with indices; every index is below the const H of
// fixed-size arrays, so none can go out of bounds.
#![allow(clippy::needless_range_loop)]

use super::guard::InputGuard;
use super::hgo::{Hgo, HgoState};
use crate::hysteresis::{ensure, ensure_finite, ParamError};
use crate::real::Real;
use crate::signals::LoopSignals;

/// Prediction horizon (moves) of the firmware's and `piezo sim`'s NMPC (the default `H`).
pub const HORIZON: usize = 8;
/// Upper bound of Gauss-Newton iterations per solve.
pub const MAX_ITERATIONS: usize = 4;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NmpcConfig<T> {
    /// The MPC runs every `decimation` loop samples; each move is held that long.
    pub decimation: u32,
    /// Input weight `R` (um^2/V^2).
    pub r: T,
    /// Gauss-Newton iterations per solve (1..=MAX_ITERATIONS).
    pub iterations: u32,
    /// Input bounds the plan is projected into (V).
    pub u_min: T,
    pub u_max: T,
    /// Penalise the distance to `io.u_ff` instead of the move increments.
    pub feedforward: bool,
}

/// HGO + NMPC over a horizon of `H` moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nmpc<T, const H: usize = HORIZON> {
    hgo: Hgo<T>,
    cfg: NmpcConfig<T>,
    /// Linear part at the MPC period: `exp(-a M dt)`, `1 - exp(-a M dt)`.
    ad: T,
    gd: T,
    dt_mpc: T,
    state: NmpcState<T, H>,
    /// The solve runs outside [`Nmpc::update`] ([`Nmpc::set_deferred`]).
    deferred: bool,
    pub(crate) guard: InputGuard<T>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NmpcState<T, const H: usize = HORIZON> {
    pub obs: HgoState<T>,
    pub plan: [T; H],
    pub count: u32,
    pub u_hold: T,
    pub fresh: bool,
    /// Deferred: the job of the last boundary, while no plan has come back for it.
    pub asked: Option<NmpcJob<T, H>>,
    /// Deferred: the plan a solver delivered for the last job (from that boundary on).
    pub delivered: Option<[T; H]>,
    /// Deferred: jobs posted since the law started (the last job's number).
    pub jobs: u32,
    /// Deferred: boundaries whose job had no plan back in time (the step went on with its
    /// own plan, shifted).
    pub missed: u32,
}

/// One deferred solve: the estimates and signals at an MPC boundary, the plan to start from
/// (its first move, applied from that boundary on, stays fixed) and the job's number.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NmpcJob<T, const H: usize = HORIZON> {
    pub seq: u32,
    obs: HgoState<T>,
    io: LoopSignals<T>,
    warm: [T; H],
}

impl<T: Copy, const H: usize> NmpcJob<T, H> {
    /// The move applied from the job's boundary on (the solve keeps it).
    pub fn first(&self) -> T {
        self.warm[0]
    }
}

impl<T: Real, const H: usize> Default for NmpcState<T, H> {
    fn default() -> Self {
        Self {
            obs: HgoState::default(),
            plan: [T::ZERO; H],
            count: 0,
            u_hold: T::ZERO,
            fresh: false,
            asked: None,
            delivered: None,
            jobs: 0,
            missed: 0,
        }
    }
}

impl<T: Real, const H: usize> Nmpc<T, H> {
    pub fn new(hgo: Hgo<T>, cfg: NmpcConfig<T>) -> Result<Self, ParamError> {
        ensure(H >= 2, "NMPC: horizon H >= 2")?;
        ensure_finite(&[cfg.r, cfg.u_min, cfg.u_max], "NMPC: finite parameters")?;
        ensure(cfg.decimation >= 1, "NMPC: decimation >= 1")?;
        ensure(cfg.r > T::ZERO, "NMPC: r > 0")?;
        ensure(
            cfg.iterations >= 1 && cfg.iterations as usize <= MAX_ITERATIONS,
            "NMPC: 1 <= iterations <= MAX_ITERATIONS",
        )?;
        ensure(cfg.u_min < cfg.u_max, "NMPC: u_min < u_max")?;
        ensure(hgo.model().d() > T::ZERO, "NMPC: d_p > 0")?;
        let dt_mpc = hgo.dt_s() * T::from_f64(cfg.decimation as f64);
        let z = -hgo.a_per_s() * dt_mpc;
        Ok(Self {
            hgo,
            cfg,
            ad: z.exp(),
            gd: -z.exp_m1(),
            dt_mpc,
            state: NmpcState {
                fresh: true,
                ..Default::default()
            },
            deferred: false,
            guard: InputGuard::default(),
        })
    }

    /// Solves outside [`Nmpc::update`]: a lower-priority task takes [`Nmpc::job`] and gives
    /// [`Nmpc::deliver`] the plan (module docs). Off by default (the solve runs in the step).
    pub fn set_deferred(&mut self, on: bool) {
        self.deferred = on;
    }

    pub fn deferred(&self) -> bool {
        self.deferred
    }

    /// The job posted at the last MPC boundary, while no plan came back for it (deferred).
    pub fn job(&self) -> Option<NmpcJob<T, H>> {
        self.state.asked
    }

    /// The plan for `job` (from its boundary on, the first move as it was applied): the
    /// solve of the step, on a copy of the law. Bounded like it; no allocation.
    pub fn solve_job(&self, job: &NmpcJob<T, H>) -> [T; H] {
        self.plan_from(&job.obs, &job.io, job.warm, true)
    }

    /// Takes the plan solved for `job` if it is still the one asked for (a plan for an older
    /// job, or for a law that was replaced since, is dropped); true if taken.
    pub fn deliver(&mut self, job: &NmpcJob<T, H>, plan: [T; H]) -> bool {
        if self.state.asked.as_ref() != Some(job) || !plan.iter().all(|p| p.is_finite()) {
            return false;
        }
        self.state.asked = None;
        self.state.delivered = Some(plan);
        true
    }

    pub fn config(&self) -> &NmpcConfig<T> {
        &self.cfg
    }
    pub fn state(&self) -> &NmpcState<T, H> {
        &self.state
    }
    pub fn observer(&self) -> &Hgo<T> {
        &self.hgo
    }

    #[inline]
    pub fn update(&mut self, io: &LoopSignals<T>) -> T {
        let io = self.guard.clean(io);
        if self.state.fresh {
            self.prime(&io);
            return io.u_applied;
        }
        self.hgo.step(&mut self.state.obs, io.y_um, io.u_applied);
        self.state.count += 1;
        if self.state.count >= self.cfg.decimation {
            self.state.count = 0;
            if self.deferred {
                self.boundary(&io);
            } else {
                self.solve(&io);
            }
        }
        let u = self.state.u_hold;
        if u.is_finite() {
            u
        } else {
            self.prime(&io);
            io.u_applied
        }
    }

    /// Deferred, at an MPC boundary: the delivered plan (else the last one), both starting
    /// at the last boundary, shifted to this one; its first move applied; the next job
    /// posted. A few copies: the solve is the job's.
    fn boundary(&mut self, io: &LoopSignals<T>) {
        if self.state.asked.is_some() {
            self.state.missed = self.state.missed.wrapping_add(1);
        }
        let mut plan = self.state.delivered.take().unwrap_or(self.state.plan);
        plan.rotate_left(1);
        plan[H - 1] = plan[H - 2];
        self.state.plan = plan;
        self.state.u_hold = plan[0];
        self.state.jobs = self.state.jobs.wrapping_add(1);
        self.state.asked = Some(NmpcJob {
            seq: self.state.jobs,
            obs: self.state.obs,
            io: *io,
            warm: plan,
        });
    }

    /// Predicted outputs for `plan` from the estimates `obs`; returns also the local
    /// `dv/du` of every move.
    #[inline]
    fn rollout(&self, obs: &HgoState<T>, plan: &[T; H], u_prev: T) -> ([T; H], [T; H]) {
        let m = self.hgo.model();
        let lo = m.d() / T::from_f64(20.0);
        let mut x = obs.x;
        let mut h = obs.h;
        let dist = obs.d;
        let mut u0 = u_prev;
        let mut y = [T::ZERO; H];
        let mut dvdu = [T::ZERO; H];
        for ((yk, gk), &u) in y.iter_mut().zip(dvdu.iter_mut()).zip(plan.iter()) {
            let du = u - u0;
            h = m.advance_h(h, u0, du);
            *gk = (m.d() - m.slope(h, du.sgn())).max(lo);
            x = self.ad * x + self.gd * (m.d() * u - h - dist);
            *yk = x;
            u0 = u;
        }
        (y, dvdu)
    }

    /// The reference previewed over the horizon: `y_d + y_d' t + y_d'' t^2/2` at the end of
    /// every move.
    fn reference(&self, io: &LoopSignals<T>) -> [T; H] {
        let sp = &io.setpoint;
        let mut reference = [T::ZERO; H];
        for (k, r) in reference.iter_mut().enumerate() {
            let t = self.dt_mpc * T::from_usize(k + 1);
            *r = sp.y_um + sp.dy * t + sp.ddy * t * t * T::HALF;
        }
        reference
    }

    /// The cost the solver minimises, for `plan` from the current estimates, with the
    /// setpoint, feedforward and applied voltage of `io`:
    /// `sum_k (y[k+1] - y_d[k+1])^2 + r * sum_k (u[k] - u_ref[k])^2`.
    pub fn cost(&self, plan: &[T; H], io: &LoopSignals<T>) -> T {
        let (y, _) = self.rollout(&self.state.obs, plan, io.u_applied);
        let reference = self.reference(io);
        let mut j = T::ZERO;
        for (k, (yk, rk)) in y.iter().zip(reference.iter()).enumerate() {
            let before = if k == 0 { io.u_applied } else { plan[k - 1] };
            let du = if self.cfg.feedforward {
                plan[k] - io.u_ff
            } else {
                plan[k] - before
            };
            j += (*yk - *rk) * (*yk - *rk) + self.cfg.r * du * du;
        }
        j
    }

    fn solve(&mut self, io: &LoopSignals<T>) {
        // Warm start: shift the previous plan.
        let mut warm = self.state.plan;
        warm.rotate_left(1);
        warm[H - 1] = warm[H - 2];
        let plan = self.plan_from(&self.state.obs, io, warm, false);
        self.state.plan = plan;
        self.state.u_hold = plan[0];
    }

    /// Gauss-Newton from `warm` on the estimates `obs` and the signals `io` of one boundary;
    /// with `first_fixed` the first move stays `warm[0]` (a deferred job's, already
    /// applied). A plan that is not finite falls back to holding `io.u_applied`.
    fn plan_from(
        &self,
        obs: &HgoState<T>,
        io: &LoopSignals<T>,
        warm: [T; H],
        first_fixed: bool,
    ) -> [T; H] {
        let n = H;
        let u_prev = io.u_applied;
        let mut plan = warm;
        let reference = self.reference(io);
        let r_w = self.cfg.r;
        for _ in 0..self.cfg.iterations {
            let (y, g) = self.rollout(obs, &plan, u_prev);
            // J[i][j] = gd * ad^(i-j) * g[j] for i >= j.
            let mut jac = [[T::ZERO; H]; H];
            for j in 0..n {
                let mut c = self.gd * g[j];
                for row in jac.iter_mut().skip(j) {
                    row[j] = c;
                    c *= self.ad;
                }
            }
            // Normal equations H d = -grad.
            let mut hm = [[T::ZERO; H]; H];
            let mut grad = [T::ZERO; H];
            for i in 0..n {
                let res = y[i] - reference[i];
                for j in 0..=i {
                    grad[j] += jac[i][j] * res;
                    for k in 0..=i {
                        hm[j][k] += jac[i][j] * jac[i][k];
                    }
                }
            }
            if self.cfg.feedforward {
                for i in 0..n {
                    hm[i][i] += r_w;
                    grad[i] += r_w * (plan[i] - io.u_ff);
                }
            } else {
                // Increments: D u with u[-1] = u_prev.
                for i in 0..n {
                    let before = if i == 0 { u_prev } else { plan[i - 1] };
                    let inc = plan[i] - before;
                    grad[i] += r_w * inc;
                    hm[i][i] += r_w;
                    if i > 0 {
                        grad[i - 1] -= r_w * inc;
                        hm[i - 1][i - 1] += r_w;
                        hm[i - 1][i] -= r_w;
                        hm[i][i - 1] -= r_w;
                    }
                }
            }
            if first_fixed {
                // The first move is applied already: its row and column decoupled, no step.
                for k in 0..n {
                    hm[0][k] = T::ZERO;
                    hm[k][0] = T::ZERO;
                }
                hm[0][0] = T::ONE;
                grad[0] = T::ZERO;
            }
            let Some(step) = cholesky_solve(hm, grad) else {
                break;
            };
            for (p, d) in plan
                .iter_mut()
                .zip(step.iter())
                .skip(usize::from(first_fixed))
            {
                *p = (*p - *d).clamp_to(self.cfg.u_min, self.cfg.u_max);
            }
        }
        if plan.iter().all(|p| p.is_finite()) {
            plan
        } else {
            [u_prev; H]
        }
    }

    fn prime(&mut self, io: &LoopSignals<T>) {
        let u = io.u_applied;
        self.state = NmpcState {
            obs: self.hgo.init(io.y_um, u),
            plan: [u; H],
            count: 0,
            u_hold: u,
            fresh: false,
            asked: None,
            delivered: None,
            jobs: 0,
            missed: 0,
        };
    }

    /// Bumpless: the next command is `u_applied`; the plan restarts flat at it.
    pub fn reset(&mut self, _io: &LoopSignals<T>) {
        self.state.fresh = true;
        self.guard.restart();
    }
}

/// Solves `H d = g` for symmetric positive definite `H` (Cholesky); `None` if a pivot is
/// not positive.
fn cholesky_solve<T: Real, const H: usize>(mut a: [[T; H]; H], g: [T; H]) -> Option<[T; H]> {
    let n = H;
    for j in 0..n {
        let mut d = a[j][j];
        for k in 0..j {
            d -= a[j][k] * a[j][k];
        }
        if !(d > T::ZERO) {
            return None;
        }
        let d = d.sqrt();
        a[j][j] = d;
        for i in j + 1..n {
            let mut s = a[i][j];
            for k in 0..j {
                s -= a[i][k] * a[j][k];
            }
            a[i][j] = s / d;
        }
    }
    let mut z = g;
    for i in 0..n {
        for k in 0..i {
            let t = a[i][k] * z[k];
            z[i] -= t;
        }
        z[i] /= a[i][i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            let t = a[k][i] * z[k];
            z[i] -= t;
        }
        z[i] /= a[i][i];
    }
    Some(z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_spd_system() {
        let mut a = [[0.0f64; HORIZON]; HORIZON];
        let mut g = [0.0; HORIZON];
        for i in 0..HORIZON {
            for j in 0..HORIZON {
                a[i][j] = 1.0 / (1.0 + (i as f64 - j as f64).abs());
            }
            a[i][i] += 1.0;
            g[i] = i as f64 - 3.0;
        }
        let x = cholesky_solve(a, g).unwrap();
        for i in 0..HORIZON {
            let r: f64 = (0..HORIZON).map(|j| a[i][j] * x[j]).sum::<f64>() - g[i];
            assert!(r.abs() < 1e-12);
        }
        a[0][0] = -1.0;
        assert!(cholesky_solve(a, g).is_none());
    }
}
