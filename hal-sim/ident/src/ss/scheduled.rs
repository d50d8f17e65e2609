//! Amplitude-scheduled state-space model (`piezo fit --model scheduled-ss`): a local
//! linear model network. One modal model per excitation level, each identified on the
//! BLA of that level's records; in simulation all of them run on the input and their
//! outputs are blended with piecewise-linear weights of `l`, a causal running RMS of the
//! inputs (clamped to the training levels). This is the describing-function picture of a
//! nonlinearity in feedback around the structure: in a stationary excitation the
//! nonlinearity acts as an equivalent gain that depends on the level and moves the
//! resonances (the FSM's shift with amplitude, differently per output, which no
//! input-side hysteresis produces). It models how the dynamics change with the level,
//! not the distortion at one level; at a training level it is that level's linear model,
//! between levels an interpolation, and it holds for excitations whose level changes
//! slowly against `tau`.

use super::frf::{self, PeriodicSpectra};
use super::model::{Modal, ModalJson};
use super::pem::{self, LineStats, PemConfig};
use super::subspace;
use crate::record::Record;
use serde::{Deserialize, Serialize};

/// Records whose levels differ by less than this ratio form one group.
const GROUP_RATIO: f64 = 1.15;

/// The schedule in `fit.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Schedule {
    /// Input level (RMS over the inputs, input unit) of each local model, ascending.
    pub levels: Vec<f64>,
    /// Time constant of the running mean square of the inputs (s).
    pub tau_s: f64,
    /// The local models, one per level.
    pub local: Vec<ModalJson>,
}

/// Piecewise-linear weights of the levels at `l` (clamped to their range).
fn weights(levels: &[f64], l: f64, w: &mut [f64]) {
    w.iter_mut().for_each(|x| *x = 0.0);
    let last = levels.len() - 1;
    if l <= levels[0] {
        w[0] = 1.0;
    } else if l >= levels[last] {
        w[last] = 1.0;
    } else {
        let i = levels.windows(2).position(|p| l < p[1]).unwrap_or(last - 1);
        let f = (l - levels[i]) / (levels[i + 1] - levels[i]);
        w[i] = 1.0 - f;
        w[i + 1] = f;
    }
}

impl Schedule {
    /// The local models, checked against the shape of `like`.
    pub fn models(&self, like: &Modal) -> anyhow::Result<Vec<Modal>> {
        anyhow::ensure!(
            !self.levels.is_empty()
                && self.levels.len() == self.local.len()
                && self.levels.iter().all(|l| l.is_finite())
                && self.levels.windows(2).all(|p| p[0] < p[1])
                && self.tau_s.is_finite()
                && self.tau_s > 0.0,
            "fit.json: the schedule needs ascending finite levels, one local model each, \
             and tau_s > 0"
        );
        self.local
            .iter()
            .map(|j| {
                let m = Modal::from_json(j)?;
                anyhow::ensure!(
                    m.inputs() == like.inputs() && m.outputs() == like.outputs(),
                    "fit.json: a local model is {} x {}, the model {} x {}",
                    m.outputs(),
                    m.inputs(),
                    like.outputs(),
                    like.inputs()
                );
                Ok(m)
            })
            .collect()
    }

    /// Simulates from rest (states and running mean square zero, so the lowest level
    /// first); `u[j][k]` is input `j` at sample `k`, sampled every `dt` s.
    pub fn simulate(&self, like: &Modal, u: &[Vec<f64>], dt: f64) -> anyhow::Result<Vec<Vec<f64>>> {
        let models = self.models(like)?;
        let m = like.inputs();
        anyhow::ensure!(
            u.len() == m,
            "the model has {m} inputs, the record {}",
            u.len()
        );
        let ys = models
            .iter()
            .map(|md| md.simulate(u))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let len = u.first().map_or(0, Vec::len);
        let alpha = 1.0 - (-dt / self.tau_s).exp();
        let mut ms = 0.0;
        let mut w = vec![0.0; models.len()];
        let mut y = vec![vec![0.0; len]; like.outputs()];
        for k in 0..len {
            let u2: f64 = u.iter().map(|x| x[k] * x[k]).sum::<f64>() / m as f64;
            ms += alpha * (u2 - ms);
            weights(&self.levels, ms.max(0.0).sqrt(), &mut w);
            for (o, yo) in y.iter_mut().enumerate() {
                yo[k] = ys.iter().zip(&w).map(|(yl, wl)| wl * yl[o][k]).sum();
            }
        }
        Ok(y)
    }
}

/// Steady-state input level of a record: RMS over the inputs of its last period.
pub fn record_level(rec: &Record, period: usize) -> f64 {
    let start = rec.len() - period.min(rec.len());
    let m = rec.u.len().max(1);
    let ms: f64 = rec
        .u
        .iter()
        .map(|u| u[start..].iter().map(|v| v * v).sum::<f64>())
        .sum::<f64>()
        / ((rec.len() - start).max(1) * m) as f64;
    ms.sqrt()
}

/// Groups record indices by level (ascending): a new group where a level exceeds the
/// group's first by `GROUP_RATIO`.
pub fn group_by_level(levels: &[f64]) -> Vec<Vec<usize>> {
    let mut idx: Vec<usize> = (0..levels.len()).collect();
    idx.sort_by(|&a, &b| levels[a].total_cmp(&levels[b]));
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in idx {
        match groups.last_mut() {
            Some(g) if levels[i] <= GROUP_RATIO * levels[g[0]] => g.push(i),
            _ => groups.push(vec![i]),
        }
    }
    groups
}

/// Identifies one local model per level, of the order of `global` (the model of all
/// records): the output-error refinement `cfg` on the level's BLA from two starts, the
/// subspace estimate and `global` with its `B, D` refitted, keeping the lower training
/// cost (the refinement finds a local minimum; a lightly damped mode that moved with the
/// level by more than its bandwidth traps it, and `global` already has the modes roughly
/// where every level has them). Returns the schedule and the summed cost.
pub fn identify(
    recs: &[Record],
    spectra: &[PeriodicSpectra],
    global: &Modal,
    tau_s: f64,
    cfg: &PemConfig,
) -> anyhow::Result<(Schedule, f64)> {
    anyhow::ensure!(
        tau_s.is_finite() && tau_s > 0.0,
        "the schedule time constant must be positive"
    );
    anyhow::ensure!(
        !spectra.is_empty() && spectra.len() == recs.len(),
        "the scheduled model needs periodic records (multisines of whole periods)"
    );
    let m = recs[0].u.len();
    let levels: Vec<f64> = recs
        .iter()
        .map(|r| record_level(r, spectra[0].period))
        .collect();
    let groups = group_by_level(&levels);
    let mut sched = Schedule {
        levels: Vec::new(),
        tau_s,
        local: Vec::new(),
    };
    let mut total = 0.0;
    for g in &groups {
        let level = g.iter().map(|&i| levels[i]).sum::<f64>() / g.len() as f64;
        anyhow::ensure!(
            g.len() >= m,
            "the level {level:.4} has {} records; its BLA needs at least {m} (one per input; \
             levels within {:.0} % are one group)",
            g.len(),
            100.0 * (GROUP_RATIO - 1.0)
        );
        let sp: Vec<PeriodicSpectra> = g.iter().map(|&i| spectra[i].clone()).collect();
        let data = frf::bla(&sp)?.data;
        let stats = LineStats::from_frf(&data);
        let mut warm = global.clone();
        subspace::fit_bd(&mut warm, &data)?;
        let starts = [
            ("model of all levels", warm),
            (
                "subspace estimate",
                subspace::identify(&data, global.order())?,
            ),
        ];
        let mut best: Option<pem::Refined> = None;
        for (name, start) in starts {
            let lcfg = PemConfig {
                progress: cfg
                    .progress
                    .as_ref()
                    .map(|l| format!("{l}, level {level:.4}, from the {name}")),
                ..cfg.clone()
            };
            let r = pem::refine(&start, &[], (&[], &[]), &|_, _| Ok(stats.clone()), &lcfg)?;
            if best.as_ref().is_none_or(|b| r.cost < b.cost) {
                best = Some(r);
            }
        }
        let r = best.ok_or_else(|| anyhow::anyhow!("no local model"))?;
        total += r.cost;
        sched.levels.push(level);
        sched.local.push(r.model.to_json());
    }
    Ok((sched, total))
}

#[cfg(test)]
mod tests {
    use super::super::model::Block;
    use super::*;

    #[test]
    fn weights_interpolate_and_clamp() {
        let lv = [1.0, 2.0, 4.0];
        let mut w = [0.0; 3];
        weights(&lv, 0.5, &mut w);
        assert_eq!(w, [1.0, 0.0, 0.0]);
        weights(&lv, 3.0, &mut w);
        assert_eq!(w, [0.0, 0.5, 0.5]);
        weights(&lv, 9.0, &mut w);
        assert_eq!(w, [0.0, 0.0, 1.0]);
    }

    /// A static gain per level: once the running RMS has settled on a level, the output
    /// is that level's model alone; the two levels' outputs differ.
    #[test]
    fn simulate_follows_the_input_level() {
        let gain = |k: f64| ModalJson {
            blocks: vec![Block::Real(0.5)],
            b: vec![vec![0.0]],
            c: vec![vec![0.0]],
            d: vec![vec![k]],
        };
        let s = Schedule {
            levels: vec![1.0, 2.0],
            tau_s: 0.01,
            local: vec![gain(3.0), gain(5.0)],
        };
        let like = Modal::from_json(&gain(1.0)).unwrap();
        for (amp, k) in [(1.0, 3.0), (2.0, 5.0)] {
            // A square wave of RMS `amp`, 1 s at 1 kHz (100 time constants).
            let u: Vec<f64> = (0..1000)
                .map(|i| if i % 2 == 0 { amp } else { -amp })
                .collect();
            let y = s.simulate(&like, std::slice::from_ref(&u), 1e-3).unwrap();
            for i in 900..1000 {
                assert!(
                    (y[0][i] - k * u[i]).abs() < 1e-6 * amp,
                    "{amp}: {}",
                    y[0][i]
                );
            }
        }
    }

    #[test]
    fn groups_by_level() {
        let g = group_by_level(&[0.2, 0.1, 0.101, 0.3, 0.205]);
        assert_eq!(g, vec![vec![1, 2], vec![0, 4], vec![3]]);
    }
}
