//! Nelder-Mead on the few nonlinear coordinates (the linear ones are solved exactly).

/// Minimises `f` from `x0` with initial steps `steps`; at most `max_evals` evaluations.
/// Returns the best point and its value. Non-finite values count as worse than any finite.
pub fn nelder_mead(
    f: &mut dyn FnMut(&[f64]) -> f64,
    x0: &[f64],
    steps: &[f64],
    max_evals: usize,
    rel_tol: f64,
) -> (Vec<f64>, f64) {
    let n = x0.len();
    let mut eval = |x: &[f64]| {
        let v = f(x);
        if v.is_finite() {
            v
        } else {
            f64::INFINITY
        }
    };
    let mut pts: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
    let f0 = eval(x0);
    pts.push((x0.to_vec(), f0));
    for k in 0..n {
        let mut x = x0.to_vec();
        x[k] += steps.get(k).copied().unwrap_or(0.1);
        let v = eval(&x);
        pts.push((x, v));
    }
    let mut evals = n + 1;
    while evals < max_evals {
        pts.sort_by(|a, b| a.1.total_cmp(&b.1));
        let best = pts[0].1;
        let worst = pts[n].1;
        if worst.is_finite() && (worst - best).abs() <= rel_tol * best.abs().max(1e-300) {
            break;
        }
        let centroid: Vec<f64> = (0..n)
            .map(|k| pts[..n].iter().map(|p| p.0[k]).sum::<f64>() / n as f64)
            .collect();
        let along = |t: f64| -> Vec<f64> {
            centroid
                .iter()
                .zip(&pts[n].0)
                .map(|(c, w)| c + t * (w - c))
                .collect()
        };
        let xr = along(-1.0);
        let fr = eval(&xr);
        evals += 1;
        if fr < pts[0].1 {
            let xe = along(-2.0);
            let fe = eval(&xe);
            evals += 1;
            pts[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < pts[n - 1].1 {
            pts[n] = (xr, fr);
        } else {
            let (xc, fc) = if fr < pts[n].1 {
                let x = along(-0.5);
                let v = eval(&x);
                (x, v)
            } else {
                let x = along(0.5);
                let v = eval(&x);
                (x, v)
            };
            evals += 1;
            if fc < pts[n].1.min(fr) {
                pts[n] = (xc, fc);
            } else {
                // Shrink towards the best point.
                let b = pts[0].0.clone();
                for p in pts.iter_mut().skip(1) {
                    for (x, bx) in p.0.iter_mut().zip(&b) {
                        *x = bx + 0.5 * (*x - bx);
                    }
                    p.1 = eval(&p.0);
                }
                evals += n;
            }
        }
    }
    pts.sort_by(|a, b| a.1.total_cmp(&b.1));
    pts.swap_remove(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_rosenbrock_minimum() {
        let mut f = |x: &[f64]| (1.0 - x[0]).powi(2) + 100.0 * (x[1] - x[0] * x[0]).powi(2);
        let (x, v) = nelder_mead(&mut f, &[-1.2, 1.0], &[0.5, 0.5], 2000, 1e-14);
        assert!(v < 1e-8, "{v} at {x:?}");
    }

    #[test]
    fn survives_nan_and_bounded_evals() {
        let mut count = 0;
        let mut f = |x: &[f64]| {
            count += 1;
            if x[0] > 0.5 {
                f64::NAN
            } else {
                x[0] * x[0]
            }
        };
        let (x, _) = nelder_mead(&mut f, &[0.4], &[1.0], 30, 0.0);
        assert!(x[0].abs() < 0.5);
        assert!(count <= 32);
    }
}
