//! `piezo predict` runs every kind of `fit.json` (`cbw` and `ss` here) on inputs-only
//! records and gives what `piezo fit` simulated; bad inputs get clear errors.
use hal_sim::ident::ss::model::{Block, Modal};
use hal_sim::record::Record;
use nalgebra::DMatrix;
use piezo_core::hysteresis::{Cbw, Hysteresis};
use std::path::Path;
use std::process::{Command, Output};

fn piezo(args: &[&str], paths: &[(&str, &Path)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_piezo"));
    c.args(args);
    for (flag, p) in paths {
        c.arg(flag).arg(p);
    }
    c.output().unwrap()
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn inputs_only(rec: &Record, path: &Path) {
    let text = rec.to_csv();
    let mut out = String::new();
    let k = 1 + rec.u.len();
    for line in text.lines() {
        let f: Vec<&str> = line.split(',').collect();
        out.push_str(&f[..k.min(f.len())].join(","));
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn a_fitted_cbw_predicts_what_fit_simulated() {
    let dir = std::env::temp_dir().join(format!("predict_cbw_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let dt = 2e-3;
    let m = Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
    let u: Vec<f64> = (0..1000)
        .map(|k| 50.0 * (1.0 + (k as f64 * 0.02).sin()))
        .collect();
    let mut s = m.init(u[0]);
    let y: Vec<f64> = u.iter().map(|&u| m.step(&mut s, u, dt)).collect();
    let t: Vec<f64> = (0..u.len()).map(|k| k as f64 * dt).collect();
    let rec = Record::new(t, vec![u], vec![y]).unwrap();
    rec.write(dir.join("train.csv")).unwrap();
    inputs_only(&rec, &dir.join("u.csv"));
    ok(&piezo(
        &[
            "fit",
            "--model",
            "cbw",
            "--quiet",
            "--generations",
            "10",
            "--lm-iterations",
            "10",
        ],
        &[
            ("--train", &dir.join("train.csv")),
            ("--out", &dir.join("fit")),
            ("--predict", &dir.join("p.csv")),
        ],
    ));
    ok(&piezo(
        &["predict"],
        &[
            ("--model", &dir.join("fit/fit.json")),
            ("--input", &dir.join("u.csv")),
            ("--out", &dir.join("y.csv")),
        ],
    ));
    let fit = Record::read(dir.join("p.csv")).unwrap();
    let text = std::fs::read_to_string(dir.join("y.csv")).unwrap();
    assert!(text.lines().any(|l| l == "t_s,y_um"), "{}", &text[..200]);
    let ys: Vec<f64> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('t'))
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    assert_eq!(ys.len(), fit.y[0].len());
    for (a, b) in ys.iter().zip(&fit.y[0]) {
        assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{a} vs {b}");
    }
}

/// A 2-input, 2-output periodic record from a known model: four periods after one of
/// warm-up, so a simulation from rest has settled by the last one.
fn mimo_record(path: &Path, fs: f64, seed: f64) {
    let sys = Modal {
        blocks: vec![Block::Pair(0.9, 0.3), Block::Real(0.5)],
        b: DMatrix::from_row_slice(3, 2, &[1.0, 0.5, -0.2, 1.0, 0.3, 0.0]),
        c: DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 2.0, 0.0, 1.0, -1.0]),
        d: DMatrix::from_row_slice(2, 2, &[0.1, 0.0, 0.0, 0.2]),
    };
    let n = 128;
    let u: Vec<Vec<f64>> = (0..2)
        .map(|j| {
            (0..5 * n)
                .map(|i| {
                    (1..40)
                        .map(|k| {
                            let ph = (k as f64 * (seed + 1.7 * j as f64 + 0.3)).sin() * 3.0;
                            (2.0 * std::f64::consts::PI * k as f64 * i as f64 / n as f64 + ph).cos()
                        })
                        .sum::<f64>()
                })
                .collect()
        })
        .collect();
    let y = sys.simulate(&u).unwrap();
    let keep = |x: &Vec<f64>| x[n..].to_vec();
    let t: Vec<f64> = (0..4 * n).map(|i| i as f64 / fs).collect();
    Record::new(
        t,
        u.iter().map(keep).collect(),
        y.iter().map(keep).collect(),
    )
    .unwrap()
    .write(path)
    .unwrap();
}

#[test]
fn state_space_fit_and_predict_with_clear_errors() {
    let dir = std::env::temp_dir().join(format!("predict_ss_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (i, s) in [0.1, 0.7, 1.3, 2.9].iter().enumerate() {
        mimo_record(&dir.join(format!("r{i}.csv")), 1000.0, *s);
    }
    mimo_record(&dir.join("slow.csv"), 500.0, 4.1);
    let train: Vec<_> = (0..4).map(|i| dir.join(format!("r{i}.csv"))).collect();
    let mut paths: Vec<(&str, &Path)> = train.iter().map(|p| ("--train", p.as_path())).collect();
    let out = dir.join("ss");
    paths.push(("--out", &out));
    ok(&piezo(
        &["fit", "--model", "ss", "--order", "3", "--quiet"],
        &paths,
    ));
    let v = Record::read(dir.join("r0.csv")).unwrap();
    inputs_only(&v, &dir.join("u.csv"));
    ok(&piezo(
        &["predict"],
        &[
            ("--model", &out.join("fit.json")),
            ("--input", &dir.join("u.csv")),
            ("--out", &dir.join("y.csv")),
        ],
    ));
    let text = std::fs::read_to_string(dir.join("y.csv")).unwrap();
    assert!(text.lines().any(|l| l == "t_s,y1_um,y2_um"), "{text:.300}");
    // Scored when the record has outputs: the right order, small error over the last period.
    let s = ok(&piezo(
        &["predict"],
        &[
            ("--model", &out.join("fit.json")),
            ("--input", &dir.join("r1.csv")),
        ],
    ));
    let mean: f64 = s
        .split("mean ")
        .nth(1)
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    // Outputs are about 4 RMS; a wrong or unsettled model misses by far more.
    assert!(mean < 1e-2, "{s}");
    // Mismatched sample rates among --train records.
    let o = piezo(
        &["fit", "--model", "ss", "--order", "3", "--quiet"],
        &[("--train", &train[0]), ("--train", &dir.join("slow.csv"))],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("sampled at"), "{e}");
    // Wrong column count for the model, and a sample rate the model was not made for.
    std::fs::write(dir.join("one.csv"), "t,u1\n0,1\n0.001,2\n0.002,3\n").unwrap();
    let o = piezo(
        &["predict"],
        &[
            ("--model", &out.join("fit.json")),
            ("--input", &dir.join("one.csv")),
        ],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("2 inputs, the record 1"),
        "{e}"
    );
    let o = piezo(
        &["predict"],
        &[
            ("--model", &out.join("fit.json")),
            ("--input", &dir.join("slow.csv")),
        ],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("500.000000 Hz"), "{e}");
    // Several --train records for a model that takes one.
    let o = piezo(
        &["fit", "--model", "cbw", "--quiet"],
        &[("--train", &train[0]), ("--train", &train[1])],
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("takes one --train record"));
}
