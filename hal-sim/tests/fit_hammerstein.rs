//! Hammerstein identification (hysteresis -> linear dynamics, 004 eq. 8): joint fit and
//! the two-step procedure of 004 sec. 4.2 (linear part from a PRBS record first).

use hal_sim::ident::fit::resample::Edge;
use hal_sim::ident::fit::{apply_linear, fit_siso, metrics, models, FitOptions, Fitted};
use hal_sim::numeric::Rng;

const FS: f64 = 2000.0;
/// The true linear part: one section at 60 Hz, damping 0.3.
const LIN: (f64, f64) = (60.0, 0.3);

/// Sine with rising frequency 2..40 Hz: the loops rotate with rate through the dynamics.
fn sweep(n: usize) -> Vec<f64> {
    let mut ph = 0.0;
    (0..n)
        .map(|i| {
            let f = 2.0 + 38.0 * i as f64 / n as f64;
            ph += 2.0 * std::f64::consts::PI * f / FS;
            50.0 + 45.0 * ph.sin()
        })
        .collect()
}

/// Truth: CBW (000 set 1) then the linear section, offset 2 um.
fn truth(u: &[f64]) -> Vec<f64> {
    let cbw = models::find("cbw").unwrap();
    let h = Fitted::from_params(cbw, &[0.16, 0.07, 0.02, 0.5], 1.0, 0.0, 1).unwrap();
    let mut y = h.simulate(u, 1.0 / FS, Edge::Hold).unwrap();
    apply_linear(&[LIN], 1.0 / FS, &mut y).unwrap();
    y.iter().map(|v| v + 2.0).collect()
}

fn opts() -> FitOptions {
    FitOptions {
        generations: 40,
        lm_iterations: 30,
        de_samples: 1000,
        linear_sections: 1,
        ..Default::default()
    }
}

#[test]
fn joint_fit_recovers_the_linear_section() {
    let u = sweep(3000);
    let y = truth(&u);
    let cbw = models::find("cbw").unwrap();
    let f = fit_siso(cbw, &u, &y, 1.0 / FS, &opts()).unwrap();
    let m = metrics(&y, &f.simulate(&u, 1.0 / FS, Edge::Hold).unwrap());
    assert!(m.rmse < 1e-3 * 15.0, "{m:?} {f:?}");
    let (fh, z) = f.linear[0];
    assert!(
        (fh - LIN.0).abs() < 0.01 * LIN.0 && (z - LIN.1).abs() < 0.02,
        "{f:?}"
    );
    // Without the linear part the rate-dependent loops cannot be matched as well.
    let plain = fit_siso(
        cbw,
        &u,
        &y,
        1.0 / FS,
        &FitOptions {
            linear_sections: 0,
            ..opts()
        },
    )
    .unwrap();
    let mp = metrics(&y, &plain.simulate(&u, 1.0 / FS, Edge::Hold).unwrap());
    assert!(mp.rmse > 5.0 * m.rmse, "{mp:?} vs {m:?}");
}

#[test]
fn two_step_identifies_linear_part_from_prbs_then_hysteresis() {
    // Step 1 record: PRBS around 50 V, small amplitude (hysteresis nearly linear there).
    let mut rng = Rng::new(5);
    let mut level = 1.0;
    let prbs: Vec<f64> = (0..3000)
        .map(|i| {
            if i % 8 == 0 && rng.uniform() < 0.5 {
                level = -level;
            }
            50.0 + 2.0 * level
        })
        .collect();
    let y1 = truth(&prbs);
    let gain = models::find("gain").unwrap();
    let lin = fit_siso(gain, &prbs, &y1, 1.0 / FS, &opts()).unwrap();
    let (fh, z) = lin.linear[0];
    assert!(
        (fh - LIN.0).abs() < 0.05 * LIN.0 && (z - LIN.1).abs() < 0.05,
        "{lin:?}"
    );
    // Step 2: hysteresis on the sweep with the linear part fixed.
    let u = sweep(3000);
    let y = truth(&u);
    let step2 = FitOptions {
        linear_fixed: Some(lin.linear.clone()),
        ..opts()
    };
    let f = fit_siso(models::find("cbw").unwrap(), &u, &y, 1.0 / FS, &step2).unwrap();
    assert_eq!(f.linear, lin.linear);
    let m = metrics(&y, &f.simulate(&u, 1.0 / FS, Edge::Hold).unwrap());
    assert!(m.mpme_pct < 2.0, "{m:?} {f:?}");
}
