//! Bounded root finding for the per-sample inversions (IMS algebraic loop, PPI).

use crate::real::Real;

/// Upper bound of function evaluations in one [`solve_increasing`] call.
pub const MAX_SOLVE_EVALS: usize = 24;

/// Result of one bounded solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Root<T> {
    /// Best argument found (finite whenever the inputs are).
    pub x: T,
    /// Function value there.
    pub fx: T,
    /// Function evaluations used (the known `f(x0)` not counted).
    pub evals: usize,
}

/// Root of a continuous, strictly increasing `f` whose slope is at least `min_slope > 0`,
/// given one point `x0` with its value `f0`.
///
/// The slope bound brackets the root exactly: it lies between `x0` and `x0 - f0/min_slope`.
/// Inside that bracket the Illinois variant of regula falsi runs (superlinear, never leaves
/// the bracket), stopping when `|f| <= tol` or the bracket is as narrow as the number type
/// allows, after at most [`MAX_SOLVE_EVALS`] evaluations. No panics, no unbounded loops;
/// a non-finite `f` value counts as "too far" and halves the step.
pub fn solve_increasing<T: Real>(
    f: impl FnMut(T) -> T,
    x0: T,
    f0: T,
    min_slope: T,
    tol: T,
) -> Root<T> {
    solve_increasing_hinted(f, x0, f0, min_slope, min_slope, tol)
}

/// As [`solve_increasing`], with a guess `slope_hint` of the typical slope (e.g. the last
/// sample's): the first trial `x0 - f0/slope_hint` usually brackets the root tightly; when
/// it falls short, the guaranteed far end `x0 - f0/min_slope` closes the bracket.
pub fn solve_increasing_hinted<T: Real>(
    mut f: impl FnMut(T) -> T,
    x0: T,
    f0: T,
    min_slope: T,
    slope_hint: T,
    tol: T,
) -> Root<T> {
    let mut best = Root {
        x: x0,
        fx: f0,
        evals: 0,
    };
    if !(f0.abs() > tol) || !(min_slope > T::ZERO) {
        return best; // also NaN f0: keep x0
    }
    let mut x0 = x0;
    let mut f0 = f0;
    // Trial point from the hint, inside the guaranteed bracket.
    if slope_hint > min_slope && slope_hint.is_finite() {
        let xt = x0 - f0 / slope_hint;
        if xt.is_finite() {
            let ft = f(xt);
            best.evals += 1;
            if ft.is_finite() {
                if ft.abs() < best.fx.abs() {
                    best.x = xt;
                    best.fx = ft;
                }
                if !(ft.abs() > tol) {
                    return best;
                }
                if ft.sgn() != f0.sgn() {
                    // Root between x0 and xt: Illinois on that bracket.
                    return illinois(&mut f, x0, f0, xt, ft, tol, best);
                }
                // Short of the root: continue from the trial point.
                x0 = xt;
                f0 = ft;
            }
        }
    }
    // Far end of the bracket; guarded so a non-finite value never comes out.
    let mut x1 = x0 - f0 / min_slope;
    if !x1.is_finite() {
        return best;
    }
    let mut f1 = f(x1);
    best.evals += 1;
    // A non-finite or wrong-signed far end (slope bound violated numerically): pull it in.
    while !(f1.is_finite() && f1.sgn() != f0.sgn()) && best.evals < MAX_SOLVE_EVALS {
        if f1.is_finite() && f1.abs() < best.fx.abs() {
            best.x = x1;
            best.fx = f1;
        }
        if f1.is_finite() {
            // Root lies beyond x1: the bound was wrong; step further out.
            x1 = x1 + (x1 - x0);
        } else {
            x1 = x0 + (x1 - x0) * T::HALF;
        }
        f1 = f(x1);
        best.evals += 1;
    }
    if !(f1.is_finite() && f1.sgn() != f0.sgn()) {
        return best;
    }
    if f1.abs() < best.fx.abs() {
        best.x = x1;
        best.fx = f1;
    }
    if f1 == T::ZERO {
        return best;
    }
    illinois(&mut f, x0, f0, x1, f1, tol, best)
}

/// Illinois regula falsi on a bracket `(a, fa)`, `(b, fb)` of opposite signs.
fn illinois<T: Real>(
    f: &mut impl FnMut(T) -> T,
    a: T,
    fa: T,
    b: T,
    fb: T,
    tol: T,
    mut best: Root<T>,
) -> Root<T> {
    let (mut a, mut fa, mut b, mut fb) = (a, fa, b, fb);
    let mut side = 0i8;
    while best.evals < MAX_SOLVE_EVALS {
        let mut x = (a * fb - b * fa) / (fb - fa);
        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
        if !(x > lo && x < hi) {
            x = (a + b) * T::HALF; // also NaN
            if !(x > lo && x < hi) {
                break; // bracket is two adjacent numbers
            }
        }
        if !(hi - lo > T::from_f64(4.0) * T::EPSILON * (lo.abs().max(hi.abs()) + T::ONE)) {
            break; // as narrow as the number type resolves
        }
        let fx = f(x);
        best.evals += 1;
        if !fx.is_finite() {
            break;
        }
        if fx.abs() < best.fx.abs() {
            best.x = x;
            best.fx = fx;
        }
        if !(fx.abs() > tol) {
            break;
        }
        if fx.sgn() == fb.sgn() {
            b = x;
            fb = fx;
            if side == -1 {
                fa *= T::HALF;
            }
            side = -1;
        } else {
            a = x;
            fa = fx;
            if side == 1 {
                fb *= T::HALF;
            }
            side = 1;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_root_of_kinked_increasing_function() {
        // Slope 1 below 2, slope 5 above.
        let f = |x: f64| {
            if x < 2.0 {
                x - 3.0
            } else {
                -1.0 + 5.0 * (x - 2.0)
            }
        };
        let r = solve_increasing(f, 0.0, f(0.0), 1.0, 1e-12);
        assert!((r.x - 2.2).abs() < 1e-10, "{r:?}");
        assert!(r.evals <= 12, "{r:?}");
    }

    #[test]
    fn decreasing_side_and_exact_start() {
        let f = |x: f64| 2.0 * x + 0.1 * x.sin();
        let r = solve_increasing(f, 5.0, f(5.0), 1.9, 1e-12);
        assert!(r.x.abs() < 1e-10, "{r:?}");
        let r = solve_increasing(f, 0.0, 0.0, 1.9, 1e-12);
        assert_eq!((r.x, r.evals), (0.0, 0));
    }

    #[test]
    fn wrong_slope_bound_still_terminates_finite() {
        // Claimed slope 10 but true slope 1: the far end falls short; the solver steps out.
        let f = |x: f64| x - 100.0;
        let r = solve_increasing(f, 0.0, f(0.0), 10.0, 1e-9);
        assert!(r.x.is_finite() && r.evals <= MAX_SOLVE_EVALS);
        assert!((r.x - 100.0).abs() < 1e-6, "{r:?}");
        // NaN everywhere: keeps the start point.
        let r = solve_increasing(|_| f64::NAN, 1.0, -1.0, 1.0, 1e-9);
        assert_eq!(r.x, 1.0);
        let r = solve_increasing(|x: f64| x, 1.0, f64::NAN, 1.0, 1e-9);
        assert_eq!(r.x, 1.0);
    }
}
