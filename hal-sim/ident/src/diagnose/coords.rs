//! Search coordinates of the diagnosis model's nonlinear parameters ([`Shape`]): one
//! unbounded vector per cause set, mapped into the valid ranges by clamping.

use super::evidence::no_shape;
use super::model::{Cause, Causes, Scales, Shape};

impl Scales {
    /// Largest delay searched: a tenth of the record, at most 50 ms.
    fn max_delay_s(&self) -> f64 {
        (0.1 * self.duration_s).min(0.05)
    }
    /// Exact discretisation: up to the sample rate (above it `G` is near unity).
    fn max_wn_hz(&self) -> f64 {
        1.0 / self.dt
    }
}

/// Search coordinates of [`Shape`] for a cause set (unbounded; mapped by clamping).
/// The CBW shape is `ln((beta + gamma) * span)` and `ln((beta - gamma) / (beta + gamma))`,
/// which covers 004 eq. (3) exactly (`gamma < 0` when the second exceeds 0).
#[derive(Debug, Clone, Copy)]
pub struct Coords {
    pub causes: Causes,
    pub scales: Scales,
}

impl Coords {
    pub fn dim(&self) -> usize {
        let c = self.causes;
        2 + usize::from(c.has(Cause::Delay))
            + 2 * usize::from(c.has(Cause::Saturation))
            + usize::from(c.has(Cause::SlewLimit))
            + 2 * usize::from(c.has(Cause::Dynamics) || c.has(Cause::AmplitudeDynamics))
            + 3 * usize::from(c.has(Cause::AmplitudeDynamics))
            + usize::from(c.has(Cause::Backlash))
            + usize::from(c.has(Cause::StartupCreep))
            + usize::from(c.has(Cause::RateDependence))
    }

    /// Shape from coordinates; every coordinate is clamped into its valid range.
    pub fn shape(&self, x: &[f64]) -> Shape {
        self.shape_and_excess(x).0
    }

    /// Shape, and how far (squared, in coordinate units) `x` lies outside the valid ranges:
    /// the search adds it as a penalty so a clamped coordinate is never a flat plateau.
    pub fn shape_and_excess(&self, x: &[f64]) -> (Shape, f64) {
        let s = &self.scales;
        let span = s.span();
        let mut it = x.iter().copied();
        let mut excess = 0.0;
        let mut next = |lo: f64, hi: f64| {
            let v = it.next().unwrap_or(0.0);
            let c = v.clamp(lo, hi);
            excess += (v - c) * (v - c);
            c
        };
        // Below 1 the loop does not saturate within the input span: CBW degenerates into a
        // quadratic in u whose unclosed minor loops ratchet from cycle to cycle.
        let a = next(0.0, 8.0).exp() / span;
        let r = next(-12.0, 5.0).exp();
        let mut shape = Shape {
            beta: 0.5 * a * (1.0 + r),
            gamma: 0.5 * a * (1.0 - r),
            ..no_shape()
        };
        let c = self.causes;
        if c.has(Cause::Delay) {
            shape.delay_s = next(0.0, s.max_delay_s() / s.dt) * s.dt;
        }
        if c.has(Cause::Saturation) {
            // A rail at the extreme of the training input was never hit: no rail on that
            // side, or the validation input beyond that extreme would be clipped on no evidence.
            let (lo, hi) = (next(0.0, 0.45), next(0.0, 0.45));
            if lo > RAIL_UNSEEN {
                shape.rail_lo_v = s.u_lo + span * lo;
            }
            if hi > RAIL_UNSEEN {
                shape.rail_hi_v = s.u_hi - span * hi;
            }
        }
        if c.has(Cause::SlewLimit) {
            shape.slew_v_per_s = s.rate_max * next(-8.0, 0.3).exp();
        }
        if c.has(Cause::Dynamics) || c.has(Cause::AmplitudeDynamics) {
            shape.wn_hz = next(0.2f64.ln(), s.max_wn_hz().ln()).exp();
            shape.zeta = next(-3.0, 1.6).exp();
        }
        if c.has(Cause::Backlash) {
            shape.play_um = s.y_span * next(PLAY_MIN.ln(), PLAY_MAX.ln()).exp();
        }
        if c.has(Cause::StartupCreep) {
            shape.startup_travel_v = span * next(TRAVEL_MIN.ln(), TRAVEL_MAX.ln()).exp();
        }
        if c.has(Cause::RateDependence) {
            shape.rate_ref_v_per_s = s.rate_max * next(RATE_REF_MIN.ln(), RATE_REF_MAX.ln()).exp();
        }
        if c.has(Cause::AmplitudeDynamics) {
            shape.amp_level_um = s.y_span * next(LEVEL_MIN.ln(), LEVEL_MAX.ln()).exp();
            shape.amp_freq_shift = next(-FREQ_SHIFT_MAX, FREQ_SHIFT_MAX);
            shape.amp_zeta_scale = next(ZETA_SCALE_MIN.ln_1p(), ZETA_SCALE_MAX.ln_1p()).exp_m1();
        }
        (shape, excess)
    }

    /// Coordinates of a shape (inverse of [`Coords::shape`] inside the ranges).
    pub fn coords(&self, shape: &Shape) -> Vec<f64> {
        let s = &self.scales;
        let span = s.span();
        let a = (shape.beta + shape.gamma).max(1e-300);
        let r = ((shape.beta - shape.gamma) / a).max(1e-300);
        let mut x = vec![(a * span).ln(), r.ln()];
        let c = self.causes;
        if c.has(Cause::Delay) {
            x.push(shape.delay_s / s.dt);
        }
        if c.has(Cause::Saturation) {
            let frac = |v: f64| {
                if v.is_finite() {
                    v.clamp(0.0, 0.45)
                } else {
                    0.0
                }
            };
            x.push(frac((shape.rail_lo_v - s.u_lo) / span));
            x.push(frac((s.u_hi - shape.rail_hi_v) / span));
        }
        if c.has(Cause::SlewLimit) {
            x.push((shape.slew_v_per_s / s.rate_max).min(1.35).ln());
        }
        if c.has(Cause::Dynamics) || c.has(Cause::AmplitudeDynamics) {
            x.push(shape.wn_hz.min(s.max_wn_hz()).ln());
            x.push(shape.zeta.ln());
        }
        if c.has(Cause::Backlash) {
            x.push((shape.play_um / s.y_span).clamp(PLAY_MIN, PLAY_MAX).ln());
        }
        if c.has(Cause::StartupCreep) {
            let f = shape.startup_travel_v / span;
            x.push(
                if f.is_finite() {
                    f.clamp(TRAVEL_MIN, TRAVEL_MAX)
                } else {
                    1.0
                }
                .ln(),
            );
        }
        if c.has(Cause::RateDependence) {
            let f = shape.rate_ref_v_per_s / s.rate_max;
            x.push(
                if f.is_finite() {
                    f.clamp(RATE_REF_MIN, RATE_REF_MAX)
                } else {
                    RATE_REF_MAX
                }
                .ln(),
            );
        }
        if c.has(Cause::AmplitudeDynamics) {
            let f = shape.amp_level_um / s.y_span;
            x.push(
                if f.is_finite() {
                    f.clamp(LEVEL_MIN, LEVEL_MAX)
                } else {
                    LEVEL_MAX
                }
                .ln(),
            );
            x.push(shape.amp_freq_shift.clamp(-FREQ_SHIFT_MAX, FREQ_SHIFT_MAX));
            x.push(
                shape
                    .amp_zeta_scale
                    .clamp(ZETA_SCALE_MIN, ZETA_SCALE_MAX)
                    .ln_1p(),
            );
        }
        x
    }

    /// Initial simplex steps per coordinate.
    pub fn steps(&self) -> Vec<f64> {
        let mut v = vec![0.5, 0.8];
        let c = self.causes;
        if c.has(Cause::Delay) {
            v.push(2.0);
        }
        if c.has(Cause::Saturation) {
            v.extend([0.03, 0.03]);
        }
        if c.has(Cause::SlewLimit) {
            v.push(0.3);
        }
        if c.has(Cause::Dynamics) || c.has(Cause::AmplitudeDynamics) {
            v.extend([0.4, 0.4]);
        }
        if c.has(Cause::Backlash) {
            v.push(0.5);
        }
        if c.has(Cause::StartupCreep) {
            v.push(0.5);
        }
        if c.has(Cause::RateDependence) {
            v.push(0.7);
        }
        if c.has(Cause::AmplitudeDynamics) {
            v.extend([0.7, 0.15, 0.4]);
        }
        v
    }
}

/// Range of the play's half width, as a fraction of the output span.
pub const PLAY_MIN: f64 = 1e-4;
pub const PLAY_MAX: f64 = 0.15;
/// Range of the start-up travel, as a multiple of the input span.
pub const TRAVEL_MIN: f64 = 0.05;
pub const TRAVEL_MAX: f64 = 50.0;
/// Range of the rate dependence's reference rate, as a multiple of the training input's
/// largest rate.
pub const RATE_REF_MIN: f64 = 1e-3;
pub const RATE_REF_MAX: f64 = 10.0;

/// Range of the amplitude dynamics' level (half the shift acts there), as a fraction of
/// the output span.
pub const LEVEL_MIN: f64 = 1e-3;
pub const LEVEL_MAX: f64 = 0.3;
/// Largest relative shift of the natural frequency at large amplitude.
pub const FREQ_SHIFT_MAX: f64 = 0.8;
/// Range of the relative change of the damping ratio at large amplitude.
pub const ZETA_SCALE_MIN: f64 = -0.8;
pub const ZETA_SCALE_MAX: f64 = 8.0;

/// Rails closer than this (fraction of the span) to the training input's extremes count as
/// never hit.
const RAIL_UNSEEN: f64 = 2e-3;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coords_round_trip() {
        let scales = Scales {
            u_lo: -10.0,
            u_hi: 90.0,
            rate_max: 500.0,
            dt: 1e-3,
            duration_s: 4.0,
            creep_rho: 0.0,
            y_span: 20.0,
            y_mid: 10.0,
        };
        let causes = Causes::default()
            .with(Cause::Delay)
            .with(Cause::Saturation)
            .with(Cause::SlewLimit)
            .with(Cause::Dynamics)
            .with(Cause::Backlash)
            .with(Cause::StartupCreep)
            .with(Cause::RateDependence)
            .with(Cause::AmplitudeDynamics);
        let c = Coords { causes, scales };
        let shape = Shape {
            beta: 0.03,
            gamma: 0.01,
            delay_s: 0.004,
            rail_lo_v: -5.0,
            rail_hi_v: 80.0,
            slew_v_per_s: 200.0,
            wn_hz: 120.0,
            zeta: 0.3,
            play_um: 1.5,
            startup_travel_v: 250.0,
            rate_ref_v_per_s: 300.0,
            amp_level_um: 0.8,
            amp_freq_shift: -0.25,
            amp_zeta_scale: 1.5,
        };
        let back = c.shape(&c.coords(&shape));
        for (a, b) in [
            (back.beta, shape.beta),
            (back.gamma, shape.gamma),
            (back.delay_s, shape.delay_s),
            (back.rail_lo_v, shape.rail_lo_v),
            (back.rail_hi_v, shape.rail_hi_v),
            (back.slew_v_per_s, shape.slew_v_per_s),
            (back.wn_hz, shape.wn_hz),
            (back.zeta, shape.zeta),
            (back.play_um, shape.play_um),
            (back.startup_travel_v, shape.startup_travel_v),
            (back.rate_ref_v_per_s, shape.rate_ref_v_per_s),
            (back.amp_level_um, shape.amp_level_um),
            (back.amp_freq_shift, shape.amp_freq_shift),
            (back.amp_zeta_scale, shape.amp_zeta_scale),
        ] {
            assert!((a - b).abs() < 1e-9 * b.abs().max(1.0), "{a} vs {b}");
        }
    }
}
