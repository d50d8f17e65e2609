//! The one seeded random generator of hal-sim (stage and converter noise, fault campaigns,
//! manipulation noise, benchmark draws, the differential-evolution search).

/// xorshift64* (Vigna 2016): small, fast, 64 bits per step, reproducible from a seed.
/// Not cryptographic; every user needs only repeatable noise and draws.
#[derive(Debug, Clone)]
pub struct Rng {
    s: u64,
    /// The second value of the last Box-Muller pair ([`Rng::normal`]).
    spare: Option<f64>,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        // Odd, so never the all-zero state xorshift cannot leave.
        Self {
            s: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
            spare: None,
        }
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.s;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.s = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `[0, 1)`, 53 random bits.
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `(0, 1)`: never 0, so its logarithm is finite.
    fn uniform_open(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Log-uniform in `[lo, hi)` (`lo > 0`).
    pub fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.range(lo.ln(), hi.ln()).exp()
    }

    /// Uniform integer in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        ((self.uniform() * n as f64) as usize).min(n.saturating_sub(1))
    }

    /// +1 or -1.
    pub fn sign(&mut self) -> f64 {
        if self.next_u64() & 1 == 0 {
            1.0
        } else {
            -1.0
        }
    }

    /// Zero-mean, unit-variance noise for the per-sample paths: the sum of four 16-bit
    /// uniforms of one step (Irwin-Hall), Gaussian to within a few percent out to 3 sigma
    /// and bounded at +-3.46.
    #[inline]
    pub fn gauss(&mut self) -> f64 {
        let r = self.next_u64();
        let s = (r & 0xFFFF) + ((r >> 16) & 0xFFFF) + ((r >> 32) & 0xFFFF) + (r >> 48);
        // mean 4 * 32767.5, variance 4 * (65536^2 - 1) / 12
        (s as f64 - 131_070.0) * (3.0f64.sqrt() / 65_536.0)
    }

    /// One sample of N(0, sigma^2), exact (Box-Muller; the pair's second value is kept for
    /// the next call).
    pub fn normal(&mut self, sigma: f64) -> f64 {
        if let Some(z) = self.spare.take() {
            return sigma * z;
        }
        let (u1, u2) = (self.uniform_open(), self.uniform_open());
        let r = (-2.0 * u1.ln()).sqrt();
        let a = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * a.sin());
        sigma * r * a.cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_is_uniform_and_reproducible() {
        let mut a = Rng::new(7);
        let mut b = Rng::new(7);
        let mut c = Rng::new(8);
        let xs: Vec<f64> = (0..10_000).map(|_| a.uniform()).collect();
        assert!(xs.iter().all(|v| (0.0..1.0).contains(v)));
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
        assert_eq!(b.uniform(), xs[0]);
        assert_ne!(c.uniform(), xs[0]);
        assert!((0..1000).all(|_| a.below(3) < 3));
        assert!((0..1000).all(|_| (2.0..5.0).contains(&a.range(2.0, 5.0))));
        assert!((0..1000).all(|_| (1e-3..1.0).contains(&a.log_uniform(1e-3, 1.0))));
    }

    #[test]
    fn gauss_has_unit_variance() {
        let mut r = Rng::new(3);
        let n = 200_000;
        let (mut m, mut v) = (0.0, 0.0);
        for _ in 0..n {
            let g = r.gauss();
            m += g;
            v += g * g;
        }
        m /= n as f64;
        v = v / n as f64 - m * m;
        assert!(m.abs() < 0.01 && (v - 1.0).abs() < 0.02, "{m} {v}");
    }

    #[test]
    fn normal_has_the_asked_variance() {
        let mut g = Rng::new(3);
        let v: Vec<f64> = (0..20_000).map(|_| g.normal(2.0)).collect();
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let s = (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt();
        assert!(m.abs() < 0.05 && (s - 2.0).abs() < 0.05, "{m} {s}");
    }
}
