//! The record `piezo diagnose` works on: time, inputs and outputs, and the warm-up.

/// Time, inputs and outputs of a record (`u[k][i]`: channel `k`, sample `i`).
#[derive(Debug, Clone, PartialEq)]
pub struct Signals {
    pub t: Vec<f64>,
    pub u: Vec<Vec<f64>>,
    pub y: Vec<Vec<f64>>,
    /// Leading samples that only bring the model's state up to date and are not scored
    /// (a validation record that continues the training record: the hysteresis state at
    /// its start is known only from the input before it).
    pub warmup: usize,
}

impl Signals {
    /// Checks shapes and values; at least 50 samples, finite, `t` increasing.
    pub fn new(t: Vec<f64>, u: Vec<Vec<f64>>, y: Vec<Vec<f64>>) -> anyhow::Result<Self> {
        let n = t.len();
        anyhow::ensure!(n >= 50, "record has {n} samples, at least 50 needed");
        anyhow::ensure!(!u.is_empty(), "record has no input column");
        anyhow::ensure!(!y.is_empty(), "record has no output column");
        anyhow::ensure!(
            u.len() == 1 || u.len() == y.len(),
            "record has {} inputs and {} outputs: need one input, or one input per output",
            u.len(),
            y.len()
        );
        for (name, chans) in [("u", &u), ("y", &y)] {
            for (k, c) in chans.iter().enumerate() {
                anyhow::ensure!(
                    c.len() == n,
                    "column {name}{} has {} samples, t has {n}",
                    k + 1,
                    c.len()
                );
                if let Some(i) = c.iter().position(|v| !v.is_finite()) {
                    anyhow::bail!("column {name}{} sample {i} is not finite", k + 1);
                }
            }
        }
        anyhow::ensure!(
            t.windows(2).all(|w| w[1] > w[0]) && t.iter().all(|v| v.is_finite()),
            "time column must be finite and strictly increasing"
        );
        Ok(Self { t, u, y, warmup: 0 })
    }

    /// The same record, scored only from sample `k` on.
    pub fn with_warmup(mut self, k: usize) -> Self {
        self.warmup = k.min(self.len().saturating_sub(50));
        self
    }

    /// The scored samples.
    pub fn scored(&self) -> Self {
        self.slice(self.warmup, self.len())
    }

    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Mean sample period (s).
    pub fn dt(&self) -> f64 {
        let n = self.t.len();
        if n < 2 {
            return 1.0;
        }
        (self.t[n - 1] - self.t[0]) / (n - 1) as f64
    }

    /// Every `m`-th sample.
    pub fn decimate(&self, m: usize) -> Self {
        let m = m.max(1);
        let pick = |c: &Vec<f64>| c.iter().step_by(m).copied().collect::<Vec<_>>();
        Self {
            t: pick(&self.t),
            u: self.u.iter().map(pick).collect(),
            y: self.y.iter().map(pick).collect(),
            warmup: 0,
        }
    }

    /// Samples `a..b`.
    pub fn slice(&self, a: usize, b: usize) -> Self {
        let b = b.min(self.len());
        let a = a.min(b);
        let cut = |c: &Vec<f64>| c[a..b].to_vec();
        Self {
            t: cut(&self.t),
            u: self.u.iter().map(cut).collect(),
            y: self.y.iter().map(cut).collect(),
            warmup: 0,
        }
    }
}

impl From<&crate::record::Record> for Signals {
    fn from(r: &crate::record::Record) -> Self {
        Self {
            t: r.t.clone(),
            u: r.u.clone(),
            y: r.y.clone(),
            warmup: 0,
        }
    }
}
