//! Frequency-domain subspace identification (McKelvey, Akcay, Ljung, "Subspace-based
//! multivariable system identification from frequency response data", IEEE TAC 41(7),
//! 1996, algorithm 2): from `G(z_k)` at lines `z_k = exp(j w_k)` to `(A, C)` through the
//! extended observability range, then `(B, D)` by weighted linear least squares.

use super::frf::FrfData;
use super::model::{Modal, C64};
use crate::numeric::least_squares;
use nalgebra::{DMatrix, DVector};

/// At most this many lines enter the subspace step (evenly thinned); the least-squares
/// and prediction-error steps use all of them.
const MAX_LINES: usize = 1200;

/// Block rows of the Hankel-like data matrices for order `n` with `p` outputs.
fn block_rows(n: usize, p: usize) -> usize {
    (2 * n).div_ceil(p.max(1)).max(n.div_ceil(p.max(1)) + 2)
}

/// Subspace estimate of order `n`, in modal form (unstable poles reflected), with `B, D`
/// fitted by weighted least squares on all lines of `data`.
pub fn identify(data: &FrfData, n: usize) -> anyhow::Result<Modal> {
    let (m, p) = (data.inputs(), data.outputs());
    anyhow::ensure!(n >= 1, "model order must be at least 1");
    let q = block_rows(n, p);
    let stride = data.bins.len().div_ceil(MAX_LINES).max(1);
    let lines: Vec<usize> = (0..data.bins.len()).step_by(stride).collect();
    let mm = lines.len();
    anyhow::ensure!(
        2 * mm * m >= q * (m + p),
        "{mm} frequency lines are too few for order {n} (need at least {})",
        (q * (m + p)).div_ceil(2 * m)
    );
    // Transposed data matrices, real parts stacked over imaginary parts:
    // rows = 2 * lines * m, columns = [W (q m) | G (q p)].
    let rows = 2 * mm * m;
    let mut h = DMatrix::<f64>::zeros(rows, q * (m + p));
    let scale = 1.0 / (mm as f64).sqrt();
    for (li, &l) in lines.iter().enumerate() {
        let z = data.z(l);
        let g = &data.g[l];
        let mut zp = C64::new(scale, 0.0);
        for i in 0..q {
            for j in 0..m {
                let col = li * m + j;
                // W: identity block times z^i.
                h[(col, i * m + j)] = zp.re;
                h[(mm * m + col, i * m + j)] = zp.im;
                for o in 0..p {
                    let v = g[(o, j)] * zp;
                    h[(col, q * m + i * p + o)] = v.re;
                    h[(mm * m + col, q * m + i * p + o)] = v.im;
                }
            }
            zp *= z;
        }
    }
    let r = h.qr().r();
    // Lower-right block of R^T: the part of G orthogonal to the input rows.
    let r22 = r.view((q * m, q * m), (q * p, q * p)).transpose();
    let svd = r22.svd(true, false);
    let u = svd
        .u
        .ok_or_else(|| anyhow::anyhow!("subspace SVD failed"))?;
    // Singular values come sorted decreasing from nalgebra's SVD only after sorting.
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let obs = DMatrix::from_fn(q * p, n, |i, j| u[(i, order[j])]);
    let c = obs.rows(0, p).into_owned();
    let upper = obs.rows(0, (q - 1) * p).into_owned();
    let lower = obs.rows(p, (q - 1) * p).into_owned();
    let a = upper
        .svd(true, true)
        .solve(&lower, 1e-12)
        .map_err(|e| anyhow::anyhow!("subspace shift equation: {e}"))?;
    let b0 = DMatrix::zeros(n, m);
    let d0 = DMatrix::zeros(p, m);
    let mut model = Modal::from_dense(&a, &b0, &c, &d0)?;
    fit_bd(&mut model, data)?;
    Ok(model)
}

/// Solves `B, D` for fixed poles and `C` by weighted least squares:
/// minimises `sum_k |(g_k - C (z_k I - A)^-1 B - D) f_k|_F^2`.
pub fn fit_bd(model: &mut Modal, data: &FrfData) -> anyhow::Result<()> {
    let (m, p, n) = (model.inputs(), model.outputs(), model.order());
    let nu = n * m + p * m;
    let rows = 2 * p * m * data.bins.len();
    let mut a = DMatrix::<f64>::zeros(rows, nu);
    let mut rhs = DVector::<f64>::zeros(rows);
    let cc = model.c.map(|v| C64::new(v, 0.0));
    for (l, (g, f)) in data.g.iter().zip(&data.f).enumerate() {
        let z = data.z(l);
        // M = C (zI - A)^-1 (p x n), by blocks.
        let res = model.resolvents(z);
        let mut mk = DMatrix::<C64>::zeros(p, n);
        let (mut i, mut r) = (0, 0);
        for blk in &model.blocks {
            let ns = blk.states();
            for o in 0..p {
                for b in 0..ns {
                    mk[(o, i + b)] = (0..ns)
                        .map(|a2| cc[(o, i + a2)] * res[r + a2 * ns + b])
                        .sum();
                }
            }
            r += ns * ns;
            i += ns;
        }
        let target = g * f;
        let base = 2 * p * m * l;
        for o in 0..p {
            for c2 in 0..m {
                let row = base + 2 * (o * m + c2);
                rhs[row] = target[(o, c2)].re;
                rhs[row + 1] = target[(o, c2)].im;
                // d/dB[s, j] of (M B f)[o, c2] = M[o, s] f[j, c2]
                for s in 0..n {
                    for j in 0..m {
                        let v = mk[(o, s)] * f[(j, c2)];
                        a[(row, s * m + j)] = v.re;
                        a[(row + 1, s * m + j)] = v.im;
                    }
                }
                // d/dD[o, j] of (D f)[o, c2] = f[j, c2]
                for j in 0..m {
                    let v = f[(j, c2)];
                    a[(row, n * m + o * m + j)] = v.re;
                    a[(row + 1, n * m + o * m + j)] = v.im;
                }
            }
        }
    }
    let x = least_squares(a, rhs)?;
    model.b = DMatrix::from_fn(n, m, |s, j| x[s * m + j]);
    model.d = DMatrix::from_fn(p, m, |o, j| x[n * m + o * m + j]);
    Ok(())
}
