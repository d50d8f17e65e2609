//! Nonparametric frequency response of multivariable records: the best linear
//! approximation (BLA) of periodic multisine records with its noise and nonlinear-distortion
//! levels (robust method: periods give the noise, realizations the total variance), and
//! the H1 estimate (Welch averaging) of non-periodic records (PRBS, sweeps).
//!
//! DFT convention: `X[k] = sum_n x[n] exp(-j 2 pi k n / N)` over one period of `N` samples;
//! a bin's mean-square contribution to the time signal is `w_k |X[k]|^2 / N^2` with
//! `w_k = 1` at DC and Nyquist, 2 elsewhere.

use super::model::C64;
use crate::record::Record;
use nalgebra::DMatrix;
use rustfft::FftPlanner;

/// Samples per period of a periodic record: the smallest `N = len / P` (`P >= 2`) over
/// which every input repeats to 1 % RMS (measured inputs carry converter noise); the
/// record length when none does.
pub fn detect_period(rec: &Record) -> usize {
    let len = rec.len();
    for p in (2..=16).rev() {
        if !len.is_multiple_of(p) || len / p < 8 {
            continue;
        }
        let n = len / p;
        let repeats = rec.u.iter().all(|u| {
            let ms: f64 = u.iter().map(|v| v * v).sum::<f64>() / len as f64;
            let dms: f64 =
                (n..len).map(|i| (u[i] - u[i - n]).powi(2)).sum::<f64>() / (len - n) as f64;
            ms > 0.0 && dms <= 1e-4 * ms
        });
        if repeats {
            return n;
        }
    }
    len
}

/// DFT bins `0..=N/2` of every period of `x` (length a multiple of `n`).
pub fn period_spectra(x: &[f64], n: usize) -> Vec<Vec<C64>> {
    let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
    x.chunks_exact(n)
        .map(|c| {
            let mut buf: Vec<C64> = c.iter().map(|&v| C64::new(v, 0.0)).collect();
            fft.process(&mut buf);
            buf.truncate(n / 2 + 1);
            buf
        })
        .collect()
}

/// Weight of bin `k` of an `n`-point DFT in the mean square of the time signal.
pub fn bin_weight(k: usize, n: usize) -> f64 {
    let w = if k == 0 || 2 * k == n { 1.0 } else { 2.0 };
    w / (n as f64 * n as f64)
}

/// Spectra of one periodic record, averaged over its periods.
#[derive(Debug, Clone)]
pub struct PeriodicSpectra {
    /// Samples per period.
    pub period: usize,
    pub fs_hz: f64,
    pub periods: usize,
    /// `u[j][k]`: input `j`, bin `k` (`0..=N/2`), mean over periods.
    pub u: Vec<Vec<C64>>,
    pub y: Vec<Vec<C64>>,
    /// Variance of one period's output spectrum across periods, `[output][bin]`
    /// (zero with one period).
    pub y_noise_var: Vec<Vec<f64>>,
}

impl PeriodicSpectra {
    pub fn of(rec: &Record, period: usize) -> anyhow::Result<Self> {
        anyhow::ensure!(
            period >= 8 && rec.len().is_multiple_of(period),
            "record of {} samples is not a whole number of {period}-sample periods",
            rec.len()
        );
        let p = rec.len() / period;
        let mean = |x: &[f64]| -> (Vec<C64>, Vec<f64>) {
            let s = period_spectra(x, period);
            let bins = period / 2 + 1;
            let m: Vec<C64> = (0..bins)
                .map(|k| s.iter().map(|v| v[k]).sum::<C64>() / p as f64)
                .collect();
            let var = (0..bins)
                .map(|k| {
                    if p < 2 {
                        0.0
                    } else {
                        s.iter().map(|v| (v[k] - m[k]).norm_sqr()).sum::<f64>() / (p - 1) as f64
                    }
                })
                .collect();
            (m, var)
        };
        let u = rec.u.iter().map(|x| mean(x).0).collect();
        let (y, y_noise_var) = rec.y.iter().map(|x| mean(x)).unzip();
        Ok(Self {
            period,
            fs_hz: rec.sample_rate_hz(),
            periods: p,
            u,
            y,
            y_noise_var,
        })
    }

    pub fn bins(&self) -> usize {
        self.period / 2 + 1
    }
}

/// Frequency-domain data for the parametric fits: at each line, the estimate `g` and a
/// factor `f` of the input power (`f f^H = sum_r U_r U_r^H` times the bin weight), so
/// `|(g - G) f|_F^2` is the mean-square output error the model `G` adds there.
#[derive(Debug, Clone)]
pub struct FrfData {
    pub fs_hz: f64,
    /// Bin index per line and its DFT length (`z = exp(j 2 pi k / n)`).
    pub bins: Vec<usize>,
    pub n: usize,
    pub g: Vec<DMatrix<C64>>,
    pub f: Vec<DMatrix<C64>>,
}

impl FrfData {
    pub fn z(&self, line: usize) -> C64 {
        C64::from_polar(
            1.0,
            2.0 * std::f64::consts::PI * self.bins[line] as f64 / self.n as f64,
        )
    }
    pub fn freq_hz(&self, line: usize) -> f64 {
        self.bins[line] as f64 * self.fs_hz / self.n as f64
    }
    pub fn inputs(&self) -> usize {
        self.g.first().map_or(0, |g| g.ncols())
    }
    pub fn outputs(&self) -> usize {
        self.g.first().map_or(0, |g| g.nrows())
    }
    /// The lines `i` with `keep(i)`.
    pub fn subset(&self, keep: impl Fn(usize) -> bool) -> Self {
        let idx: Vec<usize> = (0..self.bins.len()).filter(|&i| keep(i)).collect();
        Self {
            fs_hz: self.fs_hz,
            bins: idx.iter().map(|&i| self.bins[i]).collect(),
            n: self.n,
            g: idx.iter().map(|&i| self.g[i].clone()).collect(),
            f: idx.iter().map(|&i| self.f[i].clone()).collect(),
        }
    }
}

/// Hermitian square root factor `f` of `s` (`f f^H = s`), negative eigenvalues dropped.
pub fn psd_factor(s: &DMatrix<C64>) -> DMatrix<C64> {
    let h = (s + s.adjoint()) * C64::new(0.5, 0.0);
    let e = h.symmetric_eigen();
    let mut q = e.eigenvectors;
    for (j, l) in e.eigenvalues.iter().enumerate() {
        let r = l.max(0.0).sqrt();
        q.column_mut(j).scale_mut(r);
    }
    q
}

/// Best linear approximation from periodic records with per-line noise and distortion.
#[derive(Debug, Clone)]
pub struct Bla {
    pub data: FrfData,
    /// Realizations (records) used.
    pub realizations: usize,
    /// Per line and output: variance of the averaged output spectrum around the BLA
    /// (noise / P + nonlinear distortion), from the spread over realizations; needs
    /// more realizations than inputs, else `None`.
    pub total_var: Option<Vec<Vec<f64>>>,
    /// Per line and output: noise variance of one period's output spectrum.
    pub noise_var: Vec<Vec<f64>>,
    /// Periods per record.
    pub periods: usize,
}

/// Lines excited by any input of any realization (above 1e-8 of the strongest).
fn excited_bins(sp: &[PeriodicSpectra]) -> Vec<usize> {
    let bins = sp[0].bins();
    let power: Vec<f64> = (0..bins)
        .map(|k| {
            sp.iter()
                .flat_map(|s| s.u.iter().map(move |u| u[k].norm_sqr()))
                .sum()
        })
        .collect();
    let max = power.iter().copied().fold(0.0, f64::max);
    (0..bins).filter(|&k| power[k] > 1e-8 * max).collect()
}

/// The BLA of several periodic records of one system (same period and rate):
/// `G = S_yu S_uu^-1` per excited line, least squares over realizations.
pub fn bla(sp: &[PeriodicSpectra]) -> anyhow::Result<Bla> {
    anyhow::ensure!(!sp.is_empty(), "no records");
    let (n, m, p) = (sp[0].period, sp[0].u.len(), sp[0].y.len());
    for s in sp {
        anyhow::ensure!(
            s.period == n && s.u.len() == m && s.y.len() == p,
            "records differ in period or channel count ({} / {} / {} vs {n} / {m} / {p})",
            s.period,
            s.u.len(),
            s.y.len()
        );
    }
    let r = sp.len();
    let mut data = FrfData {
        fs_hz: sp[0].fs_hz,
        bins: Vec::new(),
        n,
        g: Vec::new(),
        f: Vec::new(),
    };
    let mut total = Vec::new();
    let mut noise = Vec::new();
    for k in excited_bins(sp) {
        let u = DMatrix::from_fn(m, r, |j, i| sp[i].u[j][k]);
        let y = DMatrix::from_fn(p, r, |o, i| sp[i].y[o][k]);
        let suu = &u * u.adjoint();
        let Some(inv) = suu.clone().try_inverse() else {
            continue; // fewer independent realizations than inputs at this line
        };
        let g = &y * u.adjoint() * inv;
        if r > m {
            let e = &y - &g * &u;
            total.push(
                (0..p)
                    .map(|o| e.row(o).iter().map(|v| v.norm_sqr()).sum::<f64>() / (r - m) as f64)
                    .collect::<Vec<f64>>(),
            );
        }
        noise.push(
            (0..p)
                .map(|o| sp.iter().map(|s| s.y_noise_var[o][k]).sum::<f64>() / r as f64)
                .collect(),
        );
        data.f
            .push(psd_factor(&(suu * C64::new(bin_weight(k, n), 0.0))));
        data.g.push(g);
        data.bins.push(k);
    }
    anyhow::ensure!(
        !data.bins.is_empty(),
        "no frequency line is excited by {m} independent inputs across the {r} records \
         (a {m}-input BLA needs at least {m} realizations with different phases)"
    );
    Ok(Bla {
        data,
        realizations: r,
        total_var: (r > m).then_some(total),
        noise_var: noise,
        periods: sp[0].periods,
    })
}

/// Time-domain levels (RMS over one period, averaged over outputs) of a BLA's
/// uncertainty, in output units.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Levels {
    /// Noise of one period at the excited lines (what no model can predict there).
    pub noise_rms: f64,
    /// Nonlinear distortion at the excited lines: total variance minus noise / P.
    pub distortion_rms: Option<f64>,
}

impl Bla {
    pub fn levels(&self) -> Levels {
        let p = self.data.outputs().max(1);
        let n = self.data.n;
        let ms = |var: &[Vec<f64>], scale: f64| -> Vec<f64> {
            (0..p)
                .map(|o| {
                    var.iter()
                        .zip(&self.data.bins)
                        .map(|(v, &k)| v[o] * scale * bin_weight(k, n))
                        .sum::<f64>()
                })
                .collect()
        };
        let avg = |v: Vec<f64>| (v.iter().map(|x| x.max(0.0).sqrt()).sum::<f64>()) / p as f64;
        let noise1 = ms(&self.noise_var, 1.0);
        let dist = self.total_var.as_ref().map(|t| {
            let tot = ms(t, 1.0);
            let noise_mean = ms(&self.noise_var, 1.0 / self.periods as f64);
            avg(tot.iter().zip(&noise_mean).map(|(a, b)| a - b).collect())
        });
        Levels {
            noise_rms: avg(noise1),
            distortion_rms: dist,
        }
    }
}

/// H1 estimate of a non-periodic record: Hann-windowed segments of `seg` samples with
/// half overlap, `G = S_yu S_uu^-1` per line where the inputs are independent. The
/// input-power factor is scaled so one record's full length counts as in [`bla`].
pub fn h1_welch(rec: &Record, seg: usize) -> anyhow::Result<FrfData> {
    let (m, p, len) = (rec.u.len(), rec.y.len(), rec.len());
    anyhow::ensure!(
        seg >= 16 && seg <= len,
        "segment of {seg} samples does not fit a {len}-sample record"
    );
    let hann: Vec<f64> = (0..seg)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / seg as f64).cos())
        .collect();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(seg);
    let spec = |x: &[f64]| -> Vec<C64> {
        let mut b: Vec<C64> = x
            .iter()
            .zip(&hann)
            .map(|(v, w)| C64::new(v * w, 0.0))
            .collect();
        fft.process(&mut b);
        b.truncate(seg / 2 + 1);
        b
    };
    let bins = seg / 2 + 1;
    let mut suu = vec![DMatrix::<C64>::zeros(m, m); bins];
    let mut syu = vec![DMatrix::<C64>::zeros(p, m); bins];
    let mut segs = 0usize;
    let mut start = 0;
    while start + seg <= len {
        let us: Vec<Vec<C64>> = rec.u.iter().map(|x| spec(&x[start..start + seg])).collect();
        let ys: Vec<Vec<C64>> = rec.y.iter().map(|x| spec(&x[start..start + seg])).collect();
        for k in 0..bins {
            let u = DMatrix::from_fn(m, 1, |j, _| us[j][k]);
            let y = DMatrix::from_fn(p, 1, |o, _| ys[o][k]);
            suu[k] += &u * u.adjoint();
            syu[k] += &y * u.adjoint();
        }
        segs += 1;
        start += seg / 2;
    }
    let wsum: f64 = hann.iter().map(|w| w * w).sum();
    let mut data = FrfData {
        fs_hz: rec.sample_rate_hz(),
        bins: Vec::new(),
        n: seg,
        g: Vec::new(),
        f: Vec::new(),
    };
    let max = suu.iter().map(|s| s.trace().re).fold(0.0, f64::max);
    for k in 1..bins {
        if suu[k].trace().re <= 1e-8 * max {
            continue;
        }
        // Inputs must be independent at the line (condition number bound).
        let sv = suu[k].singular_values();
        if sv.min() <= 1e-8 * sv.max() {
            continue;
        }
        let Some(inv) = suu[k].clone().try_inverse() else {
            continue;
        };
        data.g.push(&syu[k] * inv);
        // Mean square per sample: the segment average of |X_w|^2 / sum(w^2), one-sided.
        let scale = bin_weight(k, seg) * seg as f64 / wsum / segs as f64;
        data.f.push(psd_factor(&(&suu[k] * C64::new(scale, 0.0))));
        data.bins.push(k);
    }
    anyhow::ensure!(
        !data.bins.is_empty(),
        "no line of the record excites all {m} inputs independently"
    );
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn period_detection() {
        let u: Vec<f64> = (0..300).map(|i| ((i % 100) as f64 * 0.37).sin()).collect();
        let t: Vec<f64> = (0..300).map(|i| i as f64 * 1e-3).collect();
        let rec = Record::new(t.clone(), vec![u.clone()], vec![u.clone()]).unwrap();
        assert_eq!(detect_period(&rec), 100);
        let v: Vec<f64> = (0..300).map(|i| (i as f64 * 0.37).sin()).collect();
        let rec = Record::new(t, vec![v.clone()], vec![v]).unwrap();
        assert_eq!(detect_period(&rec), 300);
    }

    #[test]
    fn bin_weights_give_parseval() {
        let n = 64;
        let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.9).sin() + 0.3).collect();
        let s = &period_spectra(&x, n)[0];
        let ms: f64 = (0..=n / 2)
            .map(|k| bin_weight(k, n) * s[k].norm_sqr())
            .sum();
        let want = x.iter().map(|v| v * v).sum::<f64>() / n as f64;
        assert!((ms - want).abs() < 1e-12, "{ms} vs {want}");
    }
}
