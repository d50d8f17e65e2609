//! Discrete-time multivariable state-space model in real modal form:
//! `x[k+1] = A x[k] + B u[k]`, `y[k] = C x[k] + D u[k]`, with `A` block diagonal
//! (one 1x1 block per real pole, one `[[sigma, omega], [-omega, sigma]]` block per complex
//! pair `sigma +- j omega`). Poles are explicit, so stability is a bound on each block;
//! `B`, `C`, `D` are free, so zeros go anywhere (non-minimum-phase included).

use nalgebra::{Complex, DMatrix, DVector};
use serde::{Deserialize, Serialize};

pub type C64 = Complex<f64>;

/// Largest pole modulus the identification keeps (just inside the unit circle).
pub const MAX_POLE_RADIUS: f64 = 0.9999;

/// One diagonal block of `A`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Block {
    /// A real pole.
    Real(f64),
    /// A complex pair `sigma +- j omega` (`omega > 0`).
    Pair(f64, f64),
}

impl Block {
    pub fn states(&self) -> usize {
        match self {
            Block::Real(_) => 1,
            Block::Pair(..) => 2,
        }
    }

    /// Pole modulus.
    pub fn radius(&self) -> f64 {
        match *self {
            Block::Real(l) => l.abs(),
            Block::Pair(s, w) => s.hypot(w),
        }
    }

    /// Scales the pole(s) back inside `r_max` (keeping the angle).
    pub fn clamp_radius(&mut self, r_max: f64) {
        let r = self.radius();
        if r > r_max {
            let k = r_max / r;
            match self {
                Block::Real(l) => *l *= k,
                Block::Pair(s, w) => {
                    *s *= k;
                    *w *= k;
                }
            }
        }
    }

    /// The same block with unstable poles reflected into the unit circle (`1 / conj(p)`).
    pub fn reflected(self) -> Self {
        let r = self.radius();
        let mut b = if r > 1.0 {
            match self {
                Block::Real(l) => Block::Real(1.0 / l),
                Block::Pair(s, w) => Block::Pair(s / (r * r), w / (r * r)),
            }
        } else {
            self
        };
        b.clamp_radius(MAX_POLE_RADIUS);
        b
    }
}

/// A modal state-space model; `b` is `n x m`, `c` is `p x n`, `d` is `p x m`.
#[derive(Debug, Clone, PartialEq)]
pub struct Modal {
    pub blocks: Vec<Block>,
    pub b: DMatrix<f64>,
    pub c: DMatrix<f64>,
    pub d: DMatrix<f64>,
}

/// Serialized form: row-major nested arrays, readable in `fit.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModalJson {
    /// Real poles `[lambda]` and complex pairs `[sigma, omega]` (discrete time, per sample).
    pub blocks: Vec<Block>,
    pub b: Vec<Vec<f64>>,
    pub c: Vec<Vec<f64>>,
    pub d: Vec<Vec<f64>>,
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

fn from_rows(
    r: &[Vec<f64>],
    nrows: usize,
    ncols: usize,
    what: &str,
) -> anyhow::Result<DMatrix<f64>> {
    anyhow::ensure!(
        r.len() == nrows && r.iter().all(|row| row.len() == ncols),
        "state-space `{what}` must be {nrows} x {ncols}"
    );
    anyhow::ensure!(
        r.iter().flatten().all(|v| v.is_finite()),
        "state-space `{what}` has a non-finite entry"
    );
    Ok(DMatrix::from_fn(nrows, ncols, |i, j| r[i][j]))
}

impl Modal {
    pub fn order(&self) -> usize {
        self.blocks.iter().map(Block::states).sum()
    }
    pub fn inputs(&self) -> usize {
        self.b.ncols()
    }
    pub fn outputs(&self) -> usize {
        self.c.nrows()
    }

    /// A bound on the sum of the modes' peak gains: per block `|C_i| |B_i| / (1 - r_i)`
    /// (Frobenius norms, `r_i` its pole modulus), plus `|D|`. Far above the response's own
    /// peak it says the modes cancel (huge input and output gains of opposite effect): the
    /// model simulates, but it is no model of a stage.
    pub fn modal_gain_bound(&self) -> f64 {
        let mut i = 0;
        let mut sum = self.d.norm();
        for blk in &self.blocks {
            let k = blk.states();
            let b = self.b.rows(i, k).norm();
            let c = self.c.columns(i, k).norm();
            sum += b * c / (1.0 - blk.radius()).max(1e-12);
            i += k;
        }
        sum
    }

    /// Largest pole modulus.
    pub fn spectral_radius(&self) -> f64 {
        self.blocks.iter().map(Block::radius).fold(0.0, f64::max)
    }

    pub fn to_json(&self) -> ModalJson {
        ModalJson {
            blocks: self.blocks.clone(),
            b: rows(&self.b),
            c: rows(&self.c),
            d: rows(&self.d),
        }
    }

    pub fn from_json(j: &ModalJson) -> anyhow::Result<Self> {
        let n: usize = j.blocks.iter().map(Block::states).sum();
        let m = j.d.first().map_or(0, Vec::len);
        let p = j.d.len();
        anyhow::ensure!(
            p > 0 && m > 0,
            "state-space `d` must have at least one row and column"
        );
        for b in &j.blocks {
            let ok = match *b {
                Block::Real(l) => l.is_finite(),
                Block::Pair(s, w) => s.is_finite() && w.is_finite() && w > 0.0,
            };
            anyhow::ensure!(
                ok,
                "state-space block {b:?} is not a real pole or a pair with omega > 0"
            );
        }
        Ok(Self {
            blocks: j.blocks.clone(),
            b: from_rows(&j.b, n, m, "b")?,
            c: from_rows(&j.c, p, n, "c")?,
            d: from_rows(&j.d, p, m, "d")?,
        })
    }

    /// The dense `A`.
    pub fn a(&self) -> DMatrix<f64> {
        let n = self.order();
        let mut a = DMatrix::zeros(n, n);
        let mut i = 0;
        for b in &self.blocks {
            match *b {
                Block::Real(l) => a[(i, i)] = l,
                Block::Pair(s, w) => {
                    a[(i, i)] = s;
                    a[(i, i + 1)] = w;
                    a[(i + 1, i)] = -w;
                    a[(i + 1, i + 1)] = s;
                }
            }
            i += b.states();
        }
        a
    }

    /// `(z I - A_blk)^-1` of every block, concatenated (1 or 4 entries each, row-major).
    pub fn resolvents(&self, z: C64) -> Vec<C64> {
        let mut out = Vec::with_capacity(2 * self.order());
        for b in &self.blocks {
            match *b {
                Block::Real(l) => out.push(1.0 / (z - l)),
                Block::Pair(s, w) => {
                    let zs = z - s;
                    let det = zs * zs + w * w;
                    out.extend([zs / det, w / det, -w / det, zs / det]);
                }
            }
        }
        out
    }

    /// Frequency response `G(z) = C (zI - A)^-1 B + D` at `z` (`p x m`).
    pub fn response(&self, z: C64) -> DMatrix<C64> {
        let (m, p) = (self.inputs(), self.outputs());
        let mut g = self.d.map(|v| C64::new(v, 0.0));
        let res = self.resolvents(z);
        let (mut i, mut r) = (0, 0);
        for blk in &self.blocks {
            // X = R B_blk (states x m)
            let ns = blk.states();
            for j in 0..m {
                let x: Vec<C64> = (0..ns)
                    .map(|a| {
                        (0..ns)
                            .map(|bb| res[r + a * ns + bb] * self.b[(i + bb, j)])
                            .sum()
                    })
                    .collect();
                for o in 0..p {
                    let mut acc = C64::new(0.0, 0.0);
                    for (a, xa) in x.iter().enumerate() {
                        acc += *xa * self.c[(o, i + a)];
                    }
                    g[(o, j)] += acc;
                }
            }
            r += ns * ns;
            i += ns;
        }
        g
    }

    /// Simulates from rest (`x = 0`); `u[j][k]` is input `j` at sample `k`.
    pub fn simulate(&self, u: &[Vec<f64>]) -> anyhow::Result<Vec<Vec<f64>>> {
        let (m, p, n) = (self.inputs(), self.outputs(), self.order());
        anyhow::ensure!(
            u.len() == m,
            "the model has {m} inputs, the record {}",
            u.len()
        );
        let len = u.first().map_or(0, Vec::len);
        let mut x = vec![0.0; n];
        let mut xn = vec![0.0; n];
        let mut y = vec![vec![0.0; len]; p];
        let mut uk = vec![0.0; m];
        for k in 0..len {
            for (j, v) in uk.iter_mut().enumerate() {
                *v = u[j][k];
            }
            for (o, yo) in y.iter_mut().enumerate() {
                let mut s = 0.0;
                for (i, xi) in x.iter().enumerate() {
                    s += self.c[(o, i)] * xi;
                }
                for (j, v) in uk.iter().enumerate() {
                    s += self.d[(o, j)] * v;
                }
                yo[k] = s;
            }
            let mut i = 0;
            for blk in &self.blocks {
                match *blk {
                    Block::Real(l) => xn[i] = l * x[i],
                    Block::Pair(s, w) => {
                        xn[i] = s * x[i] + w * x[i + 1];
                        xn[i + 1] = -w * x[i] + s * x[i + 1];
                    }
                }
                i += blk.states();
            }
            for (i, v) in xn.iter_mut().enumerate() {
                for (j, uj) in uk.iter().enumerate() {
                    *v += self.b[(i, j)] * uj;
                }
            }
            std::mem::swap(&mut x, &mut xn);
        }
        anyhow::ensure!(
            y.iter().flatten().all(|v| v.is_finite()),
            "the state-space simulation diverged"
        );
        Ok(y)
    }

    /// Modal form of a dense `(A, B, C, D)`: eigenvectors by inverse iteration (complex
    /// LU), unstable poles reflected (`1 / conj(p)`) and pulled inside
    /// [`MAX_POLE_RADIUS`]. `B` is kept as transformed; callers refit it when poles moved.
    pub fn from_dense(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        c: &DMatrix<f64>,
        d: &DMatrix<f64>,
    ) -> anyhow::Result<Self> {
        let n = a.nrows();
        let eig = a.clone().complex_eigenvalues();
        let mut pairs: Vec<C64> = Vec::new();
        let mut reals: Vec<f64> = Vec::new();
        let tol = 1e-9;
        for l in eig.iter() {
            if l.im > tol {
                pairs.push(*l);
            } else if l.im.abs() <= tol {
                reals.push(l.re);
            }
        }
        anyhow::ensure!(
            2 * pairs.len() + reals.len() == n,
            "could not split the {n} poles into real poles and conjugate pairs"
        );
        // Sort by frequency so the modes read in order in fit.json.
        pairs.sort_by(|x, y| x.arg().total_cmp(&y.arg()));
        reals.sort_by(|x, y| y.total_cmp(x));
        let ac = a.map(|v| C64::new(v, 0.0));
        let eigvec = |l: C64| -> anyhow::Result<DVector<C64>> {
            let shift = l + C64::new(1e-10 * (1.0 + l.norm()), 1e-10 * (1.0 + l.norm()));
            let m = &ac - DMatrix::<C64>::identity(n, n) * shift;
            let lu = m.lu();
            let mut v = DVector::from_fn(n, |i, _| C64::new(1.0 + 0.1 * i as f64, 0.3));
            for _ in 0..3 {
                v = lu
                    .solve(&v)
                    .ok_or_else(|| anyhow::anyhow!("eigenvector of pole {l} not found"))?;
                let nv = v.norm();
                anyhow::ensure!(
                    nv.is_finite() && nv > 0.0,
                    "eigenvector of pole {l} not found"
                );
                v /= C64::new(nv, 0.0);
            }
            Ok(v)
        };
        let mut t = DMatrix::<f64>::zeros(n, n);
        let mut blocks = Vec::new();
        let mut col = 0;
        for l in &pairs {
            let v = eigvec(*l)?;
            for i in 0..n {
                t[(i, col)] = v[i].re;
                t[(i, col + 1)] = v[i].im;
            }
            blocks.push(Block::Pair(l.re, l.im));
            col += 2;
        }
        for l in &reals {
            let v = eigvec(C64::new(*l, 0.0))?;
            // A real eigenvector up to a complex phase: take the larger of Re/Im.
            let (re, im) = (v.map(|x| x.re), v.map(|x| x.im));
            let w = if re.norm() >= im.norm() { re } else { im };
            for i in 0..n {
                t[(i, col)] = w[i];
            }
            blocks.push(Block::Real(*l));
            col += 1;
        }
        let tinv = t.clone().try_inverse().ok_or_else(|| {
            anyhow::anyhow!("the modal transformation is singular (repeated poles?)")
        })?;
        Ok(Self {
            blocks: blocks.into_iter().map(Block::reflected).collect(),
            b: &tinv * b,
            c: c * &t,
            d: d.clone(),
        })
    }

    /// Poles as continuous-time natural frequency (Hz) and damping ratio, for reports.
    pub fn modes_hz(&self, fs_hz: f64) -> Vec<(f64, f64)> {
        self.blocks
            .iter()
            .map(|b| {
                let z = match *b {
                    Block::Real(l) => C64::new(l, 0.0),
                    Block::Pair(s, w) => C64::new(s, w),
                };
                let s = z.ln() * fs_hz;
                let wn = s.norm();
                (
                    wn / (2.0 * std::f64::consts::PI),
                    if wn > 0.0 { -s.re / wn } else { 1.0 },
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> Modal {
        Modal {
            blocks: vec![Block::Pair(0.9, 0.3), Block::Real(0.5)],
            b: DMatrix::from_row_slice(3, 2, &[1.0, 0.5, -0.2, 1.0, 0.3, 0.0]),
            c: DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 2.0, 0.0, 1.0, -1.0]),
            d: DMatrix::from_row_slice(2, 2, &[0.1, 0.0, 0.0, 0.2]),
        }
    }

    #[test]
    fn response_matches_dense_formula() {
        let m = example();
        let z = C64::from_polar(1.0, 0.7);
        let a = m.a().map(|v| C64::new(v, 0.0));
        let r = (DMatrix::<C64>::identity(3, 3) * z - a)
            .try_inverse()
            .unwrap();
        let g = m.c.map(|v| C64::new(v, 0.0)) * r * m.b.map(|v| C64::new(v, 0.0))
            + m.d.map(|v| C64::new(v, 0.0));
        assert!((g - m.response(z)).norm() < 1e-12);
    }

    #[test]
    fn simulation_matches_response_in_steady_state() {
        let m = example();
        let n = 64;
        let k = 5;
        let w = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
        let u: Vec<Vec<f64>> = vec![
            (0..20 * n).map(|i| (w * i as f64).cos()).collect(),
            vec![0.0; 20 * n],
        ];
        let y = m.simulate(&u).unwrap();
        let g = m.response(C64::from_polar(1.0, w));
        let i = 20 * n - 3;
        let want = (g[(1, 0)] * C64::from_polar(1.0, w * i as f64)).re;
        assert!((y[1][i] - want).abs() < 1e-9, "{} vs {want}", y[1][i]);
    }

    #[test]
    fn dense_to_modal_keeps_the_response_and_reflects_unstable_poles() {
        let m = example();
        // A similarity transform hides the modal structure.
        let t = DMatrix::from_row_slice(3, 3, &[1.0, 0.2, 0.1, -0.3, 1.0, 0.4, 0.5, 0.0, 1.0]);
        let ti = t.clone().try_inverse().unwrap();
        let a = &ti * m.a() * &t;
        let back = Modal::from_dense(&a, &(&ti * &m.b), &(&m.c * &t), &m.d).unwrap();
        let z = C64::from_polar(1.0, 1.1);
        assert!((back.response(z) - m.response(z)).norm() < 1e-9);
        let unstable = DMatrix::from_row_slice(1, 1, &[1.25]);
        let one = DMatrix::from_element(1, 1, 1.0);
        let r = Modal::from_dense(&unstable, &one, &one, &one).unwrap();
        assert_eq!(r.blocks, vec![Block::Real(0.8)]);
    }

    #[test]
    fn json_round_trip_and_shape_errors() {
        let m = example();
        let j = m.to_json();
        assert_eq!(Modal::from_json(&j).unwrap(), m);
        let mut bad = j.clone();
        bad.c[0].pop();
        assert!(Modal::from_json(&bad)
            .unwrap_err()
            .to_string()
            .contains("`c`"));
    }
}
