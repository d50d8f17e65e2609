//! The multivariable Bouc-Wen of 003 identified in its two steps (sec. IV) on a ground truth
//! of exactly that structure: couplings driven by the direct hysteresis states `h_j`
//! (003 eq. 7, 12). Independent per-pair models (a state of their own per coupling) are
//! run on the same records and must do clearly worse; the identified matrices are handed
//! to the multivariable IMS (003 eq. 16) and compensate the ground truth.

mod cli_support;

use hal_sim::cli::fit::{identify, identify_pairs, Identified, Part};
use hal_sim::ident::fit::resample::Edge;
use hal_sim::ident::fit::{metrics, models, FitOptions};
use hal_sim::ident::multibw;
use hal_sim::record::Record;
use piezo_core::feedforward::MultiIms;
use piezo_core::hysteresis::multi::MultiBw;
use std::f64::consts::PI;

const FS: f64 = 100.0;

/// Ground truth: direct transfers of the 000 backup-slide scale, couplings with a linear
/// part and hysteresis driven by the other axis's direct state.
fn truth() -> MultiBw<f64, 2, 2> {
    MultiBw::new(
        [[0.16, -0.012], [0.015, 0.12]],
        [[0.07, 0.0], [0.0, 0.05]],
        [[0.02, -0.0015], [0.002, 0.03]],
        [[0.01, 0.001], [0.0012, 0.006]],
    )
    .unwrap()
}

fn run(m: &MultiBw<f64, 2, 2>, u: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut s = m.init([u[0][0], u[1][0]]);
    let mut y = vec![vec![0.0; u[0].len()]; 2];
    for i in 0..u[0].len() {
        let yi = m.step(&mut s, [u[0][i], u[1][i]], 0.0);
        y[0][i] = yi[0];
        y[1][i] = yi[1];
    }
    y
}

fn record(u: Vec<Vec<f64>>, offsets: [f64; 2]) -> Record {
    let mut y = run(&truth(), &u);
    for (y, o) in y.iter_mut().zip(offsets) {
        y.iter_mut().for_each(|v| *v += o);
    }
    let t = (0..u[0].len()).map(|i| i as f64 / FS).collect();
    Record::new(t, u, y).unwrap()
}

/// 003 sec. IV.A: one input at a time, the other at zero; a decaying 0.4 Hz sine so the
/// record holds the outer loop and minor loops.
fn training() -> Record {
    let n = (12.0 * FS) as usize;
    let drive = |i: usize, axis: usize| {
        if i / (n / 2) != axis {
            return 0.0;
        }
        let t = (i % (n / 2)) as f64 / FS;
        100.0 * (2.0 * PI * 0.4 * t).sin() * (1.0 - t / 6.0)
    };
    let u = (0..2)
        .map(|a| (0..n).map(|i| drive(i, a)).collect())
        .collect();
    record(u, [0.3, -0.2])
}

/// Both inputs at once (never seen in training): 0.3 Hz and 0.45 Hz, different amplitudes.
fn validation() -> Record {
    let n = (10.0 * FS) as usize;
    let t = |i: usize| i as f64 / FS;
    let u = vec![
        (0..n)
            .map(|i| 90.0 * (2.0 * PI * 0.3 * t(i)).sin())
            .collect(),
        (0..n)
            .map(|i| 70.0 * (2.0 * PI * 0.45 * t(i) + 1.0).sin() - 70.0 * 1f64.sin())
            .collect(),
    ];
    record(u, [0.3, -0.2])
}

fn opts() -> FitOptions {
    FitOptions {
        generations: 60,
        lm_iterations: 40,
        de_samples: 1200,
        ..Default::default()
    }
}

fn pairs_simulate(parts: &[Part], rec: &Record) -> Vec<Vec<f64>> {
    let mut out = vec![vec![0.0; rec.len()]; 2];
    for p in parts {
        let y = p
            .fit
            .simulate(&rec.u[p.input], rec.dt(), Edge::Hold)
            .unwrap();
        for (d, v) in out[p.output].iter_mut().zip(y) {
            *d += v;
        }
    }
    out
}

fn rmse(rec: &Record, sim: &[Vec<f64>]) -> [f64; 2] {
    [0, 1].map(|i| metrics(&rec.y[i], &sim[i]).rmse)
}

#[test]
fn two_step_identification_beats_independent_couplings() {
    let (train, valid) = (training(), validation());
    let cbw = models::find("cbw").unwrap();
    // 003's two steps alone.
    let two = multibw::two_step(&train, &opts()).unwrap();
    let two_valid = rmse(&valid, &two.simulate(&valid.u).unwrap());
    // With the joint refinement: what `piezo fit --model cbw` runs.
    let Identified { multibw, parts } = identify(cbw, &train, &opts()).unwrap();
    let m = multibw.expect("cbw on a 2 x 2 record is the multivariable Bouc-Wen of 003");
    assert_eq!(parts.len(), 2, "{parts:?}");
    assert_eq!(m.ims, "accepted");
    let joint_valid = rmse(&valid, &m.simulate(&valid.u).unwrap());
    // Independent per-pair models with states of their own.
    let pairs = identify_pairs(cbw, &train, &opts()).unwrap();
    let pairs_train = rmse(&train, &pairs_simulate(&pairs, &train));
    let pairs_valid = rmse(&valid, &pairs_simulate(&pairs, &valid));
    let range = |y: &[f64]| {
        y.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - y.iter().cloned().fold(f64::INFINITY, f64::min)
    };
    eprintln!(
        "RMSE [y1, y2] um, train / valid (ranges {:.2}, {:.2} um):\n  003 two steps  {:?} / \
         {two_valid:?}\n  + joint LM     {:?} / {joint_valid:?}\n  independent    \
         {pairs_train:?} / {pairs_valid:?}\nD {:?}\nA {:?}\nB {:?}\nG {:?}",
        range(&valid.y[0]),
        range(&valid.y[1]),
        two.two_step_rmse,
        m.joint_rmse,
        m.d,
        m.a,
        m.b,
        m.gamma
    );
    for i in 0..2 {
        let r = range(&valid.y[i]);
        // The structure of the truth carries to the never-seen simultaneous drive.
        assert!(two_valid[i] < 1e-3 * r, "y{}: {two_valid:?}", i + 1);
        assert!(joint_valid[i] < 2e-4 * r, "y{}: {joint_valid:?}", i + 1);
        // Independent couplings cannot: at least 5x the error of 003's two steps.
        assert!(
            pairs_valid[i] > 5.0 * two_valid[i],
            "y{}: {pairs_valid:?} vs {two_valid:?}",
            i + 1
        );
    }
    // The couplings found are the truth's (D_ij - A_ij, B_ij, Gamma_ij for i != j).
    let t = truth();
    for (i, j) in [(0, 1), (1, 0)] {
        let want = [t.d()[i][j] - t.a()[i][j], t.b()[i][j], t.gamma()[i][j]];
        for (what, f, tol) in [("two-step", &two, 0.15), ("joint", &m, 0.02)] {
            let got = [f.d[i][j] - f.a[i][j], f.b[i][j], f.gamma[i][j]];
            for (g, w) in got.iter().zip(want) {
                assert!(
                    (g - w).abs() < tol * w.abs(),
                    "{what} ({i}, {j}): {got:?} vs {want:?}"
                );
            }
        }
    }
}

#[test]
fn identified_matrices_drive_the_multivariable_ims() {
    // The paper's two steps alone (the joint refinement recovers the truth exactly, which
    // would make this trivial).
    let m = multibw::two_step(&training(), &opts()).unwrap();
    let ims: MultiIms<f64, 2, 2> = m.ims(-150.0, 150.0, 1.0 / FS).unwrap();
    // The same model with its couplings removed (direct transfers only).
    let mut diag = m.clone();
    for (i, j) in [(0, 1), (1, 0)] {
        diag.d[i][j] = 0.0;
        diag.b[i][j] = 0.0;
        diag.gamma[i][j] = 0.0;
    }
    let ims_diag: MultiIms<f64, 2, 2> = diag.ims(-150.0, 150.0, 1.0 / FS).unwrap();
    // Track a Lissajous figure on the ground truth (offsets are the sensor's, not the
    // stage's: the truth runs without them).
    let plant = truth();
    let track = |mut c: MultiIms<f64, 2, 2>| {
        let mut s = plant.init([0.0; 2]);
        let mut worst = [0.0f64; 2];
        for i in 0..(10.0 * FS) as usize {
            let t = i as f64 / FS;
            let r = [
                8.0 * (2.0 * PI * 0.4 * t).sin(),
                6.0 * (2.0 * PI * 0.3 * t).sin(),
            ];
            let u = c.compensate(&r);
            let y = plant.step(&mut s, u, 1.0 / FS);
            for a in 0..2 {
                worst[a] = worst[a].max((y[a] - r[a]).abs());
            }
        }
        worst
    };
    let with = track(ims);
    let without = track(ims_diag);
    eprintln!("IMS max |error| with the couplings {with:?}, direct terms only {without:?}");
    for a in 0..2 {
        assert!(with[a] < 0.05, "axis {}: {with:?}", a + 1);
        assert!(
            with[a] < 0.2 * without[a],
            "axis {}: {with:?} vs {without:?}",
            a + 1
        );
    }
}

#[test]
fn cli_prints_and_saves_the_matrices() {
    let dir = std::env::temp_dir().join(format!("fit_multibw_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    training().write(dir.join("train.csv")).unwrap();
    validation().write(dir.join("valid.csv")).unwrap();
    let out = cli_support::piezo(&[
        &"fit",
        &"--model",
        &"cbw",
        &"--quiet",
        &"--generations",
        &"40",
        &"--train",
        &dir.join("train.csv"),
        &"--valid",
        &dir.join("valid.csv"),
        &"--out",
        &dir,
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("multivariable Bouc-Wen (003 eq. 4-7)"),
        "{text}"
    );
    assert!(
        text.contains("multivariable IMS (003 eq. 16-19): accepted"),
        "{text}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("fit.json")).unwrap()).unwrap();
    let b = &json["multibw"]["b"];
    assert!((b[0][1].as_f64().unwrap() + 0.0015).abs() < 1e-4, "{b}");
    for m in json["valid_metrics"].as_array().unwrap() {
        assert!(m["metrics"]["rmse"].as_f64().unwrap() < 1e-3, "{m}");
    }
    // `piezo predict` simulates the saved model on the inputs alone (`t,u1,u2`).
    let valid = validation();
    let mut csv = String::from("t,u1,u2\n");
    for k in 0..valid.len() {
        csv += &format!("{},{},{}\n", valid.t[k], valid.u[0][k], valid.u[1][k]);
    }
    std::fs::write(dir.join("u.csv"), csv).unwrap();
    cli_support::piezo(&[
        &"predict",
        &"--model",
        &dir.join("fit.json"),
        &"--input",
        &dir.join("u.csv"),
        &"--out",
        &dir.join("y.csv"),
    ]);
    // `t,y1,y2` after `#` comments and the header.
    let text = std::fs::read_to_string(dir.join("y.csv")).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').map(|x| x.trim().parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), valid.len());
    for i in 0..2 {
        let yi: Vec<f64> = rows.iter().map(|r| r[i + 1]).collect();
        let m = metrics(&valid.y[i], &yi);
        assert!(m.rmse < 1e-3, "y{}: {m:?}", i + 1);
    }
    std::fs::remove_dir_all(&dir).ok();
}
