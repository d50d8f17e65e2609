//! Multivariable IMS with the Moore-Penrose pseudo-inverse (003 eq. 14-20).

use super::ims::ImsLoop;
use super::{ensure, FfError};
use crate::hysteresis::multi::{MultiBw, MultiBwState};
use crate::real::Real;

/// Upper bound of Newton iterations per sample of [`MultiIms`].
pub const MAX_MULTI_ITER: usize = 8;

/// Inverse of a square matrix by Gauss-Jordan elimination with partial pivoting; `None`
/// when a pivot falls below `tol` (numerically singular).
pub fn invert<T: Real, const M: usize>(a: &[[T; M]; M], tol: T) -> Option<[[T; M]; M]> {
    let mut a = *a;
    let mut inv = [[T::ZERO; M]; M];
    for (i, row) in inv.iter_mut().enumerate() {
        row[i] = T::ONE;
    }
    for col in 0..M {
        let (piv, magnitude) = crate::manipulation::linalg::pivot(&a, col);
        if !(magnitude > tol) {
            return None;
        }
        a.swap(col, piv);
        inv.swap(col, piv);
        let p = a[col][col];
        for c in 0..M {
            a[col][c] /= p;
            inv[col][c] /= p;
        }
        for r in 0..M {
            if r != col {
                let f = a[r][col];
                if f != T::ZERO {
                    for c in 0..M {
                        let (ac, ic) = (a[col][c], inv[col][c]);
                        a[r][c] -= f * ac;
                        inv[r][c] -= f * ic;
                    }
                }
            }
        }
    }
    Some(inv)
}

/// `A * B` for `R x S` times `S x C`.
pub fn matmul<T: Real, const R: usize, const S: usize, const C: usize>(
    a: &[[T; S]; R],
    b: &[[T; C]; S],
) -> [[T; C]; R] {
    let mut o = [[T::ZERO; C]; R];
    for (i, row) in o.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..S).fold(T::ZERO, |acc, k| acc + a[i][k] * b[k][j]);
        }
    }
    o
}

/// Transpose.
pub fn transpose<T: Real, const R: usize, const C: usize>(a: &[[T; C]; R]) -> [[T; R]; C] {
    let mut o = [[T::ZERO; R]; C];
    for (i, row) in a.iter().enumerate() {
        for (j, &x) in row.iter().enumerate() {
            o[j][i] = x;
        }
    }
    o
}

/// Moore-Penrose pseudo-inverse of a full-rank `N x K` matrix (003 eq. 18-19):
/// `D^-1` (square), `(D^T D)^-1 D^T` (`N > K`, under-actuated: least-squares error),
/// `D^T (D D^T)^-1` (`N < K`, over-actuated: least-norm input).
pub fn pseudo_inverse<T: Real, const N: usize, const K: usize>(
    d: &[[T; K]; N],
) -> Result<[[T; N]; K], FfError> {
    let scale = d.iter().flatten().fold(T::ZERO, |m, &x| m.max(x.abs()));
    ensure(
        scale.is_finite() && scale > T::ZERO,
        "multivariable IMS: D must be finite and non-zero",
    )?;
    let dt = transpose(d);
    let tol = T::from_f64(1e3) * T::EPSILON * scale * scale;
    let singular = "multivariable IMS: D must have full rank (003 eq. 18-19)";
    if N >= K {
        let g: [[T; K]; K] = matmul(&dt, d);
        let gi = invert(&g, tol).ok_or(crate::hysteresis::ParamError(singular))?;
        Ok(matmul(&gi, &dt))
    } else {
        let g: [[T; N]; N] = matmul(d, &dt);
        let gi = invert(&g, tol).ok_or(crate::hysteresis::ParamError(singular))?;
        Ok(matmul(&dt, &gi))
    }
}

/// Multivariable IMS `U = D^+ (y_ref + h(U))` (003 eq. 16-18) around a [`MultiBw`] with
/// `N` outputs and `K` inputs. With [`ImsLoop::Solved`] the algebraic loop is closed by a
/// bounded quasi-Newton iteration on `G(U) = U - D^+ (y_ref + h(U))` with Jacobian
/// `I - D^+ dh/dU` (the model's `jacobian` at the end state); [`ImsLoop::Delayed`] uses
/// `h` of the previous sample.
#[derive(Debug, Clone, PartialEq)]
pub struct MultiIms<T, const N: usize, const K: usize> {
    model: MultiBw<T, N, K>,
    d_pinv: [[T; N]; K],
    closure: ImsLoop,
    volts_min: T,
    volts_max: T,
    dt_s: T,
    /// Output offsets of the model (`y = offset_um + model(U)`, see [`MultiIms::with_offset`]).
    offset_um: [T; N],
    state: MultiBwState<T, N, K>,
    iters: usize,
}

impl<T: Real, const N: usize, const K: usize> MultiIms<T, N, K> {
    pub fn new(
        model: MultiBw<T, N, K>,
        closure: ImsLoop,
        volts_min: T,
        volts_max: T,
        dt_s: T,
    ) -> Result<Self, FfError> {
        super::check_range_dt(volts_min, volts_max, dt_s)?;
        let d_pinv = pseudo_inverse(model.d())?;
        let u0 = T::ZERO.clamp_to(volts_min, volts_max);
        Ok(Self {
            state: model.init([u0; K]),
            model,
            d_pinv,
            closure,
            volts_min,
            volts_max,
            dt_s,
            offset_um: [T::ZERO; N],
            iters: 0,
        })
    }

    /// The same IMS for a model `y = offset_um + model(U)` (`piezo fit` fits an output
    /// offset per output): the references are taken relative to it.
    pub fn with_offset(mut self, offset_um: [T; N]) -> Result<Self, FfError> {
        super::ensure(
            offset_um.iter().all(|o| o.is_finite()),
            "multivariable IMS: offset_um must be finite",
        )?;
        self.offset_um = offset_um;
        Ok(self)
    }

    /// The pseudo-inverse `D^+` computed at construction.
    pub fn d_pinv(&self) -> &[[T; N]; K] {
        &self.d_pinv
    }
    pub fn closure(&self) -> ImsLoop {
        self.closure
    }
    /// Newton iterations used by the last sample.
    pub fn last_iters(&self) -> usize {
        self.iters
    }

    /// `D^+ (y_ref + h)`.
    #[inline]
    fn ims(&self, y_ref: &[T; N], h: &[T; N]) -> [T; K] {
        let mut u = [T::ZERO; K];
        for (row, u) in self.d_pinv.iter().zip(u.iter_mut()) {
            *u = row
                .iter()
                .zip(y_ref.iter().zip(h.iter()))
                .fold(T::ZERO, |acc, (&p, (&y, &h))| acc + p * (y + h));
        }
        u
    }

    /// `h` after moving from the current state to `u`.
    #[inline]
    fn h_at(&self, u: &[T; K]) -> [T; N] {
        let mut h = self.state.h;
        let mut du = [T::ZERO; K];
        for ((d, &u), &u0) in du.iter_mut().zip(u.iter()).zip(self.state.u.iter()) {
            *d = u - u0;
        }
        self.model.advance_h(&mut h, &du);
        h
    }

    /// Voltages (V) for the references (um). Any non-finite reference holds the output.
    pub fn compensate(&mut self, y_ref: &[T; N]) -> [T; K] {
        let mut rel = *y_ref;
        for (r, &o) in rel.iter_mut().zip(self.offset_um.iter()) {
            *r -= o;
        }
        // Checked after the subtraction: an overflowing reference holds the output too.
        if !rel.iter().all(|y| y.is_finite()) {
            return self.state.u;
        }
        let y_ref = &rel;
        let mut u = self.ims(y_ref, &self.state.h);
        self.iters = 0;
        if self.closure == ImsLoop::Solved {
            for _ in 0..MAX_MULTI_ITER {
                let h = self.h_at(&u);
                let target = self.ims(y_ref, &h);
                // G(U) = U - D^+ (y_ref + h(U))
                let mut g = [T::ZERO; K];
                for ((g, &u), &t) in g.iter_mut().zip(u.iter()).zip(target.iter()) {
                    *g = u - t;
                }
                let mut s = [T::ZERO; K];
                for ((s, &u), &u0) in s.iter_mut().zip(u.iter()).zip(self.state.u.iter()) {
                    *s = (u - u0).sgn();
                }
                let jh = self.model.jacobian(&h, &s);
                let pj: [[T; K]; K] = matmul(&self.d_pinv, &jh);
                let mut jac = [[T::ZERO; K]; K];
                for (i, row) in jac.iter_mut().enumerate() {
                    for (j, x) in row.iter_mut().enumerate() {
                        *x = if i == j { T::ONE } else { T::ZERO } - pj[i][j];
                    }
                }
                self.iters += 1;
                // Newton step; fixed-point step if the Jacobian is singular.
                let step = match invert(&jac, T::from_f64(1e-9)) {
                    Some(ji) => {
                        let mut st = [T::ZERO; K];
                        for (st, row) in st.iter_mut().zip(ji.iter()) {
                            *st = row
                                .iter()
                                .zip(g.iter())
                                .fold(T::ZERO, |a, (&j, &g)| a + j * g);
                        }
                        st
                    }
                    None => g,
                };
                let mut size = T::ZERO;
                let mut scale = T::ONE;
                for (u, &st) in u.iter_mut().zip(step.iter()) {
                    *u -= st;
                    size = size.max(st.abs());
                    scale = scale.max(u.abs());
                }
                if !(size > T::from_f64(16.0) * T::EPSILON * scale) {
                    break;
                }
            }
        }
        for (x, &prev) in u.iter_mut().zip(self.state.u.iter()) {
            *x = if x.is_finite() {
                x.clamp_to(self.volts_min, self.volts_max)
            } else {
                prev
            };
        }
        self.model.step(&mut self.state, u, self.dt_s);
        self.state.u
    }

    /// The last voltages (V).
    pub fn volts(&self) -> [T; K] {
        self.state.u
    }

    /// Restart relaxed (`h = 0`) at the voltages `u0`.
    pub fn reset_volts(&mut self, u0: &[T; K]) {
        let mut u = *u0;
        for x in u.iter_mut() {
            *x = if x.is_finite() { *x } else { T::ZERO };
            *x = x.clamp_to(self.volts_min, self.volts_max);
        }
        self.state = self.model.init(u);
    }

    /// Restart relaxed at the voltages that give `y` with `h = 0`.
    pub fn reset(&mut self, y: &[T; N]) {
        let mut y0 = *y;
        for (v, &o) in y0.iter_mut().zip(self.offset_um.iter()) {
            *v -= o;
            if !v.is_finite() {
                *v = T::ZERO;
            }
        }
        let mut u = self.ims(&y0, &[T::ZERO; N]);
        for x in u.iter_mut() {
            *x = x.clamp_to(self.volts_min, self.volts_max);
        }
        self.state = self.model.init(u);
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // index form mirrors 003 eq. (20)
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-10 * (1.0 + a.abs().max(b.abs()))
    }

    fn penrose<const N: usize, const K: usize>(d: [[f64; K]; N]) {
        let p = pseudo_inverse(&d).unwrap();
        let dp: [[f64; N]; N] = matmul(&d, &p);
        let pd: [[f64; K]; K] = matmul(&p, &d);
        let dpd: [[f64; K]; N] = matmul(&dp, &d);
        let pdp: [[f64; N]; K] = matmul(&pd, &p);
        // 003 eq. (20)
        for i in 0..N {
            for j in 0..K {
                assert!(close(dpd[i][j], d[i][j]), "D D+ D = D");
                assert!(close(pdp[j][i], p[j][i]), "D+ D D+ = D+");
            }
            for j in 0..N {
                assert!(close(dp[i][j], dp[j][i]), "(D D+)^T = D D+");
            }
        }
        for i in 0..K {
            for j in 0..K {
                assert!(close(pd[i][j], pd[j][i]), "(D+ D)^T = D+ D");
            }
        }
    }

    #[test]
    fn pseudo_inverse_meets_penrose_conditions() {
        penrose([[0.16, 0.02, -0.01], [0.01, 0.15, 0.03], [0.0, -0.02, 0.05]]);
        penrose([[0.16, 0.02, -0.01], [0.01, 0.15, 0.03]]); // over-actuated
        penrose([[0.16, 0.02], [0.01, 0.15], [0.03, -0.04]]); // under-actuated
        let e = pseudo_inverse(&[[1.0, 2.0], [2.0, 4.0]]).unwrap_err();
        assert!(e.0.contains("full rank"), "{e}");
    }

    /// Max |y - y_ref|, max Newton iterations, max |D^T (y - y_ref)| (zero for a
    /// least-squares solution).
    fn run<const N: usize, const K: usize>(
        model: MultiBw<f64, N, K>,
        closure: ImsLoop,
    ) -> (f64, usize, f64) {
        let fs = 10_000.0;
        let mut ff = MultiIms::new(model, closure, -500.0, 500.0, 1.0 / fs).unwrap();
        let mut s = model.init([0.0; K]);
        let (mut max_err, mut max_it, mut max_orth) = (0.0f64, 0, 0.0f64);
        for k in 0..20_000 {
            let t = k as f64 / fs;
            let mut y_ref = [0.0; N];
            for (i, y) in y_ref.iter_mut().enumerate() {
                // Lissajous-like, from 0
                let f = 1.0 + 0.37 * i as f64;
                *y = 10.0 * (2.0 * core::f64::consts::PI * f * t).sin();
            }
            let u = ff.compensate(&y_ref);
            max_it = max_it.max(ff.last_iters());
            let y = model.step(&mut s, u, 1.0 / fs);
            for i in 0..N {
                max_err = max_err.max((y[i] - y_ref[i]).abs());
            }
            for j in 0..K {
                let o: f64 = (0..N).map(|i| model.d()[i][j] * (y[i] - y_ref[i])).sum();
                max_orth = max_orth.max(o.abs());
            }
        }
        (max_err, max_it, max_orth)
    }

    fn coupled_2x2() -> MultiBw<f64, 2, 2> {
        MultiBw::new(
            [[0.16, 0.02], [0.015, 0.15]],
            [[0.07, 0.01], [0.008, 0.06]],
            [[0.02, 0.005], [0.004, 0.02]],
            [[0.01, 0.002], [0.001, 0.01]],
        )
        .unwrap()
    }

    #[test]
    fn solved_multivariable_ims_tracks_exact_model() {
        let (solved, iters, _) = run(coupled_2x2(), ImsLoop::Solved);
        let (delayed, _, _) = run(coupled_2x2(), ImsLoop::Delayed);
        assert!(solved < 1e-9, "{solved}");
        assert!(iters <= MAX_MULTI_ITER);
        assert!(delayed > 100.0 * solved, "{delayed}");
    }

    #[test]
    fn offset_shifts_the_reference_and_an_overflow_holds() {
        let m = coupled_2x2();
        let mk = || MultiIms::new(m, ImsLoop::Solved, -500.0, 500.0, 1e-4).unwrap();
        let mut plain = mk();
        let mut shifted = mk().with_offset([3.0, -2.0]).unwrap();
        for k in 0..200 {
            let y = [0.0625 * k as f64, -0.03125 * k as f64]; // exact in f64 with the offsets
            let u = plain.compensate(&y);
            // The model with the offset gives `offset + y` for the same voltages.
            assert_eq!(shifted.compensate(&[y[0] + 3.0, y[1] - 2.0]), u);
        }
        let held = shifted.volts();
        assert_eq!(
            shifted.compensate(&[f64::MAX, 0.0]),
            held,
            "finite reference"
        );
        let mut neg = mk().with_offset([f64::MAX, 0.0]).unwrap();
        assert_eq!(neg.compensate(&[-f64::MAX, 0.0]), neg.volts(), "overflow");
        assert!(mk().with_offset([f64::NAN, 0.0]).is_err());
        // Reset relative to the offset: y = offset is the relaxed zero-voltage state.
        shifted.reset(&[3.0, -2.0]);
        assert_eq!(shifted.volts(), [0.0, 0.0]);
    }

    #[test]
    fn over_actuated_is_exact_under_actuated_is_bounded() {
        let over = MultiBw::new(
            [[0.16, 0.02, 0.05], [0.015, 0.15, -0.04]],
            [[0.07, 0.01, 0.0], [0.008, 0.06, 0.0]],
            [[0.02, 0.005, 0.0], [0.004, 0.02, 0.0]],
            [[0.01, 0.002, 0.0], [0.001, 0.01, 0.0]],
        )
        .unwrap();
        let (err, _, _) = run(over, ImsLoop::Solved);
        assert!(err < 1e-9, "{err}");
        let under = MultiBw::new(
            [[0.16, 0.02], [0.015, 0.15], [0.05, 0.05]],
            [[0.07, 0.01], [0.008, 0.06], [0.01, 0.01]],
            [[0.02, 0.005], [0.004, 0.02], [0.0, 0.0]],
            [[0.01, 0.002], [0.001, 0.01], [0.0, 0.0]],
        )
        .unwrap();
        // Three independent references, two inputs: not trackable; the error is the
        // least-squares one, orthogonal to the columns of D.
        let (err, _, orth) = run(under, ImsLoop::Solved);
        assert!(err > 1.0 && err.is_finite(), "{err}");
        assert!(orth < 1e-9, "{orth}");
    }
}
