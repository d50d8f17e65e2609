//! Small fixed-size linear algebra for observer design (configuration time, not per sample).

use crate::real::Real;

/// `a * x` for an `N x N` matrix.
#[inline]
pub fn mat_vec<T: Real, const N: usize>(a: &[[T; N]; N], x: &[T; N]) -> [T; N] {
    let mut y = [T::ZERO; N];
    for (yi, row) in y.iter_mut().zip(a) {
        *yi = dot(row, x);
    }
    y
}

/// Inner product.
#[inline]
pub fn dot<T: Real, const N: usize>(a: &[T; N], b: &[T; N]) -> T {
    a.iter().zip(b).fold(T::ZERO, |s, (x, y)| s + *x * *y)
}

/// `a * b` for `N x N` matrices.
pub fn mat_mul<T: Real, const N: usize>(a: &[[T; N]; N], b: &[[T; N]; N]) -> [[T; N]; N] {
    let mut c = [[T::ZERO; N]; N];
    for (ci, ai) in c.iter_mut().zip(a) {
        for (k, aik) in ai.iter().enumerate() {
            if let Some(bk) = b.get(k) {
                for (cij, bkj) in ci.iter_mut().zip(bk) {
                    *cij += *aik * *bkj;
                }
            }
        }
    }
    c
}

/// The partial pivot of column `col`: the row at or below `col` with the largest
/// `|a[r][col]|` (the first of equals), and that magnitude.
pub fn pivot<T: Real, const N: usize>(a: &[[T; N]; N], col: usize) -> (usize, T) {
    let mut piv = col;
    for (r, row) in a.iter().enumerate().skip(col + 1) {
        if row[col].abs() > a[piv][col].abs() {
            piv = r;
        }
    }
    (piv, a[piv][col].abs())
}

/// Solves `a x = b` by Gaussian elimination with partial pivoting; `None` if `a` is singular
/// (a pivot below `1e-12` of the largest entry) or anything is not finite.
pub fn solve<T: Real, const N: usize>(mut a: [[T; N]; N], mut b: [T; N]) -> Option<[T; N]> {
    let scale = a
        .iter()
        .flat_map(|r| r.iter())
        .fold(T::ZERO, |m, v| m.max(v.abs()));
    if !(scale > T::ZERO) || !scale.is_finite() {
        return None;
    }
    let tiny = scale * T::from_f64(1e-12);
    for col in 0..N {
        let (piv, magnitude) = pivot(&a, col);
        if !(magnitude > tiny) {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        let p = a[col][col];
        for r in col + 1..N {
            let f = a[r][col] / p;
            if f != T::ZERO {
                let pivot_row = a[col];
                for (x, y) in a[r].iter_mut().zip(pivot_row.iter()).skip(col) {
                    *x -= f * *y;
                }
                let bc = b[col];
                b[r] -= f * bc;
            }
        }
    }
    let mut x = [T::ZERO; N];
    for i in (0..N).rev() {
        let mut s = b[i];
        for j in i + 1..N {
            s -= a[i][j] * x[j];
        }
        x[i] = s / a[i][i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Observer gain by Ackermann's formula: the eigenvalues of `a - l c` become the roots of
/// `s^N + p[0] s^(N-1) + ... + p[N-1]`. `None` if `(a, c)` is not observable.
///
/// The pair is balanced first (diagonal similarity `D^-1 a D`, Osborne's iteration) and time
/// scaled by its largest entry (`a / w`, roots `/ w`, gain `* w`), so plants with fast modes
/// keep the observability matrix well conditioned; the gain is mapped back (`l = D l_b`).
#[allow(clippy::needless_range_loop)] // row and column i of a square matrix at once
pub fn ackermann<T: Real, const N: usize>(
    a: &[[T; N]; N],
    c: &[T; N],
    p: &[T; N],
) -> Option<[T; N]> {
    let mut ab = *a;
    let mut d = [T::ONE; N];
    for _ in 0..20 {
        for i in 0..N {
            let (mut row, mut col) = (T::ZERO, T::ZERO);
            for j in 0..N {
                if j != i {
                    row += ab[i][j].abs();
                    col += ab[j][i].abs();
                }
            }
            if row > T::ZERO && col > T::ZERO && row.is_finite() && col.is_finite() {
                // x_i = f x_b,i: row i scales by 1/f, column i by f.
                let f = (row / col).sqrt();
                for j in 0..N {
                    ab[i][j] /= f;
                    ab[j][i] *= f;
                }
                d[i] *= f;
            }
        }
    }
    let mut cb = *c;
    for (ci, di) in cb.iter_mut().zip(&d) {
        *ci *= *di;
    }
    let lb = ackermann_scaled(&ab, &cb, p)?;
    let mut l = lb;
    for (li, di) in l.iter_mut().zip(&d) {
        *li *= *di;
    }
    l.iter().all(|x| x.is_finite()).then_some(l)
}

fn ackermann_scaled<T: Real, const N: usize>(
    a: &[[T; N]; N],
    c: &[T; N],
    p: &[T; N],
) -> Option<[T; N]> {
    let w = a
        .iter()
        .flat_map(|r| r.iter())
        .fold(T::ZERO, |m, v| m.max(v.abs()));
    let w = if w > T::ZERO && w.is_finite() {
        w
    } else {
        T::ONE
    };
    let mut a_s = *a;
    a_s.iter_mut()
        .flat_map(|r| r.iter_mut())
        .for_each(|v| *v /= w);
    let mut p_s = *p;
    let mut wk = T::ONE;
    for pk in p_s.iter_mut() {
        wk *= w;
        *pk /= wk;
    }
    let a = &a_s;
    // Observability matrix, rows c, c a, c a^2, ...
    let mut obs = [[T::ZERO; N]; N];
    let mut row = *c;
    for o in obs.iter_mut() {
        *o = row;
        // row <- row * a
        let mut next = [T::ZERO; N];
        for (j, nj) in next.iter_mut().enumerate() {
            *nj = row
                .iter()
                .zip(a.iter())
                .fold(T::ZERO, |s, (r, ak)| s + *r * ak[j]);
        }
        row = next;
    }
    let mut e_n = [T::ZERO; N];
    if let Some(last) = e_n.last_mut() {
        *last = T::ONE;
    }
    let q = solve(obs, e_n)?;
    // p(a) q by Horner: v <- a v + p_k q.
    let mut v = q;
    for pk in p_s.iter() {
        let mut av = mat_vec(a, &v);
        for (x, qi) in av.iter_mut().zip(q.iter()) {
            *x += *pk * *qi;
        }
        v = av;
    }
    v.iter_mut().for_each(|x| *x *= w);
    v.iter().all(|x| x.is_finite()).then_some(v)
}

/// Coefficients `p[0..N]` of `(s + w)^N` (without the leading 1).
pub fn repeated_pole<T: Real, const N: usize>(w: T) -> [T; N] {
    let mut p = [T::ZERO; N];
    let mut binom = T::ONE;
    let mut wk = T::ONE;
    for (k, pk) in p.iter_mut().enumerate() {
        // C(N, k+1)
        binom = binom * T::from_usize(N - k) / T::from_usize(k + 1);
        wk *= w;
        *pk = binom * wk;
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solve_recovers_known_vector() {
        let a = [[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]];
        let x = [1.0, -2.0, 0.5];
        let b = mat_vec(&a, &x);
        let got = solve(a, b).unwrap();
        for (g, w) in got.iter().zip(&x) {
            assert!((g - w).abs() < 1e-12);
        }
        assert!(solve([[1.0, 2.0], [2.0, 4.0]], [1.0, 1.0]).is_none());
    }

    #[test]
    fn ackermann_places_poles() {
        // Double integrator, poles at -3 (twice): char poly of a - l c is s^2 + 6 s + 9.
        let a = [[0.0, 1.0], [0.0, 0.0]];
        let c = [1.0, 0.0];
        let l = ackermann(&a, &c, &repeated_pole::<f64, 2>(3.0)).unwrap();
        assert!(
            (l[0] - 6.0).abs() < 1e-12 && (l[1] - 9.0).abs() < 1e-12,
            "{l:?}"
        );
        // Unobservable pair.
        assert!(ackermann(&a, &[0.0, 1.0], &[1.0, 1.0]).is_none());
    }

    #[test]
    fn ackermann_handles_fast_modes() {
        // Two modes at 100 Hz and 627 Hz, tip sensor: poles at -2000 (four times).
        let (w1, w2) = (628.3, 3940.0);
        let a = [
            [0.0, 1.0, 0.0, 0.0],
            [-w1 * w1, -0.04 * w1, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, -w2 * w2, -0.04 * w2],
        ];
        let c = [2.0, 0.0, -2.0, 0.0];
        let l = ackermann(&a, &c, &repeated_pole::<f64, 4>(2000.0)).unwrap();
        // Check: det(a - l c + 2000 I) = 0 (a root at -2000), via a singular solve.
        let mut m = a;
        for i in 0..4 {
            for j in 0..4 {
                m[i][j] -= l[i] * c[j];
            }
            m[i][i] += 2000.0;
        }
        // Power of the shifted matrix: nilpotent (all roots at -2000) -> m^4 ~ 0.
        let m2 = mat_mul(&m, &m);
        let m4 = mat_mul(&m2, &m2);
        let big = a.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
        let worst = m4.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
        assert!(worst < 1e-6 * big.powi(4), "{worst}");
    }

    #[test]
    fn repeated_pole_is_binomial() {
        let p = repeated_pole::<f64, 3>(2.0);
        assert_eq!(p, [6.0, 12.0, 8.0]);
    }

    #[test]
    fn mat_mul_identity() {
        let a = [[1.0, 2.0], [3.0, 4.0]];
        let i = [[1.0, 0.0], [0.0, 1.0]];
        assert_eq!(mat_mul(&a, &i), a);
    }
}
