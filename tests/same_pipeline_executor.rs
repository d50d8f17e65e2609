//! The firmware's command executor (`piezo_core::firmware`, as both boards use it) on the
//! host: a sensor fault latches the safe state, `fault` reports it with its counters and
//! `fault clear` leaves it.

/// The firmware as the H743 builds it with its on-chip converters.
mod control {
    pub use piezo_core::firmware::*;
    use piezo_core::firmware::{Converters, OnChip};
    pub type Ctl = piezo_core::firmware::Ctl<OnChip>;
    pub const ADC_BITS: u32 = OnChip::ADC_BITS;
    pub const DAC_FULL: i32 = OnChip::DAC_FULL;
}

/// The executor at the board's sample rate, as it powers up.
fn board() -> control::Ctl {
    let mut ctl = control::Ctl::new(control::c(control::SAMPLE_HZ as f64));
    // These tests feed one constant code (no sensor noise): the stuck-code detector off.
    ctl.lp.stuck_limit = 0;
    ctl
}

fn ask(ctl: &mut control::Ctl, line: &str) -> String {
    ctl.answer(line).as_str().to_string()
}

/// Sends each command in turn and checks its reply.
fn exchange(ctl: &mut control::Ctl, table: &[(&str, &str)]) {
    for (line, reply) in table {
        assert_eq!(ask(ctl, line), *reply, "reply to `{line}`");
    }
}

#[test]
fn a_sensor_fault_latches_until_cleared() {
    let mut ctl = board();
    assert_eq!(
        ask(&mut ctl, "fault"),
        "ok fault none sensor 0 nonfinite 0 dac 0"
    );
    // Mid-range code: no fault. Then a code beyond the sensor window.
    let mid = 1 << (control::ADC_BITS - 1);
    ctl.lp.step([mid; control::AXES]);
    ctl.lp.step([i32::MAX; control::AXES]);
    assert_eq!(
        ask(&mut ctl, "fault"),
        "ok fault sensor-range sensor 1 nonfinite 0 dac 0"
    );
    // The fault stays latched with good codes again, until cleared.
    ctl.lp.step([mid; control::AXES]);
    assert!(ask(&mut ctl, "fault").starts_with("ok fault sensor-range"));
    assert_eq!(
        ask(&mut ctl, "fault clear"),
        "ok fault none sensor 1 nonfinite 0 dac 0"
    );
    ctl.lp.step([mid; control::AXES]);
    assert!(ask(&mut ctl, "fault").starts_with("ok fault none"));
    assert_eq!(ask(&mut ctl, "fault reset"), "err 11 unknown sub-command");
}

/// The reference (`ref_um`, what the control step tracks) over `n` periods.
fn reference(ctl: &mut control::Ctl, n: usize) -> Vec<f64> {
    let mid = 1 << (control::ADC_BITS - 1);
    (0..n)
        .map(|_| {
            ctl.lp.step([mid; control::AXES]);
            ctl.lp.p.state().trace.setpoint[0].y_um as f64
        })
        .collect()
}

#[test]
fn a_table_wave_moves_the_reference_through_the_points() {
    let mut ctl = board();
    exchange(
        &mut ctl,
        &[
            ("table len", "ok table 0"),
            ("wave table 10", "err 12 not possible in the current state"),
            ("table add 5", "ok table 1"),
            ("wave table 10", "err 12 not possible in the current state"),
            ("table clear", "ok table 0"),
        ],
    );
    // 5 points in two lines; 1 kHz: 100 samples per period, 20 per point.
    let pts = [10.0, 40.0, 25.0, 60.0, 5.0];
    exchange(
        &mut ctl,
        &[
            ("table add 10 40 25", "ok table 3"),
            ("table add 60 5", "ok table 5"),
            ("table len", "ok table 5"),
            ("wave table 1000", "ok wave table 1000 5"),
        ],
    );
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
    exchange(
        &mut ctl,
        &[
            ("table add 1", "err 8 value out of range"),
            ("table len", "ok table 64"),
        ],
    );
}

#[test]
fn a_steps_wave_visits_every_level() {
    let mut ctl = board();
    exchange(
        &mut ctl,
        &[
            ("wave steps 10 40 4 1000", "ok wave steps 10 40 4 1000"),
            ("wave steps 10 40 65 1000", "err 8 value out of range"),
        ],
    );
    let r = reference(&mut ctl, control::SAMPLE_HZ as usize / 1000);
    let mut levels: Vec<i64> = r.iter().map(|y| (y * 1000.0).round() as i64).collect();
    levels.dedup();
    // Up 10, 20, 30, 40 and down 30, 20 in one period (the first level may repeat).
    let want = [10_000, 20_000, 30_000, 40_000, 30_000, 20_000];
    assert!(levels.starts_with(&want), "{levels:?}");
}

/// References of both axes (`ref_um` of axis 0 and, with `xy`, axis 1) over `n` periods.
#[cfg(feature = "xy")]
fn references(ctl: &mut control::Ctl, n: usize) -> Vec<[f64; 2]> {
    let mid = 1 << (control::ADC_BITS - 1);
    (0..n)
        .map(|_| {
            ctl.lp.step([mid; control::AXES]);
            let sp = &ctl.lp.p.state().trace.setpoint;
            [sp[0].y_um as f64, sp[sp.len() - 1].y_um as f64]
        })
        .collect()
}

#[cfg(feature = "xy")]
fn span(v: impl Iterator<Item = f64>) -> (f64, f64) {
    v.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), y| {
        (l.min(y), h.max(y))
    })
}

/// A 1-axis build refuses the 2-axis scans and axis 1 with its numbered errors.
#[cfg(not(feature = "xy"))]
#[test]
fn one_axis_build_refuses_scans_and_axis_1() {
    let mut ctl = board();
    let unsupported = "err 13 not supported on this board";
    assert_eq!(ask(&mut ctl, "wave raster 10 10 8 50"), unsupported);
    assert_eq!(ask(&mut ctl, "wave lissajous 5 5 40 30"), unsupported);
    assert_eq!(ask(&mut ctl, "rec sel ref_um y1_um"), unsupported);
    exchange(
        &mut ctl,
        &[
            ("axis", "ok axis 0 of 1"),
            ("axis 1", "err 8 value out of range"),
            ("axis 0", "ok axis 0 of 1"),
        ],
    );
}

/// The xy build (`cargo test -p piezo-core --features xy --test same_pipeline_executor`):
/// raster and Lissajous references on both axes, the axis selection of the 1-axis waves,
/// and modes and limits on both axes.
#[cfg(feature = "xy")]
#[test]
fn xy_build_scans_both_axes() {
    let mut ctl = board();
    // 4 lines at 1 kHz: x period 100 samples, y triangle at 125 Hz (800 samples), centred
    // on half the spans by default: x 0..10, y 0..6 um.
    assert_eq!(
        ask(&mut ctl, "wave raster 10 6 4 1000"),
        "ok wave raster 10 6 4 1000 5 3"
    );
    let r = references(&mut ctl, 1600);
    let (x0, x1) = span(r.iter().map(|v| v[0]));
    let (y0, y1) = span(r.iter().map(|v| v[1]));
    assert!(x0.abs() < 1e-3 && (x1 - 10.0).abs() < 1e-3, "x {x0}..{x1}");
    assert!(y0.abs() < 1e-3 && (y1 - 6.0).abs() < 1e-3, "y {y0}..{y1}");
    for k in 0..800 {
        let (a, b) = (r[k], r[k + 800]);
        assert!(
            (a[1] - b[1]).abs() < 1e-3,
            "y period is not 800 samples at {k}"
        );
        assert!(
            (a[0] - b[0]).abs() < 1e-3,
            "x period does not divide 800 at {k}"
        );
    }
    // One y sweep (400 samples) holds 4 x periods: 4 maxima of x.
    let peaks = r[..400]
        .windows(3)
        .filter(|w| w[1][0] >= w[0][0] && w[1][0] > w[2][0])
        .count();
    assert_eq!(peaks, 4);

    // Lissajous, y 45 deg ahead, around (20, 30).
    assert_eq!(
        ask(&mut ctl, "wave lissajous 5 4 1000 500 45 20 30"),
        "ok wave lissajous 5 4 1000 500 45 20 30"
    );
    let r = references(&mut ctl, 400);
    let fs = control::SAMPLE_HZ as f64;
    let tau = std::f64::consts::TAU;
    let want = |k: f64| {
        [
            20.0 + 5.0 * (tau * 1000.0 * k / fs).sin(),
            30.0 + 4.0 * (tau * (500.0 * k / fs + 0.125)).sin(),
        ]
    };
    // The first returned setpoint is phase 0 or one sample on: find which, then both axes
    // must follow the formula with that one index.
    let k0 = (-1..=1)
        .min_by(|a, b| {
            let e = |s: i32| (r[5][0] - want((5 + s) as f64)[0]).abs();
            e(*a).total_cmp(&e(*b))
        })
        .unwrap();
    for (k, v) in r.iter().enumerate() {
        let w = want((k as i32 + k0) as f64);
        assert!(
            (v[0] - w[0]).abs() < 1e-3 && (v[1] - w[1]).abs() < 1e-3,
            "sample {k}: {v:?} vs {w:?}"
        );
    }
    assert_eq!(
        ask(&mut ctl, "wave lissajous 5 4 1000 60000"),
        "err 8 value out of range"
    );

    // `axis 1`: the 1-axis waves go to y; `wave off` holds both.
    exchange(
        &mut ctl,
        &[
            ("axis 2", "err 8 value out of range"),
            ("axis 1", "ok axis 1 of 2"),
            ("wave off", "ok wave off"),
            ("wave hold 12", "ok wave hold 12"),
        ],
    );
    let r = references(&mut ctl, 10);
    assert_eq!(r[9][1], 12.0);
    assert!((r[9][0] - r[0][0]).abs() < 1e-9, "x must hold");
    assert_eq!(ask(&mut ctl, "axis 0"), "ok axis 0 of 2");

    // Modes and limits on both axes.
    assert_eq!(ask(&mut ctl, "mode ff+pid"), "ok mode ff+pid");
    for fb in ctl.lp.p.feedback() {
        assert_eq!(fb.name(), "ff+pid");
    }
    exchange(
        &mut ctl,
        &[
            ("set u_max 120", "ok u_max 120"),
            ("set slew 1", "err 8 value out of range"),
        ],
    );
    for a in &ctl.lp.p.config().axes {
        assert_eq!(a.limits.volts_max, 120.0);
        assert_eq!(a.limits.slew_volts_per_s, 20_000.0);
    }
    assert_eq!(
        ask(&mut ctl, "rec sel ref_um y_um ref1_um y1_um"),
        "ok rec sel ref_um y_um ref1_um y1_um"
    );
}

#[test]
fn narrowing_and_widening_the_range_restores_the_safe_voltage() {
    let mut ctl = board();
    let safe = |ctl: &control::Ctl| ctl.lp.p.config().axes[0].safe_volts as f64;
    assert_eq!(safe(&ctl), control::SAFE_VOLTS);
    assert_eq!(ask(&mut ctl, "set u_min 10"), "ok u_min 10");
    assert_eq!(
        safe(&ctl),
        10.0,
        "the range excludes 0 V: safe state at its edge"
    );
    assert_eq!(ask(&mut ctl, "set u_min 0"), "ok u_min 0");
    assert_eq!(
        safe(&ctl),
        control::SAFE_VOLTS,
        "back to the configured safe state"
    );
}

/// The CBW model of the IMS compensator on every axis.
fn ims_models(ctl: &control::Ctl) -> Vec<piezo_core::hysteresis::Cbw<f32>> {
    use piezo_core::feedforward::{Feedforward, MultiFeedforward};
    let MultiFeedforward::PerAxis(ffs) = ctl.lp.p.feedforward() else {
        panic!("per-axis feedforward expected");
    };
    ffs.iter()
        .map(|f| match f {
            Feedforward::ImsCbw(ims) => *ims.model(),
            other => panic!("IMS-CBW expected, got {}", other.name()),
        })
        .collect()
}

/// Every axis's IMS compensator holds the CBW `(d, alpha, beta, gamma)`.
fn assert_cbw(ctl: &control::Ctl, want: (f32, f32, f32, f32)) {
    for m in ims_models(ctl) {
        assert_eq!((m.d(), m.alpha(), m.beta(), m.gamma()), want);
    }
}

/// The observer's `eps_s` and the robust gains on every axis.
fn robust_gains(ctl: &control::Ctl) -> Vec<(f32, f32, f32)> {
    use piezo_core::feedback::Feedback;
    ctl.lp
        .p
        .feedback()
        .iter()
        .map(|f| match f {
            Feedback::Robust(r) => (r.observer().eps_s(), r.config().lambda1, r.config().lambda2),
            other => panic!("robust law expected, got {}", other.name()),
        })
        .collect()
}

#[test]
fn model_and_gains_are_set_at_run_time_and_bad_values_change_nothing() {
    let mut ctl = board();
    let help = ask(&mut ctl, "help");
    for p in control::PARAMS {
        assert!(help.contains(&format!(" {p}")), "help lacks {p}: {help}");
        assert!(ask(&mut ctl, &format!("get {p}")).starts_with(&format!("ok {p} ")));
    }
    exchange(
        &mut ctl,
        &[
            ("get cbw_d", "ok cbw_d 0.16"),
            ("get hgo_eps", "ok hgo_eps 0.0002"),
            ("ff ims-cbw", "ok ff ims-cbw"),
            ("mode ff+hgo-robust", "ok mode ff+hgo-robust"),
        ],
    );
    let mid = 1 << (control::ADC_BITS - 1);
    assert_eq!(ask(&mut ctl, "wave sine 5 100 20"), "ok wave sine 5 100 20");
    for _ in 0..200 {
        ctl.lp.step([mid; control::AXES]);
    }
    let fused = ctl.lp.p.is_fused();
    assert_eq!(
        fused,
        control::AXES == 1,
        "the 1-axis build runs the fused step"
    );

    // A new model: the compensator and the observer take it, on every axis.
    exchange(
        &mut ctl,
        &[
            ("set cbw_alpha 0.05", "ok cbw_alpha 0.05"),
            ("set cbw_d 0.2", "ok cbw_d 0.2"),
        ],
    );
    assert_cbw(&ctl, (0.2, 0.05, 0.02, 0.01));
    for f in ctl.lp.p.feedback() {
        let piezo_core::feedback::Feedback::Robust(r) = f else {
            panic!("robust law expected");
        };
        assert_eq!(r.observer().d_p(), 0.2);
    }
    exchange(
        &mut ctl,
        &[
            ("set hgo_eps 1e-4", "ok hgo_eps 0.0001"),
            ("set lambda2 3000", "ok lambda2 3000"),
        ],
    );
    for g in robust_gains(&ctl) {
        assert_eq!(g, (1e-4, 2_000.0, 3_000.0));
    }
    assert_eq!(ctl.lp.law, "ff+hgo-robust");
    assert_eq!(ctl.lp.ff, "ims-cbw");
    assert_eq!(ctl.lp.p.is_fused(), fused, "the fast path is decided again");
    // Still tracking the sine after the change (bumpless, finite).
    for _ in 0..200 {
        let codes = ctl.lp.step([mid; control::AXES]);
        assert!(codes.iter().all(|c| (0..=control::DAC_FULL).contains(c)));
    }
    assert_eq!(
        ask(&mut ctl, "fault"),
        "ok fault none sensor 0 nonfinite 0 dac 0"
    );

    // Refused values: beta < gamma (004 eq. 3), alpha <= 0, eps <= 0, negative gains,
    // zero scaling; a model IMS cannot invert (d below the hysteresis slope).
    let before_ff = ctl.lp.p.feedforward().clone();
    let before_fb = ctl.lp.p.feedback().clone();
    let before_cfg = ctl.lp.p.config().axes.map(|a| a.open_loop);
    for bad in [
        "set cbw_beta 0.001",
        "set cbw_alpha 0",
        "set cbw_d 0.01",
        "set hgo_eps 0",
        "set lambda1 -5",
        "set pid_kp -1",
        "set pid_ki -1",
        "set um_per_volt 0",
        "set cbw_gamma 0.03",
    ] {
        assert_eq!(ask(&mut ctl, bad), "err 8 value out of range", "{bad}");
    }
    assert_eq!(ask(&mut ctl, "set kp 1"), "err 7 unknown parameter");
    assert!(ctl.lp.p.feedforward() == &before_ff, "compensator changed");
    assert!(ctl.lp.p.feedback() == &before_fb, "law changed");
    assert_eq!(ctl.lp.p.config().axes.map(|a| a.open_loop), before_cfg);
    assert_eq!(ask(&mut ctl, "get cbw_beta"), "ok cbw_beta 0.02");

    // The whole model at once: valid as a whole, though not through single `set`s from
    // the present one (beta 0.005 below the present gamma 0.01 breaks 004 eq. 3).
    exchange(
        &mut ctl,
        &[
            ("set cbw_beta 0.005", "err 8 value out of range"),
            ("cbw 0.21 0.06 0.005 0.002", "ok cbw 0.21 0.06 0.005 0.002"),
        ],
    );
    assert_cbw(&ctl, (0.21, 0.06, 0.005, 0.002));
    assert_eq!(ctl.lp.p.is_fused(), fused);
    // beta < gamma (004 eq. 3); and d = 0.05 below the largest slope dh/du (0.093 um/V),
    // which IMS refuses.
    let before_ff = ctl.lp.p.feedforward().clone();
    for bad in ["cbw 0.2 0.05 0.01 0.02", "cbw 0.05 0.07 0.02 0.01"] {
        assert_eq!(ask(&mut ctl, bad), "err 8 value out of range", "{bad}");
    }
    assert!(ctl.lp.p.feedforward() == &before_ff, "compensator changed");
    assert_eq!(ask(&mut ctl, "get cbw_gamma"), "ok cbw_gamma 0.002");
    // The CBW `piezo fit` finds on the smarthysteresis record: its loop bound (230 um) lies
    // far outside 0..150 V, where |h| <= alpha * 150 V keeps dh/du below d. Accepted.
    let fitted = ask(&mut ctl, "cbw 0.394516 0.270568 0.000996874 0.000177702");
    assert!(fitted.starts_with("ok cbw 0.394516"), "{fitted}");
    assert_eq!(
        ask(&mut ctl, "cbw 0.21 0.06 0.005 0.002"),
        "ok cbw 0.21 0.06 0.005 0.002"
    );

    // PID gains and the open-loop scaling.
    exchange(
        &mut ctl,
        &[
            ("set pid_kp 0.25", "ok pid_kp 0.25"),
            ("mode pid", "ok mode pid"),
        ],
    );
    for f in ctl.lp.p.feedback() {
        let piezo_core::feedback::Feedback::Pid(p) = f else {
            panic!("PID expected");
        };
        assert_eq!((p.config().kp, p.config().ki), (0.25, 2_000.0));
    }
    exchange(
        &mut ctl,
        &[
            ("set um_per_volt 0.5", "ok um_per_volt 0.5"),
            ("set offset_um -1", "ok offset_um -1"),
        ],
    );
    for a in &ctl.lp.p.config().axes {
        assert_eq!(
            (a.open_loop.um_per_volt, a.open_loop.offset_um),
            (0.5, -1.0)
        );
    }
}

/// `fts-gbw` and `nmpc-gbw` (000 Part IV) are selectable and predict with the GBW of
/// `Params::gbw_model`: the CBW's loop with the asymmetry `gbw_b`; a `gbw_b` without
/// bounded equilibria (`|B| >= beta + gamma`) is refused and changes nothing.
#[test]
fn the_gbw_laws_predict_with_the_gbw() {
    use piezo_core::feedback::{Feedback, ObserverModel};
    fn gbw_of(f: &Feedback<f32>) -> (f32, f32, f32, f32) {
        let m = match f {
            Feedback::Robust(r) => *r.observer().model(),
            Feedback::Nmpc(n) => *n.observer().model(),
            other => panic!("a law with an observer expected, got {}", other.name()),
        };
        match m {
            ObserverModel::Gbw(g) => (g.a(), g.beta_h(), g.b(), g.g()),
            ObserverModel::Cbw(_) => panic!("{} predicts with the CBW", f.name()),
            _ => panic!("{}: GBW expected", f.name()),
        }
    }
    let mut ctl = board();
    exchange(
        &mut ctl,
        &[
            ("get gbw_b", "ok gbw_b 0"),
            ("set gbw_b 0.006", "ok gbw_b 0.006"),
        ],
    );
    let mid = 1 << (control::ADC_BITS - 1);
    assert_eq!(ask(&mut ctl, "wave sine 5 100 20"), "ok wave sine 5 100 20");
    for law in ["fts-gbw", "nmpc-gbw"] {
        assert_eq!(
            ask(&mut ctl, &format!("mode {law}")),
            format!("ok mode {law}")
        );
        assert_eq!(ctl.lp.law, law);
        for f in ctl.lp.p.feedback() {
            assert_eq!(f.name(), law);
            assert_eq!(gbw_of(f), (0.07, 0.02, 0.006, 0.01));
        }
        for _ in 0..500 {
            let codes = ctl.lp.step([mid; control::AXES]);
            assert!(codes.iter().all(|c| (0..=control::DAC_FULL).contains(c)));
        }
    }
    // The CBW laws keep the CBW.
    assert_eq!(ask(&mut ctl, "mode nmpc"), "ok mode nmpc");
    for f in ctl.lp.p.feedback() {
        let Feedback::Nmpc(n) = f else { panic!() };
        assert!(matches!(n.observer().model(), ObserverModel::Cbw(_)));
    }
    exchange(
        &mut ctl,
        &[
            ("mode ff+nmpc-gbw", "err 9 unknown mode name"),
            ("set gbw_b 0.03", "err 8 value out of range"),
            ("set gbw_b -0.031", "err 8 value out of range"),
            ("get gbw_b", "ok gbw_b 0.006"),
            ("fault", "ok fault none sensor 0 nonfinite 0 dac 0"),
        ],
    );
}
