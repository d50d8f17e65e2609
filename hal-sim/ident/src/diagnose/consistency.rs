//! The consistency check: the same discovery run on other arrangements of the same data
//! (splits of a record at other fractions, the records' roles swapped), and the causes that
//! hold in every arrangement told apart from those that do not.
//!
//! A cause named in every arrangement is `confident`; one named in some only is `uncertain`,
//! with the arrangements that name it and those that do not. The reported model and gains
//! stay those of the first arrangement (the one asked for), so `--predict` still reproduces
//! them.

use serde::Serialize;

use super::{diagnose_records, Cause, Diagnosis, Options, Signals};

/// Split fractions every single-record run is checked at.
pub const SPLITS: [f64; 3] = [0.5, 0.65, 0.8];

/// One way of using the data: which records train, which validate.
#[derive(Debug, Clone)]
pub struct Arrangement {
    /// `split 0.65`, `swapped`, ...
    pub label: String,
    pub train: Vec<Signals>,
    pub valid: Vec<Signals>,
}

impl Arrangement {
    /// Every record split at `fraction` of its samples: the first part trains, the rest
    /// validates with the first part as warm-up.
    pub fn split(records: &[Signals], fraction: f64) -> Self {
        let (mut train, mut valid) = (Vec::new(), Vec::new());
        for r in records {
            let lo = 50.min(r.len() / 2);
            let hi = r.len().saturating_sub(50).max(lo);
            let k = ((r.len() as f64 * fraction).round() as usize).clamp(lo, hi);
            train.push(r.slice(0, k));
            valid.push(r.clone().with_warmup(k));
        }
        Self {
            label: format!("split {fraction}"),
            train,
            valid,
        }
    }

    /// The records' roles swapped.
    pub fn swapped(train: &[Signals], valid: &[Signals]) -> Self {
        Self {
            label: "swapped".into(),
            train: valid.to_vec(),
            valid: train.to_vec(),
        }
    }
}

/// Whether a cause holds in every arrangement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    Confident,
    Uncertain,
}

/// One cause named in at least one arrangement.
#[derive(Debug, Clone, Serialize)]
pub struct CauseCheck {
    pub cause: Cause,
    pub status: Status,
    /// Arrangements that name it.
    pub named_in: Vec<String>,
    /// Arrangements that do not.
    pub not_in: Vec<String>,
}

/// The causes each arrangement names.
#[derive(Debug, Clone, Serialize)]
pub struct Named {
    pub label: String,
    pub causes: Vec<Cause>,
}

/// The consistency report.
#[derive(Debug, Clone, Serialize)]
pub struct Consistency {
    pub arrangements: Vec<Named>,
    pub causes: Vec<CauseCheck>,
}

impl Consistency {
    /// The report's JSON: every arrangement's causes, each cause's status, and the confident
    /// and uncertain causes by name (`piezo diagnose --json` key `consistency`).
    pub fn json(&self) -> serde_json::Value {
        let names = |v: Vec<Cause>| v.iter().map(|c| c.name()).collect::<Vec<_>>();
        serde_json::json!({
            "arrangements": self.arrangements,
            "causes": self.causes,
            "confident": names(self.confident()),
            "uncertain": names(self.uncertain()),
        })
    }

    /// Compares the causes named by each arrangement (the first is the one asked for).
    pub fn of(named: Vec<Named>) -> Self {
        let mut all: Vec<Cause> = named.iter().flat_map(|n| n.causes.clone()).collect();
        all.sort();
        all.dedup();
        // The first arrangement's causes first, in the order it named them.
        if let Some(first) = named.first() {
            all.sort_by_key(|c| {
                first
                    .causes
                    .iter()
                    .position(|x| x == c)
                    .unwrap_or(usize::MAX)
            });
        }
        let causes = all
            .into_iter()
            .map(|c| {
                let (yes, no): (Vec<&Named>, Vec<&Named>) =
                    named.iter().partition(|n| n.causes.contains(&c));
                CauseCheck {
                    cause: c,
                    status: if no.is_empty() {
                        Status::Confident
                    } else {
                        Status::Uncertain
                    },
                    named_in: yes.iter().map(|n| n.label.clone()).collect(),
                    not_in: no.iter().map(|n| n.label.clone()).collect(),
                }
            })
            .collect();
        Self {
            arrangements: named,
            causes,
        }
    }

    /// Causes named in every arrangement.
    pub fn confident(&self) -> Vec<Cause> {
        self.causes
            .iter()
            .filter(|c| c.status == Status::Confident)
            .map(|c| c.cause)
            .collect()
    }

    /// Causes named in some arrangements only.
    pub fn uncertain(&self) -> Vec<Cause> {
        self.causes
            .iter()
            .filter(|c| c.status == Status::Uncertain)
            .map(|c| c.cause)
            .collect()
    }

    /// One line for a person: `confident: creep; uncertain: drift (named in split 0.5; not
    /// in split 0.65, split 0.8)`.
    pub fn text(&self) -> String {
        let names = |v: Vec<Cause>| {
            if v.is_empty() {
                "none".to_string()
            } else {
                v.iter().map(|c| c.name()).collect::<Vec<_>>().join(", ")
            }
        };
        let labels: Vec<&str> = self.arrangements.iter().map(|a| a.label.as_str()).collect();
        let mut s = format!(
            "consistency over {}: confident {}",
            labels.join(", "),
            names(self.confident())
        );
        let uncertain: Vec<String> = self
            .causes
            .iter()
            .filter(|c| c.status == Status::Uncertain)
            .map(|c| {
                format!(
                    "{} (named in {}; not in {})",
                    c.cause.name(),
                    c.named_in.join(", "),
                    c.not_in.join(", ")
                )
            })
            .collect();
        if !uncertain.is_empty() {
            s.push_str("; uncertain ");
            s.push_str(&uncertain.join("; "));
        }
        s
    }
}

/// The other arrangements a run on `whole` records split at `fraction` checks itself on: the
/// same records split at each other fraction of [`SPLITS`].
pub fn other_splits(whole: &[Signals], fraction: f64) -> Vec<Arrangement> {
    SPLITS
        .iter()
        .filter(|&&s| (s - fraction).abs() > 1e-9)
        .map(|&s| Arrangement::split(whole, s))
        .collect()
}

/// Runs the discovery on every arrangement in `others` and compares their causes with
/// `first` (the diagnosis of the arrangement asked for, labelled `label`).
pub fn check(
    label: &str,
    first: &Diagnosis,
    others: &[Arrangement],
    opt: &Options,
) -> anyhow::Result<Consistency> {
    let mut named = vec![Named {
        label: label.to_string(),
        causes: first.findings.iter().map(|f| f.cause).collect(),
    }];
    for a in others {
        let d = diagnose_records(&a.train, &a.valid, opt)?;
        named.push(Named {
            label: a.label.clone(),
            causes: d.findings.iter().map(|f| f.cause).collect(),
        });
    }
    Ok(Consistency::of(named))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confident_only_when_every_arrangement_names_it() {
        let c = Consistency::of(vec![
            Named {
                label: "split 0.5".into(),
                causes: vec![Cause::Creep, Cause::Drift],
            },
            Named {
                label: "split 0.65".into(),
                causes: vec![Cause::Creep],
            },
            Named {
                label: "split 0.8".into(),
                causes: vec![Cause::StartupCreep, Cause::Creep],
            },
        ]);
        assert_eq!(c.confident(), vec![Cause::Creep]);
        assert_eq!(c.uncertain(), vec![Cause::Drift, Cause::StartupCreep]);
        let drift = &c.causes[1];
        assert_eq!(drift.named_in, ["split 0.5"]);
        assert_eq!(drift.not_in, ["split 0.65", "split 0.8"]);
        assert!(c
            .text()
            .contains("confident creep; uncertain drift (named in split 0.5"));
        let none = Consistency::of(vec![Named {
            label: "a".into(),
            causes: vec![],
        }]);
        assert!(none.causes.is_empty() && none.text().contains("confident none"));
    }
}
