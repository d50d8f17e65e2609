//! `piezo diagnose-bench`: `piezo diagnose` on the independent generator's cases
//! ([`crate::independent`]): per cause recall and false positives, exact-set accuracy per
//! number of hidden causes, time per case.
//!
//! ```text
//! piezo diagnose-bench --cases 300 --seed 1 --out out/diagnose-bench
//! piezo diagnose-bench --cases 300 --seed 1 --case 17 --out out/one   # one case again
//! piezo diagnose-bench --cases 60 --seed 8 --consistency   # also the confident causes
//! ```
//!
//! Diagnose is a black box here: the training and validation records go in through the
//! same library call the `piezo diagnose` CLI makes, the named causes come out.
use anyhow::{Context, Result};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use crate::ident::diagnose::consistency::{self, Arrangement};
use crate::ident::diagnose::{self, Options, Signals};
use crate::independent::{self, Case, CAUSES};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of cases (cases 0..N of the table drawn from --seed).
    #[arg(long, default_value_t = 300)]
    pub cases: usize,
    /// The table's seed (case i depends only on the seed and i).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run only these case numbers of the table (repeatable).
    #[arg(long = "case")]
    pub only: Vec<usize>,
    /// Write table.md, table.json and per case its records and answer (case-NNN/).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Cases run at once (1: one after another, diagnose using every core itself).
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// Fail (exit 1) when the exact-set accuracy over all cases is below this share.
    #[arg(long)]
    pub min_exact: Option<f64>,
    /// Fail (exit 1) when the share of hidden causes named (over all cases) is below this.
    #[arg(long)]
    pub min_recall: Option<f64>,
    /// Also run the check `piezo diagnose` runs on a pair (the rule again with the records'
    /// roles swapped) and score the confident causes (named both ways) in a second table.
    #[arg(long)]
    pub consistency: bool,
}

/// One case's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct Outcome {
    pub index: usize,
    pub truth: Vec<&'static str>,
    /// Named by diagnose (sorted); empty when it answered `none` or failed.
    pub named: Vec<String>,
    pub missing: Vec<String>,
    pub extra: Vec<String>,
    pub exact: bool,
    /// Diagnose's error, if it failed.
    pub error: Option<String>,
    /// Wall time of diagnose alone (s).
    pub time_s: f64,
    /// Wall time of drawing and simulating the case (s).
    pub gen_s: f64,
    pub presence_ok: bool,
    /// With `--consistency`: the causes named both as given and with the records swapped
    /// (sorted; empty when the check failed, see `error`).
    pub confident: Option<Vec<String>>,
}

impl Outcome {
    /// The outcome of naming `named` (sorted) where `truth` is hidden.
    fn scored(&self, named: Vec<String>) -> Self {
        let missing: Vec<String> = self
            .truth
            .iter()
            .filter(|c| !named.iter().any(|n| n == *c))
            .map(|c| c.to_string())
            .collect();
        let extra: Vec<String> = named
            .iter()
            .filter(|n| !self.truth.contains(&n.as_str()))
            .cloned()
            .collect();
        Self {
            exact: self.error.is_none() && missing.is_empty() && extra.is_empty(),
            named,
            missing,
            extra,
            ..self.clone()
        }
    }

    /// The same case scored on its confident causes (itself without `--consistency`).
    pub fn confident_only(&self) -> Self {
        match &self.confident {
            Some(c) => self.scored(c.clone()),
            None => self.clone(),
        }
    }
}

fn signals(r: &crate::record::Record) -> Result<Signals> {
    Signals::new(r.t.clone(), r.u.clone(), r.y.clone()).context("generated record")
}

/// Runs diagnose on one case (as `piezo diagnose --train train.csv --valid valid.csv`; with
/// `consistency` also its check with the records swapped, as the CLI runs it).
fn run_case(case: &Case, consistency: bool) -> (Outcome, serde_json::Value) {
    let t0 = Instant::now();
    let opt = Options::default();
    let res = (|| -> Result<_> {
        let train = [signals(&case.train)?];
        let valid = [signals(&case.valid)?];
        let d = diagnose::diagnose_records(&train, &valid, &opt)?;
        let c = if consistency {
            let others = [Arrangement::swapped(&train, &valid)];
            Some(consistency::check("as given", &d, &others, &opt)?)
        } else {
            None
        };
        Ok((d, c))
    })();
    let time_s = t0.elapsed().as_secs_f64();
    let sorted = |v: Vec<diagnose::Cause>| {
        let mut n: Vec<String> = v.iter().map(|c| c.name().to_string()).collect();
        n.sort();
        n
    };
    let (named, confident, error, json) = match res {
        Ok((d, c)) => {
            let mut json = d.json();
            if let Some(c) = &c {
                json["consistency"] = c.json();
            }
            (
                sorted(d.findings.iter().map(|f| f.cause).collect()),
                c.map(|c| sorted(c.confident())),
                None,
                json,
            )
        }
        Err(e) => (
            Vec::new(),
            consistency.then(Vec::new),
            Some(format!("{e:#}")),
            serde_json::Value::Null,
        ),
    };
    let blank = Outcome {
        index: case.index,
        truth: case.causes.clone(),
        named: Vec::new(),
        missing: Vec::new(),
        extra: Vec::new(),
        exact: false,
        error,
        time_s,
        gen_s: 0.0,
        presence_ok: case.presence_ok,
        confident,
    };
    (blank.scored(named), json)
}

fn label(v: &[impl AsRef<str>]) -> String {
    if v.is_empty() {
        "none".into()
    } else {
        v.iter().map(|s| s.as_ref()).collect::<Vec<_>>().join("+")
    }
}

fn write_case(dir: &Path, case: &Case, out: &Outcome, diagnosis: &serde_json::Value) -> Result<()> {
    let d = dir.join(format!("case-{:03}", case.index));
    std::fs::create_dir_all(&d).with_context(|| format!("cannot create {}", d.display()))?;
    case.train.write(d.join("train.csv"))?;
    case.valid.write(d.join("valid.csv"))?;
    let answer = serde_json::json!({
        "command": format!("piezo diagnose --train {0}/train.csv --valid {0}/valid.csv --json", d.display()),
        "case": case,
        "outcome": out,
        "diagnosis": diagnosis,
    });
    std::fs::write(
        d.join("answer.json"),
        serde_json::to_string_pretty(&answer)?,
    )
    .with_context(|| format!("cannot write {}", d.join("answer.json").display()))
}

/// Per-cause and per-count statistics of a set of outcomes.
#[derive(Debug, Serialize)]
pub struct Table {
    pub seed: u64,
    pub cases: usize,
    /// cause, present, named when present, absent, named when absent.
    pub per_cause: Vec<(String, usize, usize, usize, usize)>,
    /// number of causes, cases, exact.
    pub per_count: Vec<(usize, usize, usize)>,
    pub exact: usize,
    pub with_missing: usize,
    pub with_extra: usize,
    pub errors: usize,
    pub presence_flagged: usize,
    pub median_time_s: f64,
    /// Median per number of causes.
    pub median_time_per_count_s: Vec<(usize, f64)>,
    pub wall_s: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

pub fn table(seed: u64, outs: &[Outcome], wall_s: f64) -> Table {
    let per_cause = CAUSES
        .iter()
        .map(|c| {
            let present: Vec<&Outcome> = outs.iter().filter(|o| o.truth.contains(c)).collect();
            let absent: Vec<&Outcome> = outs.iter().filter(|o| !o.truth.contains(c)).collect();
            let named = |o: &&&Outcome| o.named.iter().any(|n| n == c);
            (
                c.to_string(),
                present.len(),
                present.iter().filter(named).count(),
                absent.len(),
                absent.iter().filter(named).count(),
            )
        })
        .collect();
    let per_count = (0..=3)
        .map(|k| {
            let of: Vec<&Outcome> = outs.iter().filter(|o| o.truth.len() == k).collect();
            (k, of.len(), of.iter().filter(|o| o.exact).count())
        })
        .collect();
    Table {
        seed,
        cases: outs.len(),
        per_cause,
        per_count,
        exact: outs.iter().filter(|o| o.exact).count(),
        with_missing: outs.iter().filter(|o| !o.missing.is_empty()).count(),
        with_extra: outs.iter().filter(|o| !o.extra.is_empty()).count(),
        errors: outs.iter().filter(|o| o.error.is_some()).count(),
        presence_flagged: outs.iter().filter(|o| !o.presence_ok).count(),
        median_time_s: median(outs.iter().map(|o| o.time_s).collect()),
        median_time_per_count_s: (0..=3)
            .map(|k| {
                (
                    k,
                    median(
                        outs.iter()
                            .filter(|o| o.truth.len() == k)
                            .map(|o| o.time_s)
                            .collect(),
                    ),
                )
            })
            .collect(),
        wall_s,
    }
}

fn pct(a: usize, b: usize) -> String {
    if b == 0 {
        "-".into()
    } else {
        format!("{:.1} %", 100.0 * a as f64 / b as f64)
    }
}

impl Table {
    /// Hidden causes named, over all cases: (named, present).
    pub fn recall(&self) -> (usize, usize) {
        self.per_cause
            .iter()
            .fold((0, 0), |(n, p), r| (n + r.2, p + r.1))
    }

    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "`piezo diagnose-bench`: {} cases of seed {}; {} named exactly ({}), {} with a missing cause, {} with an extra cause, {} failed; {} cases whose causes missed the presence check.\n",
            self.cases,
            self.seed,
            self.exact,
            pct(self.exact, self.cases),
            self.with_missing,
            self.with_extra,
            self.errors,
            self.presence_flagged
        );
        let (named, present) = self.recall();
        let _ = writeln!(
            s,
            "Hidden causes named: {named} of {present} ({}).\n",
            pct(named, present)
        );
        let _ = writeln!(
            s,
            "| cause | present | named when present (recall) | absent | named when absent (false positives) |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|");
        for (c, p, np, a, na) in &self.per_cause {
            let _ = writeln!(
                s,
                "| {c} | {p} | {np} ({}) | {a} | {na} ({}) |",
                pct(*np, *p),
                pct(*na, *a)
            );
        }
        let _ = writeln!(
            s,
            "\n| hidden causes | cases | named exactly | median time per case |"
        );
        let _ = writeln!(s, "|---|---|---|---|");
        for ((k, n, e), (_, t)) in self.per_count.iter().zip(&self.median_time_per_count_s) {
            let _ = writeln!(s, "| {k} | {n} | {e} ({}) | {t:.2} s |", pct(*e, *n));
        }
        let _ = writeln!(
            s,
            "| all | {} | {} ({}) | {:.2} s |",
            self.cases,
            self.exact,
            pct(self.exact, self.cases),
            self.median_time_s
        );
        let _ = writeln!(
            s,
            "\nTime per case is diagnose's wall time alone (the records' generation excluded); the whole run took {:.0} s.",
            self.wall_s
        );
        s
    }
}

pub fn run(args: Args) -> Result<()> {
    anyhow::ensure!(args.jobs >= 1, "--jobs must be at least 1");
    let indices: Vec<usize> = if args.only.is_empty() {
        (0..args.cases).collect()
    } else {
        for &i in &args.only {
            anyhow::ensure!(
                i < args.cases,
                "--case {i} is outside 0..{} (--cases)",
                args.cases
            );
        }
        args.only.clone()
    };
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let total = indices.len();
    let done = AtomicUsize::new(0);
    let start = Instant::now();
    let one = |i: usize| -> Result<Outcome> {
        let g0 = Instant::now();
        let case = independent::draw_case(args.seed, i);
        let gen_s = g0.elapsed().as_secs_f64();
        let (mut o, json) = run_case(&case, args.consistency);
        o.gen_s = gen_s;
        let k = done.fetch_add(1, Ordering::SeqCst) + 1;
        let verdict = if o.exact {
            "exact".to_string()
        } else if let Some(e) = &o.error {
            format!("FAILED: {e}")
        } else {
            let mut w = Vec::new();
            if !o.missing.is_empty() {
                w.push(format!("missing {}", label(&o.missing)));
            }
            if !o.extra.is_empty() {
                w.push(format!("extra {}", label(&o.extra)));
            }
            w.join(", ")
        };
        println!(
            "[{k:>3}/{total}] case {i:>3}: {} axis, {:.0} kHz, {:.1} s / {:.1} s; truth {}; named {}; {verdict}{}; {:.2} s (drawn in {:.1} s){}",
            case.plant.axes.len(),
            case.fs_hz / 1000.0,
            case.train.len() as f64 / case.fs_hz,
            case.valid.len() as f64 / case.fs_hz,
            label(&o.truth),
            label(&o.named),
            o.confident
                .as_ref()
                .map_or_else(String::new, |c| format!("; confident {}", label(c))),
            o.time_s,
            gen_s,
            if case.presence_ok { "" } else { " (presence check missed)" }
        );
        if let Some(dir) = &args.out {
            write_case(dir, &case, &o, &json)?;
        }
        Ok(o)
    };
    let mut outs: Vec<Outcome> = if args.jobs == 1 {
        indices.iter().map(|&i| one(i)).collect::<Result<_>>()?
    } else {
        use rayon::prelude::*;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(args.jobs)
            .build()
            .context("cannot start the worker threads")?;
        pool.install(|| indices.par_iter().map(|&i| one(i)).collect::<Result<_>>())?
    };
    outs.sort_by_key(|o| o.index);
    let wall_s = start.elapsed().as_secs_f64();
    let t = table(args.seed, &outs, wall_s);
    let mut md = t.markdown();
    if args.consistency {
        let confident: Vec<Outcome> = outs.iter().map(Outcome::confident_only).collect();
        let _ = write!(
            md,
            "\n## Confident causes only\n\nThe causes named both as given and with the records' roles swapped (what `piezo diagnose` reports as `confident` for a pair); times include both runs.\n\n{}",
            table(args.seed, &confident, wall_s).markdown()
        );
    }
    println!("\n{md}");
    if let Some(dir) = &args.out {
        std::fs::write(dir.join("table.md"), &md)
            .with_context(|| format!("cannot write {}", dir.join("table.md").display()))?;
        let j = serde_json::json!({ "table": t, "cases": outs });
        std::fs::write(dir.join("table.json"), serde_json::to_string_pretty(&j)?)
            .with_context(|| format!("cannot write {}", dir.join("table.json").display()))?;
        println!("written: {}/table.md, table.json, case-NNN/", dir.display());
    }
    if let Some(floor) = args.min_recall {
        let (named, present) = t.recall();
        let share = named as f64 / present.max(1) as f64;
        anyhow::ensure!(
            share >= floor,
            "recall {share:.3} is below the floor {floor} ({named} of {present} hidden causes named)"
        );
    }
    if let Some(floor) = args.min_exact {
        let share = t.exact as f64 / t.cases.max(1) as f64;
        anyhow::ensure!(
            share >= floor,
            "exact-set accuracy {:.3} is below the floor {floor} ({} of {} cases)",
            share,
            t.exact,
            t.cases
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn o(truth: Vec<&'static str>, named: &[&str]) -> Outcome {
        Outcome {
            index: 0,
            truth,
            named: Vec::new(),
            missing: Vec::new(),
            extra: Vec::new(),
            exact: false,
            error: None,
            time_s: 1.0,
            gen_s: 0.0,
            presence_ok: true,
            confident: None,
        }
        .scored(named.iter().map(|s| s.to_string()).collect())
    }

    #[test]
    fn table_counts_recall_false_positives_and_exact_sets() {
        let outs = vec![
            o(vec![], &[]),
            o(vec!["creep"], &["creep", "drift"]),
            o(vec!["creep", "delay"], &["creep", "delay"]),
            o(vec!["drift"], &[]),
        ];
        let t = table(1, &outs, 10.0);
        let row = |c: &str| t.per_cause.iter().find(|r| r.0 == c).unwrap().clone();
        assert_eq!(row("creep"), ("creep".into(), 2, 2, 2, 0));
        assert_eq!(row("drift"), ("drift".into(), 1, 0, 3, 1));
        assert_eq!(
            t.per_count,
            vec![(0, 1, 1), (1, 2, 0), (2, 1, 1), (3, 0, 0)]
        );
        assert_eq!((t.exact, t.with_missing, t.with_extra), (2, 1, 1));
        assert_eq!(t.recall(), (3, 4));
        assert!(t
            .markdown()
            .contains("| drift | 1 | 0 (0.0 %) | 3 | 1 (33.3 %) |"));
    }

    #[test]
    fn confident_causes_are_scored_as_a_second_answer() {
        let mut a = o(vec!["creep"], &["creep", "drift"]);
        assert!(!a.exact);
        assert_eq!(a.confident_only().extra, ["drift"]);
        a.confident = Some(vec!["creep".into()]);
        let c = a.confident_only();
        assert!(c.exact && c.extra.is_empty() && c.named == ["creep"]);
        a.confident = Some(vec![]);
        assert_eq!(a.confident_only().missing, ["creep"]);
        let t = table(1, &[a.confident_only()], 1.0);
        assert_eq!(t.recall(), (0, 1));
    }
}
