//! Rate dependence where it is measured: hal-sim's stage driven by sines at 20, 40 and
//! 100 Hz, each record training in turn while the other two validate. With the stage's
//! rate-dependent hysteresis (`stage.rate_hysteresis` at its defaults: the loop 30 % wider
//! and the gain 5 % lower at high rates, half of it at 5 kV/s) `rate-dependence` must be
//! named in every direction; on the same stage without it, in none.
use hal_sim::ident::diagnose::{diagnose_records, Cause, Options, Signals};
use hal_sim::ident::generate::Hidden;
use hal_sim::scenario::RateHysteresis;

const RATE_HZ: f64 = 10_000.0;
const DURATION_S: f64 = 0.5;
const DRIVES_HZ: [f64; 3] = [20.0, 40.0, 100.0];

/// `45 (1 - cos(2 pi f t))` V: 0..90 V, from rest at 0 V.
fn sine(f_hz: f64) -> Vec<f64> {
    let n = (RATE_HZ * DURATION_S) as usize;
    (0..n)
        .map(|k| 45.0 * (1.0 - (std::f64::consts::TAU * f_hz * k as f64 / RATE_HZ).cos()))
        .collect()
}

/// The stage of `seed` (hal-sim's hidden-cause draw, nothing else hidden) with or without
/// its rate-dependent hysteresis, one record per drive frequency.
fn records(seed: u64, rate_dependent: bool) -> Vec<Signals> {
    let mut h = Hidden::draw_at(seed, &[], RATE_HZ, DURATION_S).unwrap();
    h.scenario.stage.rate_hysteresis = RateHysteresis {
        enabled: rate_dependent,
        ..RateHysteresis::default()
    };
    DRIVES_HZ
        .iter()
        .enumerate()
        .map(|(k, &f)| h.record_with(vec![sine(f)], k as u64).unwrap())
        .collect()
}

/// The causes named with each record training and the other two validating.
fn each_direction(recs: &[Signals]) -> Vec<(f64, Vec<Cause>)> {
    (0..recs.len())
        .map(|k| {
            let valid: Vec<Signals> = (0..recs.len())
                .filter(|j| *j != k)
                .map(|j| recs[j].clone())
                .collect();
            let d = diagnose_records(&recs[k..=k], &valid, &Options::default()).unwrap();
            (DRIVES_HZ[k], d.findings.iter().map(|f| f.cause).collect())
        })
        .collect()
}

#[test]
fn rate_dependence_named_in_every_direction_and_only_with_the_effect() {
    let mut failed = Vec::new();
    for seed in 1..=2 {
        for rate_dependent in [true, false] {
            for (f, found) in each_direction(&records(seed, rate_dependent)) {
                let named = found.contains(&Cause::RateDependence);
                eprintln!(
                    "seed {seed} rate dependence {}: {f} Hz trains, found {found:?}",
                    if rate_dependent { "on" } else { "off" }
                );
                if named != rate_dependent {
                    failed.push(format!(
                        "seed {seed}, effect {rate_dependent}, {f} Hz training: {found:?}"
                    ));
                }
            }
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}
