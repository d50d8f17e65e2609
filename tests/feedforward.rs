//! Every compensator driving the exact model it inverts (y ~ y_ref), and the same with the
//! compensator's parameters 20 % off (error larger but bounded). f32, the target type.
//!
//! `cargo test --release --test feedforward -- --nocapture` prints the tables.

use piezo_core::feedforward::*;
use piezo_core::hysteresis::*;
use piezo_core::signals::Setpoint;
use std::f64::consts::PI;

const FS: f64 = 10_000.0;
const STROKE_UM: f64 = 16.0;

/// RMSE (um) of y - y_ref over the second of two periods of a 0..STROKE sine at `f_hz`.
fn rmse<M: Hysteresis<f32>>(
    model: &M,
    ff: &mut Feedforward<f32>,
    f_hz: f64,
    offset_um: f64,
) -> f64 {
    let mut s = model.init(0.0);
    let n = (2.0 * FS / f_hz) as usize;
    let (mut se, mut cnt) = (0.0, 0usize);
    let w = 2.0 * PI * f_hz;
    for k in 0..n {
        let t = k as f64 / FS;
        let a = 0.5 * STROKE_UM;
        let sp = Setpoint {
            y_um: (offset_um + a * (1.0 - (w * t).cos())) as f32,
            dy: (a * w * (w * t).sin()) as f32,
            ddy: (a * w * w * (w * t).cos()) as f32,
        };
        let u = ff.compensate(&sp);
        assert!(u.is_finite());
        let y = model.step(&mut s, u, (1.0 / FS) as f32) as f64;
        if k >= n / 2 {
            se += (y - sp.y_um as f64).powi(2);
            cnt += 1;
        }
    }
    (se / cnt as f64).sqrt()
}

const V: (f32, f32) = (-200.0, 300.0);
const DT: f32 = (1.0 / FS) as f32;

fn cbw(k: f32) -> Cbw<f32> {
    Cbw::with_n1(0.16 * k, 0.07 * k, 0.02 * k, 0.01 * k).unwrap()
}

#[test]
fn ims_solved_vs_delayed_at_1_10_50_hz() {
    let m = cbw(1.0);
    println!("| f (Hz) | IMS solved RMSE (um) | IMS delayed RMSE (um) |");
    println!("|---|---|---|");
    for &f in &[1.0, 10.0, 50.0] {
        let mut solved = Feedforward::ImsCbw(ims_solved(m));
        let mut delayed = Feedforward::ImsCbw(Ims::new(m, ImsLoop::Delayed, V.0, V.1, DT).unwrap());
        let (a, b) = (
            rmse(&m, &mut solved, f, 0.0),
            rmse(&m, &mut delayed, f, 0.0),
        );
        println!("| {f} | {a:.2e} | {b:.2e} |");
        // f32: the solve is limited by the model's own rounding (~1e-5 um on 16 um).
        assert!(a < 2e-4, "{f} Hz solved {a}");
        assert!(b > 5.0 * a, "{f} Hz delayed {b} vs solved {a}");
    }
}

/// Runs exact and 20 %-off compensators on one model; asserts tight and bounded.
fn check<M: Hysteresis<f32>>(
    name: &str,
    m: &M,
    mut exact: Feedforward<f32>,
    mut off: Feedforward<f32>,
    tight: f64,
    f_hz: f64,
) {
    let e = rmse(m, &mut exact, f_hz, 0.0);
    let o = rmse(m, &mut off, f_hz, 0.0);
    println!("| {name} | {e:.2e} | {o:.2e} |");
    assert!(e < tight, "{name}: exact model RMSE {e}");
    assert!(
        o > e && o.is_finite() && o < 0.5 * STROKE_UM,
        "{name}: 20 % off RMSE {o}"
    );
}

/// [`check`] of the compensator `ff` builds on `model(1.0)` (exact) and on `model(off)`;
/// returns the exact model.
fn check_family<M: Hysteresis<f32>>(
    name: &str,
    model: impl Fn(f32) -> M,
    off: f32,
    ff: impl Fn(&M) -> Feedforward<f32>,
    tight: f64,
    f_hz: f64,
) -> M {
    let m = model(1.0);
    check(name, &m, ff(&m), ff(&model(off)), tight, f_hz);
    m
}

/// The solved-loop IMS on `m` over the test's voltage range.
fn ims_solved<M: ImsModel<f32>>(m: M) -> Ims<f32, M> {
    Ims::new(m, ImsLoop::Solved, V.0, V.1, DT).unwrap()
}

#[test]
fn every_compensator_on_its_exact_model_and_20_percent_off() {
    println!("| compensator | RMSE exact model (um) | RMSE params 20 % off (um) |");
    println!("|---|---|---|");
    check_family(
        "ims-cbw",
        cbw,
        1.2,
        |m| Feedforward::ImsCbw(ims_solved(*m)),
        2e-4,
        1.0,
    );

    let gbw = |k: f32| Gbw::new(0.16 * k, 1.0, 0.07 * k, 0.005 * k, 0.02 * k, 1.0).unwrap();
    check_family(
        "ims-gbw",
        gbw,
        0.8,
        |m| Feedforward::ImsGbw(ims_solved(*m)),
        2e-4,
        1.0,
    );

    let dahl = |k: f32| Dahl::new(0.16 * k, 0.05 * k, 2.0 * k, 1.0).unwrap();
    check_family(
        "ims-dahl",
        dahl,
        1.2,
        |m| Feedforward::ImsDahl(ims_solved(*m)),
        2e-4,
        1.0,
    );

    // 002 table 1 MBW; rate terms scaled to this sample rate's units.
    let mbw = |k: f32| {
        Mbw002::from_002(
            1.0998 * k,
            -0.0656 * k,
            0.3922 * k,
            -0.15 * k,
            1.0,
            -0.011 * k,
            0.0108 * k,
            3.68e-5 * k,
        )
        .unwrap()
    };
    // f32 resolution: dy/du of the rate terms is ~2e3 um/V at 10 kHz, one ulp of u ~5e-7 V.
    let m = check_family(
        "ims-mbw",
        mbw,
        1.2,
        |m| Feedforward::ImsMbw(ims_solved(*m)),
        2e-3,
        1.0,
    );
    // Without inversion the error is the method's own, not rounding.
    let mbw_ff = |m: &Mbw002<f32>| Feedforward::Mbw(MbwFf::new(*m, 1.0, V.0, V.1, DT).unwrap());
    check_family("mbw-no-inverse", mbw, 1.2, mbw_ff, 0.05, 0.1);
    let mut lin = Feedforward::Linear(LinearFf {
        um_per_volt: m.abw().d(),
        offset_um: 0.0,
    });
    let lin_rmse = rmse(&m, &mut lin, 0.1, 0.0);
    println!("| linear (MBW model, 0.1 Hz) | {lin_rmse:.2e} | |");

    let wp = |k: f32| {
        Wpmbw::new(
            MbwRlm::new(0.6485 * k, 0.7217 * k, 0.7440 * k).unwrap(),
            [0.9268 * k, 0.0048 * k],
        )
        .unwrap()
    };
    let wp_ff = |m: &Wpmbw<f32, 2>| {
        Feedforward::Wpmbw(WpmbwInverse::new(m, None, None, V.0, V.1, DT).unwrap())
    };
    check_family("wpmbw-inverse", wp, 1.2, wp_ff, 2e-4, 1.0);

    let pi = |k: f32| {
        Pi::new(
            0.1 * k,
            [0.03 * k, 0.02 * k, 0.01 * k],
            [2.0 * k, 10.0 * k, 30.0 * k],
        )
        .unwrap()
    };
    let pi_ff = |m: &Pi<f32, 3>| Feedforward::PiInverse(PiInverse::new(m, V.0, V.1).unwrap());
    check_family("pi-inverse", pi, 1.2, pi_ff, 2e-4, 1.0);

    let ppi = |k: f32| {
        Ppi::new(
            1e-6 * k,
            0.1 * k,
            [0.03 * k, 0.02 * k, 0.01 * k],
            [2.0 * k, 10.0 * k, 30.0 * k],
        )
        .unwrap()
    };
    let ppi_ff = |m: &Ppi<f32, 3>| Feedforward::PpiInverse(ppi_inverse(m, V.0, V.1, DT).unwrap());
    check_family("ppi-inverse", ppi, 1.2, ppi_ff, 2e-4, 1.0);

    let dpi = |k: f32| {
        Dpi::new(
            [0.1 * k, 0.03 * k, 0.02 * k],
            [1.0 * k, 10.0 * k, 30.0 * k],
            [1.0 * k, 0.3 * k],
            [0.0, 8.0 * k],
        )
        .unwrap()
    };
    let dpi_ff =
        |m: &Dpi<f32, 3, 2>| Feedforward::DpiInverse(DpiInverse::new(m, V.0, V.1).unwrap());
    check_family("dpi-inverse", dpi, 1.2, dpi_ff, 2e-4, 1.0);
}

#[test]
fn nan_and_infinite_references_hold_every_output() {
    let m = cbw(1.0);
    let mut all = [
        Feedforward::ImsCbw(Ims::new(m, ImsLoop::Solved, 0.0, 100.0, DT).unwrap()),
        Feedforward::ImsCbw(Ims::new(m, ImsLoop::Delayed, 0.0, 100.0, DT).unwrap()),
        Feedforward::Wpmbw(
            WpmbwInverse::new(
                &Wpmbw::new(MbwRlm::new(0.6f32, 0.7, 0.8).unwrap(), [0.8, 0.02]).unwrap(),
                Some(LinearPart::second_order(600.0, 0.7)),
                Some(300.0),
                0.0,
                100.0,
                DT,
            )
            .unwrap(),
        ),
        Feedforward::PiInverse(
            PiInverse::new(&Pi::new(0.1f32, [0.03], [2.0]).unwrap(), 0.0, 100.0).unwrap(),
        ),
    ];
    for ff in all.iter_mut() {
        let u = ff.compensate(&Setpoint::hold(5.0));
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(ff.compensate(&Setpoint::hold(bad)), u, "{}", ff.name());
        }
        let big = ff.compensate(&Setpoint {
            y_um: 1e30,
            dy: f32::NAN,
            ddy: 1e30,
        });
        assert!((0.0..=100.0).contains(&big), "{}: {big}", ff.name());
    }
}

#[test]
fn decoupler_makes_per_axis_ims_exact_on_a_coupled_stage() {
    let m = cbw(1.0);
    let c = [[1.0f32, 0.04], [0.03, 1.0]];
    let axes = || {
        [
            Feedforward::ImsCbw(ims_solved(m)),
            Feedforward::ImsCbw(ims_solved(m)),
        ]
    };
    let mut dec = MultiFeedforward::decoupled(c, axes()).unwrap();
    let mut per_axis = MultiFeedforward::PerAxis(axes());
    let run = |ff: &mut MultiFeedforward<f32, 2>| {
        let mut s = [m.init(0.0), m.init(0.0)];
        let mut max_err: f64 = 0.0;
        for k in 0..20_000 {
            let t = k as f64 / FS;
            // Lissajous 4:3 (003 section VI)
            let r = [
                8.0 + 6.0 * (2.0 * PI * 4.0 * t).sin(),
                8.0 + 6.0 * (2.0 * PI * 3.0 * t).sin(),
            ];
            let sp = r.map(|y| Setpoint::hold(y as f32));
            let u = ff.compensate(&sp);
            let yh = [m.step(&mut s[0], u[0], DT), m.step(&mut s[1], u[1], DT)];
            for i in 0..2 {
                let y = c[i][0] * yh[0] + c[i][1] * yh[1];
                max_err = max_err.max((y as f64 - r[i]).abs());
            }
        }
        max_err
    };
    let (d, p) = (run(&mut dec), run(&mut per_axis));
    println!("coupled 2-axis Lissajous: decoupled {d:.2e} um, per-axis {p:.2e} um");
    assert!(d < 1e-4, "{d}");
    assert!(p > 100.0 * d, "{p}");
    assert!(MultiFeedforward::decoupled([[1.0f32, 1.0], [1.0, 1.0]], axes()).is_err());
}

#[test]
fn reset_at_applied_voltage_is_consistent_with_the_model_at_rest_there() {
    let u0 = 37.0f32;
    let pi = Pi::new(0.1f32, [0.03, 0.02], [2.0, 10.0]).unwrap();
    let dpi = Dpi::new([0.1f32, 0.03], [1.0, 10.0], [1.0, 0.3], [0.0, 3.0]).unwrap();
    let cbw = cbw(1.0);
    let cases: Vec<(Feedforward<f32>, f32)> = vec![
        (
            Feedforward::PiInverse(PiInverse::new(&pi, V.0, V.1).unwrap()),
            pi.step(&mut pi.init(u0), u0, DT),
        ),
        (
            Feedforward::DpiInverse(DpiInverse::new(&dpi, V.0, V.1).unwrap()),
            dpi.step(&mut dpi.init(u0), u0, DT),
        ),
        (
            Feedforward::ImsCbw(ims_solved(cbw)),
            cbw.step(&mut cbw.init(u0), u0, DT),
        ),
    ];
    for (mut ff, y0) in cases {
        ff.compensate(&Setpoint::hold(3.0));
        ff.reset_at(&Setpoint::hold(y0), u0);
        let u = ff.compensate(&Setpoint::hold(y0));
        assert!((u - u0).abs() < 1e-4, "{}: {u} vs {u0}", ff.name());
        // reset() keeps the last commanded voltage
        ff.reset(&Setpoint::hold(0.0));
        assert!(
            (ff.volts(&Setpoint::hold(0.0)) - u).abs() < 1e-4,
            "{}",
            ff.name()
        );
    }
}
