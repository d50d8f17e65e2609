//! What `piezo diagnose` and the Python package's `piezo.diagnose` make of a [`Diagnosis`]:
//! the records split when no validation record is given, the JSON report and the summary
//! for a person.
use std::fmt::Write as _;

use serde_json::{json, Value};

use super::{Diagnosis, Finding, Signals};
use crate::identify::split_sample;

/// Training and validation records cut from training records alone.
#[derive(Debug, Clone)]
pub struct Halves {
    pub train: Vec<Signals>,
    pub valid: Vec<Signals>,
    /// What was split where (the report's `split`).
    pub note: String,
}

/// Splits every record (read from `names`) at `fraction` of its samples: the first part
/// fits, the model runs through it into the rest, which alone validates.
pub fn split_records(
    records: Vec<Signals>,
    names: &[String],
    fraction: f64,
) -> anyhow::Result<Halves> {
    let mut notes = Vec::new();
    let (mut train, mut valid) = (Vec::new(), Vec::new());
    for (whole, name) in records.into_iter().zip(names) {
        let k = split_sample(whole.len(), fraction)?;
        notes.push(format!(
            "samples 0..{k} of {name} fit, {k}..{} validate",
            whole.len()
        ));
        train.push(whole.slice(0, k));
        valid.push(whole.with_warmup(k));
    }
    Ok(Halves {
        train,
        valid,
        note: format!(
            "no --valid: {} (the model runs through the first part to reach them)",
            notes.join("; ")
        ),
    })
}

/// The JSON report of `piezo diagnose --json`: [`Diagnosis::json`] with how the records were
/// split (`split_note`), the files (`records.train_files`, `records.valid_files`, with
/// several records) and the plots written.
pub fn json(
    d: &Diagnosis,
    split_note: Option<&str>,
    train_files: &[String],
    valid_files: &[String],
    plots: &[String],
) -> Value {
    let mut j = d.json();
    if let Some(note) = split_note {
        j["split"] = json!(note);
    }
    if j.get("records").is_some() {
        j["records"]["train_files"] = json!(train_files);
        j["records"]["valid_files"] = json!(valid_files);
    }
    j["plots"] = json!(plots);
    j
}

/// The report for a person (`piezo diagnose` without `--json`).
pub fn summary(d: &Diagnosis, split_note: Option<&str>) -> String {
    let mut s = String::new();
    if let Some(n) = split_note {
        let _ = writeln!(s, "split: {n}");
    }
    let _ = writeln!(
        s,
        "base {}: rmse train {:.4}, valid {:.4} (noise about {:.4})",
        d.base.causes.label(),
        d.base.rmse_train,
        d.base_valid,
        d.noise_rms
    );
    for c in &d.candidates {
        let _ = writeln!(
            s,
            "  round {} {:<14} valid {:.4}  gain {:+6.1} %  evidence R2 {:.2}{}",
            c.round,
            c.cause.name(),
            c.rmse_valid,
            100.0 * c.gain,
            c.evidence.r2,
            if c.significant { "  *" } else { "" }
        );
    }
    if d.findings.is_empty() {
        let _ = writeln!(
            s,
            "cause: none (no extension gains on the validation record)"
        );
    }
    // What a finding gained: `cause: <name> (round <k>): valid rmse <before> -> <after> (<gain> %`.
    let head = |f: &Finding| {
        format!(
            "cause: {} (round {}): valid rmse {:.4} -> {:.4} ({:.1} %",
            f.cause.name(),
            f.round,
            f.rmse_valid_before,
            f.rmse_valid,
            100.0 * f.gain
        )
    };
    for f in &d.findings {
        if let Some(u) = &f.upgrades {
            let _ = writeln!(s, "{}), upgraded below", head(u));
        }
        let swapped = f.confidence.swapped_gain.map_or_else(String::new, |g| {
            format!(", {:.1} % with the records swapped", 100.0 * g)
        });
        let _ = writeln!(
            s,
            "{}; gains on {:.0} % of the validation blocks, worst block {:+.1} %{swapped}); {}",
            head(f),
            100.0 * f.confidence.share_gaining,
            100.0 * f.confidence.min_gain,
            f.evidence.text
        );
    }
    for (c, g) in &d.refused {
        let _ = writeln!(
            s,
            "refused: {} (gains {:.1} % with the records swapped: does not hold up)",
            c.name(),
            100.0 * g
        );
    }
    if let Some(l) = &d.lag {
        let _ = writeln!(
            s,
            "lag: {:.3} ms kept in the model, not named: a sensor delay and a structural mode fit it alike (valid rmse {:.4} / {:.4}); a drive reaching towards the mode would tell them apart",
            1e3 * l.delay_s,
            l.rmse_valid_delay,
            l.rmse_valid_mode
        );
    }
    if let Some(u) = &d.unexplained {
        let _ = writeln!(s, "unexplained: {}", u.text);
    }
    let _ = writeln!(
        s,
        "extended {}: rmse train {:.4}, valid {:.4}; gain {:.1} %",
        d.extended.causes.label(),
        d.extended.rmse_train,
        d.extended_valid,
        100.0 * d.gain()
    );
    if d.n_train > 1 || d.per_valid.len() > 1 {
        let _ = writeln!(s, "{} training records; per validation record:", d.n_train);
        for (k, r) in d.per_valid.iter().enumerate() {
            let _ = writeln!(
                s,
                "  valid {}: rmse base {:.4} -> extended {:.4} (gain {:.1} %)",
                k + 1,
                r.rmse_base,
                r.rmse_extended,
                100.0 * r.gain
            );
        }
    }
    s
}
