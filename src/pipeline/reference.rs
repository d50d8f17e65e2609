//! Reference generator: periodic waves with exact first and second derivatives.
//!
//! The phase is a 32-bit accumulator (as in a DDS): it wraps exactly once per period and
//! never loses precision, so an `f32` generator runs for days without drifting.

use super::excitation::{self, sin_cos_turns, Chirp};
use super::ConfigError;
use crate::feedback::guard::setpoint_within_bounds;
use crate::real::Real;
use crate::signals::Setpoint;

/// Capacity of an arbitrary table (points per period).
pub const TABLE_LEN: usize = 64;

/// `2^32` as a float: phase accumulator turns.
const TURN: f64 = 4_294_967_296.0;

/// One periodic reference wave. Phase 0 is where the wave starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Wave<T> {
    /// Constant position.
    Hold { y_um: T },
    /// `offset + amplitude * sin(2 pi (f t + phase))`.
    Sine {
        offset_um: T,
        amplitude_um: T,
        freq_hz: T,
        phase_turns: T,
    },
    /// Symmetric triangle around `offset_um`, rising through the offset at phase 0
    /// (`amplitude_um` peak). Derivatives are those of the straight pieces (the corners
    /// have none).
    Triangle {
        offset_um: T,
        amplitude_um: T,
        freq_hz: T,
        phase_turns: T,
    },
    /// Staircase from `low_um` up to `high_um` in `levels` equal levels and back down
    /// (`2 (levels - 1)` steps per period; `levels = 2` is a square wave). Zero derivatives.
    Steps {
        low_um: T,
        high_um: T,
        levels: u16,
        freq_hz: T,
    },
    /// Periodic Catmull-Rom spline through `points[..len]`, one period per `freq_hz`;
    /// the derivatives are those of the spline.
    Table {
        points: [T; TABLE_LEN],
        len: usize,
        freq_hz: T,
    },
    /// Pseudo-random binary sequence between `low_um` and `high_um`: a maximal LFSR of
    /// `order` bits ([`excitation::PRBS_ORDER_MIN`]..=[`excitation::PRBS_ORDER_MAX`];
    /// `2^order - 1` bits per period), `bit_hz` bits per second, start state from `seed`.
    /// Zero derivatives. Stateful: [`WaveGen`] holds the register ([`Wave::at`] gives
    /// `low_um`).
    Prbs {
        low_um: T,
        high_um: T,
        order: u8,
        bit_hz: T,
        seed: u32,
    },
    /// Linear sweep `f0_hz` -> `f1_hz` over `duration_s`, repeated: `offset + amplitude
    /// sin(2 pi (f0 t + (f1 - f0) t^2 / (2 T)))`. Build it with [`Wave::chirp`] (the phase
    /// coefficients in fixed point, `a_fx`, `b_fx`).
    Chirp(Chirp<T>),
    /// Multisine: harmonics 1..=`harmonics` of `f0_hz` (one period is `1 / f0_hz`), equal
    /// amplitudes, phases from a seed (Schroeder's for seed 0), scaled so the peak deviation
    /// from `offset_um` is the requested amplitude. Build it with [`Wave::multisine`].
    Multisine {
        offset_um: T,
        per_harmonic_um: T,
        f0_hz: T,
        harmonics: u8,
        seed: u32,
        cos_phi: [T; excitation::MULTISINE_MAX],
        sin_phi: [T; excitation::MULTISINE_MAX],
    },
}

impl<T: Real> Wave<T> {
    /// A sine `offset_um + amplitude_um sin(2 pi freq_hz t)` starting at phase 0.
    pub fn sine(offset_um: T, amplitude_um: T, freq_hz: T) -> Self {
        Wave::Sine {
            offset_um,
            amplitude_um,
            freq_hz,
            phase_turns: T::ZERO,
        }
    }

    /// A table wave from up to [`TABLE_LEN`] points.
    pub fn table(points: &[T], freq_hz: T) -> Result<Self, ConfigError> {
        if points.len() < 2 || points.len() > TABLE_LEN {
            return Err(ConfigError::new(
                "reference.table: needs 2..=64 points per period",
            ));
        }
        let mut p = [T::ZERO; TABLE_LEN];
        p.iter_mut().zip(points).for_each(|(d, s)| *d = *s);
        Ok(Wave::Table {
            points: p,
            len: points.len(),
            freq_hz,
        })
    }

    /// A linear chirp `f0_hz` -> `f1_hz` over `duration_s` (repeated), around `offset_um`.
    pub fn chirp(
        offset_um: T,
        amplitude_um: T,
        f0_hz: T,
        f1_hz: T,
        duration_s: T,
    ) -> Result<Self, ConfigError> {
        if !(duration_s.to_f64() > 0.0 && duration_s.to_f64() <= 3600.0) {
            return Err(ConfigError::new(
                "reference.chirp: duration_s must be in (0, 3600]",
            ));
        }
        Ok(Wave::Chirp(Chirp::new(
            offset_um,
            amplitude_um,
            f0_hz,
            f1_hz,
            duration_s,
        )))
    }

    /// A multisine of `harmonics` (1..=[`excitation::MULTISINE_MAX`]) equal harmonics of
    /// `f0_hz`, peak deviation `amplitude_um` from `offset_um`, phases from `seed`.
    pub fn multisine(
        offset_um: T,
        amplitude_um: T,
        f0_hz: T,
        harmonics: u8,
        seed: u32,
    ) -> Result<Self, ConfigError> {
        if !(1..=excitation::MULTISINE_MAX).contains(&(harmonics as usize)) {
            return Err(ConfigError::new(
                "reference.multisine: harmonics must be in 1..=32",
            ));
        }
        if !amplitude_um.is_finite() {
            return Err(ConfigError::new("reference: every value must be finite"));
        }
        let (cos_phi, sin_phi) = excitation::multisine_phases(harmonics as usize, seed);
        let per_harmonic_um =
            excitation::multisine_scale(amplitude_um, harmonics, &cos_phi, &sin_phi);
        Ok(Wave::Multisine {
            offset_um,
            per_harmonic_um,
            f0_hz,
            harmonics,
            seed,
            cos_phi,
            sin_phi,
        })
    }

    /// The phase accumulator's rate: the wave's frequency, a PRBS's bit rate, a chirp's
    /// sweep rate (1 / duration), a multisine's base frequency.
    fn freq_hz(&self) -> T {
        match *self {
            Wave::Hold { .. } => T::ZERO,
            Wave::Sine { freq_hz, .. }
            | Wave::Triangle { freq_hz, .. }
            | Wave::Steps { freq_hz, .. }
            | Wave::Table { freq_hz, .. } => freq_hz,
            Wave::Prbs { bit_hz, .. } => bit_hz,
            Wave::Chirp(Chirp { duration_s, .. }) => {
                if duration_s > T::ZERO {
                    T::ONE / duration_s
                } else {
                    T::ZERO
                }
            }
            Wave::Multisine { f0_hz, .. } => f0_hz,
        }
    }

    /// The highest frequency in the wave (Hz): what must stay below Nyquist.
    fn top_hz(&self) -> T {
        match *self {
            Wave::Chirp(Chirp { f0_hz, f1_hz, .. }) => f0_hz.max(f1_hz),
            Wave::Multisine {
                f0_hz, harmonics, ..
            } => f0_hz * T::from_usize(harmonics as usize),
            // One bit per sample at most: the sample rate itself (checked below).
            Wave::Prbs { .. } => T::ZERO,
            _ => self.freq_hz(),
        }
    }

    fn start_turns(&self) -> T {
        match *self {
            Wave::Sine { phase_turns, .. } | Wave::Triangle { phase_turns, .. } => phase_turns,
            _ => T::ZERO,
        }
    }

    /// A chirp's setpoint at sweep fraction `phase` (2^-32 units); other waves: none.
    #[inline]
    fn chirp_at(&self, phase: u32) -> Setpoint<T> {
        match self {
            Wave::Chirp(c) => c.at(phase),
            _ => Setpoint::default(),
        }
    }

    /// Checks the wave for a generator running at `sample_hz`.
    pub fn validate(&self, sample_hz: T) -> Result<(), ConfigError> {
        let (f, top) = (self.freq_hz(), self.top_hz());
        if !(f >= T::ZERO && top >= T::ZERO && top < sample_hz * T::HALF) {
            return Err(ConfigError::new(
                "reference: freq_hz must be in [0, sample_hz / 2)",
            ));
        }
        if let Wave::Prbs { order, bit_hz, .. } = *self {
            if !(bit_hz > T::ZERO && bit_hz.to_f64() < sample_hz.to_f64()) {
                return Err(ConfigError::new(
                    "reference.prbs: bit_hz must be in (0, sample_hz)",
                ));
            }
            if !(excitation::PRBS_ORDER_MIN..=excitation::PRBS_ORDER_MAX).contains(&order) {
                return Err(ConfigError::new("reference.prbs: order must be in 2..=20"));
            }
        }
        let finite = match *self {
            Wave::Hold { y_um } => y_um.is_finite(),
            Wave::Sine {
                offset_um,
                amplitude_um,
                phase_turns,
                ..
            }
            | Wave::Triangle {
                offset_um,
                amplitude_um,
                phase_turns,
                ..
            } => offset_um.is_finite() && amplitude_um.is_finite() && phase_turns.is_finite(),
            Wave::Steps {
                low_um,
                high_um,
                levels,
                ..
            } => {
                if levels < 2 {
                    return Err(ConfigError::new("reference.steps: levels must be >= 2"));
                }
                low_um.is_finite() && high_um.is_finite()
            }
            Wave::Table { points, len, .. } => {
                if !(2..=TABLE_LEN).contains(&len) {
                    return Err(ConfigError::new("reference.table: len must be in 2..=64"));
                }
                points.iter().all(|p| p.is_finite())
            }
            Wave::Prbs {
                low_um, high_um, ..
            } => low_um.is_finite() && high_um.is_finite(),
            Wave::Chirp(Chirp {
                offset_um,
                amplitude_um,
                duration_s,
                ..
            }) => {
                if !(duration_s > T::ZERO) {
                    return Err(ConfigError::new(
                        "reference.chirp: duration_s must be positive",
                    ));
                }
                offset_um.is_finite() && amplitude_um.is_finite()
            }
            Wave::Multisine {
                offset_um,
                per_harmonic_um,
                harmonics,
                ..
            } => {
                if !(1..=excitation::MULTISINE_MAX).contains(&(harmonics as usize)) {
                    return Err(ConfigError::new(
                        "reference.multisine: harmonics must be in 1..=32",
                    ));
                }
                offset_um.is_finite() && per_harmonic_um.is_finite()
            }
        };
        if finite {
            Ok(())
        } else {
            Err(ConfigError::new("reference: every value must be finite"))
        }
    }

    /// The setpoint at phase `x` in `[0, 1)` turns.
    #[inline]
    pub fn at(&self, x: T) -> Setpoint<T> {
        match *self {
            Wave::Hold { y_um } => Setpoint::hold(y_um),
            Wave::Sine {
                offset_um,
                amplitude_um,
                freq_hz,
                ..
            } => {
                let w = T::TWO * T::PI * freq_hz;
                let (s, c) = sin_cos_turns(x);
                Setpoint {
                    y_um: offset_um + amplitude_um * s,
                    dy: amplitude_um * w * c,
                    ddy: -amplitude_um * w * w * s,
                }
            }
            Wave::Triangle {
                offset_um,
                amplitude_um,
                freq_hz,
                ..
            } => {
                let four = T::from_f64(4.0);
                let q = T::from_f64(0.25);
                let slope = four * amplitude_um * freq_hz;
                let (y, dy) = if x < q {
                    (four * x, slope)
                } else if x < T::from_f64(0.75) {
                    (T::TWO - four * x, -slope)
                } else {
                    (four * x - four, slope)
                };
                Setpoint {
                    y_um: offset_um + amplitude_um * y,
                    dy,
                    ddy: T::ZERO,
                }
            }
            Wave::Steps {
                low_um,
                high_um,
                levels,
                ..
            } => {
                let steps = 2 * (levels.max(2) as usize - 1);
                let k = (x * T::from_usize(steps)).floor().to_f64() as usize;
                let k = k.min(steps - 1);
                let top = levels.max(2) as usize - 1;
                let level = if k <= top { k } else { steps - k };
                let frac = T::from_usize(level) / T::from_usize(top);
                Setpoint::hold(low_um + (high_um - low_um) * frac)
            }
            Wave::Table {
                ref points,
                len,
                freq_hz,
            } => catmull_rom(points, len, x, freq_hz),
            Wave::Prbs { low_um, .. } => Setpoint::hold(low_um),
            // The sweep fraction back in 2^-32 units (exact for the generator's phase).
            Wave::Chirp(_) => self.chirp_at((x.to_f64() * TURN) as u32),
            Wave::Multisine {
                offset_um,
                per_harmonic_um,
                f0_hz,
                harmonics,
                ref cos_phi,
                ref sin_phi,
                ..
            } => excitation::multisine_at(
                x,
                offset_um,
                per_harmonic_um,
                f0_hz,
                harmonics,
                cos_phi,
                sin_phi,
            ),
        }
    }
}

/// Periodic Catmull-Rom spline at phase `x` and its time derivatives.
#[inline]
fn catmull_rom<T: Real>(points: &[T; TABLE_LEN], len: usize, x: T, freq_hz: T) -> Setpoint<T> {
    let len = len.clamp(2, TABLE_LEN);
    let pos = x * T::from_usize(len);
    let i = (pos.floor().to_f64() as usize).min(len - 1);
    let s = pos - T::from_usize(i);
    let at = |k: usize| points.get(k % len).copied().unwrap_or(T::ZERO);
    let (p0, p1, p2, p3) = (at(i + len - 1), at(i), at(i + 1), at(i + 2));
    let h = T::HALF;
    let a = T::TWO * p1;
    let b = p2 - p0;
    let c = T::TWO * p0 - T::from_f64(5.0) * p1 + T::from_f64(4.0) * p2 - p3;
    let d = T::from_f64(3.0) * (p1 - p2) + p3 - p0;
    let rate = T::from_usize(len) * freq_hz; // ds/dt
    Setpoint {
        y_um: h * (a + s * (b + s * (c + s * d))),
        dy: h * (b + s * (T::TWO * c + T::from_f64(3.0) * s * d)) * rate,
        ddy: h * (T::TWO * c + T::from_f64(6.0) * s * d) * rate * rate,
    }
}

/// Samples between two exact evaluations of a sine generator's rotation (see [`WaveGen`]).
pub const SINE_RESYNC: u16 = 32;

/// A sine as a rotating phasor scaled by the setpoint's coefficients: `(s, c) = (A sin, A w
/// cos)` of the current phase, rotated by the phase step each sample, so the setpoint is `y
/// = offset + s`, `y' = c`, `y'' = -w^2 s` (two operations, not four).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Phasor<T> {
    s: T,
    c: T,
    /// The rotation by the phase step `d` in the scaled coordinates: `cos d`, `sin d / w`
    /// and `w sin d`.
    cd: T,
    sd_w: T,
    w_sd: T,
    offset_um: T,
    /// `A`, `A w`, `-w^2`.
    amp: T,
    amp_w: T,
    minus_w2: T,
    /// Rotations left before the next exact evaluation.
    left: u16,
    /// Rotations between exact evaluations (1: every sample exact).
    every: u16,
    /// Every setpoint it gives passes the laws' input guard unchanged (decided once, from
    /// the amplitudes, with a factor 2 for the rotation's rounding).
    within_guard: bool,
}

/// A wave with its phase accumulator: advances one sample per call.
///
/// A sine is not evaluated from the phase every sample: its `(sin, cos)` phasor is rotated
/// by the (quantised) phase step, four multiplications instead of a polynomial, and
/// recomputed exactly from the 32-bit phase every [`SINE_RESYNC`] samples, so it never
/// drifts from the accumulator. Between two resyncs the rounding of the rotation grows the
/// error by at most `2 SINE_RESYNC eps` of the amplitude (f32: 8e-6, 0.4 nm at 50 um). For a
/// number type coarser than `1e-6` (fixed point) every sample is exact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaveGen<T> {
    wave: Wave<T>,
    phase: u32,
    step: u32,
    phasor: Option<Phasor<T>>,
    /// A PRBS's shift register (unused by the other waves): the next bit on each wrap of
    /// the phase.
    lfsr: u32,
}

impl<T: Real> WaveGen<T> {
    /// Generator at `sample_hz`, starting at the wave's phase 0 (plus its `phase_turns`).
    pub fn new(wave: Wave<T>, sample_hz: T) -> Result<Self, ConfigError> {
        wave.validate(sample_hz)?;
        let turns = wave.start_turns().to_f64();
        let frac = turns - libm::floor(turns);
        let step = libm::round(wave.freq_hz().to_f64() / sample_hz.to_f64() * TURN) as u32;
        let phase = (frac * TURN) as u32;
        let phasor = match wave {
            Wave::Sine {
                offset_um,
                amplitude_um,
                freq_hz,
                ..
            } => {
                let delta = core::f64::consts::TAU * step as f64 / TURN;
                let w = T::TWO * T::PI * freq_hz;
                let (amp_w, amp_w2) = (amplitude_um * w, -(amplitude_um * w * w));
                let mag = |x: T| {
                    if x.is_finite() {
                        x.to_f64().abs()
                    } else {
                        f64::INFINITY
                    }
                };
                let within_guard = setpoint_within_bounds::<T>(
                    mag(offset_um) + 2.0 * mag(amplitude_um),
                    2.0 * mag(amp_w),
                    2.0 * mag(amp_w2),
                );
                let (wf, sd) = (w.to_f64(), libm::sin(delta));
                Some(Phasor {
                    // Set by the resync below.
                    s: T::ZERO,
                    c: T::ZERO,
                    cd: T::from_f64(libm::cos(delta)),
                    sd_w: T::from_f64(if wf == 0.0 { 0.0 } else { sd / wf }),
                    w_sd: T::from_f64(wf * sd),
                    offset_um,
                    amp: amplitude_um,
                    amp_w,
                    minus_w2: -(w * w),
                    within_guard,
                    left: 0,
                    every: if T::EPSILON < T::from_f64(1e-6) {
                        SINE_RESYNC
                    } else {
                        1
                    },
                })
            }
            _ => None,
        };
        let lfsr = match wave {
            Wave::Prbs { order, seed, .. } => excitation::prbs_start(order, seed),
            _ => 0,
        };
        let mut g = Self {
            wave,
            phase,
            step,
            phasor,
            lfsr,
        };
        g.resync();
        Ok(g)
    }

    pub fn wave(&self) -> &Wave<T> {
        &self.wave
    }

    /// The current setpoint, without advancing.
    #[inline]
    pub fn current(&self) -> Setpoint<T> {
        self.at_phase(self.phase)
    }

    /// [`WaveGen::next_setpoint`] of the waves without a phasor (the phase already
    /// advanced). Out of line: inlined, the excitations' arms cost the sine's fast path
    /// about 7 instructions per step (QEMU M4F).
    #[inline(never)]
    fn next_from_phase(&mut self) -> Setpoint<T> {
        let sp = self.at_phase(self.phase.wrapping_sub(self.step));
        // The phase wrapped (a PRBS's next bit) when it is now below the step.
        if let Wave::Prbs { order, .. } = self.wave {
            if self.phase < self.step {
                self.lfsr = excitation::prbs_next(self.lfsr, order);
            }
        }
        sp
    }

    /// The setpoint at `phase` (2^-32 turns); a PRBS at its register's current bit.
    #[inline]
    fn at_phase(&self, phase: u32) -> Setpoint<T> {
        match self.wave {
            Wave::Prbs {
                low_um,
                high_um,
                order,
                ..
            } => excitation::prbs_level(self.lfsr, order, low_um, high_um),
            Wave::Chirp(_) => self.wave.chirp_at(phase),
            _ => self.wave.at(T::from_turns(phase)),
        }
    }

    /// Phasor exactly at the current phase. Cold: once in many samples, and the rotation
    /// then falls through to the setpoint's use.
    #[inline(never)]
    #[cold]
    fn resync(&mut self) {
        if let Some(p) = self.phasor.as_mut() {
            let (s, c) = sin_cos_turns(T::from_turns(self.phase));
            (p.s, p.c) = (p.amp * s, p.amp_w * c);
            p.left = p.every.saturating_sub(1);
        }
    }

    /// The current setpoint; then advance one sample.
    #[inline]
    pub fn next_setpoint(&mut self) -> Setpoint<T> {
        self.next_setpoint_guarded().0
    }

    /// [`WaveGen::next_setpoint`], and whether it passes the laws' input guard unchanged
    /// (known for a sine from its amplitudes; `false`: not known).
    #[inline(always)]
    pub(crate) fn next_setpoint_guarded(&mut self) -> (Setpoint<T>, bool) {
        self.phase = self.phase.wrapping_add(self.step);
        match self.phasor.as_mut() {
            Some(p) => {
                let within = p.within_guard;
                let sp = Setpoint {
                    y_um: p.offset_um + p.s,
                    dy: p.c,
                    ddy: p.minus_w2 * p.s,
                };
                if p.left == 0 {
                    self.resync();
                } else {
                    p.left -= 1;
                    let (s, c) = (p.s, p.c);
                    p.s = s * p.cd + c * p.sd_w;
                    p.c = c * p.cd - s * p.w_sd;
                }
                (sp, within)
            }
            None => (self.next_from_phase(), false),
        }
    }
}

/// 2-axis raster scan: fast triangle lines on x, slow triangle frame on y (both
/// continuous, so the derivatives exist everywhere but at the corners).
pub fn raster<T: Real>(
    center_um: [T; 2],
    half_span_um: [T; 2],
    line_hz: T,
    frame_hz: T,
) -> [Wave<T>; 2] {
    let tri = |i: usize, f: T| Wave::Triangle {
        offset_um: center_um[i],
        amplitude_um: half_span_um[i],
        freq_hz: f,
        phase_turns: T::ZERO,
    };
    [tri(0, line_hz), tri(1, frame_hz)]
}

/// 2-axis Lissajous scan: sines at `freq_hz[0]`, `freq_hz[1]`, y a quarter turn ahead.
pub fn lissajous<T: Real>(
    center_um: [T; 2],
    amplitude_um: [T; 2],
    freq_hz: [T; 2],
) -> [Wave<T>; 2] {
    let sine = |i: usize, phase: T| Wave::Sine {
        offset_um: center_um[i],
        amplitude_um: amplitude_um[i],
        freq_hz: freq_hz[i],
        phase_turns: phase,
    };
    [sine(0, T::ZERO), sine(1, T::from_f64(0.25))]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::feedback::guard::InputGuard;
    use crate::signals::LoopSignals;

    /// A sine says its setpoints pass the laws' input guard unchanged only when they do
    /// (the fused step then leaves the guard out); beyond a bound, or not a sine, it does not
    /// say so.
    #[test]
    fn a_sine_knows_whether_the_input_guard_passes_it() {
        fn within<T: Real>(wave: Wave<T>, fs: f64, samples: usize) -> bool {
            let mut g = WaveGen::new(wave, T::from_f64(fs)).unwrap();
            let mut guard = InputGuard::<T>::default();
            let mut all = true;
            for _ in 0..samples {
                let (sp, within) = g.next_setpoint_guarded();
                let io = LoopSignals {
                    setpoint: sp,
                    ..Default::default()
                };
                let c = guard.clean(&io);
                if within {
                    assert_eq!(
                        c.setpoint, sp,
                        "the guard changed a setpoint said to pass it"
                    );
                }
                all &= within;
            }
            all
        }
        let sine = |amp: f64, hz: f64| Wave::sine(10.0f32, amp as f32, hz as f32);
        // The firmware's bench sine (its acceleration 2e6 um/s^2), and a fast one.
        assert!(within(sine(5.0, 100.0), 100e3, 5000));
        assert!(within(sine(40.0, 1000.0), 100e3, 5000));
        // Twice the acceleration beyond its bound (40 um at 2 kHz: 6.3e9 um/s^2), a velocity
        // beyond its bound, an amplitude beyond every bound: not known.
        assert!(!within(sine(40.0, 2000.0), 100e3, 100));
        assert!(!within(sine(2e4, 10.0), 100e3, 100));
        assert!(!within(sine(1e30, 1.0), 100e3, 100));
        // Not a sine: not known.
        let tri = Wave::Triangle {
            offset_um: 0.0f32,
            amplitude_um: 1.0,
            freq_hz: 10.0,
            phase_turns: 0.0,
        };
        assert!(!within(tri, 100e3, 100));
        // Fixed point saturates near 32768: a 5 um, 100 Hz sine's acceleration is beyond it,
        // a slow one is inside.
        use crate::fixed::Q16;
        let q = |amp: f64, hz: f64| {
            Wave::sine(Q16::from_f64(10.0), Q16::from_f64(amp), Q16::from_f64(hz))
        };
        assert!(!within(q(5.0, 100.0), 16384.0, 100));
        assert!(within(q(1.0, 5.0), 16384.0, 2000));
    }

    /// Central differences of the generated sequence against the exact derivatives.
    fn check_derivatives(wave: Wave<f64>, fs: f64) {
        let mut g = WaveGen::new(wave, fs).unwrap();
        let dt = 1.0 / fs;
        let sps: Vec<_> = (0..4000).map(|_| g.next_setpoint()).collect();
        let scale_dy = sps.iter().map(|s| s.dy.abs()).fold(0.0, f64::max).max(1e-9);
        let scale_ddy = sps
            .iter()
            .map(|s| s.ddy.abs())
            .fold(0.0, f64::max)
            .max(1e-9);
        let mut checked = 0;
        for w in sps.windows(3) {
            let fd = (w[2].y_um - w[0].y_um) / (2.0 * dt);
            let fdd = (w[2].y_um - 2.0 * w[1].y_um + w[0].y_um) / (dt * dt);
            // Skip kinks (triangle corners, table knots have continuous dy only).
            if (w[2].dy - w[0].dy).abs() > 0.05 * scale_dy {
                continue;
            }
            assert!(
                (fd - w[1].dy).abs() < 2e-3 * scale_dy,
                "{fd} vs {}",
                w[1].dy
            );
            if (w[2].ddy - w[0].ddy).abs() < 0.05 * scale_ddy {
                assert!(
                    (fdd - w[1].ddy).abs() < 2e-2 * scale_ddy,
                    "{fdd} vs {}",
                    w[1].ddy
                );
            }
            checked += 1;
        }
        assert!(checked > 3000);
    }

    #[test]
    fn sine_triangle_table_derivatives_are_exact() {
        let fs = 10_000.0;
        check_derivatives(
            Wave::Sine {
                offset_um: 50.0,
                amplitude_um: 40.0,
                freq_hz: 7.0,
                phase_turns: 0.1,
            },
            fs,
        );
        check_derivatives(
            Wave::Triangle {
                offset_um: 50.0,
                amplitude_um: 40.0,
                freq_hz: 7.0,
                phase_turns: 0.0,
            },
            fs,
        );
        let pts: Vec<f64> = (0..12).map(|k| (k as f64 * 0.7).sin() * 30.0).collect();
        check_derivatives(Wave::table(&pts, 5.0).unwrap(), fs);
    }

    #[test]
    fn chirp_and_multisine_derivatives_are_exact() {
        let fs = 10_000.0;
        check_derivatives(Wave::chirp(50.0, 20.0, 2.0, 40.0, 0.3).unwrap(), fs);
        check_derivatives(Wave::multisine(50.0, 20.0, 3.0, 8, 7).unwrap(), fs);
    }

    #[test]
    fn prbs_generator_holds_each_bit_and_repeats_its_sequence() {
        let fs = 1000.0f32;
        let w = Wave::Prbs {
            low_um: 10.0,
            high_um: 30.0,
            order: 5,
            bit_hz: 250.0,
            seed: 3,
        };
        let mut g = WaveGen::new(w, fs).unwrap();
        let ys: Vec<f32> = (0..4 * 31 * 2).map(|_| g.next_setpoint().y_um).collect();
        for bit in ys.chunks(4) {
            assert!(bit.iter().all(|y| *y == bit[0]), "{bit:?}");
            assert!(bit[0] == 10.0 || bit[0] == 30.0);
        }
        assert_eq!(ys[..124], ys[124..], "period 31 bits");
        let highs = ys[..124].iter().filter(|y| **y == 30.0).count();
        assert_eq!(highs, 16 * 4);
        let prbs = |order, bit_hz| Wave::Prbs {
            low_um: 10.0f32,
            high_um: 30.0,
            order,
            bit_hz,
            seed: 3,
        };
        assert!(WaveGen::new(prbs(21, 250.0), fs).is_err());
        assert!(WaveGen::new(prbs(1, 250.0), fs).is_err());
        assert!(WaveGen::new(prbs(5, 1000.0), fs).is_err());
    }

    #[test]
    fn excitations_refuse_bad_parameters() {
        assert!(Wave::chirp(0.0, 1.0, 1.0, 6000.0, 1.0)
            .and_then(|w| w.validate(10_000.0))
            .is_err());
        assert!(Wave::chirp(0.0f64, 1.0, 1.0, 10.0, 0.0).is_err());
        assert!(Wave::multisine(0.0f64, 1.0, 1.0, 33, 0).is_err());
        assert!(Wave::multisine(0.0, 1.0, 200.0, 32, 0)
            .and_then(|w| w.validate(10_000.0))
            .is_err());
    }

    #[test]
    fn table_passes_through_its_points() {
        let pts = [1.0, 5.0, -2.0, 3.0];
        let w = Wave::table(&pts, 1.0).unwrap();
        for (k, p) in pts.iter().enumerate() {
            assert!((w.at(k as f64 / 4.0).y_um - p).abs() < 1e-12);
        }
    }

    #[test]
    fn steps_climb_and_descend() {
        let w = Wave::Steps {
            low_um: 0.0,
            high_um: 30.0,
            levels: 4,
            freq_hz: 1.0,
        };
        let ys: Vec<f64> = (0..6).map(|k| w.at((k as f64 + 0.5) / 6.0).y_um).collect();
        assert_eq!(ys, vec![0.0, 10.0, 20.0, 30.0, 20.0, 10.0]);
    }

    #[test]
    fn f32_sine_phasor_stays_on_the_exact_wave() {
        let wave = Wave::Sine {
            offset_um: 50.0f32,
            amplitude_um: 40.0,
            freq_hz: 123.4,
            phase_turns: 0.3,
        };
        let mut g = WaveGen::new(wave, 100_000.0).unwrap();
        let (mut worst, mut worst_dy) = (0.0f64, 0.0f64);
        for _ in 0..200_000 {
            let exact = g.current();
            let sp = g.next_setpoint();
            worst = worst.max((sp.y_um - exact.y_um).abs() as f64);
            worst_dy = worst_dy.max((sp.dy - exact.dy).abs() as f64);
        }
        // 2 * SINE_RESYNC * eps of the 40 um amplitude, plus the evaluation's own rounding.
        assert!(worst < 40.0 * 1e-5, "{worst}");
        let amp_dy = 40.0 * 2.0 * core::f64::consts::PI * 123.4;
        assert!(worst_dy < amp_dy * 1e-5, "{worst_dy}");
    }

    #[test]
    fn f32_phase_does_not_drift() {
        let mut g = WaveGen::new(
            Wave::Sine {
                offset_um: 0.0f32,
                amplitude_um: 1.0,
                freq_hz: 1.0,
                phase_turns: 0.0,
            },
            100_000.0,
        )
        .unwrap();
        // 1000 periods later the phase is back at 0 (error << one sample).
        for _ in 0..100_000_000u32 / 1000 * 10 {
            g.next_setpoint();
        }
        let sp = g.current();
        assert!(sp.y_um.abs() < 1e-3, "{sp:?}");
    }

    #[test]
    fn bad_waves_are_rejected() {
        let nyq = Wave::Sine {
            offset_um: 0.0,
            amplitude_um: 1.0,
            freq_hz: 6000.0,
            phase_turns: 0.0,
        };
        assert!(WaveGen::new(nyq, 10_000.0).is_err());
        assert!(Wave::<f64>::table(&[1.0], 1.0).is_err());
        let st = Wave::Steps {
            low_um: 0.0,
            high_um: 1.0,
            levels: 1,
            freq_hz: 1.0,
        };
        assert!(st.validate(100.0).is_err());
    }
}
