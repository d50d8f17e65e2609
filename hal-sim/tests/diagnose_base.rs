//! `piezo diagnose --base DIR/fit.json` on hal-sim's stage, as a lab would run it on the
//! mirror: periodic multisines at three levels, a linear state-space model fitted on the
//! lowest and the highest (`piezo fit --model ss`), discovery from it validated on the middle
//! level. With the stage's `amplitude-dynamics` (a mode that softens and damps with its
//! amplitude) `structure-nonlinearity` must be named; on the same stage with a plain
//! resonance (`dynamics`) it must not.
use hal_sim::ident::diagnose::Cause;
use hal_sim::ident::generate::Hidden;
use hal_sim::record::Record;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const RATE_HZ: f64 = 5000.0;
const PERIOD: usize = 2048;
/// Multisine RMS of the three levels (V) about 60 V.
const LEVELS_V: [f64; 3] = [1.0, 4.0, 16.0];

fn piezo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_piezo"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// One period of a random-phase multisine (lines 1..=160, 2.4-390 Hz) of unit RMS.
fn multisine(seed: u64) -> Vec<f64> {
    let mut r = hal_sim::ident::numeric::Rng::new(seed);
    let phases: Vec<f64> = (0..160)
        .map(|_| r.range(0.0, std::f64::consts::TAU))
        .collect();
    let one: Vec<f64> = (0..PERIOD)
        .map(|k| {
            phases
                .iter()
                .enumerate()
                .map(|(l, p)| {
                    (std::f64::consts::TAU * (l + 1) as f64 * k as f64 / PERIOD as f64 + p).cos()
                })
                .sum()
        })
        .collect();
    let rms = (one.iter().map(|v| v * v).sum::<f64>() / PERIOD as f64).sqrt();
    one.iter().map(|v| v / rms).collect()
}

/// The stage driven by a 0.2 s ramp to the first sample, then three periods at `level_v`
/// RMS; the last two periods are the record (steady state).
fn record(h: &Hidden, level_v: f64, seed: u64, path: &Path) {
    let one: Vec<f64> = multisine(seed).iter().map(|v| 60.0 + level_v * v).collect();
    let ramp = (0.2 * RATE_HZ) as usize;
    let u: Vec<f64> = (0..ramp)
        .map(|k| one[0] * k as f64 / ramp as f64)
        .chain((0..3 * PERIOD).map(|k| one[k % PERIOD]))
        .collect();
    let s = h.record_with(vec![u], seed).unwrap();
    let from = ramp + PERIOD;
    let t = (0..2 * PERIOD).map(|k| k as f64 / RATE_HZ).collect();
    Record::new(
        t,
        vec![s.u[0][from..].to_vec()],
        vec![s.y[0][from..].to_vec()],
    )
    .unwrap()
    .write(path)
    .unwrap();
}

/// Records of the stage with `cause` (two per level), the base fitted on the lowest and the
/// highest level, and the causes `diagnose --base` names validating on the middle one.
/// Two records per level of hal-sim's stage with `cause`, in `dir` (`files[level][r]`).
fn records(cause: Cause, seed: u64, dir: &Path) -> Vec<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).unwrap();
    let h = Hidden::draw_at(seed, &[cause], RATE_HZ, 1.0).unwrap();
    let mut files: Vec<Vec<PathBuf>> = Vec::new();
    for (l, &v) in LEVELS_V.iter().enumerate() {
        files.push(
            (0..2)
                .map(|r| {
                    let p = dir.join(format!("l{l}r{r}.csv"));
                    record(&h, v, 10 * l as u64 + r as u64 + 1, &p);
                    p
                })
                .collect(),
        );
    }
    files
}

fn named(cause: Cause, seed: u64, dir: &Path) -> (Vec<String>, String) {
    let files = records(cause, seed, dir);
    let s = |p: &PathBuf| p.display().to_string();
    // Order 8: the mode and the hysteresis' lag, as a user who looked at the order scan
    // would give it.
    let mut fit = vec![
        "fit".to_string(),
        "--model".into(),
        "ss".into(),
        "--order".into(),
        "8".into(),
        "--quiet".into(),
    ];
    for p in files[0].iter().chain(&files[2]) {
        fit.extend(["--train".into(), s(p)]);
    }
    let base = dir.join("base");
    fit.extend(["--out".into(), s(&base)]);
    ok(&piezo(&fit.iter().map(String::as_str).collect::<Vec<_>>()));
    let mut diag = vec![
        "diagnose".to_string(),
        "--base".into(),
        s(&base.join("fit.json")),
        "--json".into(),
    ];
    for p in files[0].iter().chain(&files[2]) {
        diag.extend(["--train".into(), s(p)]);
    }
    for p in &files[1] {
        diag.extend(["--valid".into(), s(p)]);
    }
    let pred = dir.join("pred.csv");
    let report = dir.join("report");
    diag.extend(["--predict".into(), s(&pred), "--out".into(), s(&report)]);
    let out = ok(&piezo(&diag.iter().map(String::as_str).collect::<Vec<_>>()));
    assert!(report.join("index.html").is_file() && report.join("diagnosis.json").is_file());
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    // The final score reproduces from --predict (official rule: per record, period and
    // output the RMSE over the scored samples, then the mean).
    let valid: Vec<Record> = files[1].iter().map(|p| Record::read(p).unwrap()).collect();
    let text = std::fs::read_to_string(&pred).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let mut scores = Vec::new();
    for (i, rec) in valid.iter().enumerate() {
        let mine: Vec<&Vec<f64>> = rows.iter().filter(|r| r[0] as usize == i + 1).collect();
        assert_eq!(mine.len(), rec.len());
        for q in 0..rec.len() / PERIOD {
            let (mut se, mut n) = (0.0, 0);
            let (y, rows) = (&rec.y[0][q * PERIOD..], &mine[q * PERIOD..(q + 1) * PERIOD]);
            for (yk, row) in y.iter().zip(rows) {
                if row[2] == 1.0 {
                    se += (yk - row[4]).powi(2);
                    n += 1;
                }
            }
            assert_eq!(n, PERIOD - 100);
            scores.push((se / n as f64).sqrt());
        }
    }
    let from_file = scores.iter().sum::<f64>() / scores.len() as f64;
    let reported = j["final_valid"].as_f64().unwrap();
    assert!(
        (from_file / reported - 1.0).abs() < 1e-9,
        "--predict gives {from_file}, the report {reported}"
    );
    // The extended model written beside the report scores the same with `piezo score`
    // (its own simulation of the saved extensions).
    let mut score = vec![
        "score".to_string(),
        "--model".into(),
        s(&report.join("fit.json")),
        "--json".into(),
    ];
    for p in &files[1] {
        score.extend(["--record".into(), s(p)]);
    }
    let sj: serde_json::Value = serde_json::from_str(&ok(&piezo(
        &score.iter().map(String::as_str).collect::<Vec<_>>(),
    )))
    .unwrap();
    let per: Vec<f64> = sj["records"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["official"]["mean"].as_f64().unwrap())
        .collect();
    let saved = per.iter().sum::<f64>() / per.len() as f64;
    assert!(
        (saved / reported - 1.0).abs() < 1e-9,
        "the saved extended model scores {saved}, the report {reported}"
    );
    for (i, r) in j["rounds"].as_array().unwrap().iter().enumerate() {
        for t in r.as_array().unwrap() {
            eprintln!(
                "  round {} {:<24} {:+.3} half {:>8} {} {}",
                i + 1,
                t["cause"].as_str().unwrap(),
                t["gain"].as_f64().unwrap_or(f64::NAN),
                t["half_gain"]
                    .as_f64()
                    .map_or("-".into(), |g| format!("{g:+.3}")),
                t["verdict"].as_str().unwrap(),
                t["detail"].as_str().unwrap()
            );
        }
    }
    eprintln!(
        "  base {:.4} final {:.4} floor {:.4}",
        j["base_valid"].as_f64().unwrap(),
        j["final_valid"].as_f64().unwrap(),
        j["noise_floor"].as_f64().unwrap_or(f64::NAN)
    );
    let names = j["named"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    (names, out)
}

#[test]
fn the_structure_nonlinearity_is_named_from_a_linear_base_and_only_where_it_is() {
    let tmp = std::env::var_os("PIEZO_DIAGNOSE_BASE_DIR").map_or_else(
        || std::env::temp_dir().join(format!("piezo-diagnose-base-{}", std::process::id())),
        PathBuf::from,
    );
    let mut failed = Vec::new();
    // Other seeds on request (`PIEZO_DIAGNOSE_BASE_SEEDS=3,4,5`): the rule was written
    // looking at seeds 1 and 2.
    let seeds: Vec<u64> = std::env::var("PIEZO_DIAGNOSE_BASE_SEEDS").map_or(vec![1, 2], |v| {
        v.split(',').map(|s| s.trim().parse().unwrap()).collect()
    });
    for seed in seeds {
        for (cause, want) in [(Cause::AmplitudeDynamics, true), (Cause::Dynamics, false)] {
            let (names, out) = named(cause, seed, &tmp.join(format!("{}-{seed}", cause.name())));
            let has = names.iter().any(|n| n == "structure-nonlinearity");
            eprintln!("seed {seed} {}: named {names:?}", cause.name());
            if has != want {
                failed.push(format!("seed {seed} {}: {out}", cause.name()));
            }
        }
    }
    // Kept for a look when the test fails.
    if failed.is_empty() && std::env::var_os("PIEZO_DIAGNOSE_BASE_DIR").is_none() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    assert!(
        failed.is_empty(),
        "records in {}\n{}",
        tmp.display(),
        failed.join("\n")
    );
}

#[test]
fn a_base_that_is_not_a_state_space_model_is_refused_by_name() {
    let tmp = std::env::temp_dir().join(format!("piezo-diagnose-base-bad-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let fit = tmp.join("fit.json");
    std::fs::write(
        &fit,
        r#"{"model": "cbw", "output_unit": "um", "parts": []}"#,
    )
    .unwrap();
    let o = piezo(&[
        "diagnose",
        "--base",
        &fit.display().to_string(),
        "--train",
        "x.csv",
        "--valid",
        "y.csv",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("model `cbw`: --base takes a state-space fit.json"),
        "{err}"
    );
    let o = piezo(&[
        "diagnose",
        "--base",
        &fit.display().to_string(),
        "--train",
        "x.csv",
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--base needs --train and --valid"));
    let _ = std::fs::remove_dir_all(&tmp);
}

/// The automatic order on these strongly hysteretic records (the BLA's nonlinear distortion
/// 0.6 um) refuses candidates whose modes cancel: before, its noisy validation minimum was
/// a 32-state model with input gains of 5e21 that fitted the training records worse than 8
/// states (0.92 against 0.75 um).
#[test]
fn the_automatic_order_refuses_modes_that_cancel() {
    let dir = std::env::temp_dir().join(format!("piezo-auto-order-{}", std::process::id()));
    let files = records(Cause::Dynamics, 1, &dir);
    let s = |p: &PathBuf| p.display().to_string();
    let fit_rms = |order: &str, out: &str| {
        let mut args = vec![
            "fit".to_string(),
            "--model".into(),
            "ss".into(),
            "--order".into(),
            order.into(),
            "--quiet".into(),
        ];
        for p in files[0].iter().chain(&files[2]) {
            args.extend(["--train".into(), s(p)]);
        }
        args.extend(["--out".into(), s(&dir.join(out))]);
        ok(&piezo(&args.iter().map(String::as_str).collect::<Vec<_>>()));
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(out).join("fit.json")).unwrap())
                .unwrap();
        (
            j["report"]["train_rms_linear"].as_f64().unwrap(),
            j["report"]["modes_to_peak"].as_f64().unwrap(),
            j["order"].as_u64().unwrap(),
        )
    };
    let (auto, ratio, order) = fit_rms("auto", "auto");
    let (eight, _, _) = fit_rms("8", "eight");
    std::fs::remove_dir_all(&dir).ok();
    assert!(
        ratio < 1e3 && auto <= 1.01 * eight,
        "auto order {order}: modes {ratio:.1e} x the peak, training RMS {auto:.4} um against {eight:.4} um at order 8"
    );
}
