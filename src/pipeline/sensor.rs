//! Position sensor: ADC code -> position (um), with a validity window.

use super::ConfigError;
use crate::real::Real;

/// Calibrated scaling of one position channel: `y_um = offset_um + um_per_code * code`.
///
/// Codes outside `[code_min, code_max]` are invalid (sensor unplugged, converter clipped or
/// a broken SPI frame): the pipeline goes to its safe state and counts them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensor<T> {
    /// Gain (um per ADC code); negative for a sensor mounted the other way round.
    pub um_per_code: T,
    /// Position at code 0 (um).
    pub offset_um: T,
    /// Lowest valid code.
    pub code_min: i32,
    /// Highest valid code.
    pub code_max: i32,
}

impl<T: Real> Sensor<T> {
    /// Two-point calibration: the codes `code_a`, `code_b` were read at the known positions
    /// `um_a`, `um_b`.
    pub fn two_point(
        code_a: i32,
        um_a: T,
        code_b: i32,
        um_b: T,
        code_min: i32,
        code_max: i32,
    ) -> Result<Self, ConfigError> {
        if code_a == code_b {
            return Err(ConfigError::new("sensor: calibration codes must differ"));
        }
        let um_per_code = (um_b - um_a) / T::from_f64(code_b as f64 - code_a as f64);
        let s = Self {
            um_per_code,
            offset_um: um_a - um_per_code * T::from_f64(code_a as f64),
            code_min,
            code_max,
        };
        s.validate()?;
        Ok(s)
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.um_per_code.is_finite() && self.um_per_code != T::ZERO) {
            return Err(ConfigError::new(
                "sensor.um_per_code must be finite and non-zero",
            ));
        }
        if !self.offset_um.is_finite() {
            return Err(ConfigError::new("sensor.offset_um must be finite"));
        }
        if self.code_min >= self.code_max {
            return Err(ConfigError::new(
                "sensor.code_min must be below sensor.code_max",
            ));
        }
        Ok(())
    }

    /// Position (um) of a valid code, `None` for a code outside the window.
    #[inline]
    pub fn position_um(&self, code: i32) -> Option<T> {
        if code < self.code_min || code > self.code_max {
            None
        } else {
            Some(self.offset_um + self.um_per_code * T::from_i32(code))
        }
    }
}

/// Stuck-code detector: `limit` identical consecutive codes are a sensor fault. A working
/// position channel never repeats its code that long (the converter's transition noise and
/// the sensor's own noise move the code by a few LSB from sample to sample); a frozen
/// converter, a data line held by nothing, or an input left floating on its sampling
/// capacitor does. Run it on the converter's own codes (before any shift drops their noise).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StuckCode {
    last: i32,
    run: u32,
}

impl StuckCode {
    /// Takes this sample's code; true once it is the `limit`-th identical code in a row
    /// (`limit` 0: never).
    #[inline(always)]
    pub fn update(&mut self, code: i32, limit: u32) -> bool {
        if code == self.last {
            self.run = self.run.saturating_add(1);
        } else {
            self.last = code;
            self.run = 1;
        }
        limit != 0 && self.run >= limit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stuck_code_trips_at_the_limit_and_not_before() {
        let mut s = StuckCode::default();
        for k in 1..=9 {
            assert!(!s.update(7, 10), "{k}");
        }
        assert!(s.update(7, 10));
        assert!(!s.update(8, 10), "a new code starts a new run");
        let mut s = StuckCode::default();
        assert!((0..1000).all(|_| !s.update(5, 0)), "0: off");
        let mut s = StuckCode::default();
        assert!(
            (0..1000).all(|k| !s.update(k % 3, 2)),
            "a moving code never trips"
        );
    }

    #[test]
    fn two_point_calibration_maps_both_points() {
        let s = Sensor::<f64>::two_point(-1000, 10.0, 3000, 90.0, -5000, 5000).unwrap();
        assert!((s.position_um(-1000).unwrap() - 10.0).abs() < 1e-12);
        assert!((s.position_um(3000).unwrap() - 90.0).abs() < 1e-12);
        assert_eq!(s.position_um(5001), None);
        assert_eq!(s.position_um(-5001), None);
        assert!(Sensor::<f64>::two_point(1, 0.0, 1, 1.0, -5, 5).is_err());
    }
}
