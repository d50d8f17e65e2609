//! `piezo fit --model gbw` identifies the GBW the laws predict with (000 eq. 3 with its CBW
//! term, `Gbw::with_beta_h`, `alpha = n = 1`) from the open-loop record of the asymmetric
//! stage `gbw-asymmetric-10hz`, and `piezo sim`'s `fts-gbw` and `nmpc-gbw` run on what it
//! identified. `gbw-printed` (eq. 3 as printed, no `B_h`) cannot follow the same record.

use hal_sim::ident::fit::{fit_siso, metrics, models, resample::Edge, FitOptions};
use hal_sim::sim::controllers::{find, identified::open_loop_record, models::identified_gbw};
use hal_sim::sim::{calibrate, default_scenarios, run_calibrated, StageInfo};

#[test]
fn fit_gbw_recovers_the_asymmetric_stage_and_the_gbw_laws_run_on_it() {
    let sc = default_scenarios(None, None)
        .into_iter()
        .find(|s| s.name == "gbw-asymmetric-10hz")
        .unwrap();
    let linear = calibrate(&sc).unwrap();
    let info = StageInfo {
        scenario: &sc,
        linear,
    };
    let rec = open_loop_record(&info).unwrap();
    let (u, y, dt) = (&rec.u[0], &rec.y[0], rec.dt());
    let rmse = |name: &str| {
        let f = fit_siso(
            models::find(name).unwrap(),
            u,
            y,
            dt,
            &FitOptions::default(),
        )
        .unwrap();
        let r = metrics(y, &f.simulate(u, dt, Edge::Hold).unwrap()).rmse;
        eprintln!(
            "{name}: RMSE {r:.4} um, {:?}, offset {:.3}",
            f.params, f.offset
        );
        r
    };
    let (full, printed) = (rmse("gbw"), rmse("gbw-printed"));
    assert!(
        full < 0.5 * printed,
        "gbw {full} um vs gbw-printed {printed} um"
    );

    // The identified model (what the laws get) against the stage's.
    let m = identified_gbw(&info).unwrap();
    let h = &sc.stage.hysteresis;
    let pairs = [
        ("A", m.a(), h.a),
        ("B_h", m.beta_h(), h.beta_h),
        ("B", m.b(), h.beta),
        ("G", m.g(), h.gamma),
    ];
    eprintln!("identified d {:.4} (stage {:.4})", m.d(), h.d);
    assert!((m.d() / h.d - 1.0).abs() < 0.05, "d {} vs {}", m.d(), h.d);
    for (name, got, want) in pairs {
        eprintln!("identified {name} {got:.5} (stage {want:.5})");
        // The record is a 10 Hz sine with creep, resonance and noise the fit does not model.
        assert!((got / want - 1.0).abs() < 0.25, "{name} {got} vs {want}");
    }
    // The asymmetry is found: B has the stage's sign and the equilibria their order.
    assert!(m.b() > 0.0, "B = {}", m.b());
    assert!(m.h_up() < m.h_down(), "{} vs {}", m.h_up(), m.h_down());
    let stage_up = h.a / (h.beta_h + h.beta + h.gamma);
    let stage_down = h.a / (h.beta_h - h.beta + h.gamma);
    eprintln!(
        "equilibria: identified {:.2} / -{:.2} um, stage {stage_up:.2} / -{stage_down:.2} um",
        m.h_up(),
        m.h_down()
    );
    assert!((m.h_up() / m.h_down() - stage_up / stage_down).abs() < 0.15);

    // The laws on it (piezo sim builds them from the identified GBW).
    for name in ["fts-gbw", "nmpc-gbw", "open-loop"] {
        let r = run_calibrated(&sc, &find(name).unwrap(), &linear, false)
            .unwrap()
            .0;
        eprintln!("{name}: RMSE {:.3} % of stroke", r.rmse_pct);
        assert_eq!(r.nonfinite_commands, 0);
        if name != "open-loop" {
            assert!(r.rmse_pct < 0.2, "{name}: {} %", r.rmse_pct);
        }
    }
}

/// `piezo sim` builds the GBW laws on every built-in scenario from its own open-loop
/// record, also where the reference holds still (the force scenarios) or two axes move.
#[test]
fn the_gbw_laws_build_on_every_builtin_scenario() {
    for sc in default_scenarios(None, None) {
        let linear = calibrate(&sc).unwrap();
        let info = StageInfo {
            scenario: &sc,
            linear,
        };
        let m = identified_gbw(&info);
        eprintln!("{}: {m:?}", sc.name);
        assert!(m.is_ok(), "{}: {m:?}", sc.name);
        if sc.name == "force-37pct" {
            let r = run_calibrated(&sc, &find("fts-gbw").unwrap(), &linear, false)
                .unwrap()
                .0;
            assert_eq!(r.nonfinite_commands, 0);
            assert!(r.volts_min >= 0.0 && r.volts_max <= 150.0, "{r:?}");
        }
    }
}
