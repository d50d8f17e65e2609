//! Identification excitations of the reference generator (issue 17 item 1): a PRBS for the
//! linear part (as seed 004 identifies its linear dynamics), a linear chirp and a
//! random-phase multisine (the fine-steering-mirror benchmark's excitation). Each is a
//! [`super::Wave`] and runs in open and closed loop like the periodic waves.
//!
//! Written here rather than taken from a crate: they run in the control interrupt (no
//! allocation, no panic, bounded work per sample) on `f32` and Q16.16 alike.

use crate::real::Real;
use crate::signals::Setpoint;

/// Most harmonics of a multisine (its per-sample cost grows with them: about 14 operations
/// each).
pub const MULTISINE_MAX: usize = 32;

/// LFSR orders a PRBS can have: sequences of `2^order - 1` bits.
pub const PRBS_ORDER_MIN: u8 = 2;
pub const PRBS_ORDER_MAX: u8 = 20;

/// Feedback taps of a maximal-length Fibonacci LFSR per order (bit `t - 1` for tap `t`;
/// Xilinx XAPP052's table). `prbs_has_maximal_period` checks every entry.
const TAPS: [u32; PRBS_ORDER_MAX as usize + 1] = [
    0,
    0,
    0b11,                       // 2: 2, 1
    0b110,                      // 3: 3, 2
    0b1100,                     // 4: 4, 3
    0b1_0100,                   // 5: 5, 3
    0b11_0000,                  // 6: 6, 5
    0b110_0000,                 // 7: 7, 6
    0b1011_1000,                // 8: 8, 6, 5, 4
    0b1_0001_0000,              // 9: 9, 5
    0b10_0100_0000,             // 10: 10, 7
    0b101_0000_0000,            // 11: 11, 9
    0b1000_0010_1001,           // 12: 12, 6, 4, 1
    0b1_0000_0000_1101,         // 13: 13, 4, 3, 1
    0b10_0000_0001_0101,        // 14: 14, 5, 3, 1
    0b110_0000_0000_0000,       // 15: 15, 14
    0b1101_0000_0000_1000,      // 16: 16, 15, 13, 4
    0b1_0010_0000_0000_0000,    // 17: 17, 14
    0b10_0000_0100_0000_0000,   // 18: 18, 11
    0b100_0000_0000_0010_0011,  // 19: 19, 6, 2, 1
    0b1001_0000_0000_0000_0000, // 20: 20, 17
];

/// The register's state after `seed` (never 0, which would lock the LFSR).
pub fn prbs_start(order: u8, seed: u32) -> u32 {
    let mask = prbs_mask(order);
    let s = seed & mask;
    if s == 0 {
        mask
    } else {
        s
    }
}

fn prbs_mask(order: u8) -> u32 {
    let n = order.clamp(PRBS_ORDER_MIN, PRBS_ORDER_MAX);
    (1u32 << n) - 1
}

/// One LFSR shift: the new bit is the parity of the tapped bits.
#[inline]
pub fn prbs_next(state: u32, order: u8) -> u32 {
    let taps = TAPS.get(order as usize).copied().unwrap_or(0);
    let fb = (state & taps).count_ones() & 1;
    ((state << 1) | fb) & prbs_mask(order)
}

/// The level of the current bit (the register's top bit).
#[inline]
pub fn prbs_level<T: Real>(state: u32, order: u8, low_um: T, high_um: T) -> Setpoint<T> {
    let top = order.clamp(PRBS_ORDER_MIN, PRBS_ORDER_MAX) - 1;
    Setpoint::hold(if (state >> top) & 1 == 1 {
        high_um
    } else {
        low_um
    })
}

/// A linear chirp's phase in 2^-32 turns at sweep fraction `x` (2^-32 units): `a x + b x^2`
/// turns with `a = f0 T`, `b = (f1 - f0) T / 2`, both in 32.32 fixed point (`chirp_coeffs`).
/// Integer arithmetic: a sweep of thousands of turns keeps its phase to 2^-32 turn, which
/// `f32` could not.
#[inline]
pub fn chirp_phase(x: u32, a_fx: i64, b_fx: i64) -> u32 {
    let x = x as i128;
    let lin = (a_fx as i128 * x) >> 32;
    let x2 = (x * x) >> 32;
    let quad = (b_fx as i128 * x2) >> 32;
    (lin + quad) as u32
}

/// `(a, b)` of [`chirp_phase`] in 32.32 fixed point (construction, not per sample).
pub fn chirp_coeffs(f0_hz: f64, f1_hz: f64, duration_s: f64) -> (i64, i64) {
    let fx = |v: f64| (v * 4_294_967_296.0) as i64;
    (
        fx(f0_hz * duration_s),
        fx((f1_hz - f0_hz) * duration_s / 2.0),
    )
}

/// A linear chirp `f0_hz` -> `f1_hz` over `duration_s` around `offset_um`, with its phase
/// coefficients in 32.32 fixed point ([`chirp_coeffs`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chirp<T> {
    pub offset_um: T,
    pub amplitude_um: T,
    pub f0_hz: T,
    pub f1_hz: T,
    pub duration_s: T,
    pub a_fx: i64,
    pub b_fx: i64,
}

impl<T: Real> Chirp<T> {
    /// The chirp and its coefficients (construction, not per sample; no range check).
    pub fn new(offset_um: T, amplitude_um: T, f0_hz: T, f1_hz: T, duration_s: T) -> Self {
        let (a_fx, b_fx) = chirp_coeffs(f0_hz.to_f64(), f1_hz.to_f64(), duration_s.to_f64());
        Self {
            offset_um,
            amplitude_um,
            f0_hz,
            f1_hz,
            duration_s,
            a_fx,
            b_fx,
        }
    }

    /// The setpoint at sweep fraction `x` (2^-32 units); the instantaneous frequency
    /// `f0 + (f1 - f0) x` gives the derivatives.
    #[inline]
    pub fn at(&self, x: u32) -> Setpoint<T> {
        let (s, c) = sin_cos_turns(T::from_turns(chirp_phase(x, self.a_fx, self.b_fx)));
        let tau = T::from_turns(x);
        let df = self.f1_hz - self.f0_hz;
        let w = T::TWO * T::PI * (self.f0_hz + df * tau);
        let dw = if self.duration_s > T::ZERO {
            T::TWO * T::PI * df / self.duration_s
        } else {
            T::ZERO
        };
        let a = self.amplitude_um;
        Setpoint {
            y_um: self.offset_um + a * s,
            dy: a * w * c,
            ddy: a * (dw * c - w * w * s),
        }
    }
}

/// Phases of a multisine's harmonics as `(cos, sin)`: Schroeder's low-crest phases
/// `-pi k (k - 1) / K` for seed 0, uniform random ones (xorshift32 of the seed) otherwise.
pub fn multisine_phases<T: Real>(
    harmonics: usize,
    seed: u32,
) -> ([T; MULTISINE_MAX], [T; MULTISINE_MAX]) {
    let (mut cos, mut sin) = ([T::ZERO; MULTISINE_MAX], [T::ZERO; MULTISINE_MAX]);
    let k_max = harmonics.clamp(1, MULTISINE_MAX);
    let mut r = seed;
    for (k, (c, s)) in cos.iter_mut().zip(sin.iter_mut()).enumerate().take(k_max) {
        let turns = if seed == 0 {
            let k = (k + 1) as f64;
            -(k * (k - 1.0)) / (2.0 * k_max as f64)
        } else {
            r ^= r << 13;
            r ^= r >> 17;
            r ^= r << 5;
            r as f64 / 4_294_967_296.0
        };
        let t = turns - libm::floor(turns);
        let (sv, cv) = sin_cos_turns(T::from_f64(t));
        *c = cv;
        *s = sv;
    }
    (cos, sin)
}

/// `sum_k a sin(k theta + phi_k)` and its time derivatives at phase `x` of the base
/// frequency `f0_hz`: `sin(k theta)`, `cos(k theta)` by angle addition from the base phasor
/// (four multiplications per harmonic, rounding growing with k: f32 keeps about 1e-5 of the
/// amplitude at 32 harmonics).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn multisine_at<T: Real>(
    x: T,
    offset_um: T,
    per_harmonic_um: T,
    f0_hz: T,
    harmonics: u8,
    cos_phi: &[T; MULTISINE_MAX],
    sin_phi: &[T; MULTISINE_MAX],
) -> Setpoint<T> {
    let (s1, c1) = sin_cos_turns(x);
    let (mut s, mut c) = (s1, c1);
    let (mut y, mut dy, mut ddy) = (T::ZERO, T::ZERO, T::ZERO);
    let mut k = T::ZERO;
    for (cp, sp) in cos_phi.iter().zip(sin_phi).take(harmonics as usize) {
        k += T::ONE;
        let sine = s * *cp + c * *sp;
        let cosine = c * *cp - s * *sp;
        y += sine;
        dy += k * cosine;
        ddy += k * k * sine;
        (s, c) = (s * c1 + c * s1, c * c1 - s * s1);
    }
    let w0 = T::TWO * T::PI * f0_hz;
    Setpoint {
        y_um: offset_um + per_harmonic_um * y,
        dy: per_harmonic_um * w0 * dy,
        ddy: -(per_harmonic_um * w0 * w0 * ddy),
    }
}

/// The per-harmonic amplitude that makes the multisine's peak deviation `amplitude_um`:
/// the unit sum's peak over a grid of 64 points per period of the highest harmonic
/// (construction, not per sample).
pub fn multisine_scale<T: Real>(
    amplitude_um: T,
    harmonics: u8,
    cos_phi: &[T; MULTISINE_MAX],
    sin_phi: &[T; MULTISINE_MAX],
) -> T {
    let n = 64 * (harmonics.max(1) as usize);
    let mut peak = T::ZERO;
    for i in 0..n {
        let x = T::from_usize(i) / T::from_usize(n);
        let sp = multisine_at(x, T::ZERO, T::ONE, T::ZERO, harmonics, cos_phi, sin_phi);
        peak = peak.max(sp.y_um.abs());
    }
    if peak > T::ZERO {
        amplitude_um / peak
    } else {
        T::ZERO
    }
}

/// `(sin, cos)` of `2 pi x` for `x` in `[0, 1)` turns, without libm: octant reduction and
/// Taylor polynomials to degree 12 on `|phi| <= pi/4` (truncation below 1e-11, so `f64`
/// keeps 11 digits and `f32` is exact to rounding). libm's `sinf`/`cosf` compute in `f64`,
/// which a single-precision FPU emulates in software.
#[inline]
pub fn sin_cos_turns<T: Real>(x: T) -> (T, T) {
    let four = T::from_f64(4.0);
    let q = (x * four + T::HALF).floor();
    let phi = (x - q * T::from_f64(0.25)) * (T::TWO * T::PI);
    let p2 = phi * phi;
    // sin: phi (1 - p2/6 (1 - p2/20 (1 - p2/42 (1 - p2/72 (1 - p2/110)))))
    let c = |k: f64| T::from_f64(1.0 / k);
    let s = phi
        * (T::ONE
            - p2 * c(6.0)
                * (T::ONE
                    - p2 * c(20.0)
                        * (T::ONE
                            - p2 * c(42.0) * (T::ONE - p2 * c(72.0) * (T::ONE - p2 * c(110.0))))));
    let co = T::ONE
        - p2 * c(2.0)
            * (T::ONE
                - p2 * c(12.0)
                    * (T::ONE
                        - p2 * c(30.0)
                            * (T::ONE
                                - p2 * c(56.0)
                                    * (T::ONE - p2 * c(90.0) * (T::ONE - p2 * c(132.0))))));
    // Quadrant: sin(phi + n pi/2).
    let n = q.to_i32().rem_euclid(4);
    match n {
        0 => (s, co),
        1 => (co, -s),
        2 => (-s, -co),
        _ => (-co, s),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_cos_turns_matches_libm() {
        for k in 0..10_000 {
            let x = k as f64 / 10_000.0;
            let (s, c) = sin_cos_turns(x);
            let a = 2.0 * std::f64::consts::PI * x;
            assert!(
                (s - a.sin()).abs() < 1e-10 && (c - a.cos()).abs() < 1e-10,
                "{x}"
            );
            let (s, c) = sin_cos_turns(x as f32);
            assert!((s as f64 - a.sin()).abs() < 5e-7 && (c as f64 - a.cos()).abs() < 5e-7);
        }
    }

    #[test]
    fn prbs_has_maximal_period() {
        for order in PRBS_ORDER_MIN..=PRBS_ORDER_MAX {
            let start = prbs_start(order, 1);
            let mut s = start;
            let mut n = 0u32;
            loop {
                s = prbs_next(s, order);
                n += 1;
                if s == start || n > (1 << order) {
                    break;
                }
            }
            assert_eq!(n, (1 << order) - 1, "order {order}");
        }
    }

    #[test]
    fn prbs_is_balanced() {
        // A maximal sequence has 2^(n-1) ones and 2^(n-1) - 1 zeros.
        let order = 10;
        let mut s = prbs_start(order, 77);
        let mut ones = 0;
        for _ in 0..(1 << order) - 1 {
            if prbs_level(s, order, 0.0f64, 1.0).y_um == 1.0 {
                ones += 1;
            }
            s = prbs_next(s, order);
        }
        assert_eq!(ones, 1 << (order - 1));
    }

    #[test]
    fn chirp_phase_matches_the_closed_form() {
        let (f0, f1, t) = (5.0, 2000.0, 3.0);
        let (a, b) = chirp_coeffs(f0, f1, t);
        for i in 0..1000u64 {
            let x = (i * 4_294_967) as u32;
            let tau = x as f64 / 4_294_967_296.0;
            let exact = f0 * t * tau + (f1 - f0) * t * tau * tau / 2.0;
            let got = chirp_phase(x, a, b) as f64 / 4_294_967_296.0;
            let d = (got - (exact - exact.floor())).abs();
            assert!(d.min(1.0 - d) < 1e-6, "{tau}: {got} vs {exact}");
        }
    }

    #[test]
    fn multisine_peak_is_its_amplitude_and_spectrum_is_flat() {
        for seed in [0u32, 1, 12345] {
            let k = 16u8;
            let (c, s) = multisine_phases::<f64>(k as usize, seed);
            let a = multisine_scale(10.0, k, &c, &s);
            let n = 4096;
            let ys: Vec<f64> = (0..n)
                .map(|i| multisine_at(i as f64 / n as f64, 0.0, a, 1.0, k, &c, &s).y_um)
                .collect();
            let peak = ys.iter().fold(0.0f64, |m, y| m.max(y.abs()));
            assert!((peak - 10.0).abs() < 0.05, "seed {seed}: peak {peak}");
            // DFT bins 1..=k carry a each, the others nothing.
            for bin in 0..40 {
                let (re, im) = ys.iter().enumerate().fold((0.0, 0.0), |(re, im), (i, y)| {
                    let ph = 2.0 * core::f64::consts::PI * (bin * i) as f64 / n as f64;
                    (re + y * ph.cos(), im - y * ph.sin())
                });
                let mag = 2.0 * (re * re + im * im).sqrt() / n as f64;
                let want = if (1..=k as usize).contains(&bin) {
                    a
                } else {
                    0.0
                };
                assert!(
                    (mag - want).abs() < 1e-6 * a.max(1.0),
                    "bin {bin}: {mag} vs {want}"
                );
            }
        }
    }
}
