//! Seed 002 on a stage whose hysteresis is its MBW (`tests/feedforward-scenarios/
//! mbw002-1hz.toml`): the ordering of its fits (RMSE of CBW > ABW > MBW, 002 table 2) on
//! that stage's open-loop record, and `mbw` with the MBW identified from it.

use hal_sim::ident::fit::{fit_siso, models, FitOptions};
use hal_sim::scenario::Scenario;
use hal_sim::sim::controllers::{find, identified::open_loop_record};
use hal_sim::sim::{calibrate, run_calibrated, StageInfo};
use std::path::Path;

fn scenario() -> Scenario {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/feedforward-scenarios/mbw002-1hz.toml");
    Scenario::load(&p).unwrap()
}

#[test]
fn fits_order_as_in_002_and_ff_mbw_compensates() {
    let sc = scenario();
    let linear = calibrate(&sc).unwrap();
    let info = StageInfo {
        scenario: &sc,
        linear,
    };
    let rec = open_loop_record(&info).unwrap();
    let rmse: Vec<f64> = ["cbw", "abw-abs", "mbw002"]
        .iter()
        .map(|m| {
            let f = fit_siso(
                models::find(m).unwrap(),
                &rec.u[0],
                &rec.y[0],
                rec.dt(),
                &FitOptions::default(),
            )
            .unwrap();
            let sim = f.simulate(
                &rec.u[0],
                rec.dt(),
                hal_sim::ident::fit::resample::Edge::Hold,
            );
            let r = hal_sim::ident::fit::metrics(&rec.y[0], &sim.unwrap()).rmse;
            eprintln!("{m}: RMSE {r:.4} um, {:?}", f.params);
            r
        })
        .collect();
    assert!(
        rmse[0] > rmse[1] && rmse[1] > rmse[2],
        "002's ordering CBW > ABW > MBW not reproduced: {rmse:?}"
    );
    let run = |name: &str| {
        run_calibrated(&sc, &find(name).unwrap(), &linear, false)
            .unwrap()
            .0
    };
    let (ol, ff) = (run("open-loop"), run("mbw"));
    eprintln!(
        "open loop {:.3} %, mbw {:.3} % of stroke",
        ol.rmse_pct, ff.rmse_pct
    );
    assert!(ff.rmse_pct < 0.7 * ol.rmse_pct, "{ff:?} vs {ol:?}");
}
