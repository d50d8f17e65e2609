//! 000 Part V compares the HGO and a neural observer (NNO) on the distributed beam and
//! reports the NNO ahead. Under the conditions that comparison may have had (more sensor
//! noise, a wrong beam model, the hysteresis model denied), each observer at its best of
//! the same sweep, the HGO stays ahead here; the NNO's learning matters most where the
//! hysteresis model is denied (issue 19 item 5). These orderings are what the README
//! reports; the test fails if an observer breaks.
use hal_sim::beam::{best_of_sweep, BeamConfig, BEAM_CONDITIONS};

#[test]
fn the_hgo_stays_ahead_under_the_seeds_conditions() {
    let base = BeamConfig::default();
    for name in ["noise-50nm", "hysteresis-denied"] {
        let cond = BEAM_CONDITIONS.iter().find(|c| c.name == name).unwrap();
        let b = best_of_sweep(&cond.apply(&base)).unwrap();
        println!("{name}: {b:?}");
        assert!(b.hgo_um.is_finite() && b.nno_um.is_finite());
        assert!(
            b.hgo_um < b.nno_um,
            "{name}: HGO {} vs NNO {}",
            b.hgo_um,
            b.nno_um
        );
        // Both estimate y(L/2) within 3 % (NNO) and 1.1 % (HGO) of its 5.5 um range
        // after the warm-up (`tests/manipulation.rs` prints 5.486 um).
        assert!(b.nno_um < 0.15 && b.hgo_um < 0.06, "{name}: {b:?}");
        if name == "hysteresis-denied" {
            // Without the hysteresis model the network's learning carries the NNO.
            assert!(b.nno_um < 0.5 * b.luenberger_um, "{b:?}");
        }
    }
}
