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
        z_limit: Vec::new(),
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
    // The cubic feedback on outputs from the BLA of all levels: the truth's structure (the
    // divergence below needs an unbounded basis).
    let fit = |model: &str| {
        let out = dir.join(model);
        let mut a: Vec<String> = ["fit", "--model", model, "--order", "3", "--quiet"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        if model == "lfr" {
            a.extend(
                [
                    "--lfr-basis",
                    "cubic",
                    "--lfr-linear",
                    "all",
                    "--lfr-channels",
                    "outputs",
                    "--lfr-iterations",
                    "60",
                ]
                .map(String::from),
            );
        }
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
    // The fit holds the feedback beyond 1.5x each channel's training peak: bounded there,
    // both records are scored.
    let o = piezo(&[
        "score",
        "--model",
        &fitjson,
        "--record",
        &d(&valid),
        "--record",
        &d(&far),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}");
    let far_line = out.lines().find(|l| l.contains("far.csv")).unwrap();
    assert!(far_line.contains("official RMSE"), "{out}");
    // Without the limit (a fit.json written before it) the cubic feedback runs away there.
    let mut j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fitjson).unwrap()).unwrap();
    let limit = j["lfr"].as_object_mut().unwrap().remove("z_limit");
    assert!(limit.is_some_and(|l| l.as_array().is_some_and(|a| a.len() == 1)));
    let unlimited = dir.join("unlimited.json");
    std::fs::write(&unlimited, j.to_string()).unwrap();
    let o = piezo(&[
        "score",
        "--model",
        &d(&unlimited),
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

/// The bounded basis, the linear part from the lowest level and one channel per mode: well
/// below the linear model on a held-out level, bounded at twice the training inputs; bad
/// settings refused by name.
#[test]
fn lfr_with_mode_channels_from_the_lowest_level_stays_bounded() {
    let dir = std::env::temp_dir().join(format!("lfr_cli_modes_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let d = |p: &Path| p.display().to_string();
    let mut args: Vec<String> = ["fit", "--model", "lfr", "--order", "3", "--quiet"]
        .map(String::from)
        .to_vec();
    for (i, amp) in [0.5, 0.55, 1.5, 2.5].iter().enumerate() {
        let p = dir.join(format!("train{i}.csv"));
        record(&p, *amp, 20 + i as u64);
        args.extend(["--train".into(), d(&p)]);
    }
    let valid = dir.join("valid.csv");
    record(&valid, 2.0, 98);
    let run = |extra: &[&str], out: &str| {
        let mut a = args.clone();
        a.extend(extra.iter().map(|s| s.to_string()));
        a.extend(["--out".into(), d(&dir.join(out))]);
        piezo(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let score = |out: &str, rec: &Path| {
        official(&ok(&piezo(&[
            "score",
            "--model",
            &d(&dir.join(out).join("fit.json")),
            "--record",
            &d(rec),
        ])))
    };
    let fit_modes = run(
        &[
            "--lfr-basis",
            "soft-cubic",
            "--lfr-linear",
            "lowest",
            "--lfr-channels",
            "modes",
            "--lfr-iterations",
            "30",
        ],
        "modes",
    );
    ok(&fit_modes);
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("modes/fit.json")).unwrap())
            .unwrap();
    // The linear part from the two records of the lowest level; one mode, one channel.
    assert_eq!(j["report"]["lfr_linear_records"], 2, "{}", j["report"]);
    assert_eq!(j["lfr"]["f"].as_array().unwrap().len(), 1);
    assert_eq!(j["lfr"]["basis"][0], "soft-cubic");
    let lfr = score("modes", &valid);
    // The linear model of all levels, as `--model ss` would fit it.
    let mut lin_args = args.clone();
    lin_args[2] = "ss".into();
    lin_args.extend(["--out".into(), d(&dir.join("ss"))]);
    ok(&piezo(
        &lin_args.iter().map(String::as_str).collect::<Vec<_>>(),
    ));
    let lin = score("ss", &valid);
    assert!(lfr < 0.5 * lin, "lfr {lfr} vs linear {lin}");
    // The soft cubic's slope is bounded: the fit's own check (training inputs scaled up to
    // 2x, from rest) finds no divergence, where the cubic's feedback runs away.
    let scale = &j["report"]["lfr_input_scale"];
    assert_eq!(scale["bounded"].as_f64(), Some(2.0), "{scale}");
    assert!(scale["diverges"].is_null(), "{scale}");
    // Far above them the loop with every channel at slope 1 (where the soft cubic tends)
    // is unstable; the fit holds the feedback beyond 1.5x each channel's training peak, so
    // far out the model is its linear part: the radius reported is that part's, and 200x
    // the inputs give a bounded prediction.
    let r = j["report"]["lfr_large_signal_radius"].as_f64().unwrap();
    assert!(r < 1.0, "{r}");
    assert_eq!(j["lfr"]["z_limit"].as_array().unwrap().len(), 1);
    let big = dir.join("big.csv");
    let mut v = Record::read(&valid).unwrap();
    v.u[0].iter_mut().for_each(|x| *x *= 200.0);
    v.write(&big).unwrap();
    let predict = |model: &Path| {
        piezo(&[
            "predict",
            "--model",
            &d(model),
            "--input",
            &d(&big),
            "--out",
            &d(&dir.join("big_y.csv")),
        ])
    };
    let limited = dir.join("modes").join("fit.json");
    ok(&predict(&limited));
    // Without the limit (a fit.json written before it) it diverges there.
    let mut nolimit = j.clone();
    nolimit["lfr"].as_object_mut().unwrap().remove("z_limit");
    let unlimited = dir.join("modes_unlimited.json");
    std::fs::write(&unlimited, nolimit.to_string()).unwrap();
    let o = predict(&unlimited);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("diverged"), "{e}");
    // Two channels per output at input gains 1/sqrt(2) and sqrt(2): two rows of F, and
    // also better than the linear model.
    ok(&run(
        &["--lfr-channels", "outputs:2", "--lfr-iterations", "10"],
        "two",
    ));
    let j2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("two/fit.json")).unwrap()).unwrap();
    assert_eq!(j2["lfr"]["f"].as_array().unwrap().len(), 2);
    let two = score("two", &valid);
    assert!(two < 0.5 * lin, "lfr outputs:2 {two} vs linear {lin}");
    for (extra, want) in [
        (
            &["--lfr-linear", "highest"][..],
            "--lfr-linear `highest`: expected all or lowest",
        ),
        (
            &["--lfr-channels", "states"][..],
            "LFR channels `states`: expected outputs, outputs:K (K = 1..=8) or modes",
        ),
        (
            &["--lfr-channels", "outputs:9"][..],
            "LFR channels `outputs:9`: expected",
        ),
        (&["--lfr-basis", "quintic"][..], "LFR basis `quintic`"),
        (
            &["--lfr-guard", "0.5"][..],
            "--lfr-guard 0.5: expected a factor >= 1",
        ),
    ] {
        let o = run(extra, "bad");
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && e.contains(want), "{extra:?}: {e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
