//! Output limits and the volts -> DAC code conversion, done in the code domain so the
//! range and slew guarantees hold exactly for what reaches the converter.

use super::ConfigError;
use crate::real::Real;

/// Voltage range and slew limit of one actuator channel (piezo volts, after the amplifier).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputLimits<T> {
    pub volts_min: T,
    pub volts_max: T,
    /// Largest rate of change (V/s).
    pub slew_volts_per_s: T,
}

/// Linear DAC transfer, including the amplifier gain: `volts = volts_at_zero + volts_per_code * code`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DacScale<T> {
    /// Piezo volts per DAC code (> 0).
    pub volts_per_code: T,
    /// Piezo volts at code 0.
    pub volts_at_zero: T,
    /// Lowest code the converter accepts.
    pub code_min: i32,
    /// Highest code the converter accepts.
    pub code_max: i32,
}

impl<T: Real> DacScale<T> {
    /// Volts at `code`.
    #[inline]
    pub fn volts(&self, code: i32) -> T {
        self.volts_at_zero + self.volts_per_code * T::from_i32(code)
    }

    /// Nearest code to `volts`, clamped into `[lo, hi]` (NaN -> `lo`).
    #[inline]
    fn code(&self, volts: T, lo: i32, hi: i32) -> i32 {
        let x = ((volts - self.volts_at_zero) / self.volts_per_code)
            .clamp_to(T::from_i32(lo), T::from_i32(hi));
        let c = (x + T::HALF).floor().to_i32();
        c.max(lo).min(hi) // not `clamp`: no panic path when lo > hi
    }
}

/// Precomputed output stage of one axis: codes allowed by both the limits and the DAC, and
/// the largest code step per sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output<T> {
    pub dac: DacScale<T>,
    codes_per_volt: T,
    /// `volts_at_zero * codes_per_volt + code_lo - 1/2` as a real (precomputed: the
    /// per-sample path only subtracts it, the rounding's half code included).
    code_origin: T,
    /// `code_hi - code_lo + 1/2` as a real: the top of the range in `x` (fixed point's
    /// clamp, see [`Output::limit_from_code_in_range`]).
    code_top_real: T,
    code_lo: i32,
    code_hi: i32,
    max_step: i32,
}

/// What the output stage did to a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limited {
    pub code: i32,
    /// The range or slew limit changed the command.
    pub saturated: bool,
}

impl<T: Real> Output<T> {
    pub fn new(
        limits: &OutputLimits<T>,
        dac: &DacScale<T>,
        sample_hz: T,
    ) -> Result<Self, ConfigError> {
        if !(dac.volts_per_code.is_finite() && dac.volts_per_code > T::ZERO) {
            return Err(ConfigError::new(
                "dac.volts_per_code must be finite and > 0",
            ));
        }
        if !dac.volts_at_zero.is_finite() {
            return Err(ConfigError::new("dac.volts_at_zero must be finite"));
        }
        if dac.code_min >= dac.code_max {
            return Err(ConfigError::new("dac.code_min must be below dac.code_max"));
        }
        if !(limits.volts_min.is_finite()
            && limits.volts_max.is_finite()
            && limits.volts_min < limits.volts_max)
        {
            return Err(ConfigError::new(
                "limits.volts_min must be finite and below limits.volts_max",
            ));
        }
        let lo = ((limits.volts_min - dac.volts_at_zero) / dac.volts_per_code).to_f64();
        let hi = ((limits.volts_max - dac.volts_at_zero) / dac.volts_per_code).to_f64();
        let code_lo = libm::ceil(lo).max(dac.code_min as f64);
        let code_hi = libm::floor(hi).min(dac.code_max as f64);
        if !(code_lo < code_hi) {
            return Err(ConfigError::new(
                "limits: the voltage range covers less than two DAC codes",
            ));
        }
        if !(sample_hz.is_finite() && sample_hz > T::ZERO) {
            return Err(ConfigError::new("sample_hz must be finite and > 0"));
        }
        // The per-sample rounding (`limit_from_code_in_range`) tells the codes of the range
        // apart only while the number type resolves half a code at the span (f32: up to
        // 2^23 codes).
        let span = code_hi - code_lo;
        if (T::from_f64(span) + T::HALF).to_i32() as f64 > span {
            return Err(ConfigError::new(
                "dac: the code range is too wide for the number type",
            ));
        }
        let step = (limits.slew_volts_per_s / sample_hz / dac.volts_per_code).to_f64();
        if !(step >= 1.0) {
            return Err(ConfigError::new(
                "limits.slew_volts_per_s must allow at least one DAC code per sample",
            ));
        }
        Ok(Self {
            dac: *dac,
            codes_per_volt: T::ONE / dac.volts_per_code,
            code_origin: T::from_f64(
                dac.volts_at_zero.to_f64() / dac.volts_per_code.to_f64() + code_lo - 0.5,
            ),
            code_top_real: T::from_f64(span + 0.5),
            code_lo: code_lo as i32,
            code_hi: code_hi as i32,
            max_step: libm::floor(step).min(i32::MAX as f64 / 4.0) as i32,
        })
    }

    /// The code range the limits allow.
    pub fn code_range(&self) -> (i32, i32) {
        (self.code_lo, self.code_hi)
    }

    /// Largest code change per sample.
    pub fn max_step(&self) -> i32 {
        self.max_step
    }

    /// Code for `volts` within the range, ignoring the slew limit (start-up value).
    pub fn code_in_range(&self, volts: T) -> i32 {
        self.dac.code(volts, self.code_lo, self.code_hi)
    }

    /// Range- and slew-limited code for the command `volts`, starting from `prev` (NaN ->
    /// lowest code of the range, then slew-limited).
    #[inline]
    pub fn limit(&self, volts: T, prev: i32) -> Limited {
        // max/min, not `clamp`: `clamp` asserts lo <= hi, a panic path in the ISR.
        self.limit_from_code_in_range(volts, prev.max(self.code_lo).min(self.code_hi))
    }

    /// [`Output::limit`] from a `prev` known to lie in [`Output::code_range`].
    #[inline(always)]
    pub(crate) fn limit_from_code_in_range(&self, volts: T, prev: i32) -> Limited {
        // Codes above the range's lowest plus 1/2, as a real.
        let x = volts * self.codes_per_volt - self.code_origin;
        if T::IEEE {
            // Truncated, the nearest code (NaN -> 0, the lowest; `as i32` saturates). The
            // range and the slew limit then clamp in integers, together.
            let want = self.code_lo.saturating_add(x.to_i32());
            let lo = prev.saturating_sub(self.max_step).max(self.code_lo);
            let hi = prev.saturating_add(self.max_step).min(self.code_hi);
            let code = want.max(lo).min(hi);
            // Truncation takes (-1, 0) to 0: a command that rounds below the lowest code
            // (or NaN) is told by its sign.
            let in_range = x >= T::ZERO;
            Limited {
                code,
                saturated: code != want || !in_range,
            }
        } else {
            // Fixed point compares its reals as integers already: the range clamps `x` into
            // `[1/2, span + 1/2]` (truncated, the codes of the range), the slew limit after.
            let in_range = x >= T::HALF && x <= self.code_top_real;
            let x = x.clamp_to(T::HALF, self.code_top_real);
            let want = self.code_lo.saturating_add(x.to_i32());
            let code = want
                .max(prev.saturating_sub(self.max_step))
                .min(prev.saturating_add(self.max_step));
            Limited {
                code,
                saturated: code != want || !in_range,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn out() -> Output<f64> {
        Output::new(
            &OutputLimits {
                volts_min: 0.0,
                volts_max: 150.0,
                slew_volts_per_s: 10_000.0,
            },
            &DacScale {
                volts_per_code: 150.0 / 1_048_575.0,
                volts_at_zero: 0.0,
                code_min: 0,
                code_max: 1_048_575,
            },
            100_000.0,
        )
        .unwrap()
    }

    #[test]
    fn range_slew_and_nan() {
        let o = out();
        let step = o.max_step();
        assert_eq!(step, (0.1 / (150.0 / 1_048_575.0)) as i32);
        let r = o.limit(200.0, 1_048_575);
        assert_eq!(r.code, 1_048_575);
        assert!(r.saturated);
        let r = o.limit(150.0, 0);
        assert_eq!(r.code, step);
        let r = o.limit(f64::NAN, 500_000);
        assert_eq!(r.code, 500_000 - step);
        let r = o.limit(75.0, 524_288);
        assert!(!r.saturated);
        assert!((o.dac.volts(r.code) - 75.0).abs() < 1e-3);
    }

    #[test]
    fn rejects_bad_limits() {
        let dac = DacScale {
            volts_per_code: 1e-4,
            volts_at_zero: 0.0,
            code_min: 0,
            code_max: 1 << 20,
        };
        let lim = |a, b, s| OutputLimits {
            volts_min: a,
            volts_max: b,
            slew_volts_per_s: s,
        };
        assert!(Output::new(&lim(10.0, 5.0, 1e4), &dac, 1e5).is_err());
        assert!(Output::new(&lim(0.0, 5.0, 1e-3), &dac, 1e5).is_err());
        assert!(Output::new(&lim(0.0, f64::NAN, 1e4), &dac, 1e5).is_err());
        assert!(Output::new(&lim(0.0, 5.0, f64::NAN), &dac, 1e5).is_err());
    }

    /// f32 takes a 20-bit converter, not one whose codes it cannot round to within the span
    /// (2^23 + 1 codes: the top one plus 1/2 rounds to 2^23 + 2); the top of the range stays
    /// the top code.
    #[test]
    fn code_span_within_the_number_type() {
        let dac = |code_max: i32| DacScale {
            volts_per_code: 1e-5f32,
            volts_at_zero: 0.0,
            code_min: 0,
            code_max,
        };
        let lim = OutputLimits {
            volts_min: 0.0,
            volts_max: 100.0,
            slew_volts_per_s: 1e9,
        };
        let top = (1 << 20) - 1;
        let o = Output::new(&lim, &dac(top), 1e5).unwrap();
        assert_eq!(o.code_range(), (0, top));
        assert_eq!(o.limit(10.5, top - 1).code, top);
        assert_eq!(o.limit(1e9, top - 1).code, top);
        assert!(Output::new(&lim, &dac((1 << 23) + 1), 1e5).is_err());
        assert!(Output::new(&lim, &dac(1 << 23), 1e5).is_ok());
    }
}
