//! `piezo fit --valid-periodic`: the steady-state simulation is scored, the from-rest one is
//! reported beside it (JSON and the `y_rest` column of `--predict`), so both are visible.

mod cli_support;
use hal_sim::record::Record;
use piezo_core::hysteresis::{Cbw, Hysteresis};

/// Four periods of a 1 Hz sine through CBW; the valid record is the last period only (its
/// start is not at rest).
fn records(dir: &std::path::Path) {
    let dt = 2e-3;
    let n = 500;
    let m = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
    let u: Vec<f64> = (0..4 * n)
        .map(|k| 50.0 * (1.0 + (2.0 * std::f64::consts::PI * k as f64 / n as f64).sin()))
        .collect();
    let mut s = m.init(u[0]);
    let y: Vec<f64> = u.iter().map(|&u| m.step(&mut s, u, dt)).collect();
    let t = |n: usize| (0..n).map(|k| k as f64 * dt).collect::<Vec<_>>();
    Record::new(t(4 * n), vec![u.clone()], vec![y.clone()])
        .unwrap()
        .write(dir.join("train.csv"))
        .unwrap();
    Record::new(t(n), vec![u[3 * n..].to_vec()], vec![y[3 * n..].to_vec()])
        .unwrap()
        .write(dir.join("valid.csv"))
        .unwrap();
}

#[test]
fn periodic_validation_reports_steady_state_and_from_rest() {
    let dir = std::env::temp_dir().join(format!("fit_cli_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    records(&dir);
    let out = cli_support::piezo(&[
        &"fit",
        &"--model",
        &"cbw",
        &"--json",
        &"--quiet",
        &"--generations",
        &"40",
        &"--valid-periodic",
        &"2",
        &"--train",
        &dir.join("train.csv"),
        &"--valid",
        &dir.join("valid.csv"),
        &"--predict",
        &dir.join("p.csv"),
    ]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let steady = j["valid_metrics"][0]["metrics"]["rmse"].as_f64().unwrap();
    let rest = j["valid_from_rest_metrics"][0]["metrics"]["rmse"]
        .as_f64()
        .unwrap();
    // The record starts mid-loop: from rest the hysteresis state is wrong at first.
    assert!(steady < 1e-3 && rest > 10.0 * steady, "{steady} vs {rest}");
    let p = Record::read(dir.join("p.csv")).unwrap();
    let y_rest = p
        .extra
        .iter()
        .find(|(name, _)| name == "y_rest")
        .map(|(_, v)| v.clone())
        .expect("y_rest column");
    assert_eq!(y_rest.len(), p.t.len());
    let _ = std::fs::remove_dir_all(&dir);
}
