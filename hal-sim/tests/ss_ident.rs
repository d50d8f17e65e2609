//! Subspace + output-error identification recovers a known multivariable system with a
//! non-minimum-phase zero from periodic multisine records.
use hal_sim::ident::ss::model::{Block, Modal, C64};
use hal_sim::ident::ss::{identify, SsOptions};
use hal_sim::numeric::Rng;
use hal_sim::record::Record;
use nalgebra::DMatrix;

/// Order 5, 2 inputs, 2 outputs. `G11 = 0.5 + 1 / (z - 0.5)` has its zero at z = -1.5?
/// No: `d + cb / (z - l)` is zero at `z = l - cb / d` = 0.5 - 1 / (-0.5) = 2.5, outside
/// the unit circle: u1 -> y1 is non-minimum phase.
fn truth() -> Modal {
    Modal {
        blocks: vec![
            Block::Pair(0.95, 0.2),
            Block::Pair(0.6, 0.7),
            Block::Real(0.5),
        ],
        // States 0..4 are the pairs; they do not reach y1 from u1 (B[.., 0] = 0 there).
        b: DMatrix::from_row_slice(5, 2, &[0.0, 0.3, 0.0, -0.2, 0.0, 0.5, 0.0, 0.4, 1.0, 0.2]),
        c: DMatrix::from_row_slice(2, 5, &[0.5, 0.1, 0.3, -0.4, 1.0, 0.7, -0.2, 0.4, 0.3, 0.6]),
        d: DMatrix::from_row_slice(2, 2, &[-0.5, 0.0, 0.1, 0.2]),
    }
}

/// Realization `r`: random-phase multisines on both inputs, two periods of steady state.
fn record(sys: &Modal, r: u64, noise: f64) -> Record {
    let n = 256;
    let mut rng = Rng::new(100 + r);
    let u: Vec<Vec<f64>> = (0..2)
        .map(|_| {
            let ph: Vec<f64> = (1..n / 2)
                .map(|_| 2.0 * std::f64::consts::PI * rng.uniform())
                .collect();
            (0..3 * n)
                .map(|i| {
                    ph.iter()
                        .enumerate()
                        .map(|(k, p)| {
                            (2.0 * std::f64::consts::PI * (k + 1) as f64 * i as f64 / n as f64 + p)
                                .cos()
                        })
                        .sum::<f64>()
                        * 0.1
                })
                .collect()
        })
        .collect();
    let y = sys.simulate(&u).unwrap();
    let keep = |x: &Vec<f64>| x[n..].to_vec();
    let t: Vec<f64> = (0..2 * n).map(|i| i as f64 * 1e-3).collect();
    let y: Vec<Vec<f64>> = y
        .iter()
        .map(|c| {
            keep(c)
                .into_iter()
                .map(|v| v + noise * (rng.uniform() - 0.5))
                .collect()
        })
        .collect();
    Record::new(t, u.iter().map(keep).collect(), y).unwrap()
}

fn max_response_error(a: &Modal, b: &Modal, zs: &[C64]) -> f64 {
    zs.iter()
        .map(|&z| (a.response(z) - b.response(z)).norm() / b.response(z).norm())
        .fold(0.0, f64::max)
}

#[test]
fn subspace_and_output_error_recover_a_nonminimum_phase_mimo_system() {
    let sys = truth();
    let recs: Vec<Record> = (0..4).map(|r| record(&sys, r, 1e-4)).collect();
    let fit = identify(
        &recs,
        &SsOptions {
            order: Some(5),
            iterations: 30,
            ..Default::default()
        },
    )
    .unwrap();
    let m = &fit.model.linear;
    assert!(fit.model.fronts.is_empty());
    assert!(m.spectral_radius() < 1.0);
    let circle: Vec<C64> = (1..64)
        .map(|k| C64::from_polar(1.0, std::f64::consts::PI * k as f64 / 64.0))
        .collect();
    let e = max_response_error(m, &sys, &circle);
    assert!(e < 1e-3, "relative response error on the unit circle {e}");
    // The non-minimum-phase zero of u1 -> y1 at z = 2.5 is recovered.
    let g11 = m.response(C64::new(2.5, 0.0))[(0, 0)].norm()
        / m.response(C64::new(1.0, 0.0))[(0, 0)].norm();
    assert!(g11 < 1e-3, "|G11(2.5)| / |G11(1)| = {g11}");
    // Time domain from rest on a fresh realization.
    let v = record(&sys, 9, 0.0);
    let sim = m.simulate(&v.u).unwrap();
    for (y, s) in v.y.iter().zip(&sim) {
        let rms = (y.iter().map(|a| a * a).sum::<f64>() / y.len() as f64).sqrt();
        let err = (y[256..]
            .iter()
            .zip(&s[256..])
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / 256.0)
            .sqrt();
        assert!(err < 1e-3 * rms, "simulation error {err} of {rms}");
    }
    // Too low an order cannot reach the bound (the checks above can fail).
    let low = identify(
        &recs,
        &SsOptions {
            order: Some(3),
            iterations: 30,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(max_response_error(&low.model.linear, &sys, &circle) > 1e-2);
}

#[test]
fn automatic_order_finds_the_true_order_or_close() {
    let sys = truth();
    let recs: Vec<Record> = (0..8).map(|r| record(&sys, r, 1e-3)).collect();
    let fit = identify(
        &recs,
        &SsOptions {
            order: None,
            candidates: (1..=10).collect(),
            iterations: 10,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(
        (5..=7).contains(&fit.order),
        "order {} chosen: {:?}",
        fit.order,
        fit.order_scan
    );
}
