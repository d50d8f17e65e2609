//! `piezo diagnose` end to end: JSON contract, `--predict` recomputes the gain, bad files
//! give an error naming the line.

mod cli_support;
mod diagnose_support;

use diagnose_support::Plant;
use hal_sim::ident::diagnose::{Cause, Signals};
use hal_sim::numeric::rmse;
use hal_sim::record::Record;
use std::process::Command;

fn write(path: &std::path::Path, s: &Signals) {
    Record::new(s.t.clone(), s.u.clone(), s.y.clone())
        .unwrap()
        .write(path)
        .unwrap();
}

#[test]
fn json_and_predict_agree() {
    let dir = std::env::temp_dir().join(format!("diagnose_cli_{}", std::process::id()));
    let plant = Plant::draw(5, &[Cause::Delay]);
    let (train, valid) = (plant.record(5, 0), plant.record(5, 1));
    write(&dir.join("a.csv"), &train);
    write(&dir.join("b.csv"), &valid);
    let out = cli_support::piezo(&[
        &"diagnose",
        &"--json",
        &"--train",
        &dir.join("a.csv"),
        &"--valid",
        &dir.join("b.csv"),
        &"--predict",
        &dir.join("p.csv"),
        &"--out",
        &dir.join("plots"),
    ]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["cause"], "delay");
    assert_eq!(j["causes"][0], "delay");
    for k in ["base", "extended"] {
        assert!(j[k]["model"].is_string() && j[k]["rmse_train"].is_number());
    }
    assert!(j["candidates"].as_array().unwrap().len() >= 7);
    let text = std::fs::read_to_string(dir.join("p.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("t,y_base,y_ext"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let col = |k: usize| rows.iter().map(|r| r[k]).collect::<Vec<_>>();
    let (b, e) = (rmse(&col(1), &valid.y[0]), rmse(&col(2), &valid.y[0]));
    let gain = j["gain"].as_f64().unwrap();
    assert!(
        (1.0 - e / b - gain).abs() < 1e-9,
        "{gain} vs {}",
        1.0 - e / b
    );
    assert!(dir.join("plots/diagnose.svg").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Several records: `--train` and `--valid` repeated; the JSON reports each validation
/// record, `--predict` writes a `record` column, and the overall gain is recomputed from it.
#[test]
fn several_records_json_and_predict_agree() {
    let dir = std::env::temp_dir().join(format!("diagnose_cli_many_{}", std::process::id()));
    let plant = Plant::draw(6, &[Cause::Delay]);
    let recs: Vec<Signals> = (0..4).map(|w| plant.record(6, w)).collect();
    for (k, r) in recs.iter().enumerate() {
        write(&dir.join(format!("r{k}.csv")), r);
    }
    let out = cli_support::piezo(&[
        &"diagnose",
        &"--json",
        &"--train",
        &dir.join("r0.csv"),
        &"--train",
        &dir.join("r2.csv"),
        &"--valid",
        &dir.join("r1.csv"),
        &"--valid",
        &dir.join("r3.csv"),
        &"--predict",
        &dir.join("p.csv"),
    ]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["cause"], "delay", "{j:#}");
    assert_eq!(j["records"]["train"], 2);
    assert_eq!(j["records"]["valid"].as_array().unwrap().len(), 2);
    assert!(j.get("unexplained").is_some());
    let text = std::fs::read_to_string(dir.join("p.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("record,t,y_base,y_ext"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let (mut sb, mut se, mut n) = (0.0, 0.0, 0.0);
    for (k, v) in [(1.0, &recs[1]), (2.0, &recs[3])] {
        let rs: Vec<&Vec<f64>> = rows.iter().filter(|r| r[0] == k).collect();
        assert_eq!(rs.len(), v.len());
        for (r, y) in rs.iter().zip(&v.y[0]) {
            sb += (r[2] - y).powi(2);
            se += (r[3] - y).powi(2);
            n += 1.0;
        }
        let per = &j["records"]["valid"][k as usize - 1];
        let b = rmse(&rs.iter().map(|r| r[2]).collect::<Vec<_>>(), &v.y[0]);
        assert!((per["rmse_base"].as_f64().unwrap() - b).abs() < 1e-9 * b.max(1.0));
    }
    let gain = j["gain"].as_f64().unwrap();
    let recomputed = 1.0 - (se / n).sqrt() / (sb / n).sqrt();
    assert!((gain - recomputed).abs() < 1e-9, "{gain} vs {recomputed}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_csv_names_the_line() {
    let dir = std::env::temp_dir().join(format!("diagnose_bad_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "t,u,y\n0,1,2\n0.001,1,abc\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_piezo"))
        .args(["diagnose", "--train"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 3"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Time windows: a training window and a scored validation window of the same record give
/// exactly `--split` at the window's edge (the model runs through the samples before the
/// validation window); a window that is too short, or `piezo fit` with a window, is an error.
#[test]
fn time_windows_select_the_samples() {
    let dir = std::env::temp_dir().join(format!("diagnose_cli_window_{}", std::process::id()));
    let plant = Plant::draw(7, &[Cause::Delay]);
    let rec = plant.record(7, 0);
    write(&dir.join("a.csv"), &rec);
    let a = dir.join("a.csv");
    let n = rec.len();
    let edge = 0.5 * (rec.t[n / 2 - 1] + rec.t[n / 2]);
    let (tw, vw) = (format!(":{edge}"), format!("{edge}:"));
    let json = |args: &[&dyn AsRef<std::ffi::OsStr>]| -> serde_json::Value {
        serde_json::from_slice(&cli_support::piezo(args).stdout).unwrap()
    };
    let windowed = json(&[
        &"diagnose",
        &"--json",
        &"--no-consistency",
        &"--train",
        &a,
        &"--train-window",
        &tw,
        &"--valid-window",
        &vw,
        &"--predict",
        &dir.join("p.csv"),
    ]);
    let split = json(&[
        &"diagnose",
        &"--json",
        &"--no-consistency",
        &"--train",
        &a,
        &"--split",
        &"0.5",
    ]);
    assert!(split.get("consistency").is_none());
    for k in ["base", "extended"] {
        assert_eq!(windowed[k]["rmse_valid"], split[k]["rmse_valid"], "{k}");
    }
    assert_eq!(windowed["causes"], split["causes"]);
    assert!(windowed["split"].as_str().unwrap().contains("fit on"));
    let text = std::fs::read_to_string(dir.join("p.csv")).unwrap();
    let ts: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(ts.len(), n - n / 2);
    assert!(ts.iter().all(|t| *t > edge));
    let fails = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_piezo"))
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let a = a.to_str().unwrap();
    assert!(fails(&[
        "diagnose",
        "--train",
        a,
        "--train-window",
        "0:0.01",
        "--valid-window",
        "1:"
    ])
    .contains("at least 50"));
    assert!(fails(&["diagnose", "--train", a, "--train-window", "0:1"]).contains("both"));
    assert!(fails(&["diagnose", "--train", a, "--valid-window", "2:1"]).contains("below"));
    assert!(fails(&[
        "fit",
        "--model",
        "cbw",
        "--train",
        a,
        "--train-window",
        "0:1"
    ])
    .contains("diagnose"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// One record checks itself at the splits 0.5, 0.65 and 0.8: the JSON names every
/// arrangement's causes and each cause's status, the text report says which are confident;
/// a pair is checked with the records swapped.
#[test]
fn consistency_over_splits_and_swap() {
    let dir = std::env::temp_dir().join(format!("diagnose_cli_consist_{}", std::process::id()));
    let plant = Plant::draw(8, &[Cause::Delay]);
    write(&dir.join("a.csv"), &plant.record(8, 0));
    write(&dir.join("b.csv"), &plant.record(8, 1));
    let (a, b) = (dir.join("a.csv"), dir.join("b.csv"));
    let out = cli_support::piezo(&[&"diagnose", &"--json", &"--train", &a, &"--split", &"0.65"]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let c = &j["consistency"];
    let labels: Vec<&str> = c["arrangements"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["label"].as_str().unwrap())
        .collect();
    assert_eq!(labels, ["split 0.65", "split 0.5", "split 0.8"], "{c:#}");
    // Every cause the first arrangement names is listed with a status; confident ones are
    // named in every arrangement.
    for cause in j["causes"].as_array().unwrap() {
        let entry = c["causes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["cause"] == *cause)
            .unwrap_or_else(|| panic!("{cause} missing in {c:#}"));
        let confident = entry["status"] == "confident";
        assert_eq!(
            confident,
            entry["not_in"].as_array().unwrap().is_empty(),
            "{c:#}"
        );
    }
    assert_eq!(c["confident"], serde_json::json!(["delay"]), "{c:#}");
    let out = cli_support::piezo(&[&"diagnose", &"--train", &a, &"--valid", &b]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("consistency over as given, swapped: confident delay"),
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
