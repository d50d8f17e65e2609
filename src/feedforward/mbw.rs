//! Feedforward without inversion for the modified Bouc-Wen of 002 (eq. 8-12), and the IMS
//! model bounds of the other Bouc-Wen-family models.

use super::ims::ImsModel;
use super::FfError;
use crate::hysteresis::{AbwAbs, Dahl, Gbw, Mbw002};
use crate::real::Real;

/// 002 eq. (8-12) in piezo form (`y = d*u - h + p*u' + q*u'^3`, [`Mbw002`]):
/// `v_r = y_r/d` (eq. 8); the model's nonlinear part `w_hat = -h_hat + p*v_r' + q*v_r'^3`
/// is estimated from `v_r` instead of the applied voltage (eq. 9-10); the command is
/// `v_c = k_p*v_r - w_hat/d` (eq. 12; `k_p = 1` is eq. 11). No model inversion and no
/// algebraic loop; the price is the error between `w_hat(v_r)` and `w(v_c)`.
///
/// [`MbwFf::with_offset`] adds the output offset of an identified model (`piezo fit` fits
/// `y = offset + M(u)`): `v_r = (y_r - offset)/d`. 002's stage is zeroed, so eq. (8) has none.
#[derive(Debug, Clone, PartialEq)]
pub struct MbwFf<T> {
    model: Mbw002<T>,
    k_p: T,
    dt_s: T,
    volts_min: T,
    volts_max: T,
    /// Output of the model at zero input (um).
    offset_um: T,
    /// `h_hat` driven by `v_r` (eq. 10).
    h: T,
    v_r: T,
    u: T,
}

impl<T: Real> MbwFf<T> {
    /// `k_p` the proportional gain of 002 eq. (12) (near 1), `dt_s` the sample period (the
    /// rate `v_r'` is the first-order-hold rate over one sample, as in the model).
    pub fn new(
        model: Mbw002<T>,
        k_p: T,
        volts_min: T,
        volts_max: T,
        dt_s: T,
    ) -> Result<Self, FfError> {
        super::check_range_dt(volts_min, volts_max, dt_s)?;
        super::ensure(
            k_p.is_finite() && k_p > T::ZERO,
            "MBW feedforward: k_p finite and > 0 (002 eq. 12)",
        )?;
        let mut s = Self {
            model,
            k_p,
            dt_s,
            volts_min,
            volts_max,
            offset_um: T::ZERO,
            h: T::ZERO,
            v_r: T::ZERO,
            u: T::ZERO,
        };
        s.reset(T::ZERO);
        Ok(s)
    }

    /// The same compensator for a model `y = offset_um + M(u)`.
    pub fn with_offset(mut self, offset_um: T) -> Result<Self, FfError> {
        super::ensure(
            offset_um.is_finite(),
            "MBW feedforward: offset_um must be finite",
        )?;
        self.offset_um = offset_um;
        self.reset(offset_um);
        Ok(self)
    }

    pub fn k_p(&self) -> T {
        self.k_p
    }

    #[inline]
    pub fn compensate(&mut self, y_ref_um: T) -> T {
        if !y_ref_um.is_finite() {
            return self.u;
        }
        let d = self.model.abw().d();
        let v_r = (y_ref_um - self.offset_um) / d; // eq. (8)
        let dv = v_r - self.v_r;
        self.h = self.model.abw().advance_h(self.h, dv); // eq. (10)
        self.v_r = v_r;
        let w_hat = -self.h + self.model.rate_term(dv / self.dt_s); // eq. (9)
        let u = self.k_p * v_r - w_hat / d; // eq. (12)
        if u.is_finite() {
            self.u = u.clamp_to(self.volts_min, self.volts_max);
        }
        self.u
    }

    /// The last voltage (V).
    pub fn volts(&self) -> T {
        self.u
    }

    /// Restart at rest at voltage `u0`.
    pub fn reset_volts(&mut self, u0: T) {
        self.u = super::rest_volts(u0, self.volts_min, self.volts_max);
        self.v_r = self.u / self.k_p;
        self.h = T::ZERO;
    }

    /// Restart at rest at `y_um`.
    pub fn reset(&mut self, y_um: T) {
        let y = if y_um.is_finite() { y_um } else { T::ZERO };
        self.v_r = (y - self.offset_um) / self.model.abw().d();
        self.h = T::ZERO;
        self.u = (self.k_p * self.v_r).clamp_to(self.volts_min, self.volts_max);
    }
}

impl<T: Real> ImsModel<T> for AbwAbs<T> {
    fn d(&self) -> T {
        self.d()
    }
    /// `dh/du = alpha + delta*s - (beta*s*sgn(h) + gamma)*|h|^n <= alpha + |delta| +
    /// (beta - gamma)*h_bound^n` (largest when `h` opposes the motion).
    fn max_h_slope(&self) -> T {
        let hb = self.h_bound();
        self.alpha() + self.delta().abs() + (self.beta() - self.gamma()) * hb.abs_pow(self.n())
    }
}

impl<T: Real> ImsModel<T> for Mbw002<T> {
    fn d(&self) -> T {
        self.abw().d()
    }
    /// The rate terms only add slope when `p, q >= 0` (then `d(p*u' + q*u'^3)/du >= 0`);
    /// otherwise the output need not increase with `u` and the IMS is refused.
    fn max_h_slope(&self) -> T {
        if self.p() >= T::ZERO && self.q() >= T::ZERO {
            self.abw().max_h_slope()
        } else {
            T::MAX
        }
    }
}

impl<T: Real> ImsModel<T> for Gbw<T> {
    fn d(&self) -> T {
        self.d()
    }
    /// `dh/du = alpha*(A - (B_h*s*sgn(h) + B*s + G)*|h|^n)`: the coefficient of `|h|^n` is
    /// at least `G - B_h - |B|` (`h` opposing the motion), so the slope is at most
    /// `alpha*(A + max(0, B_h + |B| - G)*h_bound^n)`; `alpha*A` for eq. (3) as printed.
    fn max_h_slope(&self) -> T {
        let k = (self.beta_h() + self.b().abs() - self.g()).max(T::ZERO);
        self.alpha() * (self.a() + k * self.h_bound().abs_pow(self.n()))
    }
}

impl<T: Real> ImsModel<T> for Dahl<T> {
    fn d(&self) -> T {
        self.d()
    }
    /// `dh/du = sigma0*(1 - s*h/hc)^i` with `|h| <= hc` is at most `sigma0*2^i`.
    fn max_h_slope(&self) -> T {
        self.sigma0() * T::TWO.powf(self.i())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::feedforward::{Ims, ImsLoop};
    use crate::hysteresis::Hysteresis;

    /// 002 table 1, MBW column, mapped to piezo form by `Mbw002::from_002`.
    fn mbw() -> Mbw002<f64> {
        Mbw002::from_002(1.0998, -0.0656, 0.3922, -0.15, 1.0, -0.011, 0.0108, 3.68e-5).unwrap()
    }

    /// RE (002 eq. 14) of the stage output against the reference over the second period.
    fn re(mut ff: impl FnMut(f64) -> f64, m: &Mbw002<f64>, f_hz: f64) -> f64 {
        let fs = 2000.0; // 002 sample rate
        let mut s = m.init(0.0);
        let n = (2.0 * fs / f_hz) as usize;
        let (mut se, mut sy) = (0.0, 0.0);
        for k in 0..n {
            let t = k as f64 / fs;
            // 0..50 um like 002's 0-5 V sine on a 100 um stage
            let y_ref = 25.0 * (1.0 - (2.0 * core::f64::consts::PI * f_hz * t).cos());
            let u = ff(y_ref);
            let y = m.step(&mut s, u, 1.0 / fs);
            if k >= n / 2 {
                se += (y - y_ref).powi(2);
                sy += y_ref * y_ref;
            }
        }
        (se / sy).sqrt()
    }

    #[test]
    fn mbw_feedforward_reduces_error_and_ims_is_exact() {
        let m = mbw();
        let d = m.abw().d();
        let linear = re(|y| y / d, &m, 0.1);
        let mut ff = MbwFf::new(m, 1.0, -100.0, 200.0, 1.0 / 2000.0).unwrap();
        let mbw_ff = re(|y| ff.compensate(y), &m, 0.1);
        let mut ims = Ims::new(m, ImsLoop::Solved, -100.0, 200.0, 1.0 / 2000.0).unwrap();
        let exact = re(|y| ims.compensate(y), &m, 0.1);
        assert!(mbw_ff < 0.5 * linear, "{mbw_ff} vs {linear}");
        assert!(exact < 1e-9, "{exact}");
    }

    #[test]
    fn rejects_bad_gain() {
        assert!(MbwFf::new(mbw(), f64::NAN, 0.0, 1.0, 1e-3).is_err());
        assert!(MbwFf::new(mbw(), 1.0, 1.0, 0.0, 1e-3).is_err());
    }
}
