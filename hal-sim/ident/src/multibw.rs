//! Multivariable Bouc-Wen identification in the two steps of 003 sec. IV, giving the
//! matrices `D, A, B, Gamma` of 003 eq. (4)-(7) for the core's [`MultiBw`] and
//! [`MultiIms`].
//!
//! * Step 1 (003 sec. IV.B, eq. 9-10): each direct transfer `u_j -> y_j` is a CBW with
//!   `n = 1` (`D_jj, A_jj, B_jj, Gamma_jj`), fitted by the global search and LM of
//!   [`fit_siso`].
//! * Step 2 (003 sec. IV.C, eq. 11-13): a coupling `u_j -> y_i` is
//!   `y_i = D_ij*u_j - h_i`, `h_i' = A_ij*u_j' - B_ij*|u_j'|*h_j - Gamma_ij*u_j'*|h_j|`,
//!   driven by the DIRECT state `h_j` of step 1 (eq. 12, third line), not by a state of its
//!   own. Given `h_j` the output is linear in the coupling parameters, so eq. (13) is solved
//!   exactly by linear least squares over all inputs `j != i` of output `i` at once, with
//!   the regressors `u_j`, `int |du_j|*h_j` and `int du_j*|h_j|` integrated by the core's
//!   own `MultiBw` (so the fit and the simulation discretise alike).
//!
//! `D_ij` and `A_ij` (`i != j`) enter a coupling only as `D_ij - A_ij` while `u_i` rests
//! (003's experiments drive one input at a time), so eq. (13) does not separate them; we
//! take `A_ij = 0` (the coupling's anhysteretic part in `D`, its hysteresis in `B, Gamma`).
//! Two rounds: the second refits each direct transfer on what the couplings of the first
//! leave. The assembled model is always simulated as one `MultiBw` (a coupling also moves
//! the state `h_i` its direct loop then starts from).
//!
//! 003 identifies each transfer on its own experiment, started from rest. In one record of
//! consecutive experiments the states carry over from one to the next (a coupling leaves
//! `h_i` where the direct loop of axis `i` then starts), which the two steps do not see.
//! So a third step, not in 003, refines all entries jointly by Levenberg-Marquardt on the
//! whole record simulated as one `MultiBw` (`A_ij = 0` kept for `i != j`), kept only if it
//! lowers the RMSE.

use crate::fit::resample::Edge;
use crate::fit::{fit_siso, metrics, models, FitOptions, Fitted};
use crate::numeric;
use crate::optim::{levenberg_marquardt, LmConfig};
use crate::record::Record;
use anyhow::{bail, ensure, Context, Result};
use nalgebra::{DMatrix, DVector};
use piezo_core::feedforward::ims::ImsLoop;
use piezo_core::feedforward::MultiIms;
use piezo_core::hysteresis::multi::MultiBw;
use serde::{Deserialize, Serialize};

/// Largest number of inputs and of outputs (the core's `MultiBw` is monomorphised for
/// each shape up to this).
pub const MAX_AXES: usize = 3;

type Mat = Vec<Vec<f64>>;

/// An identified multivariable Bouc-Wen model (003 eq. 4-7), rows = outputs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MultiBwFit {
    pub outputs: usize,
    pub inputs: usize,
    /// `D` (um/V), `N x K`.
    pub d: Mat,
    /// `A` (um/V).
    pub a: Mat,
    /// `B` (1/V).
    pub b: Mat,
    /// `Gamma` (1/V).
    pub gamma: Mat,
    /// Output offsets (um): the measured `y_i` is `offset_i + (D*U - h)_i`.
    pub offset: Vec<f64>,
    /// Step 1's CBW fits of the direct transfers (`u_j -> y_j`, second round).
    #[serde(skip)]
    pub direct: Vec<Fitted>,
    /// Training RMSE per output after the two steps of 003.
    pub two_step_rmse: Vec<f64>,
    /// Training RMSE per output after the joint refinement (empty when it did not run or
    /// did not lower the RMSE).
    pub joint_rmse: Vec<f64>,
    /// The multivariable IMS (003 eq. 16-19) built from the model: `accepted`, or why not.
    pub ims: String,
}

/// Runs `$body` with `N` and `K` bound to the model's shape as consts.
macro_rules! with_shape {
    ($n:expr, $k:expr, |$N:ident, $K:ident| $body:expr) => {
        match ($n, $k) {
            (1, 2) => { const $N: usize = 1; const $K: usize = 2; $body }
            (1, 3) => { const $N: usize = 1; const $K: usize = 3; $body }
            (2, 1) => { const $N: usize = 2; const $K: usize = 1; $body }
            (2, 2) => { const $N: usize = 2; const $K: usize = 2; $body }
            (2, 3) => { const $N: usize = 2; const $K: usize = 3; $body }
            (3, 1) => { const $N: usize = 3; const $K: usize = 1; $body }
            (3, 2) => { const $N: usize = 3; const $K: usize = 2; $body }
            (3, 3) => { const $N: usize = 3; const $K: usize = 3; $body }
            (n, k) => bail!(
                "multivariable Bouc-Wen: {n} outputs x {k} inputs not supported (1..={MAX_AXES} each, not 1 x 1)"
            ),
        }
    };
}

fn to_array<const N: usize, const K: usize>(m: &Mat) -> [[f64; K]; N] {
    let mut o = [[0.0; K]; N];
    for (row, src) in o.iter_mut().zip(m) {
        for (x, v) in row.iter_mut().zip(src) {
            *x = *v;
        }
    }
    o
}

impl MultiBwFit {
    /// The core model (`N`, `K` must match the fit's shape).
    pub fn model<const N: usize, const K: usize>(&self) -> Result<MultiBw<f64, N, K>> {
        ensure!(
            self.outputs == N && self.inputs == K,
            "the model is {} x {}, asked for {N} x {K}",
            self.outputs,
            self.inputs
        );
        MultiBw::new(
            to_array(&self.d),
            to_array(&self.a),
            to_array(&self.b),
            to_array(&self.gamma),
        )
        .map_err(|e| anyhow::anyhow!("{e}"))
    }

    /// The multivariable IMS of 003 eq. (16)-(19) around the identified model.
    pub fn ims<const N: usize, const K: usize>(
        &self,
        volts_min: f64,
        volts_max: f64,
        dt_s: f64,
    ) -> Result<MultiIms<f64, N, K>> {
        MultiIms::new(self.model()?, ImsLoop::Solved, volts_min, volts_max, dt_s)
            .map_err(|e| anyhow::anyhow!("{e}"))
    }

    /// A record that is one period of a periodic steady state: its inputs repeated
    /// `warmup` extra periods first, the last period returned (`warmup = 0`: from rest).
    pub fn simulate_periodic(&self, u: &[Vec<f64>], warmup: usize) -> Result<Vec<Vec<f64>>> {
        let n = u.first().map_or(0, Vec::len);
        let reps: Vec<Vec<f64>> = u
            .iter()
            .map(|u| u.iter().copied().cycle().take(n * (warmup + 1)).collect())
            .collect();
        let y = self.simulate(&reps)?;
        Ok(y.into_iter().map(|y| y[n * warmup..].to_vec()).collect())
    }

    /// Simulates every output on the inputs `u[j]` (from the relaxed state at the first
    /// sample), offsets included.
    pub fn simulate(&self, u: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        ensure!(
            u.len() >= self.inputs,
            "the record has {} inputs; the model needs {}",
            u.len(),
            self.inputs
        );
        let mut y = with_shape!(self.outputs, self.inputs, |N, K| simulate_nk::<N, K>(
            &self.model::<N, K>()?,
            u
        ));
        for (yi, o) in y.iter_mut().zip(&self.offset) {
            yi.iter_mut().for_each(|v| *v += o);
        }
        Ok(y)
    }
}

fn simulate_nk<const N: usize, const K: usize>(
    m: &MultiBw<f64, N, K>,
    u: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    let len = u.iter().take(K).map(Vec::len).min().unwrap_or(0);
    let at = |i: usize| {
        let mut x = [0.0; K];
        for (x, uj) in x.iter_mut().zip(u) {
            *x = uj[i];
        }
        x
    };
    let mut y = vec![vec![0.0; len]; N];
    if len == 0 {
        return y;
    }
    let mut s = m.init(at(0));
    for i in 0..len {
        let yi = m.step(&mut s, at(i), 0.0);
        for (col, v) in y.iter_mut().zip(yi) {
            col[i] = v;
        }
    }
    y
}

/// The regressors of a coupling driven by input `u` and direct state parameters
/// `(A, B, Gamma)` of that input's axis (003 eq. 12): the responses `h_B`, `h_G` of
/// `h' = -|u'|*h_j` and `h' = -u'*|h_j|`, integrated by a 2 x 1 `MultiBw` whose first row
/// is the direct transfer and second row the unit coupling.
fn coupling_regressors(direct: [f64; 3], u: &[f64]) -> Result<[Vec<f64>; 2]> {
    let [a, b, g] = direct;
    let unit = |cb: f64, cg: f64| -> Result<Vec<f64>> {
        let m = MultiBw::<f64, 2, 1>::new([[0.0], [0.0]], [[a], [0.0]], [[b], [cb]], [[g], [cg]])
            .map_err(|e| anyhow::anyhow!("direct transfer: {e}"))?;
        let mut s = m.init([u.first().copied().unwrap_or(0.0)]);
        Ok(u.iter()
            .map(|&x| {
                m.step(&mut s, [x], 0.0);
                s.h[1]
            })
            .collect())
    };
    Ok([unit(1.0, 0.0)?, unit(0.0, 1.0)?])
}

/// Linear least squares `min |X c - y|`, the columns of `X` given.
fn least_squares(cols: &[Vec<f64>], y: &[f64]) -> Result<Vec<f64>> {
    let a = DMatrix::from_fn(y.len(), cols.len(), |i, j| cols[j][i]);
    let c = numeric::least_squares(a, DVector::from_column_slice(y))
        .context("coupling least squares")?;
    Ok(c.iter().copied().collect())
}

/// Identifies the multivariable Bouc-Wen of 003 on a record with several inputs and/or
/// outputs: the two steps of 003 sec. IV, then the joint refinement when
/// `opts.lm_iterations > 0` (see the module doc).
pub fn identify(train: &Record, opts: &FitOptions) -> Result<MultiBwFit> {
    let mut fit = two_step(train, opts)?;
    if opts.lm_iterations > 0 {
        refine(&mut fit, train, opts)?;
    }
    let (lo, hi) = train
        .u
        .iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    let ims = with_shape!(fit.outputs, fit.inputs, |N, K| fit
        .ims::<N, K>(lo.min(0.0), hi.max(lo + 1.0), train.dt())
        .map(|_| ()));
    fit.ims = match ims {
        Ok(()) => "accepted".into(),
        Err(e) => format!("refused: {e}"),
    };
    Ok(fit)
}

/// The two steps of 003 sec. IV alone (see the module doc).
pub fn two_step(train: &Record, opts: &FitOptions) -> Result<MultiBwFit> {
    let (n, k) = (train.y.len(), train.u.len());
    ensure!(
        (1..=MAX_AXES).contains(&n) && (1..=MAX_AXES).contains(&k) && n * k > 1,
        "multivariable Bouc-Wen: {n} outputs x {k} inputs not supported (1..={MAX_AXES} each, not 1 x 1)"
    );
    ensure!(
        opts.linear_sections == 0 && opts.linear_fixed.is_none(),
        "the multivariable Bouc-Wen of 003 is static; no Hammerstein linear part"
    );
    let dt = train.dt();
    let len = train.len();
    let cbw = models::find("cbw")?;
    let m = n.min(k);
    let zero = vec![vec![0.0; k]; n];
    let (mut d, mut a, mut b, mut g) = (zero.clone(), zero.clone(), zero.clone(), zero);
    let mut direct: Vec<Option<Fitted>> = vec![None; m];
    // Coupling part of each output (no offset), from the previous round.
    let mut coupling = vec![vec![0.0; len]; n];
    for round in 1..=2 {
        // Step 1: direct transfers on what the couplings leave.
        for j in 0..m {
            if opts.progress {
                eprintln!(
                    "round {round}, step 1 (003 eq. 10): direct u{} -> y{}",
                    j + 1,
                    j + 1
                );
            }
            let target: Vec<f64> = train.y[j]
                .iter()
                .zip(&coupling[j])
                .map(|(y, c)| y - c)
                .collect();
            let f = fit_siso(cbw, &train.u[j], &target, dt, opts)
                .with_context(|| format!("direct fit u{} -> y{}", j + 1, j + 1))?;
            ensure!(
                f.sign > 0.0,
                "direct transfer u{} -> y{} falls with its input; 003's model needs D_jj, A_jj > 0",
                j + 1,
                j + 1
            );
            let p = f.values(); // d, alpha, beta, gamma/beta
            d[j][j] = p[0];
            a[j][j] = p[1];
            b[j][j] = p[2];
            g[j][j] = p[3] * p[2];
            direct[j] = Some(f);
        }
        // Step 2: couplings driven by the direct states (eq. 12-13), output by output.
        let mut regs: Vec<[Vec<f64>; 2]> = Vec::new();
        for j in 0..k {
            regs.push(if j < m {
                coupling_regressors([a[j][j], b[j][j], g[j][j]], &train.u[j])?
            } else {
                // Over-actuated: no state h_j (003 eq. 5 pads h with zeros).
                [vec![0.0; len], vec![0.0; len]]
            });
        }
        for i in 0..n {
            if opts.progress {
                eprintln!(
                    "round {round}, step 2 (003 eq. 13): couplings into y{}",
                    i + 1
                );
            }
            let mut target = train.y[i].clone();
            if let Some(f) = direct.get(i).and_then(|f| f.as_ref()) {
                let s = f.simulate(&train.u[i], dt, Edge::Hold)?;
                for (t, v) in target.iter_mut().zip(s) {
                    *t -= v - f.offset;
                }
            }
            let js: Vec<usize> = (0..k).filter(|&j| j != i).collect();
            let mut cols = vec![vec![1.0; len]];
            for &j in &js {
                cols.push(train.u[j].clone());
                if j < m {
                    cols.push(regs[j][0].iter().map(|v| -v).collect());
                    cols.push(regs[j][1].iter().map(|v| -v).collect());
                }
            }
            let c = least_squares(&cols, &target)?;
            let mut next = vec![0.0; len];
            let mut at = 1;
            for &j in &js {
                d[i][j] = c[at];
                a[i][j] = 0.0;
                (b[i][j], g[i][j]) = if j < m {
                    (c[at + 1], c[at + 2])
                } else {
                    (0.0, 0.0)
                };
                for (q, x) in next.iter_mut().enumerate() {
                    *x += d[i][j] * train.u[j][q];
                    if j < m {
                        *x -= b[i][j] * regs[j][0][q] + g[i][j] * regs[j][1][q];
                    }
                }
                at += if j < m { 3 } else { 1 };
            }
            coupling[i] = next;
        }
    }
    let mut fit = MultiBwFit {
        outputs: n,
        inputs: k,
        d,
        a,
        b,
        gamma: g,
        offset: vec![0.0; n],
        direct: direct.into_iter().flatten().collect(),
        two_step_rmse: Vec::new(),
        joint_rmse: Vec::new(),
        ims: String::new(),
    };
    set_offsets(&mut fit, train)?;
    fit.two_step_rmse = rmse(&fit, train)?;
    Ok(fit)
}

/// Offsets in closed form (mean residual) for the model's current matrices.
fn set_offsets(fit: &mut MultiBwFit, rec: &Record) -> Result<()> {
    fit.offset.iter_mut().for_each(|o| *o = 0.0);
    let sim = fit.simulate(&rec.u)?;
    for (o, (y, s)) in fit.offset.iter_mut().zip(rec.y.iter().zip(&sim)) {
        *o = y.iter().zip(s).map(|(y, s)| y - s).sum::<f64>() / y.len().max(1) as f64;
    }
    Ok(())
}

/// The refined entries: every `D_ij`, `B_ij`, `Gamma_ij` and the direct `A_jj`.
fn free_entries(fit: &MultiBwFit) -> Vec<(usize, usize, usize)> {
    let mut v = Vec::new();
    for i in 0..fit.outputs {
        for j in 0..fit.inputs {
            for mat in [0, 1, 2, 3] {
                if mat != 1 || i == j {
                    v.push((mat, i, j));
                }
            }
        }
    }
    v
}

fn entry(fit: &mut MultiBwFit, (mat, i, j): (usize, usize, usize)) -> &mut f64 {
    match mat {
        0 => &mut fit.d[i][j],
        1 => &mut fit.a[i][j],
        2 => &mut fit.b[i][j],
        _ => &mut fit.gamma[i][j],
    }
}

/// Step 3 (not in 003): all entries by LM on the whole record (see the module doc).
fn refine(fit: &mut MultiBwFit, rec: &Record, opts: &FitOptions) -> Result<()> {
    let free = free_entries(fit);
    let mut x0 = Vec::with_capacity(free.len());
    let mut work = fit.clone();
    for &e in &free {
        x0.push(*entry(&mut work, e));
    }
    // Boxes: each entry within a wide band around its two-step value, scaled by the
    // largest entry of its matrix (so a zero coupling may still grow).
    let scale = |mat: usize| {
        let m = [&fit.d, &fit.a, &fit.b, &fit.gamma][mat];
        m.iter()
            .flatten()
            .fold(0.0f64, |a, v| a.max(v.abs()))
            .max(1e-12)
    };
    let (lo, hi): (Vec<f64>, Vec<f64>) = free
        .iter()
        .zip(&x0)
        .map(|(&(mat, _, _), &x)| {
            let w = 3.0 * x.abs() + scale(mat);
            (x - w, x + w)
        })
        .unzip();
    let len = rec.len();
    let residuals = |x: &[f64], r: &mut [f64]| {
        let mut m = fit.clone();
        for (&e, &v) in free.iter().zip(x) {
            *entry(&mut m, e) = v;
        }
        let ok = set_offsets(&mut m, rec).and_then(|_| m.simulate(&rec.u));
        match ok {
            Ok(sim) => {
                for (i, (y, s)) in rec.y.iter().zip(&sim).enumerate() {
                    for (q, (y, s)) in y.iter().zip(s).enumerate() {
                        r[i * len + q] = s - y;
                    }
                }
            }
            Err(_) => r.fill(f64::INFINITY),
        }
    };
    if opts.progress {
        eprintln!("step 3 (joint, not in 003): {} entries by LM", free.len());
    }
    let lm = LmConfig {
        max_iterations: opts.lm_iterations,
        progress: opts.progress.then(|| "joint multivariable BW".to_string()),
        ..Default::default()
    };
    let best = levenberg_marquardt(residuals, len * rec.y.len(), &x0, &lo, &hi, &lm)?;
    for (&e, &v) in free.iter().zip(&best.x) {
        *entry(&mut work, e) = v;
    }
    set_offsets(&mut work, rec)?;
    let after = rmse(&work, rec)?;
    let total = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
    if total(&after) < total(&fit.two_step_rmse) {
        work.joint_rmse = after;
        *fit = work;
    }
    Ok(())
}

/// RMSE of every output of `fit` on `rec`.
pub fn rmse(fit: &MultiBwFit, rec: &Record) -> Result<Vec<f64>> {
    let sim = fit.simulate(&rec.u)?;
    Ok(rec
        .y
        .iter()
        .zip(&sim)
        .map(|(y, s)| metrics(y, s).rmse)
        .collect())
}
