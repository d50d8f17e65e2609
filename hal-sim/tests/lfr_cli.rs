//! `piezo fit --model lfr` on records of a known LFR (a lightly damped mode whose stiffness
//! hardens with the amplitude) at three levels: it beats the linear model of all levels on a
//! held-out level by the official rule (`piezo score`), `predict` runs its `fit.json`, a
//! record it diverges on is reported beside the scored ones, and a broken LFR section is
//! refused with a clear error.
use hal_sim::ident::ss::lfr::{Basis, Lfr};
use hal_sim::ident::ss::model::{Block, Modal};
use hal_sim::ident::ss::score::with_warmup;
use hal_sim::record::Record;
use nalgebra::DMatrix;
use std::path::Path;
use std::process::{Command, Output};

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

fn truth() -> Lfr {
    Lfr {
        linear: Modal {
            blocks: vec![Block::Pair(0.97, 0.2), Block::Real(0.5)],
            b: DMatrix::from_row_slice(3, 1, &[0.2, -0.1, 0.4]),
            c: DMatrix::from_row_slice(1, 3, &[1.0, 0.3, 0.5]),
            d: DMatrix::from_row_slice(1, 1, &[0.02]),
        },
        basis: vec![Basis::Cubic],
        e: DMatrix::from_row_slice(3, 1, &[-0.02, 0.01, 0.0]),
        f: DMatrix::from_row_slice(1, 3, &[1.0, 0.0, 0.0]),
        g: DMatrix::zeros(1, 1),
    }
}

/// Two periods of a random-phase multisine of `amp` RMS in steady state.
fn record(path: &Path, amp: f64, seed: u64) {
    let (period, fs) = (1024, 1000.0);
    let mut rng = seed;
    let mut next = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let phases: Vec<f64> = (1..period / 3)
        .map(|_| next() * std::f64::consts::TAU)
        .collect();
    let one: Vec<f64> = (0..period)
        .map(|k| {
            phases
                .iter()
                .enumerate()
                .map(|(l, ph)| {
                    (std::f64::consts::TAU * (l + 1) as f64 * k as f64 / period as f64 + ph).cos()
                })
                .sum()
        })
        .collect();
    let rms = (one.iter().map(|v| v * v).sum::<f64>() / period as f64).sqrt();
    let u: Vec<f64> = (0..2 * period)
        .map(|k| amp * one[k % period] / rms)
        .collect();
    let y = truth()
        .simulate(&with_warmup(std::slice::from_ref(&u), period))
        .unwrap();
    let t = (0..2 * period).map(|k| k as f64 / fs).collect();
    Record::new(t, vec![u], vec![y[0][period..].to_vec()])
        .unwrap()
        .write(path)
        .unwrap();
}

fn official(out: &str) -> f64 {
    let line = out
        .lines()
        .find(|l| l.starts_with("level"))
        .unwrap_or_else(|| panic!("no level line in {out}"));
    let v = line.split("official RMSE ").nth(1).unwrap();
    v.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn lfr_beats_the_linear_model_on_a_held_out_level_and_predict_runs_it() {
    let dir = std::env::temp_dir().join(format!("lfr_cli_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut train = Vec::new();
    for (i, amp) in [0.5, 1.5, 2.5].iter().enumerate() {
        let p = dir.join(format!("train{i}.csv"));
        record(&p, *amp, 10 + i as u64);
        train.push(p);
    }
    let valid = dir.join("valid.csv");
    record(&valid, 2.0, 99);
    let d = |p: &Path| p.display().to_string();
    let fit = |model: &str| {
        let out = dir.join(model);
        let mut a: Vec<String> = ["fit", "--model", model, "--order", "3", "--quiet"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        for t in &train {
            a.extend(["--train".into(), d(t)]);
        }
        a.extend(["--out".into(), d(&out)]);
        ok(&piezo(&a.iter().map(String::as_str).collect::<Vec<_>>()));
        let s = ok(&piezo(&[
            "score",
            "--model",
            &d(&out.join("fit.json")),
            "--record",
            &d(&valid),
        ]));
        official(&s)
    };
    let lin = fit("ss");
    let lfr = fit("lfr");
    assert!(lfr < 0.2 * lin, "lfr {lfr} vs linear {lin}");
    // predict on the inputs alone.
    let text = std::fs::read_to_string(&valid).unwrap();
    let u_only: String = text
        .lines()
        .map(|l| l.split(',').take(2).collect::<Vec<_>>().join(",") + "\n")
        .collect();
    std::fs::write(dir.join("u.csv"), u_only).unwrap();
    let fitjson = d(&dir.join("lfr/fit.json"));
    ok(&piezo(&[
        "predict",
        "--model",
        &fitjson,
        "--input",
        &d(&dir.join("u.csv")),
        "--out",
        &d(&dir.join("y.csv")),
    ]));
    let y = std::fs::read_to_string(dir.join("y.csv")).unwrap();
    let rows: Vec<&str> = y.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(rows[0], "t_s,y_um", "{y:.200}");
    assert_eq!(rows.len(), 1 + 2048);
    assert!(rows[1..].iter().all(|l| l
        .split(',')
        .nth(1)
        .unwrap()
        .parse::<f64>()
        .unwrap()
        .is_finite()));
    // Far outside the training amplitudes the cubic feedback diverges: that record is
    // reported as not scored, the others keep their score, and the command fails.
    // (The truth diverges there too: the valid record's input and output, scaled.)
    let far = dir.join("far.csv");
    let v = Record::read(&valid).unwrap();
    let scaled = |x: &[Vec<f64>]| -> Vec<Vec<f64>> {
        x.iter()
            .map(|c| c.iter().map(|a| 200.0 * a).collect())
            .collect()
    };
    Record::new(v.t.clone(), scaled(&v.u), scaled(&v.y))
        .unwrap()
        .write(&far)
        .unwrap();
    let o = piezo(&[
        "score",
        "--model",
        &fitjson,
        "--record",
        &d(&valid),
        "--record",
        &d(&far),
    ]);
    let (out, e) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(!o.status.success(), "{out}");
    assert!(
        e.contains("could not be scored on 1 of 2 records") && e.contains("far.csv"),
        "{e}"
    );
    let valid_line = out.lines().find(|l| l.contains("valid.csv")).unwrap();
    assert!(valid_line.contains("official RMSE"), "{out}");
    let far_line = out.lines().find(|l| l.contains("far.csv")).unwrap();
    assert!(
        far_line.contains("not scored (") && far_line.contains("diverged"),
        "{out}"
    );
    // The fit says how far its feedback stays bounded on the training inputs scaled up.
    let mut j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fitjson).unwrap()).unwrap();
    let scale = &j["report"]["lfr_input_scale"];
    assert!(scale["bounded"].as_f64().unwrap() >= 1.0, "{scale}");
    // A broken LFR section: refused, naming the matrix.
    j["lfr"]["f"][0].as_array_mut().unwrap().pop();
    let bad = dir.join("bad.json");
    std::fs::write(&bad, j.to_string()).unwrap();
    let o = piezo(&["predict", "--model", &d(&bad), "--input", &d(&valid)]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("LFR `f`"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
