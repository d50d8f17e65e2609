//! The stage's internal integration: a run at the default internal rate (hysteresis stepped
//! once per loop period, interpolated inside it) against the same run at 10x that rate with
//! the hysteresis stepped at every internal step (same noise sequences, same controller)
//! differs by at most 0.1 % of the stroke.

use hal_sim::scenario::Scenario;
use hal_sim::sim::controllers::find;
use hal_sim::sim::{calibrate, default_scenarios, Bench};

fn positions(sc: &Scenario, substeps: usize, exact: bool) -> Vec<f64> {
    let mut sc = sc.clone();
    sc.run.substeps = substeps;
    let lin = calibrate(&sc).unwrap();
    let c = (find("open-loop").unwrap().one_axis)(&hal_sim::sim::StageInfo {
        scenario: &sc,
        linear: lin,
    })
    .unwrap();
    let mut b = Bench::<1>::new(&sc, c, &lin).unwrap();
    b.stage.set_exact_hysteresis(exact);
    let n = (sc.run.duration_s * sc.run.loop_hz) as usize;
    (0..n).map(|_| b.step().position_um[0]).collect()
}

#[test]
fn integration_error_below_0p1_pct_of_stroke() {
    for name in ["sine-100hz", "steps-creep"] {
        let mut sc = default_scenarios(None, None)
            .into_iter()
            .find(|s| s.name == name)
            .unwrap();
        sc.run.duration_s = sc.run.duration_s.min(0.1);
        sc.reference.freq_hz = sc.reference.freq_hz.max(10.0); // steps: 8 per 0.1 s
        let base = sc.run.substeps;
        let coarse = positions(&sc, base, false);
        let fine = positions(&sc, 10 * base, true);
        let lo = fine.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = fine.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let stroke = hi - lo;
        let err = coarse
            .iter()
            .zip(&fine)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{name}: substeps {base} vs {}: max error {err:.2e} um = {:.4} % of {stroke:.1} um",
            10 * base,
            100.0 * err / stroke
        );
        assert!(stroke > 10.0);
        assert!(err <= 1e-3 * stroke, "{name}: {err} um of {stroke} um");
    }
}
