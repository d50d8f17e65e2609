//! Observers for the distributed-parameter actuator (000 Part V, eq. 9): the Euler-Bernoulli
//! beam `EI y'''' + rho A_s y_tt = q(x, t)` driven by the piezo load `q ~ d u - h`, truncated
//! to a few modes `y(x, t) = sum_i phi_i(x) eta_i(t)`. The sensor is at the tip `x = L`; the
//! control objective is at `x != L`, read from the modal estimate as `c_out . x^`.
//!
//! * [`Hgo`]: high-gain observer, 000 eq. (5)-(6) generalised to the modal model: the state is
//!   `z = [eta, eta', h]`, the linear part `Phi = [[A, -B], [0, 0]]` (hysteresis as an input of
//!   the mechanics), the known nonlinearity the CBW rate `f(h, du)` of 000 eq. (1); the gain
//!   puts every error pole at `-1/eps`.
//! * [`Nno`]: neural-network observer: the same modal model with the CBW model run open loop,
//!   plus a one-hidden-layer tanh network `g^ = W^T sigma(V xi)` that learns what model and
//!   truncation miss; weights adapt online with e-modification (`W' = eta ey sigma
//!   - rho |ey| W`), bounded by projection.
//!
//! Both take the measured tip position and the measured voltage; both are allocation-free and
//! bounded per sample (one RK4 step, one CBW step).

use super::force::{rk4, VoltageInput, VoltageInputState};
use super::linalg::{ackermann, dot, mat_vec, repeated_pole, solve};
use crate::hysteresis::{BwState, Cbw, Hysteresis, ParamError};
use crate::real::Real;

fn all_finite<T: Real, const N: usize>(v: &[T; N]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// The modal model the observers are built on: `x' = A x + B v`, tip `y = C x`, control
/// point `y_c = C_out x`, input `v = d u - h` (um).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModalModel<T, const N: usize> {
    pub a: [[T; N]; N],
    pub b: [T; N],
    pub c_tip: [T; N],
    pub c_out: [T; N],
}

impl<T: Real, const N: usize> ModalModel<T, N> {
    fn validate(&self) -> Result<(), ParamError> {
        let ok = self.a.iter().all(all_finite)
            && all_finite(&self.b)
            && all_finite(&self.c_tip)
            && all_finite(&self.c_out);
        if ok {
            Ok(())
        } else {
            Err(ParamError("modal model: all entries must be finite"))
        }
    }
}

/// High-gain observer on the augmented modal state `z = [x, h]` (`M = N + 1` entries).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hgo<T, const M: usize> {
    /// `Phi` of 000 eq. (5): modal dynamics with the hysteresis column `-B`.
    phi: [[T; M]; M],
    /// Input column of `d u`.
    b_du: [T; M],
    c_tip: [T; M],
    c_out: [T; M],
    l: [T; M],
    cbw: Cbw<T>,
    input: VoltageInput<T>,
    dt: T,
}

/// HGO state: `z^ = [x^, h^]` and the voltage input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HgoState<T, const M: usize> {
    pub z: [T; M],
    pub input: VoltageInputState<T>,
}

impl<T: Real, const M: usize> Hgo<T, M> {
    /// `model` has `N = M - 1` modal states (`N` is implied by `M`, checked at run time);
    /// `eps`: high-gain parameter (s), every error pole at `-1/eps`.
    pub fn new<const N: usize>(
        model: &ModalModel<T, N>,
        cbw: Cbw<T>,
        eps: T,
        input: VoltageInput<T>,
        rate_hz: T,
    ) -> Result<Self, ParamError> {
        model.validate()?;
        if N + 1 != M {
            return Err(ParamError("HGO: M = N + 1 (modal states plus h)"));
        }
        if !(rate_hz.is_finite() && rate_hz > T::ZERO) {
            return Err(ParamError("HGO: rate_hz > 0"));
        }
        let dt = T::ONE / rate_hz;
        if !(eps.is_finite() && eps > T::ZERO && dt <= eps) {
            return Err(ParamError(
                "HGO: eps >= 1 / rate_hz (one RK4 step per sample)",
            ));
        }
        let d = cbw.d();
        let mut phi = [[T::ZERO; M]; M];
        let mut b_du = [T::ZERO; M];
        let mut c_tip = [T::ZERO; M];
        let mut c_out = [T::ZERO; M];
        for (i, (row, bi)) in model.a.iter().zip(&model.b).enumerate() {
            phi[i][..N].copy_from_slice(row);
            phi[i][N] = -*bi;
            b_du[i] = *bi * d;
        }
        c_tip[..N].copy_from_slice(&model.c_tip);
        c_out[..N].copy_from_slice(&model.c_out);
        let l = ackermann(&phi, &c_tip, &repeated_pole(T::ONE / eps))
            .ok_or(ParamError("HGO: (Phi, C) must be observable (000 eq. 5)"))?;
        Ok(Self {
            phi,
            b_du,
            c_tip,
            c_out,
            l,
            cbw,
            input,
            dt,
        })
    }

    /// Observer gain `L` (for reports).
    pub fn gain(&self) -> &[T; M] {
        &self.l
    }

    pub fn init(&self, u0_volts: T) -> HgoState<T, M> {
        HgoState {
            z: [T::ZERO; M],
            input: self.input.init(u0_volts),
        }
    }

    /// One sample: measured tip position (um), measured voltage (V). Returns the estimated
    /// position at the control point (um).
    pub fn update(&self, s: &mut HgoState<T, M>, y_tip_um: T, u_volts: T) -> T {
        let u_prev = s.input.u_h;
        self.input.update(&mut s.input, u_volts);
        // Known nonlinearity f(h, du): exact CBW step in the input domain.
        if let Some(h) = s.z.last_mut() {
            *h = self.cbw.advance_h(*h, u_prev, s.input.u_h - u_prev);
        }
        let meas = y_tip_um.is_finite();
        let u = s.input.u_lin;
        let z = rk4(s.z, self.dt, |z| {
            let e = if meas {
                y_tip_um - dot(&self.c_tip, &z)
            } else {
                T::ZERO
            };
            let mut dz = mat_vec(&self.phi, &z);
            for ((dzi, bi), li) in dz.iter_mut().zip(&self.b_du).zip(&self.l) {
                *dzi += *bi * u + *li * e;
            }
            dz
        });
        if all_finite(&z) {
            s.z = z;
        } else {
            s.z = [T::ZERO; M];
        }
        dot(&self.c_out, &s.z)
    }

    /// Estimated tip position (um).
    pub fn tip(&self, s: &HgoState<T, M>) -> T {
        dot(&self.c_tip, &s.z)
    }
}

/// Inputs of the network: voltage, model hysteresis, voltage rate (two scales), bias.
pub const NNO_INPUTS: usize = 5;

/// Network and adaptation settings of the [`Nno`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NnoConfig<T> {
    /// Learning rate `eta` (um^-1 s^-1 per unit of output).
    pub learning_rate: T,
    /// e-modification gain `rho` (1/(um s)).
    pub e_mod: T,
    /// Projection bound of every output weight (um).
    pub w_max: T,
    /// Observer (Luenberger) error-pole frequency (Hz), moderate: the network does the rest.
    pub observer_hz: T,
    /// Input scales: position (um), voltage (V), voltage rate (V/s).
    pub y_scale_um: T,
    pub u_scale_volts: T,
    pub du_scale: T,
    /// Seed of the fixed hidden-layer weights.
    pub seed: u32,
}

/// Neural-network observer with `N` modal states and `H` hidden tanh units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nno<T, const N: usize, const H: usize> {
    model: ModalModel<T, N>,
    l: [T; N],
    /// Sign of the static gain from the network output to the tip estimate.
    adapt_sign: T,
    v: [[T; NNO_INPUTS]; H],
    cfg: NnoConfig<T>,
    cbw: Cbw<T>,
    input: VoltageInput<T>,
    dt: T,
}

/// NNO state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NnoState<T, const N: usize, const H: usize> {
    pub x: [T; N],
    /// Output weights, last one the bias.
    pub w: [T; H],
    pub w_bias: T,
    pub cbw: BwState<T>,
    pub input: VoltageInputState<T>,
    /// Last network output `g^` (um).
    pub g: T,
}

impl<T: Real, const N: usize, const H: usize> Nno<T, N, H> {
    pub fn new(
        model: &ModalModel<T, N>,
        cbw: Cbw<T>,
        cfg: NnoConfig<T>,
        input: VoltageInput<T>,
        rate_hz: T,
    ) -> Result<Self, ParamError> {
        model.validate()?;
        let pos = |v: T| v.is_finite() && v > T::ZERO;
        if !pos(rate_hz) {
            return Err(ParamError("NNO: rate_hz > 0"));
        }
        let dt = T::ONE / rate_hz;
        if !(pos(cfg.learning_rate) || cfg.learning_rate == T::ZERO) {
            return Err(ParamError("NNO: learning_rate >= 0"));
        }
        if !(pos(cfg.e_mod) || cfg.e_mod == T::ZERO) {
            return Err(ParamError("NNO: e_mod >= 0"));
        }
        if !(pos(cfg.w_max) && pos(cfg.y_scale_um) && pos(cfg.u_scale_volts) && pos(cfg.du_scale)) {
            return Err(ParamError("NNO: w_max and input scales > 0"));
        }
        let wo = T::TWO * T::PI * cfg.observer_hz;
        if !(pos(cfg.observer_hz) && wo * dt <= T::ONE) {
            return Err(ParamError("NNO: 0 < 2 pi observer_hz / rate_hz <= 1"));
        }
        let l = ackermann(&model.a, &model.c_tip, &repeated_pole(wo))
            .ok_or(ParamError("NNO: (A, C) must be observable"))?;
        // Static gain from g to the tip estimate: -C (A - L C)^-1 B.
        let mut ao = model.a;
        for (row, li) in ao.iter_mut().zip(&l) {
            for (aij, cj) in row.iter_mut().zip(&model.c_tip) {
                *aij -= *li * *cj;
            }
        }
        let w = solve(ao, model.b).ok_or(ParamError("NNO: A - L C must be invertible"))?;
        let g0 = -dot(&model.c_tip, &w);
        if g0 == T::ZERO {
            return Err(ParamError("NNO: the network output must reach the tip"));
        }
        // Fixed hidden layer: deterministic pseudo-random weights in [-1, 1] (xorshift).
        let mut v = [[T::ZERO; NNO_INPUTS]; H];
        let mut r = cfg.seed | 1;
        for row in v.iter_mut() {
            for x in row.iter_mut() {
                r ^= r << 13;
                r ^= r >> 17;
                r ^= r << 5;
                *x = T::from_f64(r as f64 / u32::MAX as f64 * 2.0 - 1.0);
            }
        }
        Ok(Self {
            model: *model,
            l,
            adapt_sign: g0.sgn(),
            v,
            cfg,
            cbw,
            input,
            dt,
        })
    }

    pub fn init(&self, u0_volts: T) -> NnoState<T, N, H> {
        let u = if u0_volts.is_finite() {
            u0_volts
        } else {
            T::ZERO
        };
        NnoState {
            x: [T::ZERO; N],
            w: [T::ZERO; H],
            w_bias: T::ZERO,
            cbw: self.cbw.init(u),
            input: self.input.init(u),
            g: T::ZERO,
        }
    }

    /// One sample: measured tip position (um), measured voltage (V). Returns the estimated
    /// position at the control point (um).
    pub fn update(&self, s: &mut NnoState<T, N, H>, y_tip_um: T, u_volts: T) -> T {
        let u_prev = s.input.u_lin;
        self.input.update(&mut s.input, u_volts);
        self.cbw.step(&mut s.cbw, s.input.u_h, self.dt);
        let v_model = self.cbw.d() * s.input.u_lin - s.cbw.h;
        let du = (s.input.u_lin - u_prev) / self.dt;
        // Inputs: what the hysteresis error depends on (voltage, model state, direction);
        // not the estimate itself, so the network does not feed back on its own output.
        let hb = self.cbw.h_bound();
        let xi = [
            s.input.u_lin / self.cfg.u_scale_volts,
            s.cbw.h / hb,
            (du / self.cfg.du_scale).tanh(),
            (T::from_f64(10.0) * du / self.cfg.du_scale).tanh(),
            T::ONE,
        ];
        let mut sigma = [T::ZERO; H];
        for (sj, vj) in sigma.iter_mut().zip(&self.v) {
            *sj = dot(vj, &xi).tanh();
        }
        let g = dot(&s.w, &sigma) + s.w_bias;
        s.g = g;
        let meas = y_tip_um.is_finite();
        let v_in = v_model + g;
        let x = rk4(s.x, self.dt, |x| {
            let e = if meas {
                y_tip_um - dot(&self.model.c_tip, &x)
            } else {
                T::ZERO
            };
            let mut dx = mat_vec(&self.model.a, &x);
            for ((dxi, bi), li) in dx.iter_mut().zip(&self.model.b).zip(&self.l) {
                *dxi += *bi * v_in + *li * e;
            }
            dx
        });
        s.x = if all_finite(&x) { x } else { [T::ZERO; N] };
        // Weight adaptation (e-modification), explicit Euler, projected onto |w| <= w_max.
        if meas {
            let ey = (y_tip_um - dot(&self.model.c_tip, &s.x)) / self.cfg.y_scale_um;
            if ey.is_finite() {
                let k = self.cfg.learning_rate * self.dt * self.adapt_sign * ey;
                let leak = self.cfg.e_mod * self.dt * ey.abs();
                let wm = self.cfg.w_max;
                for (wj, sj) in s.w.iter_mut().zip(&sigma) {
                    *wj = (*wj + k * *sj - leak * *wj).clamp_to(-wm, wm);
                }
                s.w_bias = (s.w_bias + k - leak * s.w_bias).clamp_to(-wm, wm);
            }
        }
        dot(&self.model.c_out, &s.x)
    }

    /// Estimated tip position (um).
    pub fn tip(&self, s: &NnoState<T, N, H>) -> T {
        dot(&self.model.c_tip, &s.x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One mode, tip = control point: both observers follow a static input.
    fn one_mode() -> ModalModel<f64, 2> {
        let w = 2.0 * std::f64::consts::PI * 100.0;
        ModalModel {
            a: [[0.0, 1.0], [-w * w, -0.04 * w]],
            b: [0.0, w * w],
            c_tip: [1.0, 0.0],
            c_out: [0.5, 0.0],
        }
    }

    fn raw() -> VoltageInput<f64> {
        VoltageInput::new(0.0, 0.0, 1e-4).unwrap()
    }

    fn cbw() -> Cbw<f64> {
        Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap()
    }

    #[test]
    fn hgo_converges_on_exact_model() {
        let m = one_mode();
        let o: Hgo<f64, 3> = Hgo::new(&m, cbw(), 1.0 / 1500.0, raw(), 10_000.0).unwrap();
        let mut s = o.init(0.0);
        // Plant: the model itself, simulated finely.
        let model_cbw = cbw();
        let mut hs = model_cbw.init(0.0);
        let mut x = [0.0, 0.0];
        let mut err: f64 = 0.0;
        for k in 0..20_000 {
            let u = 60.0 + 50.0 * (2.0 * std::f64::consts::PI * 5.0 * k as f64 * 1e-4).sin();
            let v = model_cbw.step(&mut hs, u, 1e-4);
            for _ in 0..10 {
                x = rk4(x, 1e-5, |x| {
                    let mut dx = mat_vec(&m.a, &x);
                    dx[1] += m.b[1] * v;
                    dx
                });
            }
            let yc = o.update(&mut s, x[0], u);
            if k > 5000 {
                err = err.max((yc - 0.5 * x[0]).abs());
            }
        }
        assert!(err < 0.02, "max error {err} um");
    }

    #[test]
    fn nno_survives_nan_and_keeps_weights_bounded() {
        let m = one_mode();
        let cfg = NnoConfig {
            learning_rate: 1e6,
            e_mod: 10.0,
            w_max: 3.0,
            observer_hz: 200.0,
            y_scale_um: 1.0,
            u_scale_volts: 100.0,
            du_scale: 1000.0,
            seed: 7,
        };
        let o: Nno<f64, 2, 6> = Nno::new(&m, cbw(), cfg, raw(), 10_000.0).unwrap();
        let mut s = o.init(0.0);
        for k in 0..5000 {
            let y = if k % 7 == 0 { f64::NAN } else { 1e3 };
            let u = if k % 11 == 0 { f64::INFINITY } else { 10.0 };
            let yc = o.update(&mut s, y, u);
            assert!(yc.is_finite());
        }
        assert!(s.w.iter().all(|w| w.abs() <= 3.0));
    }

    #[test]
    fn rejects_unobservable_and_bad_sizes() {
        let mut m = one_mode();
        m.c_tip = [0.0, 0.0];
        assert!(Hgo::<f64, 3>::new(&m, cbw(), 1e-3, raw(), 1e4).is_err());
        assert_eq!(
            Hgo::<f64, 4>::new(&one_mode(), cbw(), 1e-3, raw(), 1e4)
                .unwrap_err()
                .0,
            "HGO: M = N + 1 (modal states plus h)"
        );
    }
}
