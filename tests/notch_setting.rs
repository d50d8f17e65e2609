//! The notch of `notch_hz` / `notch_q` (issue 17 item 4): the settings' ranges and error
//! numbers, and that a set notch filters the measurement of the running law (a measured
//! oscillation at the notch frequency no longer reaches the output).
use piezo_core::firmware::{c, Ctl, OnChip, SAMPLE_HZ};

fn ctl() -> Ctl<OnChip> {
    Ctl::new(c(SAMPLE_HZ as f64))
}

fn ask(ctl: &mut Ctl<OnChip>, line: &str) -> String {
    ctl.answer(line).as_str().to_string()
}

const OUT_OF_RANGE: &str = "err 8 value out of range";

#[test]
fn notch_settings_are_range_checked_and_a_refusal_changes_nothing() {
    let mut ctl = ctl();
    assert_eq!(ask(&mut ctl, "get notch_hz"), "ok notch_hz 0");
    assert_eq!(ask(&mut ctl, "get notch_q"), "ok notch_q 2");
    assert_eq!(ask(&mut ctl, "set notch_hz 2500"), "ok notch_hz 2500");
    assert_eq!(ask(&mut ctl, "set notch_q 10"), "ok notch_q 10");
    // Below 10 Hz (other than 0), above 0.45 of the sample rate, negative: err 8.
    for bad in ["9.9", "-100", "45001", "1e6"] {
        assert_eq!(
            ask(&mut ctl, &format!("set notch_hz {bad}")),
            OUT_OF_RANGE,
            "{bad}"
        );
    }
    assert_eq!(ask(&mut ctl, "set notch_hz 45000"), "ok notch_hz 45000");
    for bad in ["0", "0.49", "50.5", "-2"] {
        assert_eq!(
            ask(&mut ctl, &format!("set notch_q {bad}")),
            OUT_OF_RANGE,
            "{bad}"
        );
    }
    assert_eq!(ask(&mut ctl, "get notch_q"), "ok notch_q 10");
    // Not a number: the parser's err 6; 0 switches the notch off.
    assert!(ask(&mut ctl, "set notch_hz nan").starts_with("err 6 "));
    assert_eq!(ask(&mut ctl, "get notch_hz"), "ok notch_hz 45000");
    assert_eq!(ask(&mut ctl, "set notch_hz 0"), "ok notch_hz 0");
    // `defaults` switches it off again.
    ask(&mut ctl, "set notch_hz 1000");
    assert_eq!(ask(&mut ctl, "defaults"), "ok defaults");
    assert_eq!(ask(&mut ctl, "get notch_hz"), "ok notch_hz 0");
}

/// Amplitude of the `f_hz` component of `x` sampled at `fs`.
fn amplitude(x: &[f64], f_hz: f64, fs: f64) -> f64 {
    let (mut re, mut im) = (0.0, 0.0);
    for (i, v) in x.iter().enumerate() {
        let ph = 2.0 * std::f64::consts::PI * f_hz * i as f64 / fs;
        re += v * ph.cos();
        im += v * ph.sin();
    }
    2.0 * (re * re + im * im).sqrt() / x.len() as f64
}

/// The DAC codes' amplitude at `f_hz` while the sensor reads 10 um plus a 1 um
/// oscillation at `f_hz`, in closed loop (`hgo-robust`), with the notch of `notch`.
fn output_ripple(notch: Option<(f64, f64)>, f_hz: f64) -> f64 {
    let mut ctl = ctl();
    if let Some((hz, q)) = notch {
        assert_eq!(
            ask(&mut ctl, &format!("set notch_hz {hz}")),
            format!("ok notch_hz {hz}")
        );
        assert_eq!(
            ask(&mut ctl, &format!("set notch_q {q}")),
            format!("ok notch_q {q}")
        );
    }
    assert_eq!(ask(&mut ctl, "wave hold 10"), "ok wave hold 10");
    assert_eq!(ask(&mut ctl, "mode hgo-robust"), "ok mode hgo-robust");
    let s = ctl.lp.p.config().axes[0].sensor;
    let fs = SAMPLE_HZ as f64;
    let mut dac = Vec::new();
    for k in 0..20_000 {
        let y = 10.0 + 1.0 * (2.0 * std::f64::consts::PI * f_hz * k as f64 / fs).sin();
        let code = ((y - s.offset_um as f64) / s.um_per_code as f64).round() as i32;
        let [d] = ctl.lp.step([code]);
        if k >= 10_000 {
            dac.push(d as f64);
        }
    }
    amplitude(&dac, f_hz, fs)
}

#[test]
fn a_set_notch_removes_its_frequency_from_the_measurement_the_law_sees() {
    let f = 2_500.0;
    let without = output_ripple(None, f);
    let with = output_ripple(Some((f, 2.0)), f);
    let elsewhere = output_ripple(Some((3.0 * f, 2.0)), f);
    eprintln!(
        "ripple at {f} Hz: without {without}, with {with}, notch elsewhere {elsewhere} codes"
    );
    assert!(
        without > 20.0,
        "the law answers the oscillation: {without} codes"
    );
    assert!(
        with < 0.02 * without,
        "notch at {f} Hz: {with} vs {without} codes"
    );
    // A notch elsewhere leaves most of it.
    assert!(elsewhere > 0.3 * without, "{elsewhere} vs {without}");
}
