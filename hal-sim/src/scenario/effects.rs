//! Scenario sections of the stage effects beyond the Hammerstein chain (what real stages do
//! besides hysteresis, creep and one resonance): rate-dependent hysteresis, backlash,
//! start-up creep after a long rest, amplitude-dependent resonance and a nonlinear position
//! sensor. All are off by default; [`crate::stage`] implements them.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use super::{finite, positive, StageConfig};

/// Rate-dependent hysteresis: the loop widens and rotates as the input rate grows, which a
/// Hammerstein model (rate-independent hysteresis, then linear dynamics) cannot follow at
/// high rates (001 sec. III, Table I). With `v` the amplifier voltage, `h = d*v - y_static`
/// the hysteresis of the stage's model, `r` the input rate `|dv/dt|` and `vbar` the input,
/// both low-passed over `tau_s`, and `rho = r / (r + rate_ref_v_per_s)` (0 at rest, towards 1
/// at high rates):
///
/// `y = d*v - (1 + widen*rho)*h - gain_drop*rho*d*(v - vbar)`
///
/// `widen` widens the loop (and, through `h`'s slope, rotates it); `gain_drop` lowers the
/// gain about the running operating point (the rate-dependent decrease of the maximum output
/// that 001 reports). Half of both act at `r = rate_ref_v_per_s`: a 0-50 V sine at 1, 50 and
/// 100 Hz has a mean rate of 100, 5000 and 10 000 V/s, so the default gives rho 0.02, 0.5 and
/// 0.67.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RateHysteresis {
    pub enabled: bool,
    /// Relative growth of the hysteresis `h` at `rho = 1` (0.3: 30 % wider).
    pub widen: f64,
    /// Relative drop of the gain `d` about the operating point at `rho = 1`.
    pub gain_drop: f64,
    /// Input rate at which half the effect acts (V/s).
    pub rate_ref_v_per_s: f64,
    /// Time constant of the rate and operating-point low-pass (s).
    pub tau_s: f64,
}

impl Default for RateHysteresis {
    fn default() -> Self {
        Self {
            enabled: false,
            widen: 0.3,
            gain_drop: 0.05,
            rate_ref_v_per_s: 5_000.0,
            tau_s: 0.005,
        }
    }
}

/// Backlash: a play (dead zone at reversals) of `width_um` between the actuator and the
/// stage's output, as in a flexure-guided micromanipulator. After a reversal the output stands
/// still until the actuator has moved `width_um` back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Backlash {
    pub enabled: bool,
    pub width_um: f64,
}

impl Default for Backlash {
    fn default() -> Self {
        Self {
            enabled: false,
            width_um: 1.0,
        }
    }
}

/// Start-up creep: after a long rest the actuator starts slowly. The displacement away from
/// the rest position (`anchor`) is short by a fraction `s` that starts at `depth` (the stage
/// rested long before the run) and decays with the input's travel:
///
/// `y = anchor + (1 - s)*(y_static - anchor)`, `ds = -s*|dv|/travel_v + (depth - s)*dt/rest_tau_s`,
///
/// the anchor following `y_static` with `rest_tau_s` (where the stage rests). So it shows in
/// the first cycles only, and comes back after a rest of about `rest_tau_s`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StartupCreep {
    pub enabled: bool,
    /// Fraction of the displacement missing at the first motion after a long rest.
    pub depth: f64,
    /// Input travel (V, summed |dv|) over which the deficit decays by `e`.
    pub travel_v: f64,
    /// Time constant with which the deficit and the anchor recover at rest (s).
    pub rest_tau_s: f64,
}

impl Default for StartupCreep {
    fn default() -> Self {
        Self {
            enabled: false,
            depth: 0.05,
            travel_v: 150.0,
            rest_tau_s: 60.0,
        }
    }
}

/// Amplitude-dependent resonance: the structure's natural frequency and damping move with its
/// oscillation amplitude `a` (um, the free motion about its input: `sqrt(dx^2 + (dv/w0)^2)`),
/// as in the fine steering mirror whose actuators' hysteresis softens and damps the modes at
/// higher drive levels. With `rho = a / (a + level_um)`:
///
/// `wn = resonance.freq_hz * (1 + freq_shift*rho)`, `zeta = resonance.zeta * (1 + zeta_scale*rho)`
///
/// (zeta capped at 0.95). Needs `stage.resonance` on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AmplitudeDynamics {
    pub enabled: bool,
    /// Oscillation amplitude at which half the shift acts (um).
    pub level_um: f64,
    /// Relative change of the natural frequency at large amplitude (-0.2: 20 % lower).
    pub freq_shift: f64,
    /// Relative change of the damping ratio at large amplitude (1.0: doubled).
    pub zeta_scale: f64,
}

impl Default for AmplitudeDynamics {
    fn default() -> Self {
        Self {
            enabled: false,
            level_um: 2.0,
            freq_shift: -0.2,
            zeta_scale: 1.0,
        }
    }
}

/// A nonlinear position sensor: it reads `x + half_range_um*(quadratic*e^2 + cubic*e^3)` for
/// the position `x` (drift included), `e = (x - center_um)/half_range_um`: at the ends of the
/// range (`e = +-1`) the error is `quadratic +- cubic` of the half range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorNonlinearity {
    pub enabled: bool,
    pub center_um: f64,
    pub half_range_um: f64,
    pub quadratic: f64,
    pub cubic: f64,
}

impl Default for SensorNonlinearity {
    fn default() -> Self {
        Self {
            enabled: false,
            center_um: 50.0,
            half_range_um: 50.0,
            quadratic: 0.01,
            cubic: 0.0,
        }
    }
}

impl StageConfig {
    /// Any of the effects of this module on.
    pub fn any_effect(&self) -> bool {
        self.rate_hysteresis.enabled
            || self.backlash.enabled
            || self.startup_creep.enabled
            || self.amplitude_dynamics.enabled
            || self.sensor_nonlinearity.enabled
    }

    /// Checks the effects' values (errors name the field).
    pub(super) fn validate_effects(&self) -> Result<()> {
        let resonance_on = self.resonance.enabled;
        let r = &self.rate_hysteresis;
        if !(r.gain_drop.is_finite() && (0.0..1.0).contains(&r.gain_drop)) {
            bail!(
                "stage.rate_hysteresis.gain_drop must be in [0, 1), got {}",
                r.gain_drop
            );
        }
        if !(r.widen.is_finite() && r.widen > -1.0) {
            bail!("stage.rate_hysteresis.widen must be > -1, got {}", r.widen);
        }
        positive(r.rate_ref_v_per_s, "stage.rate_hysteresis.rate_ref_v_per_s")?;
        positive(r.tau_s, "stage.rate_hysteresis.tau_s")?;
        if !(self.backlash.width_um.is_finite() && self.backlash.width_um >= 0.0) {
            bail!(
                "stage.backlash.width_um must be finite and >= 0, got {}",
                self.backlash.width_um
            );
        }
        let s = &self.startup_creep;
        if !(s.depth.is_finite() && (0.0..1.0).contains(&s.depth)) {
            bail!(
                "stage.startup_creep.depth must be in [0, 1), got {}",
                s.depth
            );
        }
        positive(s.travel_v, "stage.startup_creep.travel_v")?;
        positive(s.rest_tau_s, "stage.startup_creep.rest_tau_s")?;
        let a = &self.amplitude_dynamics;
        positive(a.level_um, "stage.amplitude_dynamics.level_um")?;
        if !(a.freq_shift.is_finite() && a.freq_shift > -0.9 && a.freq_shift < 1.0) {
            bail!(
                "stage.amplitude_dynamics.freq_shift must be in (-0.9, 1), got {}",
                a.freq_shift
            );
        }
        if !(a.zeta_scale.is_finite() && a.zeta_scale > -0.9) {
            bail!(
                "stage.amplitude_dynamics.zeta_scale must be finite and > -0.9, got {}",
                a.zeta_scale
            );
        }
        if a.enabled && !resonance_on {
            bail!("stage.amplitude_dynamics needs stage.resonance.enabled = true");
        }
        let n = &self.sensor_nonlinearity;
        finite(n.center_um, "stage.sensor_nonlinearity.center_um")?;
        positive(n.half_range_um, "stage.sensor_nonlinearity.half_range_um")?;
        finite(n.quadratic, "stage.sensor_nonlinearity.quadratic")?;
        finite(n.cubic, "stage.sensor_nonlinearity.cubic")?;
        // Monotone over the range: 1 + 2 q e + 3 c e^2 > 0 for |e| <= 1.
        if 2.0 * n.quadratic.abs() + 3.0 * n.cubic.abs() >= 1.0 {
            bail!(
                "stage.sensor_nonlinearity: 2|quadratic| + 3|cubic| must be below 1 (a monotone sensor), got {}",
                2.0 * n.quadratic.abs() + 3.0 * n.cubic.abs()
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::scenario::Scenario;

    #[test]
    fn sections_parse_and_errors_name_the_field() {
        let s = Scenario::from_toml(
            "[stage.rate_hysteresis]\nenabled = true\nwiden = 0.4\n[stage.backlash]\nenabled = true\nwidth_um = 0.5\n[stage.sensor_nonlinearity]\nenabled = true\nquadratic = 0.02",
        )
        .unwrap();
        assert!(s.stage.rate_hysteresis.enabled && s.stage.rate_hysteresis.widen == 0.4);
        assert_eq!(s.stage.rate_hysteresis.tau_s, 0.005);
        assert!(s.stage.any_effect());
        assert!(!Scenario::default().stage.any_effect());
        for (toml, field) in [
            (
                "[stage.backlash]\nwidth_um = -1.0",
                "stage.backlash.width_um",
            ),
            (
                "[stage.startup_creep]\ndepth = 1.5",
                "stage.startup_creep.depth",
            ),
            (
                "[stage.resonance]\nenabled = false\n[stage.amplitude_dynamics]\nenabled = true",
                "stage.amplitude_dynamics",
            ),
            (
                "[stage.sensor_nonlinearity]\nquadratic = 0.6",
                "stage.sensor_nonlinearity",
            ),
            (
                "[stage.rate_hysteresis]\nrate_ref_v_per_s = 0.0",
                "rate_ref_v_per_s",
            ),
            ("[stage.backlash]\nwidht_um = 1.0", "widht_um"),
        ] {
            let e = Scenario::from_toml(toml).unwrap_err();
            assert!(format!("{e:#}").contains(field), "{toml}: {e:#}");
        }
    }
}
