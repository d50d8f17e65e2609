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

/// The reference (`ref_um`, what the control step tracks) over `n` periods.
fn reference(ctl: &mut control::Ctl, n: usize) -> Vec<f64> {
    let mid = 1 << (control::ADC_BITS - 1);
    (0..n)
        .map(|_| {
            ctl.lp.step(mid);
            ctl.lp.p.state().trace.setpoint[0].y_um as f64
        })
        .collect()
}

#[test]
fn a_table_wave_moves_the_reference_through_the_points() {
    let mut ctl = control::Ctl::new(control::c(control::SAMPLE_HZ as f64));
    assert_eq!(ask(&mut ctl, "table len"), "ok table 0");
    assert_eq!(
        ask(&mut ctl, "wave table 10"),
        "err 12 not possible in the current state"
    );
    assert_eq!(ask(&mut ctl, "table add 5"), "ok table 1");
    assert_eq!(
        ask(&mut ctl, "wave table 10"),
        "err 12 not possible in the current state"
    );
    assert_eq!(ask(&mut ctl, "table clear"), "ok table 0");
    // 5 points in two lines; 1 kHz: 100 samples per period, 20 per point.
    let pts = [10.0, 40.0, 25.0, 60.0, 5.0];
    assert_eq!(ask(&mut ctl, "table add 10 40 25"), "ok table 3");
    assert_eq!(ask(&mut ctl, "table add 60 5"), "ok table 5");
    assert_eq!(ask(&mut ctl, "table len"), "ok table 5");
    assert_eq!(ask(&mut ctl, "wave table 1000"), "ok wave table 1000 5");
    let period = control::SAMPLE_HZ as usize / 1000;
    let r = reference(&mut ctl, 3 * period);
    // Each point is passed within one sample's travel (the phase accumulator is not an
    // exact multiple of the sample period), in order, every period.
    let step_max = r
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f64::max);
    for (k, want) in pts.iter().enumerate() {
        for per in 0..3 {
            let at = per * period + k * period / pts.len();
            let near = r[at.saturating_sub(1)..=at + 1]
                .iter()
                .map(|y| (y - want).abs())
                .fold(f64::INFINITY, f64::min);
            assert!(
                near <= step_max,
                "point {k} ({want} um), period {per}: nearest {near} um (step {step_max})"
            );
        }
    }
    // It really moves: the whole range of the points is covered.
    let (lo, hi) = r
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), y| {
            (l.min(*y), h.max(*y))
        });
    assert!(
        lo <= 5.0 + step_max && hi >= 60.0 - step_max,
        "{lo} .. {hi}"
    );

    // A full table refuses more points, whole lines at a time.
    assert_eq!(ask(&mut ctl, "table clear"), "ok table 0");
    for n in 1..=8 {
        assert_eq!(
            ask(&mut ctl, "table add 1 2 3 4 5 6 7 8"),
            format!("ok table {}", 8 * n)
        );
    }
    assert_eq!(ask(&mut ctl, "table add 1"), "err 8 value out of range");
    assert_eq!(ask(&mut ctl, "table len"), "ok table 64");
}

#[test]
fn a_steps_wave_visits_every_level() {
    let mut ctl = control::Ctl::new(control::c(control::SAMPLE_HZ as f64));
    assert_eq!(
        ask(&mut ctl, "wave steps 10 40 4 1000"),
        "ok wave steps 10 40 4 1000"
    );
    assert_eq!(
        ask(&mut ctl, "wave steps 10 40 65 1000"),
        "err 8 value out of range"
    );
    let r = reference(&mut ctl, control::SAMPLE_HZ as usize / 1000);
    let mut levels: Vec<i64> = r.iter().map(|y| (y * 1000.0).round() as i64).collect();
    levels.dedup();
    // Up 10, 20, 30, 40 and down 30, 20 in one period (the first level may repeat).
    let want = [10_000, 20_000, 30_000, 40_000, 30_000, 20_000];
    assert!(levels.starts_with(&want), "{levels:?}");
}
