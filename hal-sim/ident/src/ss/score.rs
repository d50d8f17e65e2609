//! The fine-steering-mirror benchmark's official score of one periodic record (its
//! submission example): the model first runs one period of the input (warm-up), then every
//! period of the record is scored without its first [`SKIP`] samples; RMSE per output and
//! per period, then the mean. Also the floor no model can beat: the measured periods'
//! difference (noise and drift).

use super::frf::detect_period;
use crate::numeric::rmse;
use crate::record::Record;

/// Samples left out at the start of every scored period.
pub const SKIP: usize = 100;

/// Score of one record.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Official {
    /// Samples per period.
    pub period: usize,
    /// `rmse[period][output]` (output unit).
    pub rmse: Vec<Vec<f64>>,
    /// Mean over periods and outputs.
    pub mean: f64,
}

/// The scored samples `[start, end)` of each period of a record of `len` samples.
pub fn scored_windows(len: usize, period: usize) -> Vec<(usize, usize)> {
    let skip = SKIP.min(period / 4);
    (0..len / period)
        .map(|q| (q * period + skip, (q + 1) * period))
        .collect()
}

/// The input with one period of warm-up ahead of it (`u[j][..period]` repeated).
pub fn with_warmup(u: &[Vec<f64>], period: usize) -> Vec<Vec<f64>> {
    u.iter()
        .map(|x| x[..period].iter().chain(x.iter()).copied().collect())
        .collect()
}

/// Period of a record the official rule applies to (at least two periods would be nice,
/// one suffices).
pub fn period_of(rec: &Record) -> anyhow::Result<usize> {
    let n = detect_period(rec);
    anyhow::ensure!(
        n < rec.len() || rec.len() >= 4 * SKIP,
        "the record has {} samples: too short to score",
        rec.len()
    );
    Ok(n)
}

/// Scores `simulate` (inputs `u[j][k]` -> outputs `y[o][k]`, from rest) on `rec`.
pub fn official(
    rec: &Record,
    simulate: impl Fn(&[Vec<f64>]) -> anyhow::Result<Vec<Vec<f64>>>,
) -> anyhow::Result<Official> {
    anyhow::ensure!(!rec.y.is_empty(), "the record has no outputs to score");
    let n = period_of(rec)?;
    let sim = simulate(&with_warmup(&rec.u, n))?;
    anyhow::ensure!(
        sim.len() == rec.y.len(),
        "the model has {} outputs, the record {}",
        sim.len(),
        rec.y.len()
    );
    let rmse: Vec<Vec<f64>> = scored_windows(rec.len(), n)
        .into_iter()
        .map(|(a, b)| {
            rec.y
                .iter()
                .zip(&sim)
                .map(|(y, s)| rmse(&y[a..b], &s[n + a..n + b]))
                .collect()
        })
        .collect();
    let all: Vec<f64> = rmse.iter().flatten().copied().collect();
    let mean = all.iter().sum::<f64>() / all.len().max(1) as f64;
    Ok(Official {
        period: n,
        rmse,
        mean,
    })
}

/// Noise floor of a record of several periods: RMS of consecutive periods' difference
/// over `sqrt 2` on the scored samples, mean over outputs and period pairs: the error per
/// period of a model that predicts the periodic part exactly. `None` for one period.
pub fn noise_floor(rec: &Record) -> Option<f64> {
    let n = detect_period(rec);
    let w = scored_windows(rec.len(), n);
    if w.len() < 2 || rec.y.is_empty() {
        return None;
    }
    let mut vals = Vec::new();
    for pair in w.windows(2) {
        let ((a0, b0), (a1, _)) = (pair[0], pair[1]);
        for y in &rec.y {
            vals.push(rmse(&y[a0..b0], &y[a1..a1 + (b0 - a0)]) / std::f64::consts::SQRT_2);
        }
    }
    Some(vals.iter().sum::<f64>() / vals.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(period: usize, periods: usize, noise: f64) -> Record {
        let len = period * periods;
        let u: Vec<f64> = (0..len)
            .map(|k| (2.0 * std::f64::consts::PI * 3.0 * (k % period) as f64 / period as f64).sin())
            .collect();
        // Alternating +-noise per period: the periods differ by 2 noise.
        let y: Vec<f64> = (0..len)
            .map(|k| {
                2.0 * u[k]
                    + if (k / period).is_multiple_of(2) {
                        noise
                    } else {
                        -noise
                    }
            })
            .collect();
        Record {
            comments: Vec::new(),
            t: (0..len).map(|k| k as f64 * 1e-3).collect(),
            u: vec![u],
            y: vec![y],
            extra: Vec::new(),
            unit_note: None,
        }
    }

    #[test]
    fn exact_model_scores_the_offset_and_the_floor_is_the_noise() {
        let rec = record(800, 2, 0.1);
        // A model without memory: warm-up changes nothing; the error is +-0.1 everywhere.
        let s = official(&rec, |u| Ok(vec![u[0].iter().map(|v| 2.0 * v).collect()])).unwrap();
        assert_eq!(s.period, 800);
        assert_eq!(s.rmse.len(), 2);
        assert!((s.mean - 0.1).abs() < 1e-12, "{}", s.mean);
        let f = noise_floor(&rec).unwrap();
        assert!((f - 0.2 / std::f64::consts::SQRT_2).abs() < 1e-12, "{f}");
    }

    #[test]
    fn warmup_and_skip_are_the_official_ones() {
        let rec = record(800, 2, 0.0);
        // A model whose output is its sample index: the scored samples must be
        // 800 + [100, 800) and 800 + [900, 1600) of the warmed-up input.
        let s = official(&rec, |u| {
            Ok(vec![(0..u[0].len()).map(|k| k as f64).collect()])
        });
        let s = s.unwrap();
        let y = &rec.y[0];
        let want0 = rmse(
            &y[100..800],
            &(900..1600).map(|k| k as f64).collect::<Vec<_>>(),
        );
        assert!((s.rmse[0][0] - want0).abs() < 1e-9);
        assert_eq!(scored_windows(1600, 800), vec![(100, 800), (900, 1600)]);
    }
}
