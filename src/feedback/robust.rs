//! Robust output-feedback law with virtual hysteresis control, 000 eq. (7)-(8), on the HGO.

use super::guard::InputGuard;
use super::hgo::{cbw_n1_slope_of_dv, CbwN1, Hgo, HgoState};
use crate::hysteresis::{ensure, ensure_finite, ParamError};
use crate::real::Real;
use crate::signals::{LoopSignals, Setpoint};

/// Configuration of the law (the observer carries the model and sample period).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobustConfig<T> {
    /// Tracking-error decay rate `lambda_1` of eq. (7) (1/s).
    pub lambda1: T,
    /// Hysteresis-error decay rate `lambda_2` of eq. (8) (1/s).
    pub lambda2: T,
    /// Combine with feedforward: the increment of `io.u_ff` replaces the law's own
    /// `h_d'` term, the `lambda_2` correction stays.
    pub feedforward: bool,
    /// How the two errors converge.
    pub convergence: Convergence<T>,
}

/// Convergence of the tracking error `e = x_hat - y_d` and of `e_h = h_hat - h_d`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Convergence<T> {
    /// `e' = -lambda1 e`, `e_h' = -lambda2 e_h` (000 eq. 7-8).
    Exponential,
    /// Finite time (000 Part IV, GBW + FTS): `e' = -lambda1 sig(e)^alpha1`,
    /// `e_h' = -lambda2 sig(e_h)^alpha2` with `sig(e)^a = |e|^a sgn(e)`, `0 < a < 1`,
    /// and the virtual control saturated: `|e'| <= sat_um_per_s` (the `sigma_1` of the
    /// lecture). Each sample advances the errors by the *exact* solution of these ODEs
    /// over `dt` (`|e|^(1-a)` falls linearly to 0), so the discrete law reaches zero in
    /// finite time without chattering.
    FiniteTime {
        alpha1: T,
        alpha2: T,
        sat_um_per_s: T,
    },
}

/// Exact solution over `dt` of `e' = -k sig(e)^alpha`, `0 < alpha < 1`.
#[inline]
pub fn finite_time_decay<T: Real>(e: T, k: T, alpha: T, dt: T) -> T {
    let p = T::ONE - alpha;
    let r = e.abs_pow(p) - p * k * dt;
    if r > T::ZERO {
        e.sgn() * r.powf(T::ONE / p)
    } else {
        T::ZERO
    }
}

/// HGO + robust law.
///
/// Eq. (7): `h_d = d_p u - v_d`, `v_d = (y_d' - A x_hat - lambda1 (x_hat - y_d)) / B`
/// (normalised: `B = -A = a`), the effective input that makes `x - y_d` decay at
/// `lambda1`. Eq. (8) integrates `u` so that `e_h = h_hat - h_d` decays at `lambda2`.
/// Because `h_d` contains `d_p u`, `e_h' = (slope - d_p) u' + v_d'` with
/// `slope = A_bw - (B_bw sgn(u') sgn(h) + G_bw)|h|`; solving for `u'` gives
/// `u' = (v_d' + lambda2 (h_hat - h_d)) / (d_p - slope)`. Its denominator is `dv/du`, positive
/// for a monotone actuator (`d_p > A_bw`); it is guarded into `[d_p/20, 2 d_p + A_bw]`
/// (and `h_hat` bounded) so a bad estimate cannot blow the step up.
///
/// Eq. (8) as printed, `u' = [h_d' + lambda2 (h_hat - h_d)] / slope`, differs in two
/// independent ways:
/// * the sign of `lambda2`: it makes `h_hat' = slope u' = h_d' + lambda2 e_h`, i.e.
///   `e_h' = +lambda2 e_h`, which grows for every `lambda2 > 0` even if `h_d` did not depend
///   on `u`; decay needs `h_d' - lambda2 e_h`;
/// * the denominator: `h_d` of eq. (7) contains `d_p u`, so `h_d' = d_p u' - v_d'` contains
///   `u'` and eq. (8) is implicit in `u'`. Solving `slope u' = d_p u' - v_d' - lambda2 e_h`
///   gives the form above, denominator `d_p - slope` instead of `slope`.
///
/// Discretely: the integral of eq. (8) runs from `io.u_applied` (saturation never winds it
/// up), `lambda2` enters as the exact decay `c = 1 - exp(-lambda2 dt)` per sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Robust<T> {
    hgo: Hgo<T>,
    cfg: RobustConfig<T>,
    /// `1 - c` of the decay `c = 1 - exp(-lambda2 dt)` above, computed once: what is left of
    /// `e_h` after a sample.
    left2: T,
    /// `exp(-lambda1 dt)`.
    p1: T,
    /// [`Robust::v_d`] for exponential convergence (`e_next = p1 e`) on a floating-point
    /// type ([`Robust::vd_linear`]), linear in `x_hat` and the setpoint: `v_d = vd[0] x_hat +
    /// vd[1] y_d + vd[2] y_d' + vd[3] y_d''` (computed once, in `f64`).
    vd: [T; 4],
    den_lo: T,
    den_hi: T,
    state: RobustState<T>,
    /// The observer model's parameters when it is CBW with `n = 1` (the fused update's
    /// case): read without matching the model per sample.
    cbw_n1: CbwN1<T>,
    /// The fused update's denominator never reaches `den_hi` ([`Hgo::cbw_n1_den_below`]),
    /// decided once here: the check runs in `f64`, software arithmetic on the M4F, and
    /// `fusable` is asked whenever the pipeline re-decides its path, in the control
    /// interrupt and under the command lock (asked there, it made the flood's longest
    /// control interrupt 4880 instructions instead of 3600: `.ci/test.d/31-qemu-flood.sh`).
    den_hi_free: bool,
    pub(crate) guard: InputGuard<T>,
}

/// The setpoint `y_um` and `y_next`, where it is one sample on (from its derivatives).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Target<T> {
    y_um: T,
    y_next: T,
    /// The setpoint's part of [`Robust::v_d`] for exponential convergence.
    vd_setpoint: T,
}

/// Observer state and the values of the previous sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RobustState<T> {
    pub obs: HgoState<T>,
    pub v_d_prev: T,
    pub u_ff_prev: T,
    pub fresh: bool,
}

impl<T: Real> Robust<T> {
    pub fn new(hgo: Hgo<T>, cfg: RobustConfig<T>) -> Result<Self, ParamError> {
        ensure_finite(&[cfg.lambda1, cfg.lambda2], "robust law: finite lambdas")?;
        if let Convergence::FiniteTime {
            alpha1,
            alpha2,
            sat_um_per_s,
        } = cfg.convergence
        {
            ensure_finite(
                &[alpha1, alpha2, sat_um_per_s],
                "finite-time law: finite parameters",
            )?;
            ensure(
                alpha1 > T::ZERO && alpha1 < T::ONE && alpha2 > T::ZERO && alpha2 < T::ONE,
                "finite-time law: 0 < alpha1, alpha2 < 1",
            )?;
            ensure(sat_um_per_s > T::ZERO, "finite-time law: sat_um_per_s > 0")?;
        }
        ensure(
            cfg.lambda1 > T::ZERO && cfg.lambda2 > T::ZERO,
            "robust law: lambda1 > 0 and lambda2 > 0",
        )?;
        let m = hgo.model();
        ensure(
            m.d() > T::ZERO,
            "robust law: d_p > 0 (the voltage must move the stage)",
        )?;
        let c2 = -(-cfg.lambda2 * hgo.dt_s()).exp_m1();
        // v_d = x + (y_next + p1 (x - y) - x) / gd with y_next = y + (y' + y'' dt / 2) dt:
        // x (1 - q) + y q + y' dt / gd + y'' dt^2 / (2 gd), q = (1 - p1) / gd.
        let (dt, a) = (hgo.dt_s().to_f64(), hgo.a_per_s().to_f64());
        let gd = -libm::expm1(-a * dt);
        let q = -libm::expm1(-cfg.lambda1.to_f64() * dt) / gd;
        let vd = [1.0 - q, q, dt / gd, dt * dt / (2.0 * gd)].map(T::from_f64);
        let den_hi = T::TWO * m.d() + m.slope(T::ZERO, T::ONE).abs();
        let cbw_n1 = hgo.cbw_n1();
        Ok(Self {
            hgo,
            cfg,
            left2: T::ONE - c2,
            p1: (-cfg.lambda1 * hgo.dt_s()).exp(),
            vd,
            den_lo: m.d() / T::from_f64(20.0),
            den_hi,
            cbw_n1,
            den_hi_free: hgo.is_cbw_n1() && hgo.cbw_n1_den_below(&cbw_n1, den_hi),
            state: RobustState {
                fresh: true,
                ..Default::default()
            },
            guard: InputGuard::default(),
        })
    }

    pub fn observer(&self) -> &Hgo<T> {
        &self.hgo
    }
    pub fn state(&self) -> &RobustState<T> {
        &self.state
    }
    pub fn config(&self) -> &RobustConfig<T> {
        &self.cfg
    }

    /// The effective input `v_d` of eq. (7) (um), in the exact discrete form of the
    /// observer's model: the `v` held over the next sample that brings `x` to
    /// `y_d(t + dt) + decay(x_hat - y_d)`, i.e. `(x_target - ad x_hat) / gd`. (The
    /// continuous `x_hat + (y_d' - lambda1 e)/a` is its limit `a dt -> 0`; at `a dt = 0.3` it
    /// would leave 15 % of the velocity feedforward out.) `EXP`: the convergence is known
    /// to be exponential.
    #[inline(always)]
    fn v_d<const EXP: bool>(&self, target: &Target<T>, x_hat: T) -> T {
        let dt = self.hgo.dt_s();
        let (_, gd) = self.hgo.linear_step();
        let e = x_hat - target.y_um;
        let e_next = match self.cfg.convergence {
            // Exponential: the same expression, linear in x_hat (`Robust::vd`), its
            // setpoint part computed before the compensator.
            _ if EXP && Self::vd_linear() => return self.vd[0] * x_hat + target.vd_setpoint,
            Convergence::Exponential if Self::vd_linear() => {
                return self.vd[0] * x_hat + target.vd_setpoint
            }
            _ if EXP => self.p1 * e,
            Convergence::Exponential => self.p1 * e,
            Convergence::FiniteTime {
                alpha1,
                sat_um_per_s,
                ..
            } => {
                let e1 = finite_time_decay(e, self.cfg.lambda1, alpha1, dt);
                let lim = sat_um_per_s * dt;
                e + (e1 - e).clamp_to(-lim, lim)
            }
        };
        // (x_target - ad x_hat) / gd with ad = 1 - gd, written to keep f32 differences small.
        x_hat + (target.y_next + e_next - x_hat) / gd
    }

    /// [`Robust::v_d`] in its linear form (`Robust::vd`): on a floating-point type, which
    /// keeps the coefficients' relative precision (fixed point would round the `y''` one,
    /// `dt^2 / (2 gd)`, to zero).
    #[inline(always)]
    fn vd_linear() -> bool {
        T::EPSILON < T::from_f64(1e-6)
    }

    /// The setpoint's part of [`Robust::v_d`]: the setpoint and where it is one sample on.
    #[inline(always)]
    fn target(&self, sp: &Setpoint<T>) -> Target<T> {
        let dt = self.hgo.dt_s();
        let vd = &self.vd;
        Target {
            y_um: sp.y_um,
            y_next: sp.y_um + (sp.dy + sp.ddy * dt * T::HALF) * dt,
            vd_setpoint: vd[1] * sp.y_um + vd[2] * sp.dy + vd[3] * sp.ddy,
        }
    }

    /// What is left of the error `e_h` after one sample (`EXP`: as in [`Robust::v_d`]).
    #[inline(always)]
    fn h_error_left<const EXP: bool>(&self, e: T) -> T {
        match self.cfg.convergence {
            _ if EXP => self.left2 * e,
            Convergence::Exponential => self.left2 * e,
            Convergence::FiniteTime { alpha2, .. } => {
                finite_time_decay(e, self.cfg.lambda2, alpha2, self.hgo.dt_s())
            }
        }
    }

    #[inline]
    pub fn update(&mut self, io: &LoopSignals<T>) -> T {
        let io = self.guard.clean(io);
        if self.state.fresh {
            self.prime(io);
            return io.u_applied;
        }
        let target = self.target(&io.setpoint);
        self.update_impl::<false>(target, io.y_um, io.u_ff, io.u_applied, |_| io)
    }

    /// The configuration [`Robust::update_fused`] runs: exponential convergence, no
    /// measurement filter, the observer on CBW with `n = 1`.
    pub(crate) fn fusable(&self) -> bool {
        self.cfg.convergence == Convergence::Exponential
            && self.guard.is_unfiltered()
            && self.hgo.is_cbw_n1()
            && self.den_hi_free
    }

    /// The law has not primed its observer yet (the next update does that).
    #[inline(always)]
    pub(crate) fn is_fresh(&self) -> bool {
        self.state.fresh
    }

    /// [`Robust::update`] for a primed law (not [`Robust::is_fresh`]) with
    /// [`Robust::fusable`] and inputs whose measurement, feedforward and applied voltage are
    /// finite and inside the input guard's bound (the pipeline checks the configuration
    /// once, the rest every sample), and the setpoint too when `setpoint_within` (the
    /// reference generator knows it): the same arithmetic without the checks that cannot
    /// fire then. In two parts: this one takes the setpoint (before the compensator, so the
    /// fused step holds one value across it instead of the setpoint's derivatives),
    /// [`Robust::update_fused`] the rest.
    #[inline(always)]
    pub(crate) fn fused_target(&mut self, sp: &Setpoint<T>, setpoint_within: bool) -> Target<T> {
        let sp = self.guard.clean_setpoint_fused(sp, setpoint_within);
        self.target(&sp)
    }

    /// The command after [`Robust::fused_target`].
    #[inline(always)]
    pub(crate) fn update_fused(&mut self, target: Target<T>, y_um: T, u_ff: T, u_applied: T) -> T {
        self.guard.remember_fused(y_um, u_ff, u_applied);
        // Unfiltered, the guard remembers the law's inputs as they are.
        self.update_impl::<true>(target, y_um, u_ff, u_applied, |law| law.guard.last())
    }

    /// The law on inputs the guard has cleaned (`io`: all of them, for a restart).
    #[inline(always)]
    fn update_impl<const FUSED: bool>(
        &mut self,
        target: Target<T>,
        y_um: T,
        u_ff: T,
        u0: T,
        io: impl FnOnce(&Self) -> LoopSignals<T>,
    ) -> T {
        // FUSED: the model is CBW with n = 1 (`fusable`), no match per sample.
        if FUSED {
            self.hgo
                .step_cbw_n1(&self.cbw_n1, &mut self.state.obs, y_um, u0);
        } else {
            self.hgo.step_unguarded(&mut self.state.obs, y_um, u0);
        }
        let d_p = self.hgo.d_p();
        let h_hat = self.state.obs.h_hat();
        let v_hat = d_p * u0 - h_hat;
        let v_d = self.v_d::<FUSED>(&target, self.state.obs.x);
        // Target effective input for this sample: what is left of the error to v_d.
        // Each form keeps only the memory it reads (the form is fixed per law).
        let (dv, du_ff) = if self.cfg.feedforward {
            let e = v_hat - v_d;
            let du_ff = u_ff - self.state.u_ff_prev;
            self.state.u_ff_prev = u_ff;
            (self.h_error_left::<FUSED>(e) - e, du_ff)
        } else {
            let left = self.h_error_left::<FUSED>(v_hat - self.state.v_d_prev);
            self.state.v_d_prev = v_d;
            (v_d - v_hat + left, T::ZERO)
        };
        let s = &mut self.state;
        // The model's slope at the hysteresis part of the estimate (inside the loop bound).
        let slope = if FUSED {
            cbw_n1_slope_of_dv(&self.cbw_n1, s.obs.h, dv)
        } else {
            self.hgo.model().slope(s.obs.h, dv.sgn())
        };
        // Fused: the upper bound cannot bind (`fusable` checks `Hgo::cbw_n1_den_below`), so
        // the lower one alone gives the same value (NaN: the lower bound, as `clamp_to`).
        let den = if FUSED {
            (d_p - slope).max(self.den_lo)
        } else {
            (d_p - slope).clamp_to(self.den_lo, self.den_hi)
        };
        let u = u0 + du_ff + dv / den;
        if u.is_finite() {
            u
        } else {
            self.prime(io(self));
            u0
        }
    }

    // By value: a reference would keep the caller's inputs in memory on the hot path.
    fn prime(&mut self, io: LoopSignals<T>) {
        let obs = self.hgo.init(io.y_um, io.u_applied);
        self.state = RobustState {
            obs,
            v_d_prev: self.v_d::<false>(&self.target(&io.setpoint), obs.x),
            u_ff_prev: io.u_ff,
            fresh: false,
        };
    }

    /// Bumpless restart: the observer starts at the steady state that explains `y` at
    /// `u_applied`; the first command after is `u_applied`, then the law integrates from it.
    pub fn reset(&mut self, _io: &LoopSignals<T>) {
        self.state.fresh = true;
        self.guard.restart();
    }
}
