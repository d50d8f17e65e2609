//! Construction-time dense linear algebra of the linear dynamics (f64, fixed-size arrays,
//! no allocation): Gauss solves, the matrix exponential of the ZOH design and the bilinear
//! transform. Written here rather than taken from a crate because the core is `no_std`
//! without an allocator and runs these on the target when parameters arrive over serial.

// Dense index loops read clearer here.
#![allow(clippy::needless_range_loop)]

use super::MAX_SECTIONS;

/// Largest design matrix: two states per section plus the input (ZOH augmentation).
pub(crate) const NMAX: usize = 2 * MAX_SECTIONS + 1;
pub(crate) type Mat = [[f64; NMAX]; NMAX];

/// Solves `m x = v` for the leading `n x n` block (Gauss, partial pivoting). `None` when
/// singular.
pub(crate) fn solve(m: &Mat, v: &[f64; NMAX], n: usize) -> Option<[f64; NMAX]> {
    gauss(*m, *v, n, 1e-300)
}

/// Solves `m x = v` for the leading `n x n` block of any fixed size (Gauss, partial
/// pivoting). `None` when a pivot is not above `tiny` in magnitude.
pub(crate) fn gauss<const N: usize>(
    mut m: [[f64; N]; N],
    mut v: [f64; N],
    n: usize,
    tiny: f64,
) -> Option<[f64; N]> {
    for k in 0..n {
        let p = (k..n).max_by(|&i, &j| libm::fabs(m[i][k]).total_cmp(&libm::fabs(m[j][k])))?;
        if !(libm::fabs(m[p][k]) > tiny) {
            return None;
        }
        m.swap(k, p);
        v.swap(k, p);
        for i in k + 1..n {
            let f = m[i][k] / m[k][k];
            for j in k..n {
                m[i][j] -= f * m[k][j];
            }
            v[i] -= f * v[k];
        }
    }
    let mut x = [0.0; N];
    for k in (0..n).rev() {
        let s: f64 = (k + 1..n).map(|j| m[k][j] * x[j]).sum();
        x[k] = (v[k] - s) / m[k][k];
    }
    Some(x)
}

/// Complex Gauss elimination: `(m[0] + j m[1]) x = g` (real `g`), leading `n x n` block.
pub(crate) fn csolve(m: &[Mat; 2], g: &[f64; NMAX], n: usize) -> [[f64; NMAX]; 2] {
    let (mut a, mut b) = (m[0], m[1]);
    let (mut vr, mut vi) = (*g, [0.0; NMAX]);
    for k in 0..n {
        let p = (k..n)
            .max_by(|&i, &j| {
                libm::hypot(a[i][k], b[i][k]).total_cmp(&libm::hypot(a[j][k], b[j][k]))
            })
            .unwrap_or(k);
        a.swap(k, p);
        b.swap(k, p);
        vr.swap(k, p);
        vi.swap(k, p);
        let den = a[k][k] * a[k][k] + b[k][k] * b[k][k];
        for i in k + 1..n {
            // f = m[i][k] / m[k][k]
            let fr = (a[i][k] * a[k][k] + b[i][k] * b[k][k]) / den;
            let fi = (b[i][k] * a[k][k] - a[i][k] * b[k][k]) / den;
            for j in k..n {
                let (pr, pi) = (a[k][j], b[k][j]);
                a[i][j] -= fr * pr - fi * pi;
                b[i][j] -= fr * pi + fi * pr;
            }
            let (pr, pi) = (vr[k], vi[k]);
            vr[i] -= fr * pr - fi * pi;
            vi[i] -= fr * pi + fi * pr;
        }
    }
    let (mut xr, mut xi) = ([0.0; NMAX], [0.0; NMAX]);
    for k in (0..n).rev() {
        let (mut sr, mut si) = (vr[k], vi[k]);
        for j in k + 1..n {
            sr -= a[k][j] * xr[j] - b[k][j] * xi[j];
            si -= a[k][j] * xi[j] + b[k][j] * xr[j];
        }
        let den = a[k][k] * a[k][k] + b[k][k] * b[k][k];
        xr[k] = (sr * a[k][k] + si * b[k][k]) / den;
        xi[k] = (si * a[k][k] - sr * b[k][k]) / den;
    }
    [xr, xi]
}

/// `e^M` of the leading `n x n` block by scaling and squaring with an 18-term Taylor
/// series (`||M/2^s||_inf <= 0.5`: truncation below 1e-20 relative).
pub(crate) fn expm(m: &Mat, n: usize) -> Mat {
    let norm = m[..n]
        .iter()
        .map(|r| r[..n].iter().map(|x| libm::fabs(*x)).sum::<f64>())
        .fold(0.0, f64::max);
    let mut s = 0u32;
    let mut scale = 1.0;
    while norm * scale > 0.5 && s < 64 {
        scale *= 0.5;
        s += 1;
    }
    let mul = |x: &Mat, y: &Mat| {
        let mut z = [[0.0; NMAX]; NMAX];
        for i in 0..n {
            for k in 0..n {
                let xik = x[i][k];
                if xik != 0.0 {
                    for j in 0..n {
                        z[i][j] += xik * y[k][j];
                    }
                }
            }
        }
        z
    };
    let mut a = [[0.0; NMAX]; NMAX];
    let mut sum = [[0.0; NMAX]; NMAX];
    for i in 0..n {
        for j in 0..n {
            a[i][j] = m[i][j] * scale;
        }
        sum[i][i] = 1.0;
    }
    let mut term = sum;
    for k in 1..=18 {
        term = mul(&term, &a);
        for (i, row) in term.iter_mut().enumerate().take(n) {
            for (j, x) in row.iter_mut().enumerate().take(n) {
                *x /= k as f64;
                sum[i][j] += *x;
            }
        }
    }
    for _ in 0..s {
        sum = mul(&sum, &sum);
    }
    sum
}

/// Bilinear transform with step `h` (prewarped): with `W = (I - A h/2)^-1`,
/// `Phi = W (I + A h/2)`, `Gamma = W B h`, `C_d = C W`, `D_d = D + C W B h/2`.
pub(crate) fn tustin(
    a: &[[f64; 2]; 2],
    b: &[f64; 2],
    c: &[f64; 2],
    d: f64,
    h: f64,
) -> ([[f64; 2]; 2], [f64; 2], [f64; 2], f64) {
    let q = h / 2.0;
    let m = [
        [1.0 - a[0][0] * q, -a[0][1] * q],
        [-a[1][0] * q, 1.0 - a[1][1] * q],
    ];
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let w = [
        [m[1][1] / det, -m[0][1] / det],
        [-m[1][0] / det, m[0][0] / det],
    ];
    let p = [
        [1.0 + a[0][0] * q, a[0][1] * q],
        [a[1][0] * q, 1.0 + a[1][1] * q],
    ];
    let mut phi = [[0.0; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            phi[i][j] = w[i][0] * p[0][j] + w[i][1] * p[1][j];
        }
    }
    let wb = [
        w[0][0] * b[0] + w[0][1] * b[1],
        w[1][0] * b[0] + w[1][1] * b[1],
    ];
    let gamma = [wb[0] * h, wb[1] * h];
    let cd = [
        c[0] * w[0][0] + c[1] * w[1][0],
        c[0] * w[0][1] + c[1] * w[1][1],
    ];
    let dd = d + (c[0] * wb[0] + c[1] * wb[1]) * q;
    (phi, gamma, cd, dd)
}
