//! `piezo diagnose` end to end: JSON contract, `--predict` recomputes the gain, bad files
//! give an error naming the line.
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
    let out = Command::new(env!("CARGO_BIN_EXE_piezo"))
        .args(["diagnose", "--json", "--train"])
        .arg(dir.join("a.csv"))
        .arg("--valid")
        .arg(dir.join("b.csv"))
        .arg("--predict")
        .arg(dir.join("p.csv"))
        .arg("--out")
        .arg(dir.join("plots"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
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
