//! The Bouc-Wen benchmark (Noel & Schoukens 2016): identify the structural Bouc-Wen model
//! on the training record only (parameters unknown: DE over wide boxes, then LM), simulate
//! both test records, and beat PNLSS (e_RMS 1.87e-5 m on the test multisine).
//!
//! The test multisine is one period of a periodic steady state (its first sample is not at
//! rest), so it is simulated in steady state: the test input is repeated three periods
//! before the scored one (only the test input is used). The sine sweep starts from rest.
//!
//! Heavy (a minute in release on a loaded 2-core machine): ignored in the dev profile, run
//! by `.ci/test.d/60-fit-benchmark.sh` as
//! `cargo test --release -p hal-sim --test benchmark_boucwen -- --ignored --nocapture`.

use hal_sim::ident::fit::resample::Edge;
use hal_sim::ident::fit::{fit_siso, metrics, models, FitOptions};
use hal_sim::record::{data_dir, Record};

/// Published e_RMS of PNLSS on the test multisine (Esfahani et al. 2017).
const PNLSS_M: f64 = 1.87e-5;

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

#[test]
#[ignore = "heavy: run in release via .ci/test.d/60-fit-benchmark.sh"]
fn structural_bw_beats_pnlss_on_both_test_records() {
    let dir = data_dir().join("boucwen-benchmark");
    let train = Record::read(dir.join("train_multisine.csv")).unwrap();
    let t0 = std::time::Instant::now();
    // CI-sized search: a short DE on the first 4096 samples, LM on the whole record with
    // the input upsampled 5x (the benchmark integrates at 20x; 5x with RK4 is as exact).
    let opts = FitOptions {
        generations: env("BW_GENERATIONS", 80),
        upsample: env("BW_UPSAMPLE", 5),
        progress: true,
        ..Default::default()
    };
    let def = models::find("structural-bw").unwrap();
    let fit = fit_siso(def, &train.u[0], &train.y[0], train.dt(), &opts).unwrap();
    eprintln!(
        "fit in {:.1} s: {:?}",
        t0.elapsed().as_secs_f64(),
        fit.params
    );
    let yt = fit.simulate(&train.u[0], train.dt(), Edge::Hold).unwrap();
    let train_m = metrics(&train.y[0], &yt);
    eprintln!("train: {train_m:?}");
    // The training residual is the benchmark noise (8e-6 m RMS) if the model is right.
    assert!(train_m.rmse < 1e-5, "{train_m:?}");

    let ms = Record::read(dir.join("test_multisine.csv")).unwrap();
    let y = fit.simulate_periodic(&ms.u[0], ms.dt(), 3).unwrap();
    let e_ms = metrics(&ms.y[0], &y).rmse;
    let y0 = fit.simulate(&ms.u[0], ms.dt(), Edge::Hold).unwrap();
    eprintln!(
        "test_multisine: e_RMS {e_ms:.3e} m steady state ({:.3e} m if wrongly started from rest)",
        metrics(&ms.y[0], &y0).rmse
    );
    let sw = Record::read(dir.join("test_sinesweep.csv")).unwrap();
    let y = fit.simulate(&sw.u[0], sw.dt(), Edge::Hold).unwrap();
    let e_sw = metrics(&sw.y[0], &y).rmse;
    eprintln!("test_sinesweep: e_RMS {e_sw:.3e} m from rest");
    assert!(
        e_ms < PNLSS_M,
        "multisine e_RMS {e_ms:.3e} m, PNLSS {PNLSS_M:.2e} m"
    );
    assert!(
        e_sw < PNLSS_M,
        "sweep e_RMS {e_sw:.3e} m, PNLSS {PNLSS_M:.2e} m"
    );
}

/// Why the test multisine is scored in steady state: the benchmark's own system (the
/// parameters its document states) reproduces the record only in steady state. Simulated
/// from rest over the one given period it misses by the decaying start-up transient, which
/// no model can avoid: the record starts moving (y(0) = 1.9e-4 m, y'(0) about 0.3 m/s).
#[test]
fn the_test_multisine_is_one_steady_state_period() {
    let dir = data_dir().join("boucwen-benchmark");
    let ms = Record::read(dir.join("test_multisine.csv")).unwrap();
    let def = models::find("structural-bw").unwrap();
    // m, c, k, alpha, beta*gamma, beta*delta, nu (Noel & Schoukens 2016, table 1).
    let truth = hal_sim::ident::fit::Fitted::from_params(
        def,
        &[2.0, 10.0, 5e4, 5e4, 800.0, -1100.0, 1.0],
        1.0,
        0.0,
        20,
    )
    .unwrap();
    let steady = metrics(
        &ms.y[0],
        &truth.simulate_periodic(&ms.u[0], ms.dt(), 2).unwrap(),
    );
    let rest = metrics(
        &ms.y[0],
        &truth.simulate(&ms.u[0], ms.dt(), Edge::Hold).unwrap(),
    );
    let n = ms.y[0].len();
    let head = metrics(
        &ms.y[0][..n / 10],
        &truth.simulate(&ms.u[0], ms.dt(), Edge::Hold).unwrap()[..n / 10],
    );
    eprintln!(
        "true system on test_multisine: steady state e_RMS {:.3e} m, from rest {:.3e} m (first tenth {:.3e} m)",
        steady.rmse, rest.rmse, head.rmse
    );
    assert!(steady.rmse < 1e-6, "{steady:?}");
    assert!(rest.rmse > PNLSS_M, "{rest:?}");
}
