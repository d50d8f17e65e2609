//! Output-error refinement of a modal state-space model (and of the parameters `theta` of
//! a static front end that makes its inputs, e.g. one hysteresis per actuator) by
//! Levenberg-Marquardt on the frequency-domain error of periodic steady state.
//!
//! Per line the records enter only through weighted sums (sufficient statistics):
//! `S_vv = sum_r V_r V_r^H`, `S_yv = sum_r Y_r V_r^H`, `s_yy = sum_r |Y_r|^2`, so the cost
//! `sum_k sum_r |Y_r - G(z_k) V_r|^2` (Parseval: the mean-square output error of one
//! period, summed over records and outputs) costs one `p x m` product per line. The
//! Jacobian of the model parameters is analytic; that of `theta` by forward differences
//! of the statistics (`S_dv,v`, `S_y,dv`, `S_dv,dv`).

use super::frf::{psd_factor, FrfData};
use super::model::{Block, Modal, C64, MAX_POLE_RADIUS};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Statistics of one frequency line, already multiplied by the bin weight.
#[derive(Debug, Clone)]
pub struct LineStats {
    pub z: C64,
    pub svv: DMatrix<C64>,
    pub syv: DMatrix<C64>,
    pub syy: f64,
    /// Per `theta` parameter `b`: `sum_r dV_b V^H` (`m x m`).
    pub sdv_v: Vec<DMatrix<C64>>,
    /// Per `b`: `sum_r Y dV_b^H` (`p x m`).
    pub sy_dv: Vec<DMatrix<C64>>,
    /// Per `(a, b)`, row-major: `sum_r dV_b dV_a^H` (`m x m`).
    pub sdv_dv: Vec<DMatrix<C64>>,
}

impl LineStats {
    /// Statistics of a reduced (linear) problem: `|(g - G) f|_F^2` per line.
    pub fn from_frf(data: &FrfData) -> Vec<Self> {
        (0..data.bins.len())
            .map(|l| {
                let svv = &data.f[l] * data.f[l].adjoint();
                let syv = &data.g[l] * &svv;
                let syy = (&data.g[l] * &svv * data.g[l].adjoint()).trace().re;
                Self {
                    z: data.z(l),
                    svv,
                    syv,
                    syy,
                    sdv_v: Vec::new(),
                    sy_dv: Vec::new(),
                    sdv_dv: Vec::new(),
                }
            })
            .collect()
    }
}

/// Front-end statistics for a parameter vector: `stats(theta, with_derivatives)`.
pub type StatsFn<'a> = dyn Fn(&[f64], bool) -> anyhow::Result<Vec<LineStats>> + Sync + 'a;

/// Settings of the refinement.
#[derive(Debug, Clone)]
pub struct PemConfig {
    pub iterations: usize,
    /// Stop when an accepted step lowers the cost by less than this (relative).
    pub ftol: f64,
    pub progress: Option<String>,
}

impl Default for PemConfig {
    fn default() -> Self {
        Self {
            iterations: 50,
            ftol: 1e-9,
            progress: None,
        }
    }
}

/// Model parameters as a vector: block poles, then `B`, `C`, `D` row-major.
pub fn pack(m: &Modal) -> Vec<f64> {
    let mut v = Vec::new();
    for b in &m.blocks {
        match *b {
            Block::Real(l) => v.push(l),
            Block::Pair(s, w) => v.extend([s, w]),
        }
    }
    for mat in [&m.b, &m.c, &m.d] {
        for i in 0..mat.nrows() {
            v.extend(mat.row(i).iter());
        }
    }
    v
}

/// Inverse of [`pack`] with the block structure of `like`; poles pulled inside the
/// stability radius.
pub fn unpack(like: &Modal, v: &[f64]) -> Modal {
    let mut out = like.clone();
    let mut i = 0;
    for b in out.blocks.iter_mut() {
        match b {
            Block::Real(l) => {
                *l = v[i];
                i += 1;
            }
            Block::Pair(s, w) => {
                *s = v[i];
                *w = v[i + 1].abs().max(1e-9);
                i += 2;
            }
        }
        b.clamp_radius(MAX_POLE_RADIUS);
    }
    for mat in [&mut out.b, &mut out.c, &mut out.d] {
        for r in 0..mat.nrows() {
            for c in 0..mat.ncols() {
                mat[(r, c)] = v[i];
                i += 1;
            }
        }
    }
    out
}

/// Cost `sum_k [s_yy - 2 Re tr(G S_yv^H) + Re tr(G S_vv G^H)]`.
pub fn cost(model: &Modal, stats: &[LineStats]) -> f64 {
    stats
        .par_iter()
        .map(|s| {
            let g = model.response(s.z);
            let cross: f64 = g
                .iter()
                .zip(s.syv.iter())
                .map(|(a, b)| (a * b.conj()).re)
                .sum();
            let quad = (&g * &s.svv * g.adjoint()).trace().re;
            s.syy - 2.0 * cross + quad
        })
        .sum::<f64>()
        .max(0.0)
}

/// `dG/dparam` at `z` for every model parameter, as rows `vec(dG)` (row-major `p x m`).
fn model_jacobian(model: &Modal, z: C64) -> DMatrix<C64> {
    let (m, p, n) = (model.inputs(), model.outputs(), model.order());
    let n_pole_params: usize =
        model.blocks.len() + model.blocks.iter().filter(|b| b.states() == 2).count();
    let rows = n_pole_params + n * m + p * n + p * m;
    let mut jac = DMatrix::<C64>::zeros(rows, p * m);
    let res = model.resolvents(z);
    // RB (n x m) and CR (p x n), block by block.
    let mut rb = DMatrix::<C64>::zeros(n, m);
    let mut cr = DMatrix::<C64>::zeros(p, n);
    let (mut i, mut r, mut row) = (0, 0, 0);
    for blk in &model.blocks {
        let ns = blk.states();
        let rr = |a: usize, b: usize| res[r + a * ns + b];
        for a in 0..ns {
            for j in 0..m {
                rb[(i + a, j)] = (0..ns).map(|b| rr(a, b) * model.b[(i + b, j)]).sum();
            }
            for o in 0..p {
                cr[(o, i + a)] = (0..ns).map(|b| rr(b, a) * model.c[(o, i + b)]).sum();
            }
        }
        // Pole derivatives: C_i R dA R B_i.
        match blk {
            Block::Real(_) => {
                for o in 0..p {
                    for j in 0..m {
                        jac[(row, o * m + j)] = cr[(o, i)] * rb[(i, j)];
                    }
                }
                row += 1;
            }
            Block::Pair(..) => {
                // dA/dsigma = I, dA/domega = [[0, 1], [-1, 0]].
                for o in 0..p {
                    for j in 0..m {
                        let (c0, c1) = (cr[(o, i)], cr[(o, i + 1)]);
                        let (b0, b1) = (rb[(i, j)], rb[(i + 1, j)]);
                        jac[(row, o * m + j)] = c0 * b0 + c1 * b1;
                        jac[(row + 1, o * m + j)] = c0 * b1 - c1 * b0;
                    }
                }
                row += 2;
            }
        }
        r += ns * ns;
        i += ns;
    }
    // B[s, j]: CR[:, s] e_j^T.
    for s in 0..n {
        for j in 0..m {
            for o in 0..p {
                jac[(row, o * m + j)] = cr[(o, s)];
            }
            row += 1;
        }
    }
    // C[o, s]: e_o RB[s, :].
    for o in 0..p {
        for s in 0..n {
            for j in 0..m {
                jac[(row, o * m + j)] = rb[(s, j)];
            }
            row += 1;
        }
    }
    // D[o, j].
    for o in 0..p {
        for j in 0..m {
            jac[(row, o * m + j)] = C64::new(1.0, 0.0);
            row += 1;
        }
    }
    jac
}

/// Re of the row-wise conjugate product `conj(a) . vec(b)` (both row-major `p x m`).
fn re_dot(jac: &DMatrix<C64>, row: usize, b: &DMatrix<C64>) -> f64 {
    let (p, m) = b.shape();
    let mut s = 0.0;
    for o in 0..p {
        for j in 0..m {
            s += (jac[(row, o * m + j)].conj() * b[(o, j)]).re;
        }
    }
    s
}

/// Gauss-Newton normal equations `(J^T J, J^T e)` of all parameters at `(model, theta)`.
pub fn normal_equations(
    model: &Modal,
    stats: &[LineStats],
    n_theta: usize,
) -> (DMatrix<f64>, DVector<f64>) {
    let n_model = pack(model).len();
    let np = n_theta + n_model;
    let chunk = stats
        .len()
        .div_ceil(rayon::current_num_threads().max(1) * 4)
        .max(1);
    stats
        .par_chunks(chunk)
        .map(|lines| {
            let mut h = DMatrix::<f64>::zeros(np, np);
            let mut g = DVector::<f64>::zeros(np);
            for s in lines {
                let gm = model.response(s.z);
                let jac = model_jacobian(model, s.z);
                let (p, m) = gm.shape();
                let f = psd_factor(&s.svv);
                // Rows vec(dG_a F): H_GG += Re(X X^H).
                // Row-major vec: the columns of output o are jac[:, o m .. o m + m] F.
                let mut x = DMatrix::<C64>::zeros(n_model, p * m);
                for o in 0..p {
                    let cols = jac.columns(o * m, m) * &f;
                    x.columns_mut(o * m, m).copy_from(&cols);
                }
                let xr = x.map(|v| v.re);
                let xi = x.map(|v| v.im);
                let mut hgg = h.view_mut((n_theta, n_theta), (n_model, n_model));
                hgg.gemm(1.0, &xr, &xr.transpose(), 1.0);
                hgg.gemm(1.0, &xi, &xi.transpose(), 1.0);
                // e = Y - G V: J_a = -dG_a V, J^T e = -Re tr(dG_a^H (S_yv - G S_vv)).
                let e = &s.syv - &gm * &s.svv;
                for a in 0..n_model {
                    g[n_theta + a] -= re_dot(&jac, a, &e);
                }
                // Front-end parameters: J_b = -G dV_b.
                for b in 0..n_theta {
                    let sv_dv = s.sdv_v[b].adjoint(); // sum V dV_b^H
                    let eb = &s.sy_dv[b] - &gm * &sv_dv;
                    g[b] -= (gm.adjoint() * eb).trace().re;
                    let tb = &gm * &s.sdv_v[b];
                    for a in 0..n_model {
                        let v = re_dot(&jac, a, &tb);
                        h[(n_theta + a, b)] += v;
                        h[(b, n_theta + a)] += v;
                    }
                    for a in 0..=b {
                        let v = (&gm * &s.sdv_dv[a * n_theta + b] * gm.adjoint()).trace().re;
                        h[(a, b)] += v;
                        if a != b {
                            h[(b, a)] += v;
                        }
                    }
                }
            }
            (h, g)
        })
        .reduce(
            || (DMatrix::zeros(np, np), DVector::zeros(np)),
            |(h1, g1), (h2, g2)| (h1 + h2, g1 + g2),
        )
}

/// Result of a refinement.
#[derive(Debug, Clone)]
pub struct Refined {
    pub model: Modal,
    pub theta: Vec<f64>,
    pub cost: f64,
    pub iterations: usize,
}

/// The Levenberg-Marquardt step `(H + lambda diag(H))^-1 g` (each diagonal term at least
/// `1e-12 (1 + H_ii)` before scaling); `None` when the damped matrix is not positive
/// definite.
pub(crate) fn damped_step(h: &DMatrix<f64>, g: &DVector<f64>, lambda: f64) -> Option<DVector<f64>> {
    let mut damped = h.clone();
    for i in 0..damped.nrows() {
        let d = h[(i, i)];
        damped[(i, i)] = d + lambda * d.max(1e-12 * (1.0 + d));
    }
    Some(damped.cholesky()?.solve(g))
}

/// Levenberg-Marquardt on `(theta, model)`; `theta` is kept in `[lo, hi]`.
pub fn refine(
    model: &Modal,
    theta: &[f64],
    bounds: (&[f64], &[f64]),
    stats_fn: &StatsFn,
    cfg: &PemConfig,
) -> anyhow::Result<Refined> {
    let nt = theta.len();
    let (lo, hi) = bounds;
    anyhow::ensure!(
        lo.len() == nt && hi.len() == nt,
        "theta bounds do not match theta"
    );
    let mut th = theta.to_vec();
    let mut mdl = model.clone();
    let mut stats = stats_fn(&th, nt > 0)?;
    let mut c = cost(&mdl, &stats);
    anyhow::ensure!(c.is_finite(), "the start model's cost is not finite");
    let mut lambda = 1e-3;
    let mut it = 0;
    while it < cfg.iterations {
        it += 1;
        let (h, g) = normal_equations(&mdl, &stats, nt);
        if h.iter().chain(g.iter()).any(|v| !v.is_finite()) {
            break;
        }
        let z0: Vec<f64> = th.iter().copied().chain(pack(&mdl)).collect();
        let mut improved = None;
        for _ in 0..12 {
            let Some(dz) = damped_step(&h, &g, lambda) else {
                lambda *= 10.0;
                continue;
            };
            let zt: Vec<f64> = z0.iter().zip(dz.iter()).map(|(z, d)| z - d).collect();
            let tht: Vec<f64> = (0..nt).map(|i| zt[i].clamp(lo[i], hi[i])).collect();
            let mt = unpack(&mdl, &zt[nt..]);
            // A front-end parameter set the model refuses counts as a failed step.
            let st = if nt > 0 {
                match stats_fn(&tht, false) {
                    Ok(st) => st,
                    Err(_) => {
                        lambda *= 4.0;
                        continue;
                    }
                }
            } else {
                Vec::new()
            };
            let ct = cost(&mt, if nt > 0 { &st } else { &stats });
            if ct.is_finite() && ct < c {
                improved = Some((tht, mt, ct));
                lambda = (lambda / 3.0).max(1e-12);
                break;
            }
            lambda *= 4.0;
        }
        let Some((tht, mt, ct)) = improved else { break };
        let rel = (c - ct) / c.max(f64::MIN_POSITIVE);
        th = tht;
        mdl = mt;
        c = ct;
        if nt > 0 {
            stats = stats_fn(&th, true)?;
        }
        if let Some(l) = &cfg.progress {
            eprintln!("{l}: iteration {it}: cost {c:.6e} (lambda {lambda:.1e})");
        }
        if rel < cfg.ftol {
            break;
        }
    }
    Ok(Refined {
        model: mdl,
        theta: th,
        cost: c,
        iterations: it,
    })
}
