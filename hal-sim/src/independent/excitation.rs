//! The generator's excitations: commands in V over `0..u_max`, each starting at rest (0 V)
//! and faded in over the first 0.25 s.
use serde::Serialize;

use crate::numeric::Rng;

/// Fade-in from rest (s).
const FADE_S: f64 = 0.25;

/// One record's drive. Fractions are of the command range `u_max`.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum Excitation {
    /// `0.5 + amp sin(2 pi f t)`.
    Sine { f_hz: f64, amp: f64 },
    /// A sine about mid-range whose amplitude moves exponentially from `from` to `to`
    /// over the record (decaying when `from > to`, growing otherwise).
    SweptAmplitude { f_hz: f64, from: f64, to: f64 },
    /// Between `lo` and `hi`.
    Triangle { f_hz: f64, lo: f64, hi: f64 },
    /// Gaussian noise through four first-order low-passes at `band_hz`, `rms` about
    /// mid-range, clipped to 1-99 %.
    Noise { band_hz: f64, rms: f64, seed: u64 },
    /// `n` sines log-uniform in `f_lo..f_hi` with random phases, peak `0.45` about mid-range.
    Multisine {
        f_lo: f64,
        f_hi: f64,
        n: usize,
        seed: u64,
    },
}

/// The kinds, for drawing two different ones.
pub const KINDS: usize = 6;

impl Excitation {
    /// Draws kind `kind` (`0..KINDS`: sine, decaying, growing, triangle, noise, multisine).
    pub fn draw(kind: usize, rng: &mut Rng) -> Self {
        match kind {
            0 => Self::Sine {
                f_hz: rng.log_uniform(0.5, 100.0),
                amp: rng.range(0.30, 0.48),
            },
            1 => Self::SweptAmplitude {
                f_hz: rng.log_uniform(1.0, 60.0),
                from: rng.range(0.35, 0.48),
                to: rng.range(0.03, 0.10),
            },
            2 => Self::SweptAmplitude {
                f_hz: rng.log_uniform(1.0, 60.0),
                from: rng.range(0.03, 0.10),
                to: rng.range(0.35, 0.48),
            },
            3 => Self::Triangle {
                f_hz: rng.log_uniform(0.5, 40.0),
                lo: rng.range(0.02, 0.15),
                hi: rng.range(0.85, 0.98),
            },
            4 => Self::Noise {
                band_hz: rng.log_uniform(2.0, 100.0),
                rms: rng.range(0.12, 0.2),
                seed: rng.next_u64(),
            },
            _ => Self::Multisine {
                f_lo: rng.range(0.5, 2.0),
                f_hi: rng.log_uniform(10.0, 100.0),
                n: 4 + rng.below(7),
                seed: rng.next_u64(),
            },
        }
    }

    /// The highest frequency with a sizeable share of the drive (a triangle's fifth
    /// harmonic, a noise band's edge).
    pub fn top_hz(&self) -> f64 {
        match *self {
            Self::Sine { f_hz, .. } | Self::SweptAmplitude { f_hz, .. } => f_hz,
            Self::Triangle { f_hz, .. } => 5.0 * f_hz,
            Self::Noise { band_hz, .. } => 2.0 * band_hz,
            Self::Multisine { f_hi, .. } => f_hi,
        }
    }

    /// `n` command samples at `fs_hz`, in V over `0..u_max`, the first at 0 V.
    pub fn command(&self, fs_hz: f64, n: usize, u_max: f64) -> Vec<f64> {
        let dt = 1.0 / fs_hz;
        let dur = n as f64 * dt;
        let tau = std::f64::consts::TAU;
        // Fractions of the range, before the fade-in.
        let wave: Vec<f64> = match *self {
            Self::Sine { f_hz, amp } => (0..n)
                .map(|k| 0.5 + amp * (tau * f_hz * k as f64 * dt).sin())
                .collect(),
            Self::SweptAmplitude { f_hz, from, to } => (0..n)
                .map(|k| {
                    let t = k as f64 * dt;
                    let a = from * (to / from).powf(t / dur);
                    0.5 + a * (tau * f_hz * t).sin()
                })
                .collect(),
            Self::Triangle { f_hz, lo, hi } => (0..n)
                .map(|k| {
                    // Starts at the middle going up, like a sine.
                    let ph = (f_hz * k as f64 * dt + 0.25).fract();
                    let tri = if ph < 0.5 {
                        4.0 * ph - 1.0
                    } else {
                        3.0 - 4.0 * ph
                    };
                    0.5 * (lo + hi) + 0.5 * (hi - lo) * tri
                })
                .collect(),
            Self::Noise { band_hz, rms, seed } => {
                let mut rng = Rng::new(seed);
                let a = (-tau * band_hz * dt).exp();
                let mut s = [0.0; 4];
                // Settle the filter first so the record does not start with its transient.
                let settle = (5.0 / (tau * band_hz) / dt) as usize * 4;
                let mut out = Vec::with_capacity(n);
                for k in 0..settle + n {
                    let mut x = rng.normal(1.0);
                    for si in s.iter_mut() {
                        *si = a * *si + (1.0 - a) * x;
                        x = *si;
                    }
                    if k >= settle {
                        out.push(x);
                    }
                }
                let m = out.iter().sum::<f64>() / n.max(1) as f64;
                let sd = (out.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / n.max(1) as f64)
                    .sqrt()
                    .max(1e-12);
                out.iter()
                    .map(|x| (0.5 + rms * (x - m) / sd).clamp(0.01, 0.99))
                    .collect()
            }
            Self::Multisine {
                f_lo,
                f_hi,
                n: m,
                seed,
            } => {
                let mut rng = Rng::new(seed);
                let comps: Vec<(f64, f64)> = (0..m)
                    .map(|_| (rng.log_uniform(f_lo, f_hi), rng.range(0.0, tau)))
                    .collect();
                let raw: Vec<f64> = (0..n)
                    .map(|k| {
                        let t = k as f64 * dt;
                        comps.iter().map(|(f, p)| (tau * f * t + p).sin()).sum()
                    })
                    .collect();
                let peak = raw.iter().fold(1e-12f64, |a, x| a.max(x.abs()));
                raw.iter().map(|x| 0.5 + 0.45 * x / peak).collect()
            }
        };
        wave.iter()
            .enumerate()
            .map(|(k, w)| {
                let t = k as f64 * dt;
                let fade = if t < FADE_S {
                    0.5 * (1.0 - (std::f64::consts::PI * t / FADE_S).cos())
                } else {
                    1.0
                };
                u_max * (fade * w).clamp(0.0, 1.0)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_starts_at_rest_and_stays_in_range() {
        let mut rng = Rng::new(5);
        for kind in 0..KINDS {
            for _ in 0..5 {
                let e = Excitation::draw(kind, &mut rng);
                let u = e.command(5000.0, 20_000, 150.0);
                assert_eq!(u[0], 0.0, "{e:?}");
                assert!(u.iter().all(|v| (0.0..=150.0).contains(v)), "{e:?}");
                // It moves: at least a third of the range.
                let (lo, hi) = u
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
                assert!(hi - lo > 50.0, "{e:?}: {lo}..{hi}");
            }
        }
    }
}
