//! Fit-time fast paths: the model simulations the searches evaluate thousands of times,
//! specialised to f64 with their per-evaluation constants hoisted out of the sample loop.
//!
//! Each kernel computes what the generic model step of `piezo_core::hysteresis` computes
//! (the tests compare them sample by sample); it only avoids the generic path's per-sample
//! overhead (parameter checks, `Real` dispatch to `libm`, the generic piece selection).

/// Classical Bouc-Wen with `n = 1` and unit `alpha` (000 eq. 1, `d = 0`): the hysteresis
/// variable `h` after every sample of `v`, from rest (`h = 0`) at the first sample.
///
/// Exactly the closed-form input-domain update of `Cbw::advance_h` (`dh/du = 1 - kappa*h` on
/// each piece of fixed `sgn(du)`, `sgn(h)`, with `kappa*|du| = (beta +- gamma)*|du|`), so
/// the result equals `-Cbw::with_n1(0, 1, beta, gamma).step(..)` to rounding. Parameters
/// that `Cbw` rejects (004 eq. 3) give zeros, as the caller's generic path did.
pub fn cbw_unit(v: &[f64], beta: f64, gamma: f64, out: &mut Vec<f64>) {
    out.clear();
    let valid = beta.is_finite()
        && gamma.is_finite()
        && beta + gamma > 0.0
        && beta - gamma >= 0.0
        && (0.1 / (beta + gamma.abs())).is_finite();
    if !valid {
        out.resize(v.len(), 0.0);
        return;
    }
    // Pass 1, no loop-carried dependency: the piece factors `q = |du| * phi(kappa*|du|)` of
    // both pieces (moving away from h = 0: kappa = beta + gamma; towards it: beta - gamma).
    let (k_away, k_toward) = (beta + gamma, beta - gamma);
    out.resize(v.len(), 0.0);
    SCRATCH.with_borrow_mut(|q| {
        q.clear();
        q.resize(v.len(), [0.0; 2]);
        let mut m_max = 0.0f64;
        for (w, qi) in v.windows(2).zip(q.iter_mut().skip(1)) {
            let m = (w[1] - w[0]).abs();
            m_max = m_max.max(m);
            *qi = [m * phi_series(k_away * m), m * phi_series(k_toward * m)];
        }
        // The series is exact to rounding for both pieces up to here; exp_m1 beyond.
        let k_max = k_away.max(k_toward);
        if k_max * m_max >= PHI_SERIES_MAX {
            for (w, qi) in v.windows(2).zip(q.iter_mut().skip(1)) {
                let m = (w[1] - w[0]).abs();
                if k_max * m >= PHI_SERIES_MAX {
                    *qi = [m * phi(k_away * m), m * phi(k_toward * m)];
                }
            }
        }
        // Pass 2, the recurrence `h = a*h + b` on the piece `h` is on (the branch changes only
        // at reversals and zero crossings, so it stays off the dependency chain).
        let mut h = 0.0f64;
        let mut prev = v.first().copied().unwrap_or(0.0);
        for ((&x, &[q_away, q_toward]), o) in v.iter().zip(q.iter()).zip(out.iter_mut()) {
            let du = x - prev;
            prev = x;
            let s = if du > 0.0 { 1.0 } else { -1.0 };
            // dh/du = s*(s - kappa*h) on a piece: h1 = (1 - kappa*q)*h + s*q; du = 0 gives q = 0.
            // At h = 0 the piece is the one h moves into (same sign as du).
            h = if h * s < 0.0 {
                let h1 = (1.0 - k_toward * q_toward) * h + s * q_toward;
                if h1 * s > 0.0 {
                    cross_zero(h, du, k_toward, k_away)
                } else {
                    h1
                }
            } else {
                (1.0 - k_away * q_away) * h + s * q_away
            };
            *o = h;
        }
    });
}

/// Below this argument [`phi_series`] is exact to rounding.
const PHI_SERIES_MAX: f64 = 0.1;

/// `(1 - exp(-x)) / x` by its Taylor series to `x^8` (error below `x^9/10!`, 3e-16 at
/// [`PHI_SERIES_MAX`]); branch-free so the sample loop vectorises.
#[inline(always)]
fn phi_series(x: f64) -> f64 {
    const C: [f64; 9] = [
        1.0,
        -1.0 / 2.0,
        1.0 / 6.0,
        -1.0 / 24.0,
        1.0 / 120.0,
        -1.0 / 720.0,
        1.0 / 5040.0,
        -1.0 / 40320.0,
        1.0 / 362880.0,
    ];
    let x2 = x * x;
    let x4 = x2 * x2;
    // Estrin's scheme: shorter dependency chains than Horner.
    let p01 = C[0] + C[1] * x;
    let p23 = C[2] + C[3] * x;
    let p45 = C[4] + C[5] * x;
    let p67 = C[6] + C[7] * x;
    let p03 = p01 + p23 * x2;
    let p47 = p45 + p67 * x2;
    p03 + (p47 + C[8] * x4) * x4
}

std::thread_local! {
    static SCRATCH: std::cell::RefCell<Vec<[f64; 2]>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// `(1 - exp(-x)) / x` for `x >= 0`.
#[inline]
fn phi(x: f64) -> f64 {
    if x < PHI_SERIES_MAX {
        phi_series(x)
    } else {
        -(-x).exp_m1() / x
    }
}

/// A sample whose update towards zero overshoots it: the input distance to `h = 0` on the
/// `k_toward` piece, then the rest from zero on the `k_away` piece.
#[cold]
fn cross_zero(h: f64, du: f64, k_toward: f64, k_away: f64) -> f64 {
    let (s, m, a) = (du.signum(), du.abs(), h.abs());
    let to_zero = if k_toward == 0.0 {
        a
    } else {
        (k_toward * a).ln_1p() / k_toward
    };
    // (also when to_zero is NaN)
    if to_zero.partial_cmp(&m) != Some(core::cmp::Ordering::Less) {
        return 0.0;
    }
    let r = m - to_zero;
    s * r * phi(k_away * r)
}

/// The state-transition recurrence of `model::dynamics` (a second-order system, input held
/// over each sample, at rest at each column's first sample) on every column in place: the
/// deviation `d = p - u` from the held input decays by `phi`. Columns of equal length run
/// four or two at a time, their independent recurrences interleaved (one column's chain is
/// latency-bound); each column's arithmetic is exactly the one-column loop's.
pub fn held_second_order(cols: &mut [&mut [f64]], phi: &[[f64; 2]; 2]) {
    let mut rest = cols;
    while !rest.is_empty() {
        let len = rest[0].len();
        let same = rest.iter().take_while(|c| c.len() == len).count();
        let take = if same >= 4 {
            4
        } else if same >= 2 {
            2
        } else {
            1
        };
        let (group, tail) = rest.split_at_mut(take);
        match group {
            [a, b, c, d] => held_group([&mut **a, &mut **b, &mut **c, &mut **d], phi),
            [a, b] => held_group([&mut **a, &mut **b], phi),
            [a] => held_group([&mut **a], phi),
            _ => unreachable!("groups of 4, 2 or 1"),
        }
        rest = tail;
    }
}

/// [`held_second_order`] on `N` columns of equal length.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // the sample index runs through all N columns
fn held_group<const N: usize>(cols: [&mut [f64]; N], phi: &[[f64; 2]; 2]) {
    let len = cols[0].len();
    if len == 0 {
        return;
    }
    let mut p = [0.0; N];
    let mut v = [0.0; N];
    for j in 0..N {
        p[j] = cols[j][0];
    }
    let [[a00, a01], [a10, a11]] = *phi;
    let cols = cols.map(|c| &mut c[..len]);
    for k in 0..len {
        for j in 0..N {
            let u = cols[j][k];
            let d = p[j] - u;
            p[j] = u + a00 * d + a01 * v[j];
            v[j] = a10 * d + a11 * v[j];
            cols[j][k] = p[j];
        }
    }
}

/// The normal equations' sums of the least squares `min |X b - y|` on columns `cols`: the
/// Gram matrix `X^T X` (row-major, `p x p`) and `X^T y`. Each sum is [`dot`]'s, to the bit;
/// a column's products with up to three others are summed in one pass over it (the
/// accumulators' add chains, not the loads, bound one sum at a time). The samples run in
/// blocks that stay in cache while every pair is summed over them, in AVX2 where the CPU has
/// it: 16 columns of 20 000 samples took 0.60 ms, 0.52 in blocks, 0.39 in blocks in AVX2.
pub fn gram(cols: &[&[f64]], y: &[f64]) -> (Vec<f64>, Vec<f64>) {
    with_avx2(
        #[inline(always)]
        || gram_blocks(cols, y),
    )
}

/// Runs `f` compiled for AVX2 where the CPU has it (four lanes per instruction instead of
/// two), else as built. No FMA: the same IEEE operations in the same order, so the same
/// bits. `f` and its kernels must be `#[inline(always)]` to be compiled for it.
#[inline(always)]
fn with_avx2<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2<R>(f: impl FnOnce() -> R) -> R {
            f()
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above), the only requirement of a
            // `target_feature` function.
            #[allow(unsafe_code)]
            return unsafe { avx2(f) };
        }
    }
    f()
}

#[inline(always)]
fn gram_blocks(cols: &[&[f64]], y: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let p = cols.len();
    let mut g = vec![0.0; p * p];
    let mut xty = vec![0.0; p];
    let n = y.len();
    let mut put = |r: usize, c: usize, v: f64| {
        if c == r + 1 {
            xty[r] = v;
        } else {
            g[r * p + c] = v;
            g[c * p + r] = v;
        }
    };
    if cols.iter().any(|c| c.len() != n) {
        for (r, &x) in cols.iter().enumerate() {
            for (c, q) in cols[..=r].iter().chain([&y]).enumerate() {
                put(r, c, dot(x, q));
            }
        }
        return (g, xty);
    }
    let body = n - n % 4;
    // dot's four accumulators of every (column, partner) pair, kept across the blocks: each
    // accumulator sums the same products in the same order as dot's.
    let pairs = p * (p + 3) / 2;
    let mut acc = vec![[[0.0f64; 2]; 2]; pairs];
    let mut partners: Vec<&[f64]> = Vec::with_capacity(p + 1);
    let mut start = 0;
    while start < body {
        let end = (start + GRAM_BLOCK).min(body);
        let mut k = 0;
        for (r, &x) in cols.iter().enumerate() {
            let x = &x[start..end];
            partners.clear();
            partners.extend(cols[..=r].iter().chain([&y]).map(|q| &q[start..end]));
            for group in partners.chunks(3) {
                let a = &mut acc[k..k + group.len()];
                match *group {
                    [q0, q1, q2] => dots_into(x, [q0, q1, q2], a),
                    [q0, q1] => dots_into(x, [q0, q1], a),
                    [q0] => dots_into(x, [q0], a),
                    _ => unreachable!("groups of 1 to 3"),
                }
                k += group.len();
            }
        }
        start = end;
    }
    let mut k = 0;
    for (r, &x) in cols.iter().enumerate() {
        for (c, q) in cols[..=r].iter().chain([&y]).enumerate() {
            let [lo, hi] = acc[k];
            let tail: f64 = x[body..].iter().zip(&q[body..]).map(|(a, b)| a * b).sum();
            put(r, c, lo[0] + lo[1] + hi[0] + hi[1] + tail);
            k += 1;
        }
    }
    (g, xty)
}

/// Samples per block of [`gram`]: 32 KiB a column.
const GRAM_BLOCK: usize = 4096;

/// `sum a_k b_k` with four accumulators (so the loop vectorises), over the shorter slice.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ac, ar) = a.split_at(a.len() - a.len() % 4);
    let (bc, br) = b.split_at(ac.len().min(b.len()));
    for (x, y) in ac.chunks_exact(4).zip(bc.chunks_exact(4)) {
        for k in 0..4 {
            acc[k] += x[k] * y[k];
        }
    }
    let tail: f64 = ar.iter().zip(br).map(|(x, y)| x * y).sum();
    acc[0] + acc[1] + acc[2] + acc[3] + tail
}

/// [`dot`]'s accumulators (as two pairs, one vector register each) of `x` with each of `ys`
/// (all as long as `x`, a multiple of 4), continued from `acc`, in one pass over `x`.
#[inline(always)]
fn dots_into<const N: usize>(x: &[f64], ys: [&[f64]; N], acc: &mut [[[f64; 2]; 2]]) {
    let mut lo: [[f64; 2]; N] = std::array::from_fn(|j| acc[j][0]);
    let mut hi: [[f64; 2]; N] = std::array::from_fn(|j| acc[j][1]);
    let mut heads = ys.map(|y| y.chunks_exact(4));
    for xs in x.chunks_exact(4) {
        for j in 0..N {
            let Some(ys) = heads[j].next() else { break };
            lo[j][0] += xs[0] * ys[0];
            lo[j][1] += xs[1] * ys[1];
            hi[j][0] += xs[2] * ys[2];
            hi[j][1] += xs[3] * ys[3];
        }
    }
    for j in 0..N {
        acc[j] = [lo[j], hi[j]];
    }
}

/// `crate::numeric::lowpass(x, tau, dt)` for each of `taus`, to the bit: the first-order
/// recurrences run four at a time, interleaved (one alone is latency-bound).
pub fn lowpass_many(x: &[f64], taus: &[f64], dt: f64) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = taus.iter().map(|_| vec![0.0; x.len()]).collect();
    let Some(&first) = x.first() else {
        return out;
    };
    // lowpass_n's coefficients for order 1: s = (1 - a)*x + a*s, a = exp(-dt/tau).
    let coef: Vec<[f64; 2]> = taus
        .iter()
        .map(|tau| {
            let a = (-(dt / tau)).exp();
            [1.0 - a, a]
        })
        .collect();
    for (cols, coef) in out.chunks_mut(4).zip(coef.chunks(4)) {
        match cols {
            [a, b, c, d] => lowpass_group([a, b, c, d], coef, x, first),
            [a, b] => lowpass_group([a, b], coef, x, first),
            [a, b, c] => {
                lowpass_group([a, b], &coef[..2], x, first);
                lowpass_group([c], &coef[2..], x, first);
            }
            [a] => lowpass_group([a], coef, x, first),
            _ => {}
        }
    }
    out
}

#[inline(always)]
fn lowpass_group<const N: usize>(
    cols: [&mut Vec<f64>; N],
    coef: &[[f64; 2]],
    x: &[f64],
    first: f64,
) {
    let mut s = [first; N];
    let k: [[f64; 2]; N] = std::array::from_fn(|j| coef[j]);
    let mut cols = cols.map(|c| c[..x.len()].iter_mut());
    for &v in x {
        for j in 0..N {
            let mut acc = k[j][0] * v;
            acc += k[j][1] * s[j];
            s[j] = acc;
            if let Some(o) = cols[j].next() {
                *o = acc;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use piezo_core::hysteresis::{Cbw, Hysteresis};

    fn reference(v: &[f64], beta: f64, gamma: f64) -> Vec<f64> {
        let Ok(m) = Cbw::with_n1(0.0, 1.0, beta, gamma) else {
            return vec![0.0; v.len()];
        };
        let mut s = m.init(v[0]);
        v.iter().map(|&x| -m.step(&mut s, x, 0.0)).collect()
    }

    #[test]
    fn cbw_unit_equals_the_core_model() {
        let mut out = Vec::new();
        // Smooth input with reversals, steps, a held input, and coarse decimation.
        for (n, step_v) in [(20_000, 0.0), (400, 0.0), (3000, 40.0)] {
            let v: Vec<f64> = (0..n)
                .map(|k| {
                    let t = k as f64 / n as f64;
                    let w = 60.0 * (12.0 * t).sin() + 25.0 * (41.0 * t).cos();
                    let hold = if (k / 97) % 5 == 0 { 0.0 } else { w };
                    hold + if k % 331 == 0 { step_v } else { 0.0 }
                })
                .collect();
            for (beta, gamma) in [
                (0.02, 0.01),
                (0.05, -0.04),
                (0.3, 0.3),
                (1e-4, 5e-5),
                (2.0, -1.5),
                (0.01, 0.02),
                (f64::NAN, 0.0),
            ] {
                cbw_unit(&v, beta, gamma, &mut out);
                let r = reference(&v, beta, gamma);
                let scale = r.iter().fold(1e-300f64, |m, x| m.max(x.abs()));
                for (k, (a, b)) in out.iter().zip(&r).enumerate() {
                    assert!(
                        (a - b).abs() <= 1e-11 * scale,
                        "n {n} beta {beta} gamma {gamma} sample {k}: {a} vs {b}"
                    );
                }
            }
        }
    }

    #[test]
    fn held_second_order_equals_one_column_at_a_time() {
        let phi = [[0.93, 8e-5], [-310.0, 0.71]];
        let one = |x: &mut [f64]| {
            let (mut p, mut v) = (x[0], 0.0);
            for u in x.iter_mut() {
                let d = p - *u;
                p = *u + phi[0][0] * d + phi[0][1] * v;
                v = phi[1][0] * d + phi[1][1] * v;
                *u = p;
            }
        };
        // Seven columns (a group of four, of two, then one), the last two of other lengths.
        let mut cols: Vec<Vec<f64>> = (0..7)
            .map(|j| {
                let n = if j < 5 { 1000 } else { 300 + j };
                (0..n)
                    .map(|k| ((k * (j + 3)) as f64 * 0.01).sin() + j as f64)
                    .collect()
            })
            .collect();
        let mut want = cols.clone();
        for c in want.iter_mut() {
            one(c);
        }
        let mut refs: Vec<&mut [f64]> = cols.iter_mut().map(Vec::as_mut_slice).collect();
        held_second_order(&mut refs, &phi);
        assert_eq!(cols, want);
    }

    #[test]
    fn gram_equals_dot_by_dot() {
        // (several of gram's blocks, and a tail)
        for n in [0, 1, 5, 4003, 9003] {
            let cols: Vec<Vec<f64>> = (0..7)
                .map(|j| {
                    (0..n)
                        .map(|k| ((k * (j + 2)) as f64 * 0.37).cos() * (j + 1) as f64)
                        .collect()
                })
                .collect();
            let y: Vec<f64> = (0..n).map(|k| (k as f64 * 0.11).sin()).collect();
            let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
            let (g, xty) = gram(&refs, &y);
            // (AVX2 where the machine has it; the kernel as built, too)
            assert_eq!(gram_blocks(&refs, &y), (g.clone(), xty.clone()));
            for r in 0..7 {
                for c in 0..7 {
                    assert_eq!(g[r * 7 + c].to_bits(), dot(&cols[r], &cols[c]).to_bits());
                }
                assert_eq!(xty[r].to_bits(), dot(&cols[r], &y).to_bits());
            }
        }
    }

    #[test]
    fn lowpass_many_equals_lowpass() {
        let x: Vec<f64> = (0..2001)
            .map(|k| ((k * 7) as f64 * 0.013).sin() * 40.0 + 60.0)
            .collect();
        for n in 0..=8 {
            let taus: Vec<f64> = (0..n).map(|j| 0.002 * 2f64.powi(j)).collect();
            let got = lowpass_many(&x, &taus, 1e-4);
            for (g, tau) in got.iter().zip(&taus) {
                assert_eq!(g, &crate::numeric::lowpass(&x, *tau, 1e-4));
            }
        }
        assert!(lowpass_many(&[], &[0.1], 1e-3)[0].is_empty());
    }
}
