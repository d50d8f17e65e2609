//! The output side of the diagnosis model: the pieces that act on the model's output and so
//! are not linear in its coefficients (the amplitude-dependent dynamics, the play, the sensor
//! polynomial), fitted as a fixed point by [`fit_linear`]; and the model's prediction.

use super::dynamics::{AmpFilter, AMP_LEVEL_MIN};
use super::model::{
    combine, combine_rmse, least_squares, least_squares_refs, play, regressors, sensor_columns,
    Cause, Causes, OutputModel, Scales, Shape,
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
    /// A fixed course of `rho` for the amplitude-dependent dynamics (records one after the
    /// other): they are then a linear time-varying filter, no fixed point to find.
    course: Option<&'a [f64]>,
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
        let mut out: Vec<Vec<f64>> = cols[..self.n_pre].to_vec();
        self.follow_in_place(&mut out, rho);
        out
    }

    /// `cols` (records one after the other) through the dynamics with the course `rho`.
    fn follow_in_place(&self, cols: &mut [Vec<f64>], rho: &[f64]) {
        let f = self.amp.as_deref().unwrap_or_default();
        let mut at = 0;
        for (n, f) in self.lens.iter().zip(f) {
            let end = (at + n).min(rho.len());
            let mut part: Vec<&mut [f64]> = cols
                .iter_mut()
                .map(|c| {
                    let e = end.min(c.len());
                    &mut c[at.min(e)..e]
                })
                .collect();
            f.follow_all(&mut part, &rho[at..end]);
            at = end;
        }
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
        let rho = match self.course {
            Some(c) => {
                let mut one = [x];
                self.follow_in_place(&mut one, c);
                [x] = one;
                c.to_vec()
            }
            None => self.run_amp(&mut x),
        };
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
        self.output_and_course(cols, coef).0
    }

    /// [`OutputSide::output`] and the dynamics' course of `rho` (empty without them).
    fn output_and_course(&self, cols: &[Vec<f64>], coef: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (mut x, rho) = self.position(cols, coef, true);
        if self.sensor && coef.len() >= cols.len() + 2 {
            let [e2, e3] = sensor_columns(&x, self.scales);
            let (s2, s3) = (coef[cols.len()], coef[cols.len() + 1]);
            for ((x, a), b) in x.iter_mut().zip(&e2).zip(&e3) {
                *x += s2 * a + s3 * b;
            }
        }
        (x, rho)
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
        course: None,
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
    let (model, e, _) = fit_linear_with(data, i, causes, shape, scales, taus, Iterate::Full);
    (model, e)
}

/// How [`fit_linear_with`] treats the output-side pieces' fixed point.
#[derive(Debug, Clone, Copy)]
pub(super) enum Iterate<'a> {
    /// [`OUTPUT_ITERATIONS`]: the final fits.
    Full,
    /// One iteration: the search's cost (its result is refitted in full), half the work.
    Rough,
    /// The amplitude-dependent dynamics along a given course of the amplitude (output
    /// units): with it `rho` is known, and they are a linear time-varying filter (no
    /// iteration for them, no serial square root per sample). The search of a model that
    /// already has them, from the course of its fit.
    Course(&'a [f64]),
}

/// [`fit_linear`] with the fixed point as `how` says; also returns the amplitude-dependent
/// dynamics' course of the amplitude in the model's output (empty without them).
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_linear_with(
    data: &[Signals],
    i: usize,
    causes: Causes,
    shape: &Shape,
    scales: &Scales,
    taus: &[f64],
    how: Iterate,
) -> (OutputModel, f64, Vec<f64>) {
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
    let level = shape.amp_level_um.max(AMP_LEVEL_MIN);
    let given: Option<Vec<f64>> = match how {
        Iterate::Course(a) => Some(a.iter().map(|a| a / (a + level)).collect()),
        _ => None,
    };
    let mut side = output_side(&refs, causes, shape, scales, &names);
    side.course = given.as_deref();
    let iterations = match how {
        Iterate::Full => OUTPUT_ITERATIONS,
        Iterate::Rough => 1,
        Iterate::Course(_) => usize::from(side.play > 0.0 || side.sensor),
    };
    let (coef, e, course) = if side.play > 0.0 || side.sensor || side.amp.is_some() {
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
        let mut rho = side
            .course
            .map_or_else(|| vec![0.0; y_meas.len()], <[f64]>::to_vec);
        let mut coef = Vec::new();
        for k in 0..=iterations {
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
            if k == iterations {
                break;
            }
            // The position without the play: its offset is what the play adds.
            let (m, r) = side.position(&cols, &coef[..n_lin], false);
            if side.amp.is_some() && side.course.is_none() {
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
        let (y, rho) = side.output_and_course(&cols, &coef);
        let course = rho.iter().map(|r| level * r / (1.0 - r)).collect();
        (coef, rmse(&y, y_meas), course)
    } else {
        let coef = least_squares(&cols, y_meas);
        let e = combine_rmse(&cols, &coef, y_meas);
        (coef, e, Vec::new())
    };
    if side.sensor {
        names.extend(["sensor_e2", "sensor_e3"]);
    }
    let model = OutputModel {
        shape: *shape,
        names: names.into_iter().map(String::from).collect(),
        coef,
    };
    (model, if e.is_finite() { e } else { f64::INFINITY }, course)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::evidence::no_shape;
    use crate::diagnose::model::min_max;
    use crate::diagnose::signals::Signals;
    use piezo_core::hysteresis::{BwState, Cbw};

    /// A stage whose resonance softens and damps with its oscillation amplitude, simulated
    /// here (this crate has no simulator): CBW (000 eq. (6)) of a sine with steps on it,
    /// then a resonance at 110 Hz, zeta 0.093, -23 % and +69 % at large amplitude, half at
    /// 0.35 um of free motion about the held input; sub-stepped semi-implicit Euler.
    fn amplitude_record() -> Signals {
        let (fs, n, sub) = (10_000.0, 40_000, 20);
        let cbw = Cbw::new(0.9, 0.3, 0.012, 0.004, 1.0).expect("valid CBW");
        let mut h = BwState::default();
        let (wn0, z0, shift, scale, level) =
            (2.0 * std::f64::consts::PI * 110.0, 0.093, -0.23, 0.69, 0.35);
        let (mut x, mut v) = (0.0, 0.0);
        let (mut t, mut u, mut y) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..n {
            let tk = k as f64 / fs;
            let step = if (tk * 4.0).fract() < 0.5 { 8.0 } else { -8.0 };
            let uk = 60.0 + 45.0 * (2.0 * std::f64::consts::PI * 1.5 * tk).sin() + step;
            let xin = cbw.step_n1(&mut h, uk);
            let dt = 1.0 / (fs * sub as f64);
            for _ in 0..sub {
                let a = ((x - xin).powi(2) + (v / wn0).powi(2)).sqrt();
                let rho = a / (a + level);
                let (wn, z) = (wn0 * (1.0 + shift * rho), z0 * (1.0 + scale * rho));
                v += dt * (wn * wn * (xin - x) - 2.0 * z * wn * v);
                x += dt * v;
            }
            t.push(tk);
            u.push(uk);
            y.push(x);
        }
        Signals::new(t, vec![u], vec![y]).expect("valid record")
    }

    /// The search of a model with the amplitude dependence runs along the course of its
    /// fit: along it the fit is the full fit again, and along no amplitude the plain
    /// dynamics'.
    #[test]
    fn fit_along_a_course() {
        let r = amplitude_record();
        let mut scales = Scales::of(&r.t, &r.u[0]);
        let (lo, hi) = min_max(&r.y[0]);
        (scales.y_span, scales.y_mid) = (hi - lo, 0.5 * (hi + lo));
        let shape = Shape {
            beta: 0.012,
            gamma: 0.004,
            wn_hz: 110.0,
            zeta: 0.093,
            amp_level_um: 0.35,
            amp_freq_shift: -0.23,
            amp_zeta_scale: 0.69,
            ..no_shape()
        };
        let amp = Causes::default().with(Cause::AmplitudeDynamics);
        let data = std::slice::from_ref(&r);
        let fit = |causes, how| fit_linear_with(data, 0, causes, &shape, &scales, &[], how);
        let (_, e_full, course) = fit(amp, Iterate::Full);
        assert_eq!(course.len(), r.len());
        assert!(course.iter().all(|a| a.is_finite() && *a >= 0.0));
        let (_, e_along, _) = fit(amp, Iterate::Course(&course));
        assert!((e_along / e_full - 1.0).abs() < 1e-3, "{e_along} {e_full}");
        let (_, e_rough, _) = fit(amp, Iterate::Rough);
        assert!((e_rough / e_full - 1.0).abs() < 0.05, "{e_rough} {e_full}");
        let still = vec![0.0; r.len()];
        let (_, e_still, _) = fit(amp, Iterate::Course(&still));
        let plain = Causes::default().with(Cause::Dynamics);
        let (_, e_plain, _) = fit(plain, Iterate::Full);
        assert!(
            (e_still / e_plain - 1.0).abs() < 1e-9,
            "{e_still} {e_plain}"
        );
        assert!(e_full < 0.8 * e_plain, "{e_full} {e_plain}");
    }
}
