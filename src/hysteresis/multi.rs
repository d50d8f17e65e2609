//! Multivariable Bouc-Wen of 003 (eq. 4-7) for `N` outputs and `K` inputs.

use super::{ensure, sane_input, ParamError, MAX_SUBSTEPS};
use crate::real::Real;

/// State of [`MultiBw`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MultiBwState<T, const N: usize, const K: usize> {
    /// Last input vector `U` (V).
    pub u: [T; K],
    /// Hysteresis state vector `h`.
    pub h: [T; N],
}

/// Multivariable Bouc-Wen (003 eq. 4-7): `y = D*U - h` with
/// `dh_i/dt = sum_{j=1..K} A_ij*U'_j - B_ij*|U'_j|*hh_j - G_ij*U'_j*|hh_j|`,
/// `hh_j = h_j` for `j <= N`, `0` beyond (003 eq. 5: `h` padded with zeros when the system
/// is over-actuated, `K > N`; `U'` padded when `N > K`, which leaves the sums over `j <= K`).
/// `D, A, B, G` are `N x K`; under-, over- and fully actuated systems are all this type.
///
/// Discretisation: the input moves along the straight (first-order hold) path
/// `U = U0 + theta*dU` over the sample, and
/// `dh_i/dtheta = sum_j dU_j*(A_ij - B_ij*s_j*hh_j - G_ij*|hh_j|)` (`s_j = sgn(dU_j)`) is
/// integrated by RK4 in `theta` with sub-steps whose Lipschitz product is at most 0.05
/// (at most [`MAX_SUBSTEPS`]). Rate independent like the scalar CBW.
///
/// Accepted when every entry is finite and each direct transfer (`i = j <= min(N, K)`)
/// meets 004 eq. (3): `A_jj > 0`, `B_jj + G_jj > 0`, `B_jj - G_jj >= 0`. Then the direct
/// states are bounded as in CBW; a coupling state `h_i` driven only by other axes has no
/// restoring term in eq. (7) and follows the seed's equation wherever it goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MultiBw<T, const N: usize, const K: usize> {
    d: [[T; K]; N],
    a: [[T; K]; N],
    b: [[T; K]; N],
    g: [[T; K]; N],
    /// `max_i sum_j (|B_ij| + |G_ij|)`, the Lipschitz bound per volt of input path.
    lipschitz: T,
}

impl<T: Real, const N: usize, const K: usize> MultiBw<T, N, K> {
    /// `D` (um/V), `A` (um/V), `B`, `G` (`Gamma`, 1/V), each `N x K` (row = output).
    pub fn new(
        d: [[T; K]; N],
        a: [[T; K]; N],
        b: [[T; K]; N],
        g: [[T; K]; N],
    ) -> Result<Self, ParamError> {
        let finite = [d, a, b, g]
            .iter()
            .all(|m| m.iter().flatten().all(|v| v.is_finite()));
        ensure(
            finite,
            "MultiBW: all entries of D, A, B, Gamma must be finite",
        )?;
        ensure(N >= 1 && K >= 1, "MultiBW: N >= 1 and K >= 1")?;
        for j in 0..N.min(K) {
            ensure(a[j][j] > T::ZERO, "MultiBW: A_jj > 0 (004 eq. 3)")?;
            ensure(
                b[j][j] + g[j][j] > T::ZERO,
                "MultiBW: B_jj + Gamma_jj > 0 (004 eq. 3)",
            )?;
            ensure(
                b[j][j] - g[j][j] >= T::ZERO,
                "MultiBW: B_jj - Gamma_jj >= 0 (004 eq. 3)",
            )?;
        }
        let mut lipschitz = T::ZERO;
        for i in 0..N {
            let mut row = T::ZERO;
            for j in 0..K.min(N) {
                row += b[i][j].abs() + g[i][j].abs();
            }
            lipschitz = lipschitz.max(row);
        }
        Ok(Self {
            d,
            a,
            b,
            g,
            lipschitz,
        })
    }

    pub fn d(&self) -> &[[T; K]; N] {
        &self.d
    }
    pub fn a(&self) -> &[[T; K]; N] {
        &self.a
    }
    pub fn b(&self) -> &[[T; K]; N] {
        &self.b
    }
    pub fn gamma(&self) -> &[[T; K]; N] {
        &self.g
    }

    /// `hh_j`: `h_j` for `j < N`, else 0 (003 eq. 5).
    #[inline(always)]
    fn hh(h: &[T; N], j: usize) -> T {
        h.get(j).copied().unwrap_or(T::ZERO)
    }

    /// `dh_i/dU_j` at state `h` for input directions `s_j = sgn(dU_j)`:
    /// `A_ij - B_ij*s_j*hh_j - G_ij*|hh_j|`.
    #[inline]
    pub fn jacobian(&self, h: &[T; N], s: &[T; K]) -> [[T; K]; N] {
        let mut jac = [[T::ZERO; K]; N];
        for (i, row) in jac.iter_mut().enumerate() {
            for (j, (x, &sj)) in row.iter_mut().zip(s.iter()).enumerate() {
                let hj = Self::hh(h, j);
                *x = self.a[i][j] - self.b[i][j] * sj * hj - self.g[i][j] * hj.abs();
            }
        }
        jac
    }

    /// `dh/dtheta` along the path with increment `du`.
    #[inline]
    fn rate(&self, h: &[T; N], du: &[T; K]) -> [T; N] {
        let mut out = [T::ZERO; N];
        for (i, o) in out.iter_mut().enumerate() {
            let mut acc = T::ZERO;
            for (j, &dj) in du.iter().enumerate() {
                let hj = Self::hh(h, j);
                acc +=
                    dj * self.a[i][j] - self.b[i][j] * dj.abs() * hj - self.g[i][j] * dj * hj.abs();
            }
            *o = acc;
        }
        out
    }

    /// Update of `h` over the input increment `du` (straight path).
    pub fn advance_h(&self, h: &mut [T; N], du: &[T; K]) {
        let path = du.iter().fold(T::ZERO, |acc, &x| acc + x.abs());
        if !(path > T::ZERO) {
            return;
        }
        let ratio = path * self.lipschitz / T::from_f64(0.05);
        let n = if !(ratio >= T::ONE) {
            1
        } else if ratio < T::from_usize(MAX_SUBSTEPS) {
            ratio.to_f64() as usize + 1
        } else {
            MAX_SUBSTEPS
        };
        let dth = T::ONE / T::from_usize(n);
        let half = dth * T::HALF;
        let sixth = dth / T::from_f64(6.0);
        let add = |h: &[T; N], k: &[T; N], c: T| {
            let mut o = *h;
            for (o, &k) in o.iter_mut().zip(k.iter()) {
                *o += c * k;
            }
            o
        };
        for _ in 0..n {
            let k1 = self.rate(h, du);
            let k2 = self.rate(&add(h, &k1, half), du);
            let k3 = self.rate(&add(h, &k2, half), du);
            let k4 = self.rate(&add(h, &k3, dth), du);
            for (i, x) in h.iter_mut().enumerate() {
                *x += sixth * (k1[i] + T::TWO * (k2[i] + k3[i]) + k4[i]);
            }
        }
    }

    /// `y = D*U - h` (003 eq. 6).
    #[inline]
    pub fn output(&self, u: &[T; K], h: &[T; N]) -> [T; N] {
        let mut y = [T::ZERO; N];
        for (i, y) in y.iter_mut().enumerate() {
            let du = self.d[i]
                .iter()
                .zip(u.iter())
                .fold(T::ZERO, |acc, (&d, &u)| acc + d * u);
            *y = du - h[i];
        }
        y
    }

    /// The relaxed state at input `u0` (`h = 0`).
    pub fn init(&self, u0: [T; K]) -> MultiBwState<T, N, K> {
        let mut u = u0;
        for x in u.iter_mut() {
            *x = sane_input(*x, T::ZERO);
        }
        MultiBwState { u, h: [T::ZERO; N] }
    }

    /// Advance to input `u` (each non-finite entry holds its previous value) and return `y`.
    pub fn step(&self, s: &mut MultiBwState<T, N, K>, u: [T; K], _dt: T) -> [T; N] {
        let mut un = u;
        let mut du = [T::ZERO; K];
        for ((un, d), &prev) in un.iter_mut().zip(du.iter_mut()).zip(s.u.iter()) {
            *un = sane_input(*un, prev);
            *d = *un - prev;
        }
        self.advance_h(&mut s.h, &du);
        s.u = un;
        self.output(&s.u, &s.h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hysteresis::assert_refused;

    #[test]
    fn rejects_bad_direct_terms() {
        let z = [[0.0; 2]; 2];
        let a = [[0.07, 0.01], [0.0, 0.05]];
        let b = [[0.02, 0.0], [0.0, 0.01]];
        let g = [[0.01, 0.0], [0.0, 0.02]];
        assert_refused(
            MultiBw::new(z, a, b, g),
            "MultiBW: B_jj - Gamma_jj >= 0 (004 eq. 3)",
        );
        let mut bad = a;
        bad[0][1] = f64::NAN;
        assert!(MultiBw::new(z, bad, b, b).is_err());
    }

    #[test]
    fn nan_entry_holds_its_input() {
        let m = MultiBw::<f64, 2, 3>::new(
            [[0.16, 0.01, 0.0], [0.0, 0.15, 0.02]],
            [[0.07, 0.002, 0.0], [0.001, 0.06, 0.003]],
            [[0.02, 0.0, 0.0], [0.0, 0.02, 0.0]],
            [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0]],
        )
        .unwrap();
        let mut s = m.init([0.0; 3]);
        m.step(&mut s, [10.0, 5.0, 3.0], 1e-3);
        let y = m.step(&mut s, [f64::NAN, 6.0, f64::INFINITY], 1e-3);
        assert_eq!(s.u, [10.0, 6.0, 3.0]);
        assert!(y.iter().all(|y| y.is_finite()));
    }
}
