//! `diagnose` on records of hal-sim's simulated actuator (`hal_sim::stage`): one stage effect
//! switched on with a seeded random size (input delay, amplifier rail, amplifier slew limit,
//! creep, structural resonance), or none; train and valid records have different excitations.
mod diagnose_support;

use diagnose_support::{excitation, Rng};
use hal_sim::ident::diagnose::{diagnose, Cause, Options, Signals};
use hal_sim::scenario::Scenario;
use hal_sim::stage::Stage;

const RATE_HZ: f64 = 2000.0;

/// A clean stage (CBW hysteresis and sensor noise only) plus `effect` with a size drawn from
/// `seed`.
fn scenario(seed: u64, effect: Option<Cause>) -> Scenario {
    let mut r = Rng::new(seed ^ 0xD1A6);
    let mut s = Scenario::default();
    s.run.loop_hz = RATE_HZ;
    s.run.substeps = 4;
    let st = &mut s.stage;
    st.creep.enabled = false;
    st.resonance.enabled = false;
    st.drift.enabled = false;
    st.delay.enabled = false;
    st.coupling.enabled = false;
    st.hysteresis.asym_um_per_v2 = 0.0;
    st.amplifier.bandwidth_hz = 1e5;
    st.amplifier.current_limit_a = 10.0;
    st.noise.sigma_um = 0.02;
    match effect {
        Some(Cause::Delay) => {
            st.delay.enabled = true;
            st.delay.seconds = r.uniform(1e-3, 4e-3);
        }
        Some(Cause::Saturation) => st.amplifier.rail_max_volts = r.uniform(100.0, 115.0),
        Some(Cause::Dynamics) => {
            st.resonance.enabled = true;
            st.resonance.freq_hz = r.uniform(40.0, 120.0);
            st.resonance.zeta = r.uniform(0.3, 0.6);
        }
        Some(Cause::SlewLimit) => {
            // slew = I / C (V/s); the excitation's steps reach about 5000 V/s at the piezo
            st.amplifier.current_limit_a = r.uniform(1500.0, 3000.0) * st.amplifier.capacitance_f;
        }
        Some(Cause::Creep) => {
            st.creep.enabled = true;
            st.creep.gains = vec![r.uniform(0.03, 0.08)];
            st.creep.taus_s = vec![r.uniform(0.1, 0.5)];
        }
        _ => {}
    }
    s
}

/// DAC volts 0..10 (0..150 V at the piezo) and the sensor reading, one sample per period.
fn record(s: &Scenario, seed: u64, which: u64) -> Signals {
    let mut s = s.clone();
    s.run.seed = seed * 10 + which;
    let mut stage = Stage::new(&s).expect("stage");
    let mut r = Rng::new(seed.wrapping_mul(7_777).wrapping_add(which));
    let n = (RATE_HZ * 2.0) as usize;
    let t: Vec<f64> = (0..n).map(|k| k as f64 / RATE_HZ).collect();
    // The stage rests at 0 V: ramp in from there so the record starts at rest too.
    let u: Vec<f64> = excitation(&t, &mut r)
        .iter()
        .zip(&t)
        .map(|(v, t)| v / 10.0 * (t / 0.25).min(1.0))
        .collect();
    let y = u
        .iter()
        .map(|&dac| {
            stage.advance(&[dac]);
            stage.sensor_um(0)
        })
        .collect();
    Signals::new(t, vec![u], vec![y]).expect("record")
}

fn check(effect: Option<Cause>) {
    for seed in 1..=3 {
        let s = scenario(seed, effect);
        let d = diagnose(
            &record(&s, seed, 0),
            &record(&s, seed, 1),
            &Options::default(),
        )
        .expect("diagnose runs");
        eprintln!(
            "stage seed {seed} hidden {effect:?}: {:?} gain {:.3}",
            d.findings.iter().map(|f| f.cause).collect::<Vec<_>>(),
            d.gain()
        );
        match effect {
            None => assert_eq!(d.cause(), "none", "seed {seed}: {:#}", d.json()),
            Some(c) => {
                assert_eq!(d.cause(), c.name(), "seed {seed}: {:#}", d.json());
                assert!(d.gain() > 0.0);
            }
        }
    }
}

#[test]
fn stage_clean_is_none() {
    check(None);
}

#[test]
fn stage_delay() {
    check(Some(Cause::Delay));
}

#[test]
fn stage_rail() {
    check(Some(Cause::Saturation));
}

#[test]
fn stage_slew_limit() {
    check(Some(Cause::SlewLimit));
}

#[test]
fn stage_creep() {
    check(Some(Cause::Creep));
}

#[test]
fn stage_resonance() {
    check(Some(Cause::Dynamics));
}
