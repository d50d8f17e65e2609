//! The output side of the diagnosis model: the pieces that act on the model's output and so
//! are not linear in its coefficients (the amplitude-dependent dynamics, the play, the sensor
//! polynomial), fitted as a fixed point by [`super::model::fit_linear`].

use super::dynamics::AmpFilter;
use super::model::{combine, play, sensor_columns, Cause, Causes, Scales, Shape};
use super::Signals;

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
            data.iter().map(|d| AmpFilter::new(shape, d.dt())).collect()
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
