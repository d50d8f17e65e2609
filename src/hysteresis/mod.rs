//! Hysteresis models of the seeds, one type per model.
//!
//! Every model keeps its validated parameters (the type itself, immutable) apart from its
//! state (`Model::State`, plain data), so one parameter set can drive many axes and a reset
//! is `state = model.init(u)`.
//!
//! # Discretisation
//! Between two samples the input is taken to move linearly (first-order hold). The
//! rate-independent part of each model is then integrated in the *input* domain over the
//! increment `du`, which makes the result independent of the sample rate:
//! * closed form where one exists (CBW/GBW/ABW with `n = 1`: `dh/du = a - kappa*h` on each
//!   piece of fixed `sgn(du)` and `sgn(h)`, at most one zero crossing of `h` per step; Dahl
//!   for any exponent `i`);
//! * otherwise classical RK4 in `u` with sub-steps no larger than `0.1 / L` (L the local
//!   Lipschitz bound of `dh/du`), at most [`MAX_SUBSTEPS`] per sample. The local error of one
//!   sub-step is below `(L*du)^5 / 120 * |h|max`, about 1e-7 of the loop height; the tests
//!   check it against a much finer integration.
//!
//! Sign convention: the Bouc-Wen family uses the piezo form `y = d*u - h` of 000 eq. (2),
//! 003 eq. (2) and 004 eq. (1). Seeds 001 and 002 write `y = k*v + h`; their parameters map
//! by `alpha -> -alpha`, `gamma -> -gamma` (k, beta, n, p, q unchanged) and, for `delta`,
//! as the form says: `delta -> -delta` for 002's `+delta*|v'|`, `delta -> delta` for 001's
//! `+delta*u*sgn(u')` (the piezo form writes that term with a minus; see [`abw`]).

pub mod abw;
pub mod cbw;
pub mod dahl;
pub mod gbw;
pub mod multi;
pub mod pi;
pub mod rlm;
pub mod structural;

pub use abw::{AbwAbs, AbwU, Mbw002, MbwState};
pub use cbw::Cbw;
pub use dahl::Dahl;
pub use gbw::Gbw;
pub use multi::{MultiBw, MultiBwState};
pub use pi::{backlash, dead_zone, Dpi, Pi, PiState, Ppi};
pub use rlm::{MbwRlm, RlmState, Wpmbw};

use crate::real::Real;

/// Upper bound of RK4 sub-steps in one sample: the per-sample work is bounded.
pub const MAX_SUBSTEPS: usize = 64;

/// A parameter set broke a condition; the text names the model and the condition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamError(pub &'static str);

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "invalid parameter: {}", self.0)
    }
}

impl core::error::Error for ParamError {}

/// Fails with `msg` unless `cond`.
#[inline]
pub(crate) fn ensure(cond: bool, msg: &'static str) -> Result<(), ParamError> {
    if cond {
        Ok(())
    } else {
        Err(ParamError(msg))
    }
}

/// Fails with `msg` unless every value is finite.
pub(crate) fn ensure_finite<T: Real>(values: &[T], msg: &'static str) -> Result<(), ParamError> {
    ensure(values.iter().all(|v| v.is_finite()), msg)
}

/// A hysteresis model advanced one input sample at a time.
pub trait Hysteresis<T: Real> {
    /// Everything that changes from sample to sample.
    type State: Copy + core::fmt::Debug;

    /// The relaxed state at input `u0` (hysteresis variable zero, operators centred).
    fn init(&self, u0: T) -> Self::State;

    /// Advance to input `u`, reached linearly from the previous input over `dt` seconds,
    /// and return the model output. A non-finite `u` holds the previous input.
    fn step(&self, state: &mut Self::State, u: T, dt: T) -> T;
}

/// State of a single-input model with one hysteresis variable.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BwState<T> {
    /// Last input (V).
    pub u: T,
    /// Hysteresis variable `h`.
    pub h: T,
}

impl<T: Real> BwState<T> {
    /// At rest at input `u0` (a non-finite one counts as 0 V), `h = 0`.
    pub fn rest(u0: T) -> Self {
        Self {
            u: sane_input(u0, T::ZERO),
            h: T::ZERO,
        }
    }

    /// One sample of a piezo-form model `y = d*u - h` (000 eq. 2): the input made sane,
    /// `h` advanced by `advance(h, u_prev, du)`. The models differ only in `advance`.
    #[inline(always)]
    pub fn step_piezo(&mut self, d: T, u: T, advance: impl FnOnce(T, T, T) -> T) -> T {
        let u = sane_input(u, self.u);
        self.h = advance(self.h, self.u, u - self.u);
        self.u = u;
        d * u - self.h
    }
}

/// [`Hysteresis`] for a piezo-form model on a [`BwState`] ([`BwState::step_piezo`]):
/// `|model, h, u_prev, du, dt| update` is its update of `h` over one sample.
macro_rules! piezo_form {
    ($model:ty, |$m:ident, $h:pat_param, $u0:pat_param, $du:pat_param, $dt:pat_param| $update:expr) => {
        impl<T: Real> Hysteresis<T> for $model {
            type State = BwState<T>;

            fn init(&self, u0: T) -> BwState<T> {
                BwState::rest(u0)
            }

            #[inline]
            fn step(&self, s: &mut BwState<T>, u: T, $dt: T) -> T {
                let $m = self;
                s.step_piezo(self.d, u, |$h, $u0, $du| $update)
            }
        }
    };
}
pub(crate) use piezo_form;

/// Copy accessors for a model's parameter fields.
macro_rules! getters {
    ($($name:ident),* $(,)?) => {
        $(
            pub fn $name(&self) -> T {
                self.$name
            }
        )*
    };
}
pub(crate) use getters;

/// Replaces a non-finite input by the previous one so NaN never enters a state.
#[inline(always)]
pub(crate) fn sane_input<T: Real>(u: T, prev: T) -> T {
    if u.is_finite() {
        u
    } else {
        prev
    }
}

/// `(1 - exp(-x)) / x`, with its limit 1 at `x = 0`.
#[inline]
pub(crate) fn phi<T: Real>(x: T) -> T {
    if x.abs() < T::from_f64(1e-2) {
        // Series sum_k (-x)^k / (k+1)! to x^6: the first omitted term, x^7 / 8!, is below
        // 3e-19, under the rounding of f64. Most loop-rate steps land here (no libm call).
        // Estrin's scheme: short dependency chains.
        let c = |k: f64| T::from_f64(1.0 / k);
        let x2 = x * x;
        let x4 = x2 * x2;
        let p01 = T::ONE - x * c(2.0);
        let p23 = c(6.0) - x * c(24.0);
        let p45 = c(120.0) - x * c(720.0);
        p01 + x2 * p23 + x4 * (p45 + x2 * c(5040.0))
    } else {
        -(-x).exp_m1() / x
    }
}

/// Exact input-domain step of `dh/du = a - kappa(sigma) * h`, where `sigma = sgn(h)` selects
/// the piece (the slope `a` must not depend on `sigma`). Handles the one possible zero
/// crossing of `h`; two pieces at most.
#[inline]
pub(crate) fn step_piecewise_affine<T: Real>(h0: T, du: T, a: T, kappa: impl Fn(T) -> T) -> T {
    let mut h = h0;
    let mut rem = du;
    for _ in 0..2 {
        if rem == T::ZERO {
            break;
        }
        let sigma = if h != T::ZERO {
            h.sgn()
        } else {
            (a * rem).sgn()
        };
        if sigma == T::ZERO {
            break; // h = 0 and no drive: stays 0
        }
        let k = kappa(sigma);
        let h1 = h + (a - k * h) * rem * phi(k * rem);
        if h1.sgn() != -sigma || h == T::ZERO {
            h = h1;
            break;
        }
        // Crosses zero inside this step: go to h = 0, then continue on the other piece.
        let to_zero = if k == T::ZERO {
            -h / a
        } else {
            (-k * h / a).ln_1p() / k
        };
        if !(to_zero.abs() < rem.abs()) {
            h = T::ZERO;
            break;
        }
        h = T::ZERO;
        rem -= to_zero;
    }
    h
}

/// RK4 in the input domain: integrates `dh/du = f(h, u)` from `(h0, u0)` over `du` with
/// sub-steps no larger than `max_du` (at most [`MAX_SUBSTEPS`]).
#[inline]
pub(crate) fn rk4_input<T: Real>(h0: T, u0: T, du: T, max_du: T, f: impl Fn(T, T) -> T) -> T {
    if du == T::ZERO {
        return h0;
    }
    let n = substeps(du, max_du);
    let d = du / T::from_usize(n);
    let half = d * T::HALF;
    let mut h = h0;
    let mut u = u0;
    for _ in 0..n {
        let k1 = f(h, u);
        let k2 = f(h + half * k1, u + half);
        let k3 = f(h + half * k2, u + half);
        let k4 = f(h + d * k3, u + d);
        h += d / T::from_f64(6.0) * (k1 + T::TWO * (k2 + k3) + k4);
        u += d;
    }
    h
}

/// RK4 along the sample's path `theta in [0, 1]` for `dh/dtheta = f(h, theta, sigma)`,
/// where `f` is smooth for a fixed piece `sigma = sgn(h)` but kinks at `h = 0` (the `|h|` of
/// the Bouc-Wen family). `n` sub-steps (callers bound it by [`substeps`]). A sub-step that
/// crosses zero is split at the crossing (located by linear interpolation, error of third
/// order), so the kink costs no accuracy.
#[inline]
pub(crate) fn rk4_kinked<T: Real>(h0: T, n: usize, f: impl Fn(T, T, T) -> T) -> T {
    let n = n.clamp(1, MAX_SUBSTEPS);
    let d = T::ONE / T::from_usize(n);
    let rk4 = |h: T, th: T, d: T, sigma: T| {
        let half = d * T::HALF;
        let k1 = f(h, th, sigma);
        let k2 = f(h + half * k1, th + half, sigma);
        let k3 = f(h + half * k2, th + half, sigma);
        let k4 = f(h + d * k3, th + d, sigma);
        h + d / T::from_f64(6.0) * (k1 + T::TWO * (k2 + k3) + k4)
    };
    let mut h = h0;
    let mut th = T::ZERO;
    for _ in 0..n {
        // At h = 0 the piece is the side h moves to (|h| = 0 there, f does not depend on sigma).
        let sigma = if h != T::ZERO {
            h.sgn()
        } else if f(T::ZERO, th, T::ONE) >= T::ZERO {
            T::ONE
        } else {
            -T::ONE
        };
        let h1 = rk4(h, th, d, sigma);
        h = if h != T::ZERO && h1.sgn() == -sigma {
            let frac = (h / (h - h1)).clamp_to(T::ZERO, T::ONE);
            let hm = rk4(h, th, d * frac, sigma);
            rk4(hm, th + d * frac, d * (T::ONE - frac), -sigma)
        } else {
            h1
        };
        th += d;
    }
    h
}

/// Number of sub-steps for an increment `du` at most `max_du` long, in `1..=MAX_SUBSTEPS`.
#[inline]
pub(crate) fn substeps<T: Real>(du: T, max_du: T) -> usize {
    let ratio = du.abs() / max_du;
    if !(ratio >= T::ONE) {
        1 // also NaN
    } else if ratio < T::from_usize(MAX_SUBSTEPS) {
        ratio.to_f64() as usize + 1
    } else {
        MAX_SUBSTEPS
    }
}

/// Test drive: the input `amp*sin(w*k)` for `k = 1..n` through two updates of `h`, each
/// called as `update(h, u_prev, du)`; returns both final values.
#[cfg(test)]
pub(crate) fn along_sine(
    amp: f64,
    w: f64,
    n: usize,
    mut exact: impl FnMut(f64, f64, f64) -> f64,
    mut reference: impl FnMut(f64, f64, f64) -> f64,
) -> (f64, f64) {
    let (mut h, mut h_ref, mut u) = (0.0, 0.0, 0.0);
    for k in 1..n {
        let un = amp * (k as f64 * w).sin();
        let du = un - u;
        h = exact(h, u, du);
        h_ref = reference(h_ref, u, du);
        u = un;
    }
    (h, h_ref)
}

/// Test check: `r` is refused with the text `why`.
#[cfg(test)]
pub(crate) fn assert_refused<M: core::fmt::Debug>(r: Result<M, ParamError>, why: &str) {
    assert_eq!(r.unwrap_err().0, why);
}

/// Test reference: `h' = f(h, t)` integrated over `dt` by `n` classical RK4 steps.
#[cfg(test)]
pub(crate) fn rk4_time(mut h: f64, dt: f64, n: usize, f: impl Fn(f64, f64) -> f64) -> f64 {
    let d = dt / n as f64;
    for j in 0..n {
        let t = j as f64 * d;
        let k1 = f(h, t);
        let k2 = f(h + 0.5 * d * k1, t + 0.5 * d);
        let k3 = f(h + 0.5 * d * k2, t + 0.5 * d);
        let k4 = f(h + d * k3, t + d);
        h += d / 6.0 * (k1 + 2.0 * (k2 + k3) + k4);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference: fine forward integration of the same piecewise-affine ODE.
    fn fine(h0: f64, du: f64, a: f64, kappa: impl Fn(f64) -> f64) -> f64 {
        let n = 200_000;
        let d = du / n as f64;
        let mut h = h0;
        for _ in 0..n {
            let sigma = if h != 0.0 {
                h.signum()
            } else {
                (a * d).signum()
            };
            let k1 = a - kappa(sigma) * h;
            let hm = h + 0.5 * d * k1;
            let sm = if hm != 0.0 { hm.signum() } else { sigma };
            h += d * (a - kappa(sm) * hm);
        }
        h
    }

    #[test]
    fn piecewise_affine_matches_fine_integration_across_zero() {
        let kappa = |s: f64| 0.03 + 0.01 * s;
        for &(h0, du) in &[
            (-1.5, 40.0),
            (1.2, -35.0),
            (0.0, 10.0),
            (-0.2, 3.0),
            (2.0, 1.0),
        ] {
            let a = 0.07;
            let exact = step_piecewise_affine(h0, du, a, kappa);
            let reference = fine(h0, du, a, kappa);
            assert!(
                (exact - reference).abs() < 1e-6,
                "{h0} {du}: {exact} vs {reference}"
            );
        }
    }

    #[test]
    fn phi_series_matches_exp_m1_to_rounding() {
        for &x in &[
            0.0f64, 1e-9, -3e-5, 1e-4, -2e-3, 5e-3, 0.0099, -0.0099, 0.01, 0.3, -2.0,
        ] {
            let direct = if x == 0.0 { 1.0 } else { -(-x).exp_m1() / x };
            let p = phi(x);
            assert!(
                (p - direct).abs() <= 4.0 * f64::EPSILON,
                "{x}: {p} vs {direct}"
            );
        }
        let p32 = phi(0.0099f32);
        let d32 = -(-0.0099f64).exp_m1() / 0.0099;
        assert!(
            (p32 as f64 - d32).abs() < 2.0 * f32::EPSILON as f64,
            "{p32} vs {d32}"
        );
    }

    #[test]
    fn rk4_is_exact_enough_for_exponential() {
        // dh/du = 1 - h from 0 over 3: 1 - e^-3
        let h = rk4_input(0.0f64, 0.0, 3.0, 0.1, |h, _| 1.0 - h);
        assert!((h - (1.0 - (-3.0f64).exp())).abs() < 2e-6);
    }

    #[test]
    fn substeps_are_bounded_even_for_huge_or_nan_steps() {
        assert_eq!(substeps(1e30f64, 1e-3), MAX_SUBSTEPS);
        assert_eq!(substeps(f64::NAN, 1.0), 1);
        assert_eq!(substeps(0.5f64, 1.0), 1);
    }
}
