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
    let j = fit_json(
        &dir.join("train.csv"),
        &[
            &"--valid-periodic",
            &"2",
            &"--valid",
            &dir.join("valid.csv"),
            &"--predict",
            &dir.join("p.csv"),
        ],
    );
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

/// `--t-col`, `--u-col`, `--y-col` of the foreign exports, the output column `y`.
fn foreign_cols(y: &str) -> [String; 6] {
    ["--t-col", "Time [s]", "--u-col", "Drive (V)", "--y-col", y].map(String::from)
}

/// `piezo fit --model cbw --json` on `train`: the report.
fn fit_json(train: &std::path::Path, more: &[&dyn AsRef<std::ffi::OsStr>]) -> serde_json::Value {
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
        &"fit",
        &"--model",
        &"cbw",
        &"--json",
        &"--quiet",
        &"--generations",
        &"40",
        &"--train",
        &train,
    ];
    args.extend_from_slice(more);
    serde_json::from_slice(&cli_support::piezo(&args).stdout).unwrap()
}

/// The fitted CBW parameters of a report.
fn params(j: &serde_json::Value) -> Vec<f64> {
    j["parts"][0]["fit"]["params"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p[1].as_f64().unwrap())
        .collect()
}

/// `a` and `b` agree to `tol` relative.
fn same(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= tol * x.abs().max(y.abs()))
}

/// The record of [`records`] with other units and column names: `header`, and each row's
/// `t`, `u`, `y` scaled by `scale`.
fn rewrite(from: &std::path::Path, to: &std::path::Path, header: &str, scale: [f64; 3]) {
    let r = Record::read(from).unwrap();
    let mut s = format!("# the same record, other units\n{header}\n");
    for i in 0..r.len() {
        s += &format!(
            "{},{},{},21.5\n",
            r.t[i] * scale[0],
            r.u[0][i] * scale[1],
            r.y[0][i] * scale[2]
        );
    }
    std::fs::write(to, s).unwrap();
}

#[test]
fn a_record_in_nm_fits_the_same_model_as_in_um() {
    let dir = std::env::temp_dir().join(format!("fit_cli_units_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    records(&dir);
    let train = dir.join("train.csv");
    assert!(std::fs::read_to_string(&train)
        .unwrap()
        .starts_with("t_s,u_V,y_um\n"));
    let um = fit_json(&train, &[]);
    assert_eq!(
        (um["input_unit"].as_str(), um["output_unit"].as_str()),
        (Some("V"), Some("um"))
    );
    // The same samples in ms, mV and nm: converted on reading, the same model in um and V.
    let nm = dir.join("nm.csv");
    rewrite(&train, &nm, "t_ms,u_mV,y_nm,temp_C", [1e3, 1e3, 1e3]);
    let j = fit_json(&nm, &[]);
    assert!(
        same(&params(&j), &params(&um), 1e-6),
        "{:?} vs {:?}",
        params(&j),
        params(&um)
    );
    assert_eq!(j["output_unit"].as_str(), Some("um"));
    let rmse = |j: &serde_json::Value| j["train_metrics"][0]["metrics"]["rmse"].as_f64().unwrap();
    // In um, like the fit on the um record (the loop spans about 16 um).
    assert!(
        rmse(&j) < 1e-3 && (rmse(&j) - rmse(&um)).abs() < 1e-7,
        "{} vs {}",
        rmse(&j),
        rmse(&um)
    );
    // A foreign export: columns chosen by name, units in brackets.
    let foreign = dir.join("foreign.csv");
    rewrite(
        &train,
        &foreign,
        "Time [s],Drive (V),Sensor [m],Temp",
        [1.0, 1.0, 1e-6],
    );
    let cols = foreign_cols("Sensor [m]");
    let more: Vec<&dyn AsRef<std::ffi::OsStr>> = cols.iter().map(|c| c as _).collect();
    let j = fit_json(&foreign, &more);
    assert!(
        same(&params(&j), &params(&um), 1e-6),
        "{:?} vs {:?}",
        params(&j),
        params(&um)
    );
    // Unitless outputs in nm, said with --output-unit.
    let bare = dir.join("bare.csv");
    rewrite(&train, &bare, "t,u,y,temp", [1.0, 1.0, 1e3]);
    let j = fit_json(&bare, &[&"--output-unit", &"nm"]);
    assert!(
        same(&params(&j), &params(&um), 1e-6),
        "{:?} vs {:?}",
        params(&j),
        params(&um)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Runs `piezo` expecting failure; its stderr.
fn refused(args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_piezo"))
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .unwrap();
    let shown: Vec<_> = args.iter().map(|a| a.as_ref().to_string_lossy()).collect();
    assert!(!out.status.success(), "{shown:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn missing_columns_and_unknown_units_are_named() {
    let dir = std::env::temp_dir().join(format!("fit_cli_refused_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    records(&dir);
    let train = dir.join("train.csv");
    let foreign = dir.join("foreign.csv");
    rewrite(
        &train,
        &foreign,
        "Time [s],Drive (V),Sensor [ft],Temp",
        [1.0, 1.0, 1.0],
    );
    let fit = [
        &"fit" as &dyn AsRef<std::ffi::OsStr>,
        &"--model",
        &"cbw",
        &"--quiet",
        &"--train",
        &foreign,
    ];
    let e = refused(&fit);
    assert!(
        e.contains("no `t` column")
            && e.contains("the columns are `Time [s]`, `Drive (V)`, `Sensor [ft]`, `Temp`"),
        "{e}"
    );
    let position = foreign_cols("Position");
    let mut chosen = fit.to_vec();
    chosen.extend(position.iter().map(|c| c as &dyn AsRef<std::ffi::OsStr>));
    let e = refused(&chosen);
    assert!(
        e.contains("no output column `Position` in the header"),
        "{e}"
    );
    chosen.pop();
    chosen.push(&"Sensor [ft]");
    let e = refused(&chosen);
    assert!(
        e.contains("column `Sensor [ft]`: unknown length unit `ft`"),
        "{e}"
    );
    // diagnose and predict take the same options and the same reader.
    let ft = foreign_cols("Sensor [ft]");
    let mut diagnose: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![&"diagnose", &"--train", &foreign];
    diagnose.extend(ft.iter().map(|c| c as &dyn AsRef<std::ffi::OsStr>));
    let e = refused(&diagnose);
    assert!(e.contains("unknown length unit `ft`"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_sim_out_record_is_read_by_fit() {
    let dir = std::env::temp_dir().join(format!("fit_cli_sim_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    cli_support::piezo(&[
        &"sim",
        &"--scenario",
        &"sine-10hz",
        &"--controller",
        &"open-loop",
        &"--out",
        &dir,
    ]);
    let rec = dir.join("sine-10hz_open-loop_record.csv");
    let text = std::fs::read_to_string(&rec).unwrap();
    assert!(text.starts_with("t_s,u_V,y_um\n"), "{:.100}", text);
    let r = Record::read(&rec).unwrap();
    assert_eq!(r.unit_note, None);
    let j = fit_json(&rec, &[&"--lm-iterations", &"10"]);
    // The simulated stage's open-loop response is a hysteresis loop CBW describes well:
    // the fit reads the record's volts and um (a wrong column would not fit).
    assert_eq!(
        j["train_metrics"][0]["metrics"]["samples"].as_u64(),
        Some(r.len() as u64)
    );
    let re = j["train_metrics"][0]["metrics"]["re_pct"].as_f64().unwrap();
    assert!(re < 5.0, "relative error {re} %");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--split` (shared with `diagnose`): the first part fits, the model runs on through the
/// rest, which is scored; a fraction outside 0.1..0.9 or beside `--valid` is refused.
#[test]
fn split_fits_the_first_part_and_scores_the_rest() {
    let dir = std::env::temp_dir().join(format!("fit_cli_split_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    records(&dir);
    let train = dir.join("train.csv");
    let j = fit_json(&train, &[&"--split", &"0.6"]);
    assert!(
        j["valid"]
            .as_str()
            .unwrap()
            .contains("samples 1200..2000 after fitting on 0..1200"),
        "{}",
        j["valid"]
    );
    let rmse = j["valid_metrics"][0]["metrics"]["rmse"].as_f64().unwrap();
    // Noise-free CBW data: the model of the first 1200 samples predicts the rest.
    assert!(rmse < 1e-2, "{rmse}");
    let fit = [
        &"fit" as &dyn AsRef<std::ffi::OsStr>,
        &"--model",
        &"cbw",
        &"--train",
        &train,
    ];
    let mut far = fit.to_vec();
    far.extend([&"--split" as &dyn AsRef<std::ffi::OsStr>, &"0.95"]);
    assert!(refused(&far).contains("--split must be within 0.1..0.9"));
    let mut both = fit.to_vec();
    both.extend([
        &"--split" as &dyn AsRef<std::ffi::OsStr>,
        &"0.5",
        &"--valid",
        &train,
    ]);
    assert!(refused(&both).contains("cannot be used with"));
    let _ = std::fs::remove_dir_all(&dir);
}
