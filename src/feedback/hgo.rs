//! High-gain observer (HGO) on the observer-canonical form, 000 eq. (5)-(6).
//!
//! # Model
//! The linear part of 000 eq. (2) is used normalised to unit DC gain,
//! `x' = -a*x + a*(d_p*u - h)`, `y = x` (um). The backup slide's `A = -86.28 1/s`,
//! `B = 7.95e7` with `y = C*x` is the same first-order system with `a = -A` and
//! `C = -A/B`; normalising keeps `x` in um and `h` in um (the units of `d_p*u`).
//!
//! # Gains
//! With the coupling `-a` of `h` into `x'` (the `-B` of `Phi` in eq. 5), the error
//! dynamics are `s^2 + (l1 - A) s - a*l2`, so the `h` gain must be *negative*:
//! `l1 = k1/eps`, `l2 = -k2/(a*eps^2)` gives `s^2 + k1/eps s + k2/eps^2` (plus the known
//! pole `a` in the `s` coefficient). Eq. (6) writes `+k2/eps^2` for the scaled state
//! `-B*h`; here `h` keeps its physical sign and unit.
//!
//! # Discretisation (stable for every `eps > 0`)
//! The linear part is discretised exactly (zero-order hold of `v = d_p*u - h`):
//! `x+ = ad*x + (1 - ad)*v`, `ad = exp(-a*dt)`. The hysteresis term `f(h, u')` is
//! integrated in the input domain over the applied increment `du` (the model's own exact
//! update, as in the plant models), so it does not depend on the sample rate. The stiff
//! `k/eps` correction is a current-estimator update with `y[k]`, and its two gains are
//! chosen so that the discrete error matrix `(I - L C) Ad` has exactly the poles
//! `exp(s_i*dt)` of the continuous design (`s_i` the roots of `s^2 + k1/eps s + k2/eps^2`):
//! the exact discretisation of the linear error dynamics. Those poles lie inside the unit
//! circle for any `eps > 0`, so no explicit-Euler stability limit `eps > k*dt` exists.
//! As `eps -> 0` the poles go to 0 (dead-beat) and the noise gain grows, which is what
//! [`Hgo::epsilon_for`] trades off.

use crate::hysteresis::{ensure, ensure_finite, Cbw, Dahl, Gbw, ParamError};
use crate::real::Real;

/// Hysteresis model the observer predicts `h` with (the `f(h, u')` of 000 eq. 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ObserverModel<T> {
    /// Classical Bouc-Wen (000 eq. 1).
    Cbw(Cbw<T>),
    /// Generalized Bouc-Wen (000 eq. 3), for asymmetric loops (finite-time law, NMPC).
    Gbw(Gbw<T>),
    /// Dahl (000 eq. 4).
    Dahl(Dahl<T>),
}

impl<T: Real> ObserverModel<T> {
    /// Piezo coefficient `d_p` (um/V).
    #[inline]
    pub fn d(&self) -> T {
        match self {
            ObserverModel::Cbw(m) => m.d(),
            ObserverModel::Gbw(m) => m.d(),
            ObserverModel::Dahl(m) => m.d(),
        }
    }
    /// `dh/du` at `h` moving in direction `s`.
    #[inline]
    pub fn slope(&self, h: T, s: T) -> T {
        match self {
            ObserverModel::Cbw(m) if m.n() == T::ONE => cbw_n1_slope(&CbwN1::of(m), h, s),
            ObserverModel::Cbw(m) => m.slope(h, s),
            ObserverModel::Gbw(m) => m.slope(h, s),
            ObserverModel::Dahl(m) => m.slope(h, s),
        }
    }
    /// Input-domain update of `h` over `du` from `u0`.
    #[inline]
    pub fn advance_h(&self, h: T, u0: T, du: T) -> T {
        match self {
            ObserverModel::Cbw(m) => match cbw_n1_piece(m, h, du) {
                Some(h1) => h1,
                None => m.advance_h(h, u0, du),
            },
            ObserverModel::Gbw(m) => m.advance_h(h, u0, du),
            ObserverModel::Dahl(m) => m.advance_h(h, du),
        }
    }
    /// Bound of `|h|` on the major loop.
    #[inline]
    pub fn h_bound(&self) -> T {
        match self {
            ObserverModel::Cbw(m) => m.h_bound(),
            ObserverModel::Gbw(m) => m.h_bound(),
            ObserverModel::Dahl(m) => m.hc(),
        }
    }
}

/// The CBW step for `n = 1` on one affine piece (000 eq. 1 integrated exactly over `du`:
/// `h1 = h + (alpha - k h) du phi(k du)`, `k = beta sgn(du) + gamma sgn(h)`), the
/// per-sample case; the same closed form as [`Cbw::advance_h`] without its generic
/// bookkeeping. `None` when `n != 1` or `h` crosses zero inside the step (the model's own
/// two-piece step handles that, once per half cycle).
#[inline]
pub(crate) fn cbw_n1_piece<T: Real>(m: &Cbw<T>, h: T, du: T) -> Option<T> {
    if m.n() != T::ONE {
        return None;
    }
    let m = CbwN1::of(m);
    if du == T::ZERO {
        // No move, as NMPC's held input gives on most samples: the step's own value there
        // (`k du = +0`, `phi = 1`; so the same bits, zero's sign included) without its
        // polynomial. The fused step, whose input moves every sample, goes without the test.
        return Some(h + (m.alpha * du - T::ZERO * h));
    }
    cbw_n1_piece_unchecked(&m, h, du)
}

/// The parameters of CBW with `n = 1` its per-sample step and slope use.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct CbwN1<T> {
    alpha: T,
    beta: T,
    gamma: T,
}

impl<T: Real> CbwN1<T> {
    #[inline(always)]
    fn of(m: &Cbw<T>) -> Self {
        Self {
            alpha: m.alpha(),
            beta: m.beta(),
            gamma: m.gamma(),
        }
    }
}

/// `dh/du` of CBW for `n = 1` at `h` moving in the direction of `s`'s sign: `beta s sgn(h)
/// |h| = beta s h` for `s` in {-1, 0, 1}, exactly (no sign tests of `h`), with `beta s`
/// picked instead of multiplied (`beta * 1` and `beta * -1` are `beta` and `-beta` exactly,
/// in fixed point too), so the fused law can pass `dv` itself.
#[inline(always)]
pub(crate) fn cbw_n1_slope<T: Real>(m: &CbwN1<T>, h: T, s: T) -> T {
    let bs = if s > T::ZERO {
        m.beta
    } else if s < T::ZERO {
        -m.beta
    } else {
        m.beta * T::ZERO
    };
    m.alpha - m.gamma * h.abs() - bs * h
}

/// [`cbw_n1_slope`] in the direction of `dv`'s sign bit (a sign flip, no compare): the
/// robust law's, whose command does not depend on the slope when `dv = 0` (`dv / den` is
/// then a zero of `dv`'s sign for any positive `den`), so `+-0` may take either side.
#[inline(always)]
pub(crate) fn cbw_n1_slope_of_dv<T: Real>(m: &CbwN1<T>, h: T, dv: T) -> T {
    m.alpha - m.gamma * h.abs() - m.beta.mul_sign(dv) * h
}

/// [`cbw_n1_piece`] for a model known to have `n = 1`. Written in `k du = beta |du| + gamma
/// sgn(h) du`, the piece's sign from the signs of `h` and `du` (at `h = 0`: the piece `h`
/// moves into): one sign test instead of two sign flips, and no branch for `du = 0`, which
/// gives `k du = 0`, `phi = 1` and `h1 = h` (a NaN `du` is refused by the callers).
#[inline(always)]
fn cbw_n1_piece_unchecked<T: Real>(m: &CbwN1<T>, h: T, du: T) -> Option<T> {
    let a = du.abs();
    let sgn_h_du = if h.opposite_signs(du) { -a } else { a };
    let k_du = m.beta * a + m.gamma * sgn_h_du;
    // k du >= 0: beta >= |gamma| (CBW's bounded loops), so beta a >= |gamma a| as rounded.
    let (phi, _) = k_du.phi_expm1_neg_nonneg();
    let h1 = h + (m.alpha * du - k_du * h) * phi;
    if h.opposite_signs(h1) {
        None
    } else {
        Some(h1)
    }
}

/// The robust law's prediction of `h` over `du` for CBW with `n = 1`: the exact step
/// `h + (alpha du - k du h) phi(k du)` ([`cbw_n1_piece_unchecked`]) to second order in `k
/// du`, `phi ~ 1 - k du / 2`, on the piece `h` starts on (where `h` crosses zero inside the
/// step, the change of piece is left to the correction, as any other model error), while
/// `k du <= 1/32`: the relative error of the increment is below `(k du)^2 / 6 = 1.6e-4`
/// (the firmware's 100 Hz, 5 um sine at 100 kHz: `k du < 0.006`, `6e-6`). Larger steps
/// (and NaN) take `exact`, the model's step.
#[inline(always)]
fn cbw_n1_predict<T: Real>(m: &CbwN1<T>, h: T, du: T, exact: impl FnOnce() -> T) -> T {
    // k du = beta |du| + gamma sgn(h) du, sgn(h) du by a sign flip (h = 0 counts by its
    // sign bit: either piece is as near there, h being 0).
    let k_du = m.beta * du.abs() + m.gamma * du.mul_sign(h);
    if k_du <= T::from_f64(1.0 / 32.0) {
        h + (m.alpha * du - k_du * h) * (T::ONE - T::HALF * k_du)
    } else {
        exact()
    }
}

/// HGO configuration: model, sample period and the discrete gains derived from `eps`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hgo<T> {
    model: ObserverModel<T>,
    a_per_s: T,
    eps_s: T,
    dt_s: T,
    /// `exp(-a*dt)` and `1 - exp(-a*dt)`.
    ad: T,
    gd: T,
    l1: T,
    l2: T,
    /// `model.h_bound()` (a `powf` for CBW: computed once) and `model.d()`.
    h_bound: T,
    d_p: T,
}

/// Estimates `x_hat` (um), `h_hat` (um) and the input they correspond to (V).
///
/// `h_hat = h + d`: `h` is the part inside the model's loop bound, which the model's
/// dynamics `f(h, u')` act on; `d` is what the correction pushed beyond the bound (creep,
/// an external force, model error), held constant by the prediction and drained first by
/// corrections of the other sign. Without the split a
/// large lumped disturbance in `h` would be pulled back to the loop bound by `f` at every
/// input move.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct HgoState<T> {
    pub x: T,
    pub h: T,
    pub d: T,
    pub u: T,
}

impl<T: Real> HgoState<T> {
    /// The lumped estimate `h_hat = h + d` (um) of 000 eq. (6).
    #[inline]
    pub fn h_hat(&self) -> T {
        self.h + self.d
    }
}

/// Hurwitz coefficients of `s^2 + k1 s + k2` used by default: a double pole at `-1/eps`.
pub const K1: f64 = 2.0;
pub const K2: f64 = 1.0;

impl<T: Real> Hgo<T> {
    /// `a_per_s`: pole of the linear part (1/s, the lecture's `-A`); `eps_s`: the HGO's
    /// `epsilon` (s); `k1, k2`: `s^2 + k1 s + k2` Hurwitz; `dt_s`: sample period.
    pub fn new(
        model: ObserverModel<T>,
        a_per_s: T,
        eps_s: T,
        k1: T,
        k2: T,
        dt_s: T,
    ) -> Result<Self, ParamError> {
        ensure_finite(
            &[a_per_s, eps_s, k1, k2, dt_s],
            "HGO: parameters must be finite",
        )?;
        ensure(a_per_s > T::ZERO, "HGO: linear pole a_per_s > 0 (A < 0)")?;
        ensure(eps_s > T::ZERO, "HGO: eps_s > 0")?;
        ensure(dt_s > T::ZERO, "HGO: dt_s > 0")?;
        ensure(
            k1 > T::ZERO && k2 > T::ZERO,
            "HGO: s^2 + k1 s + k2 Hurwitz (k1 > 0, k2 > 0)",
        )?;
        let ad = (-a_per_s * dt_s).exp();
        let gd = -(-a_per_s * dt_s).exp_m1();
        // Discrete poles exp(s_i dt): their sum and product.
        let (sum, prod) = discrete_poles(k1 / eps_s, k2 / (eps_s * eps_s), dt_s);
        let l1 = T::ONE - prod / ad;
        let l2 = -(T::ONE - sum + prod) / gd;
        ensure(
            l1.is_finite() && l2.is_finite() && gd > T::ZERO,
            "HGO: eps_s or dt_s out of range for this number type",
        )?;
        Ok(Self {
            model,
            a_per_s,
            eps_s,
            dt_s,
            ad,
            gd,
            l1,
            l2,
            h_bound: model.h_bound(),
            d_p: model.d(),
        })
    }

    /// The default design `k1 = 2, k2 = 1` (double pole at `-1/eps`).
    pub fn with_eps(
        model: ObserverModel<T>,
        a_per_s: T,
        eps_s: T,
        dt_s: T,
    ) -> Result<Self, ParamError> {
        Self::new(
            model,
            a_per_s,
            eps_s,
            T::from_f64(K1),
            T::from_f64(K2),
            dt_s,
        )
    }

    pub fn model(&self) -> &ObserverModel<T> {
        &self.model
    }
    /// The model's piezo coefficient `d_p` (um/V).
    #[inline]
    pub fn d_p(&self) -> T {
        self.d_p
    }
    pub fn a_per_s(&self) -> T {
        self.a_per_s
    }
    pub fn eps_s(&self) -> T {
        self.eps_s
    }
    pub fn dt_s(&self) -> T {
        self.dt_s
    }
    /// Exact discretisation of the linear part: `(exp(-a dt), 1 - exp(-a dt))`.
    pub fn linear_step(&self) -> (T, T) {
        (self.ad, self.gd)
    }
    /// Discrete gains `(l1, l2)`.
    pub fn gains(&self) -> (T, T) {
        (self.l1, self.l2)
    }

    /// Error-propagation matrix `(I - L C) Ad` of the discrete observer (row major).
    pub fn error_matrix(&self) -> [[T; 2]; 2] {
        let (a, g) = (self.ad, self.gd);
        [
            [(T::ONE - self.l1) * a, -(T::ONE - self.l1) * g],
            [-self.l2 * a, T::ONE + self.l2 * g],
        ]
    }

    /// Steady state consistent with measurement `y` at input `u`: `x = y`,
    /// `h_hat = d_p*u - y`.
    pub fn init(&self, y: T, u: T) -> HgoState<T> {
        let b = self.h_bound;
        let h_hat = self.model.d() * u - y;
        let h = h_hat.clamp_to(-b, b);
        HgoState {
            x: y,
            h,
            d: h_hat - h,
            u,
        }
    }

    /// One sample: `u` is the voltage applied since the last sample, `y` the new
    /// measurement. Inputs must be finite (the laws sanitise them).
    #[inline]
    pub fn step(&self, s: &mut HgoState<T>, y: T, u: T) {
        // f(h, u') integrated over the input increment (000 eq. 6, second line).
        let h_pred = self.model.advance_h(s.h, s.u, u - s.u);
        self.correct::<true>(s, y, u, h_pred);
    }

    /// [`Hgo::step`] without its finiteness test of the state (IEEE types), for a law whose
    /// command is non-finite whenever the state is: the robust law, which then primes the
    /// observer again (and holds the applied voltage for that sample).
    #[inline]
    pub(crate) fn step_unguarded(&self, s: &mut HgoState<T>, y: T, u: T) {
        let du = u - s.u;
        let h_pred = match &self.model {
            ObserverModel::Cbw(m) if m.n() == T::ONE => {
                cbw_n1_predict(&CbwN1::of(m), s.h, du, || {
                    self.model.advance_h(s.h, s.u, du)
                })
            }
            model => model.advance_h(s.h, s.u, du),
        };
        self.correct::<false>(s, y, u, h_pred);
    }

    /// The model's parameters when [`Hgo::is_cbw_n1`] (else zeros).
    pub(crate) fn cbw_n1(&self) -> CbwN1<T> {
        match self.model {
            ObserverModel::Cbw(m) if m.n() == T::ONE => CbwN1::of(&m),
            _ => CbwN1::default(),
        }
    }

    /// For the model's parameters `m` ([`Hgo::cbw_n1`]): every `d_p - cbw_n1_slope(m, h, s)`
    /// over the states the observer keeps (`|h| <= h_bound`, any `s`), as `T` rounds it,
    /// lies strictly below `upper`. The slope is at least `alpha - (beta + gamma) |h| >=
    /// alpha - (beta + gamma) h_bound`, which is 0 (`h_bound = alpha / (beta + gamma)`) up
    /// to the rounding; the margin covers the rounding of `T` (relative for IEEE types,
    /// absolute for fixed point).
    pub(crate) fn cbw_n1_den_below(&self, m: &CbwN1<T>, upper: T) -> bool {
        let f = |x: T| x.to_f64();
        let (a, b, g, hb, dp) = (
            f(m.alpha),
            f(m.beta),
            f(m.gamma),
            f(self.h_bound),
            f(self.d_p),
        );
        let eps = f(T::EPSILON);
        let margin = 16.0 * eps * (1.0 + dp + a + (b.abs() + g.abs()) * hb.abs());
        let slope_min = a - (b + g) * hb.abs();
        dp - slope_min + margin < f(upper)
    }

    /// The model is CBW with `n = 1`, the case [`Hgo::step_cbw_n1`] runs.
    pub(crate) fn is_cbw_n1(&self) -> bool {
        matches!(self.model, ObserverModel::Cbw(m) if m.n() == T::ONE)
    }

    /// [`Hgo::step_unguarded`] for an observer whose model is CBW with `n = 1` (the
    /// pipeline's fused step checks [`Hgo::is_cbw_n1`] once per configuration), `m` its
    /// parameters ([`Hgo::cbw_n1`]); the same arithmetic.
    #[inline(always)]
    pub(crate) fn step_cbw_n1(&self, m: &CbwN1<T>, s: &mut HgoState<T>, y: T, u: T) {
        let du = u - s.u;
        let h_pred = cbw_n1_predict(m, s.h, du, || self.model.advance_h(s.h, s.u, du));
        self.correct::<false>(s, y, u, h_pred);
    }

    /// The measurement update after the prediction `h_pred` of `h`; `GUARD`: a non-finite
    /// state restarts the observer.
    #[inline(always)]
    fn correct<const GUARD: bool>(&self, s: &mut HgoState<T>, y: T, u: T, h_pred: T) {
        let x_pred = self.ad * s.x + self.gd * (self.d_p * u - h_pred - s.d);
        let e = y - x_pred;
        s.x = x_pred + self.l1 * e;
        // The correction drains `d` first, so `d` holds only what `h` cannot.
        let corr = self.l2 * e;
        let b = self.h_bound;
        let h = h_pred + corr;
        if !GUARD && s.d == T::ZERO && h.abs() < b {
            // The robust law's usual case, nothing beyond the bound before or after: the
            // values of `correct_beyond` (one test instead of two; `d` keeps its bits,
            // where that would turn -0 into +0). The guarded step (NMPC, whose observer
            // often holds a `d`) keeps the two tests: the third one cost it instructions.
            s.h = h;
        } else {
            self.correct_beyond(s, h_pred, corr);
        }
        s.u = u;
        // One test for the three: a sum of finite values is finite (or overflowed, which
        // is as bad). `h + d` is the estimate the laws read next (`HgoState::h_hat`).
        // Unguarded on IEEE types only: there a non-finite state stays non-finite through
        // the law's arithmetic; a saturated fixed-point one need not.
        if (GUARD || !T::OVERFLOW_PROPAGATES) && !(s.x + s.h_hat()).is_finite() {
            *s = self.init(y, u);
        }
    }

    /// The correction `corr` of `h` when `d` holds something or `h_pred + corr` leaves the
    /// bound: it drains `d` first, so `d` holds only what `h` cannot.
    #[inline(always)]
    fn correct_beyond(&self, s: &mut HgoState<T>, h_pred: T, corr: T) {
        let mut corr = corr;
        if s.d * corr < T::ZERO {
            if corr.abs() <= s.d.abs() {
                s.d += corr;
                corr = T::ZERO;
            } else {
                corr += s.d;
                s.d = T::ZERO;
            }
        }
        let h = h_pred + corr;
        s.h = h.clamp_sym(self.h_bound);
        s.d += h - s.h;
    }

    /// Standard deviation of `h_hat` per unit of white measurement noise: the H2 norm of
    /// the discrete observer from `y` to `h_hat`, from the discrete Lyapunov equation.
    pub fn h_noise_gain(&self) -> T {
        let f = self.error_matrix();
        let (f11, f12, f21, f22) = (f[0][0], f[0][1], f[1][0], f[1][1]);
        // Noise enters as z = F z + L n; the injection is L = (l1, l2).
        let (l1, l2) = (self.l1, self.l2);
        // P = F P F' + L L' for symmetric P = [p11 p12; p12 p22], as M p = q.
        let m = [
            [T::ONE - f11 * f11, -T::TWO * f11 * f12, -f12 * f12],
            [-f11 * f21, T::ONE - (f11 * f22 + f12 * f21), -f12 * f22],
            [-f21 * f21, -T::TWO * f21 * f22, T::ONE - f22 * f22],
        ];
        let q = [l1 * l1, l1 * l2, l2 * l2];
        match solve3(m, q) {
            Some(p) if p[2] >= T::ZERO => p[2].sqrt(),
            _ => T::MAX,
        }
    }

    /// Picks `eps` from the sample period and the sensor noise.
    ///
    /// Trade-off: the observer tracks `h` (and everything the model misses, which ends up in
    /// `h_hat`) with a lag of about `2*eps`, so a small `eps` rejects disturbances faster;
    /// but the noise on `h_hat` grows like `eps^-1.5` (the HGO's peaking of measurement
    /// noise). The law feeds `h_hat` straight into the voltage, so its noise is the
    /// position noise the loop adds. Returns the smallest `eps >= dt` (one observer time
    /// constant per sample; below that the poles approach dead-beat and the continuous
    /// design has no meaning left) whose `h_hat` noise is at most `h_noise_budget_um` for
    /// `noise_rms_um` of white sensor noise, capped at `eps_max = min(1000 dt, 2/a)`: an
    /// observer slower than half the linear pole lags the plant the law inverts (on the
    /// simulated stage the loop goes unstable near `eps = 4/a`), and one slower than
    /// `1000 dt` no longer tracks the hysteresis of a 10 Hz scan. Past the cap the noise
    /// budget is exceeded rather than the loop destabilised. Bisection on `ln(eps)`,
    /// 48 iterations.
    pub fn epsilon_for(
        model: ObserverModel<T>,
        a_per_s: T,
        dt_s: T,
        noise_rms_um: T,
        h_noise_budget_um: T,
    ) -> Result<T, ParamError> {
        ensure_finite(
            &[a_per_s, dt_s, noise_rms_um, h_noise_budget_um],
            "HGO epsilon: parameters must be finite",
        )?;
        ensure(
            noise_rms_um >= T::ZERO && h_noise_budget_um > T::ZERO,
            "HGO epsilon: noise_rms_um >= 0 and h_noise_budget_um > 0",
        )?;
        let eps_min = dt_s;
        let eps_max = (T::from_f64(1000.0) * dt_s).min(T::TWO / a_per_s);
        if !(eps_max > eps_min) {
            return Ok(eps_min);
        }
        let ok = |eps: T| -> Result<bool, ParamError> {
            let g = Self::with_eps(model, a_per_s, eps, dt_s)?.h_noise_gain();
            Ok(g * noise_rms_um <= h_noise_budget_um)
        };
        if ok(eps_min)? {
            return Ok(eps_min);
        }
        if !ok(eps_max)? {
            return Ok(eps_max);
        }
        let (mut lo, mut hi) = (eps_min.ln(), eps_max.ln());
        for _ in 0..48 {
            let mid = (lo + hi) * T::HALF;
            if ok(mid.exp())? {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Ok(hi.exp())
    }
}

/// Sum and product of `exp(s_i*dt)` for the roots `s_i` of `s^2 + c1 s + c0`.
fn discrete_poles<T: Real>(c1: T, c0: T, dt: T) -> (T, T) {
    let re = -c1 * T::HALF;
    let disc = re * re - c0;
    let prod = (T::TWO * re * dt).exp();
    let sum = if disc >= T::ZERO {
        let w = disc.sqrt();
        ((re + w) * dt).exp() + ((re - w) * dt).exp()
    } else {
        T::TWO * (re * dt).exp() * ((-disc).sqrt() * dt).cos()
    };
    (sum, prod)
}

/// Solves a 3x3 system by Cramer's rule; `None` if singular.
pub(crate) fn solve3<T: Real>(m: [[T; 3]; 3], q: [T; 3]) -> Option<[T; 3]> {
    let det = |a: &[[T; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(&m);
    if !(d.abs() > T::ZERO) || !d.is_finite() {
        return None;
    }
    let mut x = [T::ZERO; 3];
    for (c, xc) in x.iter_mut().enumerate() {
        let mut mc = m;
        for (row, qr) in mc.iter_mut().zip(q.iter()) {
            row[c] = *qr;
        }
        *xc = det(&mc) / d;
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::Hysteresis;

    pub(crate) fn cbw() -> Cbw<f64> {
        Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap()
    }

    /// The shortcut for a held input is the step's own value at `du = 0`, bit for bit
    /// (zero's sign included), in f32 and in fixed point.
    #[test]
    fn held_input_shortcut_is_the_step() {
        use crate::fixed::Q16;
        let m = Cbw::<f32>::with_n1(0.16, 0.07, 0.02, -0.01).unwrap();
        for h in [-3.0f32, -1e-20, -0.0, 0.0, 1e-20, 2.5] {
            for du in [0.0f32, -0.0] {
                let short = cbw_n1_piece(&m, h, du).unwrap();
                let full = cbw_n1_piece_unchecked(&CbwN1::of(&m), h, du).unwrap();
                assert_eq!(short.to_bits(), full.to_bits(), "h {h} du {du}");
            }
        }
        let q = |x: f64| Q16::from_f64(x);
        let m = Cbw::with_n1(q(0.16), q(0.07), q(0.02), q(0.01)).unwrap();
        for h in [-3.0, 0.0, 2.5] {
            let short = cbw_n1_piece(&m, q(h), Q16::ZERO);
            let full = cbw_n1_piece_unchecked(&CbwN1::of(&m), q(h), Q16::ZERO);
            assert_eq!(short, full, "Q16 h {h}");
        }
    }

    fn spectral_radius(f: [[f64; 2]; 2]) -> f64 {
        let tr = f[0][0] + f[1][1];
        let det = f[0][0] * f[1][1] - f[0][1] * f[1][0];
        let disc = tr * tr / 4.0 - det;
        if disc >= 0.0 {
            (tr / 2.0 + disc.sqrt())
                .abs()
                .max((tr / 2.0 - disc.sqrt()).abs())
        } else {
            det.sqrt()
        }
    }

    #[test]
    fn discrete_poles_are_the_mapped_continuous_ones() {
        let dt = 1e-5;
        for &eps in &[1e-5, 1e-4, 1e-3] {
            let o = Hgo::with_eps(ObserverModel::Cbw(cbw()), 86.28, eps, dt).unwrap();
            let r = spectral_radius(o.error_matrix());
            assert!((r - (-dt / eps).exp()).abs() < 1e-6, "eps {eps}: {r}");
        }
    }

    /// Exact plant (same model, same discretisation), wrong initial state: the estimates
    /// converge to the true `x` and `h`.
    #[test]
    fn converges_on_exact_model_from_wrong_initial_state() {
        let dt = 1e-5;
        let a = 86.28;
        let m = cbw();
        let o = Hgo::with_eps(ObserverModel::Cbw(m), a, 2e-4, dt).unwrap();
        let mut plant = m.init(0.0);
        let mut x = 0.0;
        let mut est = HgoState {
            x: 5.0,
            h: -2.0,
            d: 0.0,
            u: 0.0,
        };
        let mut err_h = f64::MAX;
        for k in 0..20_000 {
            let u = 60.0 + 50.0 * (2.0 * core::f64::consts::PI * 10.0 * k as f64 * dt).sin();
            // Plant: hysteresis jumps with the held input, then the exact linear step.
            plant_step(&m, &mut plant, &mut x, u, a, dt);
            o.step(&mut est, x, u);
            err_h = (est.h_hat() - plant.h).abs();
        }
        assert!((est.x - x).abs() < 1e-9, "x {} vs {}", est.x, x);
        assert!(err_h < 1e-9, "h error {err_h}");
        assert!(est.d.abs() < 1e-9, "no disturbance to lump: {est:?}");
    }

    pub(crate) fn plant_step(
        m: &Cbw<f64>,
        s: &mut crate::hysteresis::BwState<f64>,
        x: &mut f64,
        u: f64,
        a: f64,
        dt: f64,
    ) {
        let v = m.step(s, u, dt);
        let ad = (-a * dt).exp();
        *x = ad * *x + (1.0 - ad) * v;
    }

    #[test]
    fn stable_at_smallest_helper_eps_at_100khz_in_f32() {
        let dt = 1e-5f32;
        let m = Cbw::with_n1(0.16f32, 0.07, 0.02, 0.01).unwrap();
        let model = ObserverModel::Cbw(m);
        // No noise budget pressure: the helper returns its lower limit.
        let eps = Hgo::epsilon_for(model, 86.28f32, dt, 0.0, 1.0).unwrap();
        assert_eq!(eps, dt);
        let o = Hgo::with_eps(model, 86.28, eps, dt).unwrap();
        let f = o.error_matrix();
        let f64m = [
            [f[0][0] as f64, f[0][1] as f64],
            [f[1][0] as f64, f[1][1] as f64],
        ];
        assert!(spectral_radius(f64m) < 0.4);
        // Wrong start, constant input, 1 s at 100 kHz: stays finite and converges.
        let mut est = HgoState {
            x: 30.0f32,
            h: 2.0,
            d: 1.0,
            u: 50.0,
        };
        for _ in 0..100_000 {
            o.step(&mut est, 5.0, 50.0);
            assert!(est.x.is_finite() && est.h.is_finite());
        }
        assert!((est.x - 5.0).abs() < 1e-3, "{est:?}");
        assert!((est.h_hat() - (0.16 * 50.0 - 5.0)).abs() < 1e-2, "{est:?}");
    }

    #[test]
    fn helper_trades_eps_against_noise() {
        let model = ObserverModel::Cbw(cbw());
        let dt = 1e-5;
        let quiet = Hgo::epsilon_for(model, 86.28, dt, 1e-4, 0.05).unwrap();
        let noisy = Hgo::epsilon_for(model, 86.28, dt, 1e-3, 0.05).unwrap();
        assert!(noisy > quiet, "{noisy} <= {quiet}");
        // The returned eps meets the budget.
        let g = Hgo::with_eps(model, 86.28, noisy, dt)
            .unwrap()
            .h_noise_gain();
        assert!(g * 1e-3 <= 0.05 * (1.0 + 1e-9), "{g}");
    }

    #[test]
    fn noise_gain_matches_simulation() {
        // H2 norm from the Lyapunov equation vs the impulse response summed directly.
        let o = Hgo::with_eps(ObserverModel::Cbw(cbw()), 86.28, 1e-4, 1e-5).unwrap();
        let f = o.error_matrix();
        let (l1, l2) = o.gains();
        let mut z = [l1, l2];
        let mut sum = 0.0;
        for _ in 0..200_000 {
            sum += z[1] * z[1];
            z = [
                f[0][0] * z[0] + f[0][1] * z[1],
                f[1][0] * z[0] + f[1][1] * z[1],
            ];
        }
        let g = o.h_noise_gain();
        assert!((g - sum.sqrt()).abs() < 1e-6 * g, "{g} vs {}", sum.sqrt());
    }

    #[test]
    fn rejects_bad_parameters() {
        let m = ObserverModel::Cbw(cbw());
        assert_eq!(
            Hgo::with_eps(m, 86.28, 0.0, 1e-5).unwrap_err().0,
            "HGO: eps_s > 0"
        );
        assert_eq!(
            Hgo::with_eps(m, -1.0, 1e-4, 1e-5).unwrap_err().0,
            "HGO: linear pole a_per_s > 0 (A < 0)"
        );
    }
}
