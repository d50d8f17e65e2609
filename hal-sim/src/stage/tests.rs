//! Unit tests of the stage: stroke and hysteresis of the default stage, the exact blocks, the
//! one-step fast path.
use super::*;

fn quasi_static() -> Scenario {
    let mut s = Scenario::default();
    s.stage.creep.enabled = false;
    s.stage.drift.enabled = false;
    s.stage.noise.enabled = false;
    s.stage.delay.enabled = false;
    s.stage.zero_um = 0.0;
    s.run.loop_hz = 10_000.0;
    s
}

/// Drives the DAC with a slow full-range sine and returns (piezo volts, position).
fn sweep(s: &Scenario, freq_hz: f64, periods: f64) -> (Vec<f64>, Vec<f64>) {
    let mut st = Stage::new(s).unwrap();
    let n = (periods * s.run.loop_hz / freq_hz) as usize;
    let full = s.converters.dac_vrefp * 150.0 / 150.0;
    let (mut u, mut y) = (vec![], vec![]);
    for k in 0..n {
        let t = k as f64 / s.run.loop_hz;
        let dac = full * 0.5 * (1.0 - (2.0 * PI * freq_hz * t).cos());
        st.advance(&[dac]);
        u.push(st.piezo_volts(0));
        y.push(st.position_um(0));
    }
    (u, y)
}

/// Loop width: largest gap between ascending and descending branch at equal voltage.
pub(crate) fn loop_width(u: &[f64], y: &[f64]) -> f64 {
    let bins = 200;
    let (lo, hi) = (
        u.iter().cloned().fold(f64::INFINITY, f64::min),
        u.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
    );
    let mut up = vec![f64::NAN; bins];
    let mut dn = vec![f64::NAN; bins];
    for k in 1..u.len() {
        let b = (((u[k] - lo) / (hi - lo)) * (bins as f64 - 1.0)) as usize;
        if u[k] > u[k - 1] {
            up[b] = y[k];
        } else if u[k] < u[k - 1] {
            dn[b] = y[k];
        }
    }
    up.iter()
        .zip(&dn)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

#[test]
fn default_stage_has_100um_stroke_and_15pct_hysteresis() {
    let s = quasi_static();
    let (u, y) = sweep(&s, 1.0, 3.0);
    let tail = u.len() / 3;
    let (u, y) = (&u[u.len() - tail..], &y[y.len() - tail..]);
    let stroke = y.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - y.iter().cloned().fold(f64::INFINITY, f64::min);
    let width = loop_width(u, y) / stroke;
    eprintln!("stroke {stroke:.2} um, hysteresis {:.1} %", 100.0 * width);
    assert!((90.0..110.0).contains(&stroke), "stroke {stroke}");
    assert!((0.12..0.18).contains(&width), "hysteresis {width}");
}

#[test]
fn slew_limited_amplifier_is_exact() {
    let s = quasi_static();
    let mut st = Stage::new(&s).unwrap();
    // A 150 V step: the amplifier ramps at I/C = 40 kV/s.
    st.advance(&[10.0]);
    let rate = st.piezo_volts(0) / 1e-4;
    assert!((rate - 40_000.0).abs() < 1.0, "{rate}");
}

#[test]
fn resonance_rings_at_its_frequency() {
    let mut s = quasi_static();
    s.stage.hysteresis.model = HysteresisModel::None;
    s.stage.hysteresis.asym_um_per_v2 = 0.0;
    s.stage.amplifier.current_limit_a = 100.0;
    s.stage.amplifier.bandwidth_hz = 1e6;
    s.run.loop_hz = 100_000.0;
    let mut st = Stage::new(&s).unwrap();
    let mut y = vec![];
    for _ in 0..2000 {
        st.advance(&[0.1]);
        y.push(st.position_um(0));
    }
    // Upward zero crossings of (y - final) give the damped frequency.
    let fin = 0.1 * 15.0 * s.stage.hysteresis.d;
    let ups: Vec<usize> = (1..y.len())
        .filter(|&k| y[k - 1] < fin && y[k] >= fin)
        .collect();
    let period = (ups[ups.len() - 1] - ups[0]) as f64 / (ups.len() - 1) as f64 / 1e5;
    let fd = 1500.0 * (1.0f64 - 0.03 * 0.03).sqrt();
    assert!((1.0 / period - fd).abs() < 10.0, "{}", 1.0 / period);
    let overshoot = y.iter().cloned().fold(0.0, f64::max) / fin - 1.0;
    assert!(overshoot > 0.8, "lightly damped: overshoot {overshoot}");
}

#[test]
fn one_step_fast_path_equals_the_general_path() {
    let mut s = Scenario::default();
    s.stage.force.enabled = true;
    s.stage.force.at_s = 1e-3;
    s.stage.force.freq_hz = 50.0;
    let mut fast = Stage::new(&s).unwrap();
    let mut general = fast.clone();
    // The same discretisation, summed in another order: equal to rounding.
    agree_on_bursts(
        5_000,
        &mut fast,
        Stage::advance,
        &mut general,
        Stage::advance_general,
    );
}

/// Drives two stages with a slow sine and short bursts for `n` steps, each by its own
/// `advance`; position and sensor reading agree to 1e-9 um at every step.
fn agree_on_bursts(
    n: usize,
    a: &mut Stage,
    advance_a: fn(&mut Stage, &[f64]),
    b: &mut Stage,
    advance_b: fn(&mut Stage, &[f64]),
) {
    for k in 0..n {
        let dac = 5.0 - 4.9 * (k as f64 * 2e-3).cos() + if k % 700 < 5 { 3.0 } else { 0.0 };
        advance_a(a, &[dac]);
        advance_b(b, &[dac]);
        let (pa, pb) = (a.position_um(0), b.position_um(0));
        assert!((pa - pb).abs() < 1e-9, "step {k}: {pa} vs {pb}");
        let (sa, sb) = (a.sensor_um(0), b.sensor_um(0));
        assert!((sa - sb).abs() < 1e-9, "step {k}: {sa} vs {sb}");
    }
}

#[test]
fn fractional_delay_interpolates() {
    let mut s = quasi_static();
    s.stage.hysteresis.model = HysteresisModel::None;
    s.stage.hysteresis.asym_um_per_v2 = 0.0;
    s.stage.resonance.enabled = false;
    s.stage.amplifier.bandwidth_hz = 1e7;
    s.stage.amplifier.current_limit_a = 1e3;
    s.stage.delay.enabled = true;
    s.stage.delay.seconds = 2.5e-4; // 2.5 loop periods at 10 kHz, one step each
    let mut st = Stage::new(&s).unwrap();
    let mut pos = vec![];
    for k in 0..20 {
        st.advance(&[0.01 * k as f64]);
        pos.push(st.position_um(0));
        if k >= 3 {
            let want = 0.5 * (pos[k - 2] + pos[k - 3]);
            assert!((st.sensor_um(0) - want).abs() < 1e-12, "{k}");
        }
    }
}

/// A stage with only a linear actuator (no hysteresis, creep, resonance, drift, noise,
/// delay) and an amplifier fast enough for 100 Hz full-range sines.
fn linear_stage() -> Scenario {
    let mut s = quasi_static();
    s.stage.hysteresis.model = HysteresisModel::None;
    s.stage.hysteresis.asym_um_per_v2 = 0.0;
    s.stage.resonance.enabled = false;
    s.stage.amplifier.bandwidth_hz = 1e6;
    s.stage.amplifier.current_limit_a = 1e3;
    s
}

/// Position over the last of `periods` periods of a 0..150 V sine at `freq_hz`.
fn last_period(s: &Scenario, freq_hz: f64, periods: f64) -> (Vec<f64>, Vec<f64>) {
    let (u, y) = sweep(s, freq_hz, periods);
    let k = (s.run.loop_hz / freq_hz) as usize;
    (u[u.len() - k..].to_vec(), y[y.len() - k..].to_vec())
}

fn span(y: &[f64]) -> f64 {
    y.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - y.iter().cloned().fold(f64::INFINITY, f64::min)
}

/// Loop width at the middle of the input range: the two branches interpolated where the
/// input crosses its mid value.
fn width_at_mid(u: &[f64], y: &[f64]) -> f64 {
    let mid = 0.5 * (span(u) + 2.0 * u.iter().cloned().fold(f64::INFINITY, f64::min));
    let mut at = vec![];
    for k in 1..u.len() {
        if (u[k - 1] - mid) * (u[k] - mid) <= 0.0 && u[k] != u[k - 1] {
            let f = (mid - u[k - 1]) / (u[k] - u[k - 1]);
            at.push(y[k - 1] + f * (y[k] - y[k - 1]));
        }
    }
    span(&at)
}

#[test]
fn rate_hysteresis_widens_and_rotates_the_loop() {
    let mut s = quasi_static();
    s.run.loop_hz = 100_000.0;
    s.stage.amplifier.bandwidth_hz = 1e6;
    s.stage.amplifier.current_limit_a = 1e3;
    s.stage.resonance.enabled = false;
    let measure = |s: &Scenario, f: f64| {
        let (u, y) = last_period(s, f, 3.0);
        (width_at_mid(&u, &y), span(&y))
    };
    // Without the effect the stage's hysteresis is rate-independent.
    let (w1, s1) = measure(&s, 1.0);
    let (w100, s100) = measure(&s, 100.0);
    assert!((w100 / w1 - 1.0).abs() < 0.03, "{w1} {w100}");
    assert!((s100 / s1 - 1.0).abs() < 0.01, "{s1} {s100}");
    s.stage.rate_hysteresis.enabled = true;
    s.stage.rate_hysteresis.widen = 0.6;
    s.stage.rate_hysteresis.gain_drop = 0.1;
    let (r1, p1) = measure(&s, 1.0);
    let (r100, p100) = measure(&s, 100.0);
    eprintln!("width {r1:.2} -> {r100:.2} um, span {p1:.2} -> {p100:.2} um");
    // 1 Hz: the mean rate is 300 V/s, rho 0.06: nearly the static loop.
    assert!((r1 / w1 - 1.0).abs() < 0.1, "{r1} vs {w1}");
    // 100 Hz: rho about 0.86: the loop widens and the output span drops (rotation).
    assert!(r100 > 1.25 * r1, "{r1} {r100}");
    assert!(p100 < 0.97 * p1, "{p1} {p100}");
}

#[test]
fn backlash_holds_the_output_at_reversals() {
    let mut s = linear_stage();
    s.stage.backlash.enabled = true;
    s.stage.backlash.width_um = 2.0;
    let d = s.stage.hysteresis.d;
    let mut st = Stage::new(&s).unwrap();
    // Up 0 -> 100 V, then down, 0.01 V per sample.
    let mut y = vec![];
    for k in 0..20_000 {
        let v = if k < 10_000 {
            k as f64
        } else {
            20_000.0 - k as f64
        } * 0.01;
        st.advance(&[v / 15.0]);
        y.push(st.position_um(0));
    }
    // The input peaks at sample 10 000 (100 V).
    let top = y[10_000];
    assert!((top - (d * 100.0 - 1.0)).abs() < 1e-6, "{top}");
    // After the reversal the output stands still until the input has come back 2 um / d.
    let back = (2.0 / d / 0.01) as usize;
    assert!((y[10_000 + back - 2] - top).abs() < 1e-9);
    assert!(y[10_000 + back + 2] < top - 1e-3);
    // Down-going, the output leads the actuator by half the play.
    assert!((y[19_999] - (d * 0.01 + 1.0)).abs() < 1e-6, "{}", y[19_999]);
}

#[test]
fn startup_creep_shows_in_the_first_cycles_only() {
    let mut s = linear_stage();
    s.stage.startup_creep.enabled = true;
    s.stage.startup_creep.depth = 0.1;
    s.stage.startup_creep.travel_v = 150.0;
    let (_, y) = sweep(&s, 1.0, 6.0);
    let per = s.run.loop_hz as usize;
    let first = span(&y[..per]);
    let last = span(&y[5 * per..]);
    let want = s.stage.hysteresis.d * 150.0;
    eprintln!("first cycle {first:.2} um, sixth {last:.2} um of {want:.2}");
    // Over the first cycle the deficit decays from 10 % (travel 300 V: to 1.4 %).
    assert!(first < 0.975 * want, "{first} vs {want}");
    // In motion the deficit settles at depth * travel / (rate * rest_tau): 0.08 % here.
    assert!((last / want - 1.0).abs() < 2e-3, "{last} vs {want}");
    // Without the effect: the full span from the start.
    s.stage.startup_creep.enabled = false;
    let (_, y) = sweep(&s, 1.0, 1.0);
    assert!((span(&y) / want - 1.0).abs() < 1e-6, "{}", span(&y));
}

/// Frequency (Hz) of the ringing after a step of `volts` DAC volts: upward crossings of the
/// final value over the first `cycles` periods.
fn ringing_hz(s: &Scenario, volts: f64, cycles: usize) -> f64 {
    let mut st = Stage::new(s).unwrap();
    let mut y = vec![];
    for _ in 0..3_000 {
        st.advance(&[volts]);
        y.push(st.position_um(0));
    }
    let fin = *y.last().unwrap();
    let ups: Vec<usize> = (1..y.len())
        .filter(|&k| y[k - 1] < fin && y[k] >= fin)
        .take(cycles + 1)
        .collect();
    (ups.len() - 1) as f64 / ((ups[ups.len() - 1] - ups[0]) as f64 / s.run.loop_hz)
}

#[test]
fn amplitude_dynamics_moves_the_resonance_with_the_level() {
    let mut s = linear_stage();
    s.stage.resonance.enabled = true;
    s.run.loop_hz = 100_000.0;
    let f0 = 1500.0 * (1.0f64 - 0.03 * 0.03).sqrt();
    // Off: the same frequency at any level.
    for v in [0.005, 5.0] {
        let f = ringing_hz(&s, v, 3);
        assert!((f - f0).abs() < 15.0, "{v} V: {f}");
    }
    s.stage.amplitude_dynamics.enabled = true;
    s.stage.amplitude_dynamics.level_um = 2.0;
    s.stage.amplitude_dynamics.freq_shift = -0.2;
    let small = ringing_hz(&s, 0.005, 3); // 0.07 um ringing: rho 0.03
    let large = ringing_hz(&s, 5.0, 3); // 70 um: rho about 0.9 at first
    eprintln!("ringing {small:.0} Hz small, {large:.0} Hz large");
    assert!((small - f0).abs() < 25.0, "{small}");
    assert!(large < 0.9 * f0, "{large}");
}

#[test]
fn sensor_nonlinearity_reads_the_polynomial() {
    let mut s = linear_stage();
    s.stage.sensor_nonlinearity.enabled = true;
    s.stage.sensor_nonlinearity.quadratic = 0.02;
    s.stage.sensor_nonlinearity.cubic = -0.01;
    let mut st = Stage::new(&s).unwrap();
    for k in 0..2_000 {
        st.advance(&[5.0 + 4.9 * (k as f64 * 3e-3).sin()]);
        let x = st.position_um(0);
        let e = (x - 50.0) / 50.0;
        let want = x + 50.0 * (0.02 * e * e - 0.01 * e * e * e);
        assert!((st.sensor_um(0) - want).abs() < 1e-9, "{k}");
    }
}

#[test]
fn effects_of_zero_size_change_nothing() {
    let mut s = Scenario::default();
    s.run.substeps = 4; // both runs on the general path
    let mut z = s.clone();
    let st = &mut z.stage;
    st.rate_hysteresis.enabled = true;
    st.rate_hysteresis.widen = 0.0;
    st.rate_hysteresis.gain_drop = 0.0;
    st.backlash.enabled = true;
    st.backlash.width_um = 0.0;
    st.startup_creep.enabled = true;
    st.startup_creep.depth = 0.0;
    st.amplitude_dynamics.enabled = true;
    st.amplitude_dynamics.freq_shift = 0.0;
    st.amplitude_dynamics.zeta_scale = 0.0;
    st.sensor_nonlinearity.enabled = true;
    st.sensor_nonlinearity.quadratic = 0.0;
    let (mut a, mut b) = (Stage::new(&s).unwrap(), Stage::new(&z).unwrap());
    assert!(a.fx.is_none() && b.fx.is_some());
    agree_on_bursts(3_000, &mut a, Stage::advance, &mut b, Stage::advance);
}
