//! Interaction-force estimation from position and voltage only (000 Part V, "Object
//! characterization via piezoelectric manipulation": no force sensor).
//!
//! Actuator model (000 eq. 2 with second-order mechanics, loaded by the object):
//! `m y'' + c y' + k y = k (d u - h) - F`, `h` the CBW hysteresis (000 eq. 1).
//! The force is an extra, slowly varying state of an extended-state observer (the construction
//! of 000 eq. 10 with the force as the extended state):
//! ```text
//! y^'  = v^ + l1 e                                 e = y - y^
//! v^'  = w^2 (d u - h^ - y^) - 2 zeta w v^ - (w^2 / k) F^ + l2 e
//! F^'  = -(k / w^2) l3 e
//! ```
//! `h^` is the CBW model driven by the (low-pass filtered) measured voltage. The gains place
//! all three error poles at `-w_o`; the estimate is then the true force through the low-pass
//! `w_o^3 / (s + w_o)^3` plus the effect of model error and noise, which the object
//! identification uses to filter its regressors the same way.

use crate::hysteresis::{BwState, Cbw, Hysteresis, ParamError};
use crate::real::Real;

/// Second-order mechanics of the stage: natural frequency, damping ratio and stiffness
/// (`m = k / w^2`, `c = 2 zeta w m`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageDynamics<T> {
    /// Unloaded natural frequency (Hz).
    pub natural_hz: T,
    /// Damping ratio (1).
    pub damping_ratio: T,
    /// Stage stiffness `k` (mN/um): force per um of `d u - h - y`.
    pub stiffness_mn_per_um: T,
}

impl<T: Real> StageDynamics<T> {
    fn validate(&self) -> Result<(), ParamError> {
        let ok = |v: T| v.is_finite() && v > T::ZERO;
        if !ok(self.natural_hz) {
            return Err(ParamError("stage: natural_hz > 0"));
        }
        if !(self.damping_ratio.is_finite() && self.damping_ratio >= T::ZERO) {
            return Err(ParamError("stage: damping_ratio >= 0"));
        }
        if !ok(self.stiffness_mn_per_um) {
            return Err(ParamError("stage: stiffness_mn_per_um > 0"));
        }
        Ok(())
    }

    /// Angular natural frequency (rad/s).
    pub fn omega(&self) -> T {
        T::TWO * T::PI * self.natural_hz
    }
}

/// How an observer takes the measured voltage: a one-pole low-pass for the linear term
/// `d u`, then a play (backlash) of half-width `play_volts` for the hysteresis input.
///
/// The hysteresis model sees the voltage itself while it keeps moving one way; after a
/// reversal it holds the turning point until the voltage has come back by `2 play`.
///
/// Why: the CBW rate `dh = alpha du - beta |du| h - gamma du |h|` integrates `|du|`,
/// so voltage-measurement noise alone (a random walk of tiny reversals) would make the model's
/// `h` decay towards zero; reversals smaller than the play width are noise and are ignored.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageInput<T> {
    alpha: T,
    play: T,
}

/// State of [`VoltageInput`]: filtered voltage and the play output.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct VoltageInputState<T> {
    pub u_lin: T,
    /// Play output (V).
    pub u_play: T,
    /// Direction of the last push of the play (-1, 0, 1).
    pub dir: T,
    /// Input of the hysteresis model (V): the play output moved back by its lag.
    pub u_h: T,
}

impl<T: Real> VoltageInput<T> {
    /// `filter_hz` cutoff (0 = none), `play_volts` half-width (0 = none), `dt` sample time.
    pub fn new(filter_hz: T, play_volts: T, dt: T) -> Result<Self, ParamError> {
        if !(filter_hz.is_finite() && filter_hz >= T::ZERO) {
            return Err(ParamError("voltage input: u_filter_hz >= 0"));
        }
        if !(play_volts.is_finite() && play_volts >= T::ZERO) {
            return Err(ParamError("voltage input: u_play_volts >= 0"));
        }
        let alpha = if filter_hz > T::ZERO {
            -(-(T::TWO * T::PI * filter_hz * dt)).exp_m1()
        } else {
            T::ONE
        };
        Ok(Self {
            alpha,
            play: play_volts,
        })
    }

    pub fn init(&self, u0: T) -> VoltageInputState<T> {
        let u = if u0.is_finite() { u0 } else { T::ZERO };
        VoltageInputState {
            u_lin: u,
            u_play: u,
            dir: T::ZERO,
            u_h: u,
        }
    }

    /// Takes one measured voltage; a non-finite one holds the state.
    #[inline]
    pub fn update(&self, s: &mut VoltageInputState<T>, u: T) {
        if u.is_finite() {
            s.u_lin += self.alpha * (u - s.u_lin);
            let lo = s.u_lin - self.play;
            let hi = s.u_lin + self.play;
            if s.u_play < lo {
                s.u_play = lo;
                s.dir = T::ONE;
            } else if s.u_play > hi {
                s.u_play = hi;
                s.dir = -T::ONE;
            }
            // While the play is pushed, its output lags the voltage by `play`; the model
            // gets the voltage itself and only the small reversals are dropped.
            s.u_h = s.u_play + self.play * s.dir;
        }
    }
}

/// Force extended-state observer: configuration (immutable after `new`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceEso<T> {
    cbw: Cbw<T>,
    stage: StageDynamics<T>,
    dt: T,
    w2: T,
    two_zeta_w: T,
    /// `w^2 / k` (1/(mN s^2) * um): acceleration per mN.
    accel_per_mn: T,
    l: [T; 3],
    input: VoltageInput<T>,
    observer_hz: T,
}

/// Force observer state.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ForceEsoState<T> {
    /// Estimated position (um).
    pub y_um: T,
    /// Estimated velocity (um/s).
    pub v_um_per_s: T,
    /// Estimated interaction force (mN), positive pushing against the stage.
    pub force_mn: T,
    /// Voltage input and model hysteresis.
    pub input: VoltageInputState<T>,
    pub cbw: BwState<T>,
}

impl<T: Real> ForceEso<T> {
    /// `observer_hz`: error-pole frequency `w_o / 2 pi`; `input`: how the measured voltage is
    /// taken (see [`VoltageInput`]); `rate_hz`: sample rate.
    pub fn new(
        cbw: Cbw<T>,
        stage: StageDynamics<T>,
        observer_hz: T,
        input: VoltageInput<T>,
        rate_hz: T,
    ) -> Result<Self, ParamError> {
        stage.validate()?;
        if !(rate_hz.is_finite() && rate_hz > T::ZERO) {
            return Err(ParamError("force ESO: rate_hz > 0"));
        }
        let dt = T::ONE / rate_hz;
        let w = stage.omega();
        let wo = T::TWO * T::PI * observer_hz;
        if !(observer_hz.is_finite() && observer_hz > T::ZERO) {
            return Err(ParamError("force ESO: observer_hz > 0"));
        }
        // One RK4 step per sample: keep every observer and plant pole well inside its
        // stability region.
        if !(wo * dt <= T::ONE && w * dt <= T::ONE) {
            return Err(ParamError(
                "force ESO: 2 pi observer_hz / rate_hz <= 1 and 2 pi natural_hz / rate_hz <= 1",
            ));
        }
        let two_zeta_w = T::TWO * stage.damping_ratio * w;
        let w2 = w * w;
        // Characteristic polynomial of the error: s^3 + (l1 + 2 zeta w) s^2
        //   + (2 zeta w l1 + w^2 + l2) s + l3 = (s + w_o)^3.
        let l1 = T::from_f64(3.0) * wo - two_zeta_w;
        let l2 = T::from_f64(3.0) * wo * wo - w2 - two_zeta_w * l1;
        let l3 = wo * wo * wo;
        Ok(Self {
            cbw,
            stage,
            dt,
            w2,
            two_zeta_w,
            accel_per_mn: w2 / stage.stiffness_mn_per_um,
            l: [l1, l2, l3],
            input,
            observer_hz,
        })
    }

    pub fn stage(&self) -> &StageDynamics<T> {
        &self.stage
    }
    pub fn observer_hz(&self) -> T {
        self.observer_hz
    }
    pub fn cbw(&self) -> &Cbw<T> {
        &self.cbw
    }

    /// At rest at position `y0_um` with voltage `u0_volts`, no force.
    pub fn init(&self, y0_um: T, u0_volts: T) -> ForceEsoState<T> {
        let u = if u0_volts.is_finite() {
            u0_volts
        } else {
            T::ZERO
        };
        ForceEsoState {
            y_um: if y0_um.is_finite() { y0_um } else { T::ZERO },
            v_um_per_s: T::ZERO,
            force_mn: T::ZERO,
            input: self.input.init(u),
            cbw: self.cbw.init(u),
        }
    }

    /// One sample: measured position (um) and measured voltage (V); returns the force
    /// estimate (mN). A non-finite measurement is skipped (prediction only).
    pub fn update(&self, s: &mut ForceEsoState<T>, y_um: T, u_volts: T) -> T {
        self.input.update(&mut s.input, u_volts);
        self.cbw.step(&mut s.cbw, s.input.u_h, self.dt);
        let v_in = self.cbw.d() * s.input.u_lin - s.cbw.h;
        let meas = y_um.is_finite();
        let [l1, l2, l3] = self.l;
        let f = |x: [T; 3]| -> [T; 3] {
            let e = if meas { y_um - x[0] } else { T::ZERO };
            [
                x[1] + l1 * e,
                self.w2 * (v_in - x[0]) - self.two_zeta_w * x[1] - self.accel_per_mn * x[2]
                    + l2 * e,
                -l3 * e / self.accel_per_mn,
            ]
        };
        let x0 = [s.y_um, s.v_um_per_s, s.force_mn];
        let x = rk4(x0, self.dt, f);
        if x.iter().all(|v| v.is_finite()) {
            [s.y_um, s.v_um_per_s, s.force_mn] = x;
        } else {
            // Cannot happen for finite inputs; restart from the measurement if it does.
            s.y_um = if meas { y_um } else { T::ZERO };
            s.v_um_per_s = T::ZERO;
            s.force_mn = T::ZERO;
        }
        s.force_mn
    }
}

/// One classical RK4 step of `x' = f(x)` over `h`.
#[inline]
pub(crate) fn rk4<T: Real, const N: usize>(
    x: [T; N],
    h: T,
    f: impl Fn([T; N]) -> [T; N],
) -> [T; N] {
    let add = |a: [T; N], b: [T; N], s: T| -> [T; N] {
        let mut r = a;
        for (ri, bi) in r.iter_mut().zip(b.iter()) {
            *ri += s * *bi;
        }
        r
    };
    let half = h * T::HALF;
    let k1 = f(x);
    let k2 = f(add(x, k1, half));
    let k3 = f(add(x, k2, half));
    let k4 = f(add(x, k3, h));
    let mut out = x;
    let sixth = h / T::from_f64(6.0);
    for i in 0..N {
        out[i] += sixth * (k1[i] + T::TWO * (k2[i] + k3[i]) + k4[i]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eso() -> ForceEso<f64> {
        ForceEso::new(
            Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap(),
            StageDynamics {
                natural_hz: 800.0,
                damping_ratio: 0.15,
                stiffness_mn_per_um: 200.0,
            },
            150.0,
            VoltageInput::new(0.0, 0.0, 1e-4).unwrap(),
            10_000.0,
        )
        .unwrap()
    }

    /// A constant force on the exact model is recovered with zero steady-state error.
    #[test]
    fn constant_force_is_recovered() {
        let o = eso();
        let mut s = o.init(0.0, 0.0);
        // Static equilibrium at u = 50 V with F = 30 mN: y = d u - h - F/k.
        let cbw = *o.cbw();
        let mut hs = cbw.init(0.0);
        let mut y_free = 0.0;
        for k in 0..=500 {
            y_free = cbw.step(&mut hs, 50.0 * k as f64 / 500.0, 1e-4);
        }
        let y = y_free - 30.0 / 200.0;
        let mut f = 0.0;
        for k in 0..=5000 {
            let u = 50.0 * (k.min(500) as f64) / 500.0;
            f = o.update(&mut s, if k >= 500 { y } else { f64::NAN }, u);
        }
        assert!((f - 30.0).abs() < 1e-3, "{f}");
    }

    #[test]
    fn rejects_too_fast_observer_and_bad_stage() {
        let cbw = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
        let st = StageDynamics {
            natural_hz: 800.0,
            damping_ratio: 0.15,
            stiffness_mn_per_um: 200.0,
        };
        assert!(ForceEso::new(
            cbw,
            st,
            5000.0,
            VoltageInput::new(0.0, 0.0, 1e-4).unwrap(),
            10_000.0
        )
        .is_err());
        let bad = StageDynamics {
            stiffness_mn_per_um: -1.0,
            ..st
        };
        assert_eq!(
            ForceEso::new(
                cbw,
                bad,
                100.0,
                VoltageInput::new(0.0, 0.0, 1e-4).unwrap(),
                10_000.0
            )
            .unwrap_err()
            .0,
            "stage: stiffness_mn_per_um > 0"
        );
    }

    #[test]
    fn nan_measurements_keep_state_finite() {
        let o = eso();
        let mut s = o.init(0.0, 0.0);
        for k in 0..100 {
            let y = if k % 3 == 0 { f64::NAN } else { 0.1 };
            let u = if k % 5 == 0 { f64::INFINITY } else { 1.0 };
            let f = o.update(&mut s, y, u);
            assert!(f.is_finite());
        }
    }
}
