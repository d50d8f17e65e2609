//! Seed 001's comparison re-run (issue 19 item 4): five hysteresis models in a Hammerstein
//! structure, fitted at 1 Hz, validated at 1, 50 and 100 Hz on a stage with rate-dependent
//! hysteresis ([`hal_sim::ident::rate`]). 001's finding: a Hammerstein model cannot follow
//! the loop's rotation at high rates, so its error grows with the rate. The same models on
//! the same stage without the rate dependence stay accurate at 100 Hz: the growth is the
//! rate dependence, not the fit.
use hal_sim::ident::rate::{compare, RateStage, FREQS_001};

#[test]
fn a_hammerstein_model_cannot_follow_rate_dependent_hysteresis() {
    let rate_hz = 10_000.0;
    let gens = 40;
    let on = compare(&RateStage::new(true, rate_hz), rate_hz, gens).unwrap();
    let off = compare(&RateStage::new(false, rate_hz), rate_hz, gens).unwrap();
    let (lin, on, off) = (on.linear, on.rows, off.rows);
    println!("linear part from the step: {lin:?}");
    println!("model   rate-dependent stage (um) {FREQS_001:?} Hz   | without the rate dependence");
    for (a, b) in on.iter().zip(&off) {
        println!(
            "{:5} {:>8.4} {:>8.4} {:>8.4}   | {:>8.4} {:>8.4} {:>8.4}",
            a.model,
            a.rmse_um[0],
            a.rmse_um[1],
            a.rmse_um[2],
            b.rmse_um[0],
            b.rmse_um[1],
            b.rmse_um[2]
        );
    }
    for (a, b) in on.iter().zip(&off) {
        let [e1, e50, e100] = a.rmse_um;
        // The error grows with the rate ...
        assert!(e1 < e50 && e50 < e100, "{}: {:?}", a.model, a.rmse_um);
        // ... and the growth is the rate dependence: without it the same models grow at
        // most half as much from 1 to 100 Hz, and end at least 0.3 um better.
        let (grow_on, grow_off) = (e100 - e1, b.rmse_um[2] - b.rmse_um[0]);
        assert!(
            grow_on > 2.0 * grow_off.max(0.0),
            "{}: {:?} vs {:?}",
            a.model,
            a.rmse_um,
            b.rmse_um
        );
        assert!(
            e100 > b.rmse_um[2] + 0.3,
            "{}: {:?} vs {:?}",
            a.model,
            a.rmse_um,
            b.rmse_um
        );
    }
}
