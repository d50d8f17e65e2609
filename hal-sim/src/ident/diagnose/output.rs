//! The output side of the diagnosis model: the pieces that act on the model's output and so
//! are not linear in its coefficients (the amplitude-dependent dynamics, the play, the sensor
//! polynomial), fitted as a fixed point by [`fit_linear`]; and the model's prediction.

use super::dynamics::AmpFilter;
use super::model::{
    combine, least_squares, least_squares_refs, play, regressors, sensor_columns, Cause, Causes,
    OutputModel, Scales, Shape,
};
use super::Signals;
use crate::numeric::rmse;

/// The output-side pieces of a model that are not linear in its coefficients: the
/// amplitude-dependent dynamics (per record), the play and the sensor polynomial.
pub(super) struct OutputSide<'a> {
    /// Records' lengths, one after the other.
    pub(super) lens: Vec<usize>,
    /// Columns before `y0` (the ones the dynamics act on).
    pub(super) n_pre: usize,
    pub(super) amp: Option<Vec<AmpFilter>>,
    pub(super) play: f64,
    pub(super) sensor: bool,
    scales: &'a Scales,
}

impl OutputSide<'_> {
    /// `x` (records one after the other) through the amplitude-dependent dynamics; returns
    /// the course of `rho`.
    fn run_amp(&self, x: &mut [f64]) -> Vec<f64> {
        let mut rho = Vec::with_capacity(x.len());
        if let Some(f) = &self.amp {
            let mut at = 0;
            for (n, f) in self.lens.iter().zip(f) {
                let end = (at + n).min(x.len());
                rho.extend(f.run(&mut x[at..end]));
                at = end;
            }
        }
        rho
    }

    /// The columns before `y0` through the dynamics with the course `rho`.
    pub(super) fn follow(&self, cols: &[Vec<f64>], rho: &[f64]) -> Vec<Vec<f64>> {
        let f = self.amp.as_deref().unwrap_or_default();
        let mut out: Vec<Vec<f64>> = cols[..self.n_pre].to_vec();
        let mut at = 0;
        for (n, f) in self.lens.iter().zip(f) {
            let end = (at + n).min(rho.len());
            let mut part: Vec<&mut [f64]> = out
                .iter_mut()
                .map(|c| {
                    let e = end.min(c.len());
                    &mut c[at.min(e)..e]
                })
                .collect();
            f.follow_all(&mut part, &rho[at..end]);
            at = end;
        }
        out
    }

    /// The model's position from its linear columns `cols` (the first coefficients): the
    /// columns before `y0` through the amplitude-dependent dynamics, then (`with_play`) the
    /// play; and the dynamics' course of `rho` (empty without them).
    pub(super) fn position(
        &self,
        cols: &[Vec<f64>],
        coef: &[f64],
        with_play: bool,
    ) -> (Vec<f64>, Vec<f64>) {
        let play = if with_play { self.play } else { 0.0 };
        let n = cols.len().min(coef.len());
        if self.amp.is_none() {
            let mut x = combine(&cols[..n], &coef[..n]);
            if play > 0.0 {
                x = played(&x, &self.lens, play);
            }
            return (x, Vec::new());
        }
        let pre = self.n_pre.min(n);
        let mut x = combine(&cols[..pre], &coef[..pre]);
        let rho = self.run_amp(&mut x);
        let post = combine(&cols[pre..n], &coef[pre..n]);
        for (x, p) in x.iter_mut().zip(post) {
            *x += p;
        }
        if play > 0.0 {
            x = played(&x, &self.lens, play);
        }
        (x, rho)
    }

    /// The model's output: its position read by the sensor (its polynomial's coefficients
    /// after the linear columns').
    pub(super) fn output(&self, cols: &[Vec<f64>], coef: &[f64]) -> Vec<f64> {
        let (mut x, _) = self.position(cols, coef, true);
        if self.sensor && coef.len() >= cols.len() + 2 {
            let [e2, e3] = sensor_columns(&x, self.scales);
            let (s2, s3) = (coef[cols.len()], coef[cols.len() + 1]);
            for ((x, a), b) in x.iter_mut().zip(&e2).zip(&e3) {
                *x += s2 * a + s3 * b;
            }
        }
        x
    }
}

/// The output side of `causes` with `shape` on records `data`; `names`: the columns' names.
pub(super) fn output_side<'a>(
    data: &[&Signals],
    causes: Causes,
    shape: &Shape,
    scales: &'a Scales,
    names: &[&str],
) -> OutputSide<'a> {
    OutputSide {
        lens: data.iter().map(|d| d.len()).collect(),
        n_pre: names.iter().position(|n| *n == "y0").unwrap_or(names.len()),
        amp: if causes.has(Cause::AmplitudeDynamics) {
            data.iter()
                .map(|d| {
                    AmpFilter::new(
                        shape.wn_hz,
                        shape.zeta,
                        shape.amp_level_um,
                        shape.amp_freq_shift,
                        shape.amp_zeta_scale,
                        d.dt(),
                    )
                })
                .collect()
        } else {
            None
        },
        play: if causes.has(Cause::Backlash) {
            shape.play_um
        } else {
            0.0
        },
        sensor: causes.has(Cause::SensorNonlinearity),
        scales,
    }
}

/// `m` (records of lengths `lens` one after the other) through a play of half width `half`,
/// each record from rest at its first value.
pub(super) fn played(m: &[f64], lens: &[usize], half: f64) -> Vec<f64> {
    let mut out = m.to_vec();
    let mut at = 0;
    for &n in lens {
        let end = (at + n).min(out.len());
        play(&mut out[at..end], half);
        at = end;
    }
    out
}

/// Fits the linear coefficients of output `i` for a given shape on all of `data` (one
/// model for every record, each record's model state starting from its own first sample);
/// returns the model and its training RMSE over all samples.
pub fn fit_linear(
    data: &[Signals],
    i: usize,
    causes: Causes,
    shape: &Shape,
    scales: &Scales,
    taus: &[f64],
) -> (OutputModel, f64) {
    let mut names = Vec::new();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    let mut joined = Vec::new();
    for (k, d) in data.iter().enumerate() {
        let (n, c) = regressors(d, i, causes, shape, scales, taus);
        if k == 0 {
            (names, cols) = (n, c);
            // Room for all records at once (no copy of the first one on growth).
            let total: usize = data.iter().map(Signals::len).sum();
            for a in cols.iter_mut() {
                a.reserve_exact(total.saturating_sub(a.len()));
            }
        } else {
            for (a, b) in cols.iter_mut().zip(c) {
                a.extend(b);
            }
        }
        if data.len() > 1 {
            joined.extend_from_slice(&d.y[i]);
        }
    }
    let y_meas: &[f64] = match data {
        [one] => &one.y[i],
        _ => &joined,
    };
    let refs: Vec<&Signals> = data.iter().collect();
    let side = output_side(&refs, causes, shape, scales, &names);
    let (coef, y) = if side.play > 0.0 || side.sensor || side.amp.is_some() {
        // The play, the sensor and the amplitude-dependent dynamics act on the model's output,
        // which the coefficients make: a fixed point. Fit the coefficients to the measurement
        // minus the play's offset of the last iterate, with the sensor polynomial of the last
        // iterate's position as two more columns and the dynamics following the last
        // iterate's course of the amplitude (at first none: the plain dynamics); then
        // recompute all three.
        let n_lin = cols.len();
        let mut target = y_meas.to_vec();
        // First iterate: the position is about what the sensor reads.
        let mut x = y_meas.to_vec();
        let mut rho = vec![0.0; y_meas.len()];
        let mut coef = Vec::new();
        for k in 0..=OUTPUT_ITERATIONS {
            let followed = side.amp.as_ref().map(|_| side.follow(&cols, &rho));
            let mut all: Vec<&[f64]> = match &followed {
                Some(f) => f
                    .iter()
                    .chain(&cols[side.n_pre..])
                    .map(Vec::as_slice)
                    .collect(),
                None => cols.iter().map(Vec::as_slice).collect(),
            };
            let sensor = side.sensor.then(|| sensor_columns(&x, scales));
            if let Some(c) = &sensor {
                all.extend(c.iter().map(Vec::as_slice));
            }
            coef = least_squares_refs(&all, &target);
            if k == OUTPUT_ITERATIONS {
                break;
            }
            // The position without the play: its offset is what the play adds.
            let (m, r) = side.position(&cols, &coef[..n_lin], false);
            if side.amp.is_some() {
                rho = r;
            }
            x = if side.play > 0.0 {
                played(&m, &side.lens, side.play)
            } else {
                m.clone()
            };
            for ((t, y), (x, m)) in target.iter_mut().zip(y_meas).zip(x.iter().zip(&m)) {
                *t = y - (x - m);
            }
        }
        let y = side.output(&cols, &coef);
        (coef, y)
    } else {
        let coef = least_squares(&cols, y_meas);
        let y = combine(&cols, &coef);
        (coef, y)
    };
    if side.sensor {
        names.extend(["sensor_e2", "sensor_e3"]);
    }
    let e = rmse(&y, y_meas);
    let model = OutputModel {
        shape: *shape,
        names: names.into_iter().map(String::from).collect(),
        coef,
    };
    (model, if e.is_finite() { e } else { f64::INFINITY })
}

/// Fixed-point iterations of the fit of the play, the sensor polynomial and the
/// amplitude-dependent dynamics.
const OUTPUT_ITERATIONS: usize = 3;

/// Output `i` of `model` on `data`.
pub fn predict(
    data: &Signals,
    i: usize,
    causes: Causes,
    model: &OutputModel,
    scales: &Scales,
    taus: &[f64],
) -> Vec<f64> {
    let (names, cols) = regressors(data, i, causes, &model.shape, scales, taus);
    output_side(&[data], causes, &model.shape, scales, &names).output(&cols, &model.coef)
}
