//! Invariants of the manipulation observers and the BLF law for arbitrary inputs: the
//! voltage stays in range and within the rate bound, estimates stay finite.
use piezo_core::hysteresis::Cbw;
use piezo_core::manipulation::{BlfForce, ForceEso, StageDynamics, VoltageInput};
use proptest::prelude::*;

fn any_value() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1e3..1e3f64,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(1e300),
        Just(-1e300),
    ]
}

proptest! {
    #[test]
    fn blf_voltage_is_bounded_and_rate_limited(
        inputs in prop::collection::vec((any_value(), any_value(), any_value()), 1..200),
        u0 in -50.0..200.0f64,
    ) {
        let law = BlfForce::new(3.0, 90.0, 6.0, 1500.0, 0.0, 150.0, 10_000.0).unwrap();
        let mut s = law.init(u0);
        let mut prev = s.u_volts;
        prop_assert!((0.0..=150.0).contains(&prev));
        for (f, fd, dfd) in inputs {
            let u = law.update(&mut s, f, fd, dfd);
            prop_assert!((0.0..=150.0).contains(&u));
            prop_assert!((u - prev).abs() <= 1500.0 / 10_000.0 + 1e-9);
            prev = u;
        }
    }

    #[test]
    fn force_eso_stays_finite(
        inputs in prop::collection::vec((any_value(), any_value()), 1..200),
    ) {
        let eso = ForceEso::new(
            Cbw::with_n1(0.16, 0.07, 0.02, 0.01).unwrap(),
            StageDynamics { natural_hz: 800.0, damping_ratio: 0.15, stiffness_mn_per_um: 200.0 },
            400.0,
            VoltageInput::new(0.0, 0.06, 1e-4).unwrap(),
            10_000.0,
        )
        .unwrap();
        let mut s = eso.init(0.0, 0.0);
        for (y, u) in inputs {
            let f = eso.update(&mut s, y, u);
            prop_assert!(f.is_finite());
        }
    }
}
