//! Multi-axis identification: per-pair models (`identify_pairs`, for models without a
//! multivariable form) on a record whose couplings have states of their own, and the
//! multivariable Bouc-Wen of 003 (two steps, couplings driven by the direct states) in
//! `fit_multibw.rs`.

use hal_sim::cli::fit::identify_pairs;
use hal_sim::ident::fit::resample::Edge;
use hal_sim::ident::fit::{metrics, models, FitOptions, Fitted};
use hal_sim::record::Record;

#[test]
fn pairs_find_direct_and_coupling_hysteresis() {
    let fs = 200.0;
    let n = 2400;
    // Axis 1 driven in the first half, axis 2 in the second (003 sec. IV.A experiments).
    let drive = |i: usize, half: usize| {
        if i / (n / 2) == half {
            let t = (i % (n / 2)) as f64 / fs;
            60.0 * (1.0 - (2.0 * std::f64::consts::PI * t).cos()) * (1.0 - t / 8.0)
        } else {
            0.0
        }
    };
    let u1: Vec<f64> = (0..n).map(|i| drive(i, 0)).collect();
    let u2: Vec<f64> = (0..n).map(|i| drive(i, 1)).collect();
    let cbw = models::find("cbw").unwrap();
    let sim = |p: [f64; 4], u: &[f64]| {
        Fitted::from_params(cbw, &p, 1.0, 0.0, 1)
            .unwrap()
            .simulate(u, 1.0 / fs, Edge::Hold)
            .unwrap()
    };
    let d1 = sim([0.16, 0.07, 0.02, 0.5], &u1);
    let d2 = sim([0.12, 0.05, 0.03, 0.2], &u2);
    let c21 = sim([0.02, 0.01, 0.02, 0.5], &u1); // u1 -> y2 coupling
    let y1 = d1.clone();
    let y2: Vec<f64> = d2.iter().zip(&c21).map(|(a, b)| a + b).collect();
    let t: Vec<f64> = (0..n).map(|i| i as f64 / fs).collect();
    let rec = Record::new(t, vec![u1, u2], vec![y1.clone(), y2.clone()]).unwrap();
    let opts = FitOptions {
        generations: 40,
        lm_iterations: 30,
        de_samples: 800,
        ..Default::default()
    };
    let parts = identify_pairs(cbw, &rec, &opts).unwrap();
    let kinds: Vec<_> = parts.iter().map(|p| (p.kind, p.input, p.output)).collect();
    assert!(kinds.contains(&("direct", 0, 0)) && kinds.contains(&("direct", 1, 1)));
    assert!(kinds.contains(&("coupling", 0, 1)), "{kinds:?}");
    // Total model of y2 = direct + coupling.
    let mut y2m = vec![0.0; n];
    for p in parts.iter().filter(|p| p.output == 1) {
        for (a, b) in y2m.iter_mut().zip(
            p.fit
                .simulate(&rec.u[p.input], rec.dt(), Edge::Hold)
                .unwrap(),
        ) {
            *a += b;
        }
    }
    let m = metrics(&y2, &y2m);
    // Ignoring the coupling leaves its whole loop as error.
    let direct_only = metrics(&y2, &d2);
    assert!(m.rmse < 0.2 * direct_only.rmse, "{m:?} vs {direct_only:?}");
    assert!(m.mpme_pct < 3.0, "{m:?}");
}
