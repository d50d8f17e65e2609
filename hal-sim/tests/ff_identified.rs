//! The feedforward compensators that run on models identified from the stage's own
//! open-loop record (`wpmbw`, `pi-inverse`, `ppi-inverse`, `dpi-inverse`: `piezo fit
//! --model wpmbw|pi|ppi|dpi` on it, [`identified`]) track the matched stage at 1 Hz
//! (`tests/feedforward-scenarios/ff-matched-1hz.toml`) well below open loop, and PPI and
//! DPI, each on its own fit, no longer command what the PI inverse commands (before, both
//! were built from the PI and gave its output).

use hal_sim::scenario::Scenario;
use hal_sim::sim::controllers::{
    find,
    identified::{identified, identified_multibw},
};
use hal_sim::sim::{calibrate, run_calibrated, StageInfo};
use std::path::Path;

fn scenario() -> Scenario {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/feedforward-scenarios/ff-matched-1hz.toml");
    Scenario::load(&p).unwrap()
}

#[test]
fn compensators_on_identified_models_track_the_stage() {
    let sc = scenario();
    let linear = calibrate(&sc).unwrap();
    let info = StageInfo {
        scenario: &sc,
        linear,
    };
    for m in ["wpmbw", "pi", "ppi", "dpi"] {
        let f = identified(&info, m).unwrap();
        eprintln!(
            "{m}: sign {} offset {:.3} um, {:?}",
            f.sign,
            f.offset,
            f.values()
        );
        assert!(f.sign > 0.0, "{m}: {f:?}");
    }
    // The identified models invert: no fallback to the linear feedforward.
    for name in ["wpmbw", "pi-inverse", "ppi-inverse", "dpi-inverse"] {
        let c = (find(name).unwrap().one_axis)(&info).unwrap();
        assert_ne!(c.feedforward.name(), "linear", "{name} fell back to linear");
    }
    let run = |name: &str| {
        let (r, rec) = run_calibrated(&sc, &find(name).unwrap(), &linear, true).unwrap();
        eprintln!(
            "{name}: RE {:.3} % of stroke, max {:.3} %",
            r.rmse_pct, r.max_err_pct
        );
        assert_eq!(r.nonfinite_commands, 0, "{name}");
        (r.rmse_pct, rec.unwrap().volts[0].clone())
    };
    let (ol, _) = run("open-loop");
    // Measured (host profile): open loop 4.57 %, wpmbw 0.38 %, pi-inverse 1.02 %,
    // ppi-inverse 2.16 %, dpi-inverse 1.36 %.
    let mut volts = Vec::new();
    for (name, bound) in [
        ("wpmbw", 0.6),
        ("pi-inverse", 1.5),
        ("ppi-inverse", 3.0),
        ("dpi-inverse", 1.8),
    ] {
        let (re, v) = run(name);
        assert!(
            re < bound && re < 0.5 * ol,
            "{name}: RE {re:.3} % (bound {bound} %, open loop {ol:.3} %)"
        );
        volts.push((name, v));
    }
    let pi = &volts[1].1;
    for (name, v) in &volts[2..] {
        let diff = v
            .iter()
            .zip(pi)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        eprintln!("{name} vs pi-inverse: max voltage difference {diff:.3} V");
        assert!(
            diff > 0.5,
            "{name} commands what pi-inverse does ({diff} V)"
        );
    }
}

/// `multi-ims` runs 003's multivariable IMS on the model `piezo fit --model cbw` identifies
/// from the open-loop record of both axes of the coupled Lissajous scenario (before, it ran
/// on the stage's own CBW times its coupling matrix): the identified couplings match the
/// stage's (`y_i += m_ij y_j`, m_01 = 0.04, m_10 = 0.03), and the IMS tracks well below
/// open loop and below the IMS on the stage's bare hysteresis model.
#[test]
fn multi_ims_runs_on_the_identified_multivariable_model() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/feedforward-scenarios/ff-lissajous-coupled.toml");
    let sc = Scenario::load(&p).unwrap();
    let linear = calibrate(&sc).unwrap();
    let info = StageInfo {
        scenario: &sc,
        linear,
    };
    let f = identified_multibw(&info).unwrap();
    eprintln!(
        "D {:?} A {:?} offsets {:?} ims {}",
        f.d, f.a, f.offset, f.ims
    );
    assert_eq!((f.outputs, f.inputs), (2, 2));
    assert_eq!(f.ims, "accepted");
    // With A_ij = 0 (i != j) a coupling's anhysteretic slope is D_ij, the direct one
    // D_jj - A_jj: their ratio is the stage's m_ij. Measured: 0.047, 0.028.
    let ratio = |i: usize, j: usize| f.d[i][j] / (f.d[j][j] - f.a[j][j]);
    let (r01, r10) = (ratio(0, 1), ratio(1, 0));
    assert!((0.03..0.055).contains(&r01), "m_01 = {r01} (stage 0.04)");
    assert!((0.02..0.04).contains(&r10), "m_10 = {r10} (stage 0.03)");
    let re = |name: &str| {
        let (r, _) = run_calibrated(&sc, &find(name).unwrap(), &linear, false).unwrap();
        eprintln!("{name}: RE {:.3} % of stroke", r.rmse_pct);
        assert_eq!(r.nonfinite_commands, 0, "{name}");
        r.rmse_pct
    };
    let (ol, bare, multi) = (re("open-loop"), re("ims-cbw-bare"), re("multi-ims"));
    // Measured (dev profile): open loop 5.07 %, ims-cbw-bare 3.48 %, multi-ims 0.70 %.
    assert!(
        multi < 1.0 && multi < 0.5 * bare && multi < 0.2 * ol,
        "{multi}"
    );
}
