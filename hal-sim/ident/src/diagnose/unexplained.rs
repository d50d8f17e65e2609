//! The residual no cause in the catalogue explains: is a significant part of it structured,
//! and where does that part live?
//!
//! The final model's residual on the validation records is grouped by six signals a person
//! can act on: the input level, the output level (the modelled position), the position in the
//! loop (input level and direction of motion), the input rate, the drive amplitude (the input's recent excursion) and the time
//! since the record's start from rest. The share of the residual variance a grouping explains
//! (between-group variance over total variance, less what as many groups explain in white
//! noise) says how structured the residual is along that signal. The residual is called
//! unexplained when it is mostly not sensor noise ([`MIN_NON_NOISE`]) and one grouping
//! explains at least [`MIN_SHARE`] of it, or, when no grouping does, when one frequency band
//! holds that share of its energy above the noise (many lightly damped modes follow no level or
//! rate); the band is reported either way.

use serde::Serialize;

use super::evidence::derivative;
use super::model::{min_max, own_input};
use super::Signals;
use crate::numeric::lowpass;

/// Smallest share of the residual variance a grouping must explain.
pub const MIN_SHARE: f64 = 0.2;
/// Smallest share of the residual variance that is not sensor noise (`1 - noise^2/rms^2`).
pub const MIN_NON_NOISE: f64 = 0.5;

/// Groups per signal.
const BINS: usize = 24;

/// One grouping of the residual.
#[derive(Debug, Clone, Serialize)]
pub struct Location {
    pub name: &'static str,
    /// Share of the residual variance explained by the grouping (noise-adjusted).
    pub share: f64,
    /// Where along the signal the residual is largest.
    pub detail: String,
}

/// The structured residual that the named causes leave.
#[derive(Debug, Clone, Serialize)]
pub struct Unexplained {
    /// Share of the residual variance the best grouping explains.
    pub share: f64,
    /// Share of the residual variance that is not sensor noise.
    pub non_noise: f64,
    pub rms: f64,
    pub noise_rms: f64,
    /// The best grouping: `input level`, `output level`, `position in the loop`, `input
    /// rate`, `amplitude` or `time since rest`; else `frequency band`.
    pub location: &'static str,
    pub detail: String,
    /// The frequency band holding most of the residual's energy above the noise.
    pub band: String,
    /// Every grouping, best first.
    pub locations: Vec<Location>,
    pub text: String,
}

/// Group labels (`0..groups`) of every sample and a phrase per group.
struct Grouping {
    name: &'static str,
    labels: Vec<usize>,
    phrases: Vec<String>,
}

/// Quantile bins of `x`: labels and the value range of each bin.
fn bins(x: &[f64], n_bins: usize, unit: &str, what: &str) -> (Vec<usize>, Vec<String>) {
    let mut sorted: Vec<f64> = x.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len().max(1);
    let edges: Vec<f64> = (0..=n_bins)
        .map(|b| sorted[((n - 1) * b) / n_bins])
        .collect();
    let labels = x
        .iter()
        .map(|v| edges[1..n_bins].partition_point(|e| e <= v))
        .collect();
    let phrases = (0..n_bins)
        .map(|b| format!("{what} {:.3}..{:.3} {unit}", edges[b], edges[b + 1]))
        .collect();
    (labels, phrases)
}

fn groupings(rec: &Signals, i: usize, r: &[f64]) -> Vec<Grouping> {
    let u = &rec.u[own_input(i, rec.u.len())];
    let dt = rec.dt();
    let n = u.len();
    let rate = lowpass(&derivative(u, dt), 2e-3_f64.max(2.0 * dt), dt);
    let mut out = Vec::new();
    let (labels, phrases) = bins(u, BINS, "V", "input");
    out.push(Grouping {
        name: "input level",
        labels,
        phrases,
    });
    // The position the model puts the stage at (measurement less residual): a sensor's
    // error that depends on the position lives here, not at an input level.
    let y = &rec.y[i];
    let x: Vec<f64> = y.iter().zip(r).map(|(y, r)| y - r).collect();
    let (labels, phrases) = bins(&x, BINS, "um", "position");
    out.push(Grouping {
        name: "output level",
        labels,
        phrases,
    });
    let half = BINS / 2;
    let (lv, pv) = bins(u, half, "V", "input");
    let (lo, hi) = min_max(&rate.iter().map(|r| r.abs()).collect::<Vec<_>>());
    let still = lo + 0.01 * (hi - lo);
    out.push(Grouping {
        name: "position in the loop",
        labels: lv
            .iter()
            .zip(&rate)
            .map(|(b, r)| if *r >= still { *b } else { b + half })
            .collect(),
        phrases: pv
            .iter()
            .map(|p| format!("{p} rising"))
            .chain(pv.iter().map(|p| format!("{p} falling")))
            .collect(),
    });
    let (labels, phrases) = bins(&rate, BINS, "V/s", "input rate");
    out.push(Grouping {
        name: "input rate",
        labels,
        phrases,
    });
    let mean = lowpass(u, 0.5, dt);
    let dev: Vec<f64> = u.iter().zip(&mean).map(|(u, m)| (u - m).abs()).collect();
    let amp = lowpass(&dev, 0.5, dt);
    let (labels, phrases) = bins(&amp, half, "V", "drive amplitude");
    out.push(Grouping {
        name: "amplitude",
        labels,
        phrases,
    });
    let t0 = rec.t.first().copied().unwrap_or(0.0);
    let since: Vec<f64> = rec.t.iter().map(|t| t - t0).collect();
    let span = since.last().copied().unwrap_or(0.0).max(1e-12);
    out.push(Grouping {
        name: "time since rest",
        labels: since
            .iter()
            .map(|s| ((s / span * half as f64) as usize).min(half - 1))
            .collect(),
        phrases: (0..half)
            .map(|b| {
                format!(
                    "{:.2}..{:.2} s after the record's start",
                    span * b as f64 / half as f64,
                    span * (b + 1) as f64 / half as f64
                )
            })
            .collect(),
    });
    debug_assert!(out.iter().all(|g| g.labels.len() == n));
    out
}

/// Between-group and total sums of squares of `r` under `labels`, and the group whose mean
/// contributes most.
fn between(r: &[f64], labels: &[usize], groups: usize) -> (f64, f64, usize) {
    let mean = r.iter().sum::<f64>() / r.len().max(1) as f64;
    let mut sum = vec![0.0; groups];
    let mut cnt = vec![0usize; groups];
    for (v, &l) in r.iter().zip(labels) {
        sum[l] += v - mean;
        cnt[l] += 1;
    }
    let contrib: Vec<f64> = sum
        .iter()
        .zip(&cnt)
        .map(|(s, &c)| if c > 0 { s * s / c as f64 } else { 0.0 })
        .collect();
    let total: f64 = r.iter().map(|v| (v - mean) * (v - mean)).sum();
    let top = (0..groups)
        .max_by(|a, b| contrib[*a].total_cmp(&contrib[*b]))
        .unwrap_or(0);
    (contrib.iter().sum(), total, top)
}

/// `r` less the mean of its group under `labels`.
fn without_means(r: &[f64], labels: &[usize], groups: usize) -> Vec<f64> {
    let mut sum = vec![0.0; groups];
    let mut cnt = vec![0usize; groups];
    for (v, &l) in r.iter().zip(labels) {
        sum[l] += v;
        cnt[l] += 1;
    }
    r.iter()
        .zip(labels)
        .map(|(v, &l)| v - sum[l] / cnt[l].max(1) as f64)
        .collect()
}

/// The band of `r` (below 1 Hz, 1-10, 10-100, 100-1000 Hz, above) holding most of its
/// energy above the white noise's share of that band: its name and that excess as a share of
/// the residual's energy.
fn band(r: &[f64], dt: f64, noise_rms: f64) -> (String, f64) {
    let tau = |hz: f64| 1.0 / (2.0 * std::f64::consts::PI * hz);
    let nyq = 0.5 / dt;
    let cuts: Vec<f64> = [1.0, 10.0, 100.0, 1000.0]
        .into_iter()
        .filter(|&hz| hz < 0.5 * nyq)
        .collect();
    let mut lows: Vec<Vec<f64>> = cuts.iter().map(|&hz| lowpass(r, tau(hz), dt)).collect();
    lows.push(r.to_vec());
    let var = |x: &[f64]| {
        let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
        x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len().max(1) as f64
    };
    let total = var(r).max(1e-300);
    let mut excess = Vec::new();
    let mut prev: Option<&Vec<f64>> = None;
    for (k, l) in lows.iter().enumerate() {
        let part: Vec<f64> = match prev {
            Some(p) => l.iter().zip(p).map(|(a, b)| a - b).collect(),
            None => l.clone(),
        };
        // White noise spreads evenly up to the Nyquist frequency.
        let lo = if k == 0 { 0.0 } else { cuts[k - 1] };
        let hi = cuts.get(k).copied().unwrap_or(nyq);
        let white = noise_rms * noise_rms * (hi - lo) / nyq;
        excess.push((var(&part) - white).max(0.0));
        prev = Some(l);
    }
    let k = (0..excess.len())
        .max_by(|a, b| excess[*a].total_cmp(&excess[*b]))
        .unwrap_or(0);
    let lo = if k == 0 { 0.0 } else { cuts[k - 1] };
    let name = match cuts.get(k) {
        Some(hi) => format!("{lo:.0}-{hi:.0} Hz"),
        None => format!("above {lo:.0} Hz"),
    };
    (name, (excess[k] / total).clamp(0.0, 1.0))
}

/// The structured part of `residual` (per record, per output, on the scored samples of
/// `scored`), if it is significant.
pub fn find(scored: &[Signals], residual: &[Vec<Vec<f64>>], noise_rms: f64) -> Option<Unexplained> {
    /// One grouping pooled over records and outputs.
    struct Pool {
        name: &'static str,
        between: f64,
        total: f64,
        /// Expected between-group share of white noise, summed over the pooled series.
        chance: f64,
        n: usize,
        /// The series with the largest between-group part names the place.
        top: (f64, String),
    }
    let mut pools: Vec<Pool> = Vec::new();
    let (mut ss, mut count) = (0.0, 0usize);
    let mut band_of = (0.0, String::new(), 0.0);
    // Every series' residual and groupings, for the tie-break between the best two.
    let mut series: Vec<(&[f64], Vec<Grouping>)> = Vec::new();
    for (rec, res) in scored.iter().zip(residual) {
        for (i, r) in res.iter().enumerate() {
            let n = r.len();
            if n < 2 * BINS {
                continue;
            }
            let e: f64 = r.iter().map(|v| v * v).sum();
            ss += e;
            count += n;
            let gs = groupings(rec, i, r);
            for (g, grouping) in gs.iter().enumerate() {
                let groups = grouping.phrases.len();
                let (b, tot, top) = between(r, &grouping.labels, groups);
                if pools.len() <= g {
                    pools.push(Pool {
                        name: grouping.name,
                        between: 0.0,
                        total: 0.0,
                        chance: 0.0,
                        n: 0,
                        top: (0.0, String::new()),
                    });
                }
                let p = &mut pools[g];
                p.between += b;
                p.total += tot;
                // As many groups explain about (groups - 1)/n of white noise.
                p.chance += groups as f64 - 1.0;
                p.n += n;
                if b > p.top.0 {
                    p.top = (b, grouping.phrases[top].clone());
                }
            }
            if e > band_of.0 {
                let (name, share) = band(r, rec.dt(), noise_rms);
                band_of = (e, name, share);
            }
            series.push((r, gs));
        }
    }
    if count == 0 {
        return None;
    }
    let rms = (ss / count as f64).sqrt();
    let non_noise = 1.0 - (noise_rms * noise_rms) / (rms * rms).max(1e-300);
    let mut locations: Vec<Location> = pools
        .into_iter()
        .map(|p| {
            let chance = p.chance / p.n.max(1) as f64;
            let r2 = if p.total > 0.0 {
                p.between / p.total
            } else {
                0.0
            };
            Location {
                name: p.name,
                share: ((r2 - chance) / (1.0 - chance)).clamp(0.0, 1.0),
                detail: p.top.1,
            }
        })
        .collect();
    locations.sort_by(|a, b| b.share.total_cmp(&a.share));
    // Two groupings that both explain much may share it (the input level also changes with
    // time): the one that explains more of what the other leaves is where it lives.
    if locations.len() > 1 && locations[1].share >= MIN_SHARE {
        let unique = |a: &str, b: &str| -> f64 {
            let (mut bt, mut tot) = (0.0, 0.0);
            for (r, gs) in &series {
                let find = |name: &str| gs.iter().find(|g| g.name == name);
                if let (Some(ga), Some(gb)) = (find(a), find(b)) {
                    let left = without_means(r, &gb.labels, gb.phrases.len());
                    let (x, t, _) = between(&left, &ga.labels, ga.phrases.len());
                    bt += x;
                    tot += t;
                }
            }
            if tot > 0.0 {
                bt / tot
            } else {
                0.0
            }
        };
        let (a, b) = (locations[0].name, locations[1].name);
        if unique(b, a) > unique(a, b) {
            locations.swap(0, 1);
        }
    }
    // A signal a person can act on first; else the frequency band, when the residual's
    // excess energy sits in one band (many lightly damped modes: no level or rate groups it).
    let band_location = Location {
        name: "frequency band",
        share: band_of.2,
        detail: band_of.1.clone(),
    };
    let best = match locations.first() {
        Some(b) if b.share >= MIN_SHARE => b.clone(),
        _ => band_location.clone(),
    };
    locations.push(band_location);
    if non_noise < MIN_NON_NOISE || best.share < MIN_SHARE {
        return None;
    }
    let text = format!(
        "{:.0} % of the residual (rms {rms:.4}, noise {noise_rms:.4}) is not noise, and no cause in the catalogue explains it: {:.0} % of it follows the {} (largest at {}); its energy above the noise lies mostly in {} ({:.0} % of the residual)",
        100.0 * non_noise,
        100.0 * best.share,
        best.name,
        best.detail,
        band_of.1,
        100.0 * band_of.2
    );
    Some(Unexplained {
        share: best.share,
        non_noise,
        rms,
        noise_rms,
        location: best.name,
        detail: best.detail,
        band: band_of.1,
        locations,
        text,
    })
}
