//! Closed-loop checks of the feedback laws on the lecture's plant (000 eq. 2, CBW set 1 of
//! the backup slide, linear pole A = -86.28 1/s normalised to unit DC gain), and the
//! invariant that no law ever returns a non-finite command.

use piezo_core::feedback::{
    Adrc, AdrcConfig, Biquad, Convergence, Feedback, Hgo, Nmpc, NmpcConfig, ObserverModel, Pid,
    PidConfig, Robust, RobustConfig,
};
use piezo_core::hysteresis::{Cbw, Gbw, Hysteresis};
use piezo_core::signals::{LoopSignals, Setpoint};
use proptest::prelude::*;

const DT: f64 = 1e-5;
const A: f64 = 86.28;
const U_MAX: f64 = 150.0;

fn cbw(scale: f64) -> Cbw<f64> {
    Cbw::with_n1(0.16, 0.07 * scale, 0.02 * scale, 0.01 * scale).unwrap()
}

fn robust(feedforward: bool) -> Feedback<f64> {
    let hgo = Hgo::with_eps(ObserverModel::Cbw(cbw(1.0)), A, 2e-4, DT).unwrap();
    Feedback::Robust(
        Robust::new(
            hgo,
            RobustConfig {
                lambda1: 2.0 * std::f64::consts::PI * 200.0,
                lambda2: 2.0 * std::f64::consts::PI * 2000.0,
                feedforward,
                convergence: Convergence::Exponential,
            },
        )
        .unwrap(),
    )
}

/// GBW observer model for the CBW plant (different loop shape: a model error on purpose).
fn gbw_hgo() -> Hgo<f64> {
    let m = Gbw::new(0.16, 1.0, 0.07, 0.005, 0.025, 1.0).unwrap();
    Hgo::with_eps(ObserverModel::Gbw(m), A, 2e-4, DT).unwrap()
}

fn fts(feedforward: bool) -> Feedback<f64> {
    Feedback::Robust(
        Robust::new(
            gbw_hgo(),
            RobustConfig {
                lambda1: 400.0,
                lambda2: 4000.0,
                feedforward,
                convergence: Convergence::FiniteTime {
                    alpha1: 0.5,
                    alpha2: 0.5,
                    sat_um_per_s: 5e4,
                },
            },
        )
        .unwrap(),
    )
}

fn nmpc(feedforward: bool) -> Feedback<f64> {
    Feedback::Nmpc(
        Nmpc::new(
            gbw_hgo(),
            NmpcConfig {
                decimation: 10,
                r: 1e-6,
                iterations: 2,
                u_min: 0.0,
                u_max: U_MAX,
                feedforward,
            },
        )
        .unwrap(),
    )
}

fn pid(feedforward: bool) -> Feedback<f64> {
    Feedback::Pid(
        Pid::new(PidConfig {
            // PI zero on the plant pole, crossover near 200 Hz at the nominal slope.
            kp: 100.0,
            ki: 100.0 * A,
            kd: 0.0,
            tf_s: 1e-4,
            kb: 1.0,
            feedforward,
            dt_s: DT,
        })
        .unwrap(),
    )
}

fn adrc(feedforward: bool) -> Feedback<f64> {
    Feedback::Adrc(
        Adrc::new(AdrcConfig {
            b: 0.16 * A * 5000.0,
            a1: 0.0,
            a2: 0.0,
            eps_s: 5e-5,
            omega_c: 2000.0,
            feedforward,
            dt_s: DT,
        })
        .unwrap(),
    )
}

/// Runs `law` on the plant (hysteresis `plant`, optional output disturbance in um) tracking
/// `y_d = 12 + 7 sin(2 pi f t)` for two periods; returns the RMSE over the last period
/// and the largest command seen (after limits).
fn run(law: &mut Feedback<f64>, plant: Cbw<f64>, f_hz: f64, disturbance_um: f64) -> (f64, f64) {
    run_with(law, plant, f_hz, disturbance_um, |_| {})
}

/// [`run`], with `after` called on the law after every sample (a deferred NMPC's solver).
fn run_with(
    law: &mut Feedback<f64>,
    plant: Cbw<f64>,
    f_hz: f64,
    disturbance_um: f64,
    mut after: impl FnMut(&mut Feedback<f64>),
) -> (f64, f64) {
    let mut s = plant.init(0.0);
    let mut x = 0.0;
    let mut u_applied = 0.0;
    let ad = (-A * DT).exp();
    let n = (2.0 / f_hz / DT) as usize;
    let tail = (1.0 / f_hz / DT) as usize;
    let mut se = 0.0;
    let mut u_peak: f64 = 0.0;
    let w = 2.0 * std::f64::consts::PI * f_hz;
    for k in 0..n {
        let t = k as f64 * DT;
        let sp = Setpoint {
            y_um: 12.0 + 7.0 * (w * t).sin(),
            dy: 7.0 * w * (w * t).cos(),
            ddy: -7.0 * w * w * (w * t).sin(),
        };
        let y = x + if t > 0.5 / f_hz { disturbance_um } else { 0.0 };
        if k >= n - tail {
            se += (y - sp.y_um).powi(2);
        }
        let io = LoopSignals {
            setpoint: sp,
            y_um: y,
            u_ff: (sp.y_um + 1.0) / 0.16 * 0.95,
            u_applied,
        };
        let u = law.update(&io);
        after(law);
        u_applied = u.clamp(0.0, U_MAX);
        u_peak = u_peak.max(u_applied.abs());
        let v = plant.step(&mut s, u_applied, DT);
        x = ad * x + (1.0 - ad) * v;
    }
    ((se / tail as f64).sqrt(), u_peak)
}

#[test]
fn robust_law_tracks_10hz_on_nominal_plant() {
    for ff in [false, true] {
        let (rmse, _) = run(&mut robust(ff), cbw(1.0), 10.0, 0.0);
        eprintln!("hgo-robust ff={ff} rmse {rmse:.2e} um");
        // Exact model: only f64 rounding is left without feedforward; the (deliberately 5 %
        // off) linear feedforward leaves a little for the lambda2 correction.
        let bound = if ff { 0.01 } else { 1e-4 };
        assert!(rmse < bound, "ff={ff}: rmse {rmse} um");
    }
}

#[test]
fn robust_law_tolerates_20_percent_parameter_error_and_disturbance() {
    for scale in [0.8, 1.2] {
        let (rmse, _) = run(&mut robust(false), cbw(scale), 10.0, -1.0);
        eprintln!("hgo-robust scale {scale} rmse {rmse:.2e} um");
        assert!(rmse < 0.01, "scale {scale}: rmse {rmse} um");
    }
}

#[test]
fn baselines_close_the_loop() {
    type Make = fn(bool) -> Feedback<f64>;
    for (make, ff) in [
        (pid as Make, false),
        (pid, true),
        (adrc, false),
        (adrc, true),
        (fts, false),
        (fts, true),
        (nmpc, false),
        (nmpc, true),
    ] {
        let name = make(ff).name();
        let (rmse, _) = run(&mut make(ff), cbw(1.0), 10.0, 0.0);
        let (rmse_d, _) = run(&mut make(ff), cbw(1.2), 10.0, -1.0);
        eprintln!("{name} rmse {rmse:.2e} um, with error+disturbance {rmse_d:.2e} um");
        assert!(
            rmse < 0.5 && rmse_d < 0.5,
            "{name}: rmse {rmse} / {rmse_d} um"
        );
    }
}

fn deferred(mut law: Feedback<f64>) -> Feedback<f64> {
    if let Feedback::Nmpc(n) = &mut law {
        n.set_deferred(true);
    }
    law
}

/// The firmware's deferred NMPC (its solve in a lower-priority task, one MPC period behind
/// the boundary it starts from, the first move fixed) tracks like the NMPC that solves in
/// the step, with a solver that delivers within every MPC period.
#[test]
fn deferred_nmpc_tracks_like_the_inline_one() {
    for ff in [false, true] {
        let (inline, _) = run(&mut nmpc(ff), cbw(1.2), 10.0, -1.0);
        let mut solves = 0;
        let (late, _) = run_with(&mut deferred(nmpc(ff)), cbw(1.2), 10.0, -1.0, |law| {
            if let Feedback::Nmpc(n) = law {
                if let Some(job) = n.job() {
                    let plan = n.solve_job(&job);
                    assert_eq!(plan[0], job.first(), "the first move stays");
                    assert!(n.deliver(&job, plan));
                    solves += 1;
                }
            }
        });
        eprintln!(
            "nmpc ff={ff}: rmse inline {inline:.2e} um, deferred {late:.2e} um ({solves} solves)"
        );
        // 2 periods of 10 Hz at 100 kHz, a solve every 10 samples.
        assert!(solves >= 1999, "{solves} solves");
        let mut law = deferred(nmpc(ff));
        run_with(&mut law, cbw(1.0), 10.0, 0.0, |law| {
            if let Feedback::Nmpc(n) = law {
                if let Some(job) = n.job() {
                    let plan = n.solve_job(&job);
                    n.deliver(&job, plan);
                }
            }
        });
        let Feedback::Nmpc(n) = &law else {
            unreachable!()
        };
        // Numbered in order; none missed.
        assert_eq!((n.state().jobs, n.state().missed), (1999, 0));
        assert!(
            late < 0.5 && late < 2.0 * inline + 0.02,
            "ff={ff}: {late} vs {inline} um"
        );
    }
}

/// Without a solver (late or gone) the deferred NMPC holds its last plan, shifted: finite,
/// inside the input range, and a plan for a job that is no longer asked is refused.
#[test]
fn deferred_nmpc_without_a_solver_holds_its_plan() {
    let mut law = deferred(nmpc(false));
    let (rmse, u_peak) = run(&mut law, cbw(1.0), 10.0, 0.0);
    assert!(rmse.is_finite() && u_peak <= U_MAX, "{rmse} {u_peak}");
    let Feedback::Nmpc(n) = &mut law else {
        unreachable!()
    };
    // Every boundary but the first found its job unanswered.
    assert_eq!(n.state().missed, n.state().jobs - 1);
    let job = n.job().expect("a job is posted at every boundary");
    let plan = n.solve_job(&job);
    // A job of an older boundary: not the one asked.
    let mut old = job;
    old.seq = old.seq.wrapping_sub(1);
    assert!(!n.deliver(&old, plan));
    assert!(!n.deliver(&job, [f64::NAN; 8]));
    assert!(n.deliver(&job, plan));
    assert!(n.job().is_none());
}

#[test]
fn open_loop_is_worse_than_feedback() {
    let (ol, _) = run(&mut Feedback::OpenLoop, cbw(1.0), 10.0, 0.0);
    let (fb, _) = run(&mut robust(false), cbw(1.0), 10.0, 0.0);
    assert!(ol > 10.0 * fb, "open loop {ol} vs {fb}");
}

fn all_laws() -> Vec<Feedback<f64>> {
    let mut v = vec![
        Feedback::OpenLoop,
        pid(false),
        pid(true),
        robust(false),
        robust(true),
        adrc(false),
        adrc(true),
        fts(false),
        fts(true),
        nmpc(false),
        nmpc(true),
    ];
    let mut notched = robust(false);
    notched.set_measurement_filter(Some(Biquad::notch(1419.0, 1.0, 1.0 / DT).unwrap()));
    v.push(notched);
    v
}

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -1e3f64..1e3,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => proptest::num::f64::NORMAL,
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
    #[test]
    fn every_law_returns_finite_commands(
        seq in proptest::collection::vec(
            (any_f64(), any_f64(), any_f64(), any_f64(), any_f64(), any_f64()), 1..40)
    ) {
        for mut law in all_laws() {
            for (i, &(yd, dy, ddy, y, uff, ua)) in seq.iter().enumerate() {
                let io = LoopSignals {
                    setpoint: Setpoint { y_um: yd, dy, ddy },
                    y_um: y,
                    u_ff: uff,
                    u_applied: ua,
                };
                if i == seq.len() / 2 {
                    law.reset(&io);
                }
                let u = law.update(&io);
                prop_assert!(u.is_finite(), "{}: {u} at {i}", law.name());
            }
        }
    }
}

#[test]
fn every_law_is_bumpless_after_reset() {
    for mut law in all_laws() {
        let io = LoopSignals::hold(12.0, 10.0, 70.0, 77.0);
        law.update(&io);
        law.reset(&io);
        let u = law.update(&io);
        if !matches!(law, Feedback::OpenLoop) {
            assert!((u - 77.0).abs() < 1e-9, "{}: {u}", law.name());
        }
    }
}
