//! The linear solve of every least-squares and Levenberg-Marquardt step on the host.
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
}
