//! The linear solves of the host: the SPD solve of every Levenberg-Marquardt and
//! normal-equations step, and least squares by SVD.
use nalgebra::{DMatrix, DVector};

/// Solves `A x = b` for symmetric positive definite `A` (row-major `n x n`) by Cholesky
/// (nalgebra). `None` when `A` is not positive definite (a pivot <= 0 or NaN) or the
/// solution is not finite, so callers can damp or regularise and retry.
pub fn solve_spd(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    if a.len() != n * n || b.len() != n {
        return None;
    }
    let chol = DMatrix::from_row_slice(n, n, a).cholesky()?;
    let x = chol.solve(&DVector::from_column_slice(b));
    x.iter()
        .all(|v| v.is_finite())
        .then(|| x.as_slice().to_vec())
}

/// Least squares `min |A x - rhs|` by column-scaled SVD (robust to rank deficiency).
pub fn least_squares(mut a: DMatrix<f64>, rhs: DVector<f64>) -> anyhow::Result<DVector<f64>> {
    let scale: Vec<f64> = a
        .column_iter()
        .map(|c| {
            let n = c.norm();
            if n > 0.0 {
                1.0 / n
            } else {
                1.0
            }
        })
        .collect();
    for (j, s) in scale.iter().enumerate() {
        a.column_mut(j).scale_mut(*s);
    }
    let x = a
        .svd(true, true)
        .solve(&rhs, 1e-12)
        .map_err(|e| anyhow::anyhow!("least squares: {e}"))?;
    anyhow::ensure!(
        x.iter().all(|v| v.is_finite()),
        "least squares: no finite solution"
    );
    Ok(DVector::from_fn(x.len(), |j, _| x[j] * scale[j]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_spd_and_refuses_indefinite() {
        // A = M^T M + I for a fixed M, x known.
        let a = [4.0, 1.0, 0.5, 1.0, 3.0, 0.25, 0.5, 0.25, 2.0];
        let x = [1.0, -2.0, 0.5];
        let b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| a[i * 3 + j] * x[j]).sum())
            .collect();
        let got = solve_spd(&a, &b, 3).unwrap();
        for (g, w) in got.iter().zip(x) {
            assert!((g - w).abs() < 1e-12, "{got:?}");
        }
        assert!(solve_spd(&[1.0, 2.0, 2.0, 1.0], &[1.0, 1.0], 2).is_none());
        assert!(solve_spd(&[f64::NAN], &[1.0], 1).is_none());
        assert!(solve_spd(&[0.0], &[1.0], 1).is_none());
        assert!(solve_spd(&[1.0], &[1.0, 2.0], 1).is_none());
    }

    #[test]
    fn least_squares_fits_and_survives_a_zero_column() {
        // y = 2 x0 - 0.5 x1 exactly; the third column is zero.
        let rows = 20;
        let a = DMatrix::from_fn(rows, 3, |i, j| match j {
            0 => i as f64,
            1 => (i as f64 * 0.7).sin() * 1e3,
            _ => 0.0,
        });
        let rhs = DVector::from_fn(rows, |i, _| 2.0 * a[(i, 0)] - 0.5 * a[(i, 1)]);
        let x = least_squares(a, rhs).unwrap();
        assert!(
            (x[0] - 2.0).abs() < 1e-9 && (x[1] + 0.5).abs() < 1e-9 && x[2] == 0.0,
            "{x}"
        );
    }
}
