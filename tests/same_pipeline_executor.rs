//! The firmware's command executor (`src/bin/firmware/control.rs`, as both boards build it)
//! on the host: a sensor fault latches the safe state, `fault` reports it with its counters
//! and `fault clear` leaves it.

#[path = "../src/bin/firmware/control.rs"]
#[allow(dead_code)]
mod control;

use piezo_core::command::{parse, Reply};

fn ask(ctl: &mut control::Ctl, line: &str) -> String {
    let mut r = Reply::<160>::new();
    match parse(line.as_bytes()) {
        Ok(c) => ctl.execute(c, &mut r),
        Err(e) => r.push_error(e),
    }
    r.as_str().to_string()
}

#[test]
fn a_sensor_fault_latches_until_cleared() {
    let mut ctl = control::Ctl::new(control::c(control::SAMPLE_HZ as f64));
    assert_eq!(
        ask(&mut ctl, "fault"),
        "ok fault none sensor 0 nonfinite 0 dac 0"
    );
    // Mid-range code: no fault. Then a code beyond the sensor window.
    let mid = 1 << (control::ADC_BITS - 1);
    ctl.lp.step(mid);
    ctl.lp.step(i32::MAX);
    assert_eq!(
        ask(&mut ctl, "fault"),
        "ok fault sensor-range sensor 1 nonfinite 0 dac 0"
    );
    // The fault stays latched with good codes again, until cleared.
    ctl.lp.step(mid);
    assert!(ask(&mut ctl, "fault").starts_with("ok fault sensor-range"));
    assert_eq!(
        ask(&mut ctl, "fault clear"),
        "ok fault none sensor 1 nonfinite 0 dac 0"
    );
    ctl.lp.step(mid);
    assert!(ask(&mut ctl, "fault").starts_with("ok fault none"));
    assert_eq!(ask(&mut ctl, "fault reset"), "err 11 unknown sub-command");
}
