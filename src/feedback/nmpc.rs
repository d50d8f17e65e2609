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
    pub(crate) guard: InputGuard<T>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NmpcState<T, const H: usize = HORIZON> {
    pub obs: HgoState<T>,
    pub plan: [T; H],
    pub count: u32,
    pub u_hold: T,
    pub fresh: bool,
}

impl<T: Real, const H: usize> Default for NmpcState<T, H> {
    fn default() -> Self {
        Self {
            obs: HgoState::default(),
            plan: [T::ZERO; H],
            count: 0,
            u_hold: T::ZERO,
            fresh: false,
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
            guard: InputGuard::default(),
        })
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
            self.solve(&io);
        }
        let u = self.state.u_hold;
        if u.is_finite() {
            u
        } else {
            self.prime(&io);
            io.u_applied
        }
    }

    /// Predicted outputs for `plan` from the current estimates; returns also the local
    /// `dv/du` of every move.
    #[inline]
    fn rollout(&self, plan: &[T; H], u_prev: T) -> ([T; H], [T; H]) {
        let m = self.hgo.model();
        let lo = m.d() / T::from_f64(20.0);
        let mut x = self.state.obs.x;
        let mut h = self.state.obs.h;
        let dist = self.state.obs.d;
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
        let (y, _) = self.rollout(plan, io.u_applied);
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
        let n = H;
        let u_prev = io.u_applied;
        // Warm start: shift the previous plan.
        let mut plan = self.state.plan;
        plan.rotate_left(1);
        plan[n - 1] = plan[n - 2];
        let reference = self.reference(io);
        let r_w = self.cfg.r;
        for _ in 0..self.cfg.iterations {
            let (y, g) = self.rollout(&plan, u_prev);
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
            let Some(step) = cholesky_solve(hm, grad) else {
                break;
            };
            for (p, d) in plan.iter_mut().zip(step.iter()) {
                *p = (*p - *d).clamp_to(self.cfg.u_min, self.cfg.u_max);
            }
        }
        if plan.iter().all(|p| p.is_finite()) {
            self.state.plan = plan;
            self.state.u_hold = plan[0];
        } else {
            self.state.plan = [u_prev; H];
            self.state.u_hold = u_prev;
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
