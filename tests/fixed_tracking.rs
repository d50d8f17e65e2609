//! Fixed point (Q16.16, the FPU-less Cortex-M3 build) against f32: the same feedforward and
//! feedback laws track the same reference on the same simulated stage.
//!
//! Stage (f64): CBW set 1 of the 000 backup slide followed by a first-order lag (500 Hz),
//! measured by a 16-bit ADC over 0..100 um. Sample rate 65 536 Hz, so the sample period is
//! exactly one Q16.16 unit (`2^-16 s`). Reference: 10 + 5 sin(2 pi 50 t) um.
//!
//! The second test runs the core `Pipeline` itself as the firmware configures it.
//!
//! Prints the tracking errors (`cargo test --test fixed_tracking -- --nocapture`).

use piezo_core::feedback::{
    hgo, Adrc, AdrcConfig, Convergence, Feedback, Hgo, ObserverModel, Pid, PidConfig, Robust,
    RobustConfig,
};
use piezo_core::feedforward::{Feedforward, Ims, ImsLoop, LinearFf};
use piezo_core::fixed::Q16;
use piezo_core::hysteresis::{Cbw, Hysteresis};
use piezo_core::signals::{LoopSignals, Setpoint};
use piezo_core::Real;

const FS_HZ: f64 = 65_536.0;
const POLE_PER_S: f64 = 2.0 * std::f64::consts::PI * 500.0;
const UM_PER_CODE: f64 = 100.0 / 65_535.0;

fn cbw<T: Real>() -> Cbw<T> {
    Cbw::with_n1(
        T::from_f64(0.16),
        T::from_f64(0.07),
        T::from_f64(0.02),
        T::from_f64(0.01),
    )
    .unwrap()
}

/// The PID of both tests at sample period `dt_s`.
fn pid<T: Real>(dt_s: f64) -> Result<Pid<T>, piezo_core::hysteresis::ParamError> {
    let f = T::from_f64;
    Pid::new(PidConfig {
        kp: f(0.5),
        ki: f(2_000.0),
        kd: f(0.0),
        tf_s: f(1e-4),
        kb: f(1.0),
        feedforward: true,
        dt_s: f(dt_s),
    })
}

/// The HGO-based robust law on the plant's CBW: observer `eps_s`, gains `lambda`.
fn robust<T: Real>(
    eps_s: f64,
    lambda: f64,
    dt_s: f64,
) -> Result<Feedback<T>, piezo_core::hysteresis::ParamError> {
    let f = T::from_f64;
    let hgo = Hgo::new(
        ObserverModel::Cbw(cbw()),
        f(POLE_PER_S),
        f(eps_s),
        f(hgo::K1),
        f(hgo::K2),
        f(dt_s),
    )?;
    let cfg = RobustConfig {
        lambda1: f(lambda),
        lambda2: f(lambda),
        feedforward: true,
        convergence: Convergence::Exponential,
    };
    Ok(Feedback::Robust(Robust::new(hgo, cfg)?))
}

/// IMS on the plant's CBW over 0..150 V, or the linear scaling.
fn feedforward<T: Real>(ims: bool, dt_s: f64) -> Feedforward<T> {
    let f = T::from_f64;
    if ims {
        Feedforward::ImsCbw(Ims::new(cbw(), ImsLoop::Solved, f(0.0), f(150.0), f(dt_s)).unwrap())
    } else {
        Feedforward::Linear(LinearFf {
            um_per_volt: f(0.16),
            offset_um: f(0.0),
        })
    }
}

fn law<T: Real>(name: &str) -> Result<Feedback<T>, piezo_core::hysteresis::ParamError> {
    let f = T::from_f64;
    let dt = f(1.0 / FS_HZ);
    Ok(match name {
        "open-loop" => Feedback::OpenLoop,
        "ff+pid" => Feedback::Pid(pid(1.0 / FS_HZ)?),
        "ff+hgo-robust" => robust(2e-4, 2_000.0, 1.0 / FS_HZ)?,
        "ff+adrc" => Feedback::Adrc(Adrc::new(AdrcConfig {
            b: f(0.16 * POLE_PER_S * POLE_PER_S),
            a1: f(0.0),
            a2: f(0.0),
            eps_s: f(2e-4),
            omega_c: f(2_000.0),
            feedforward: true,
            dt_s: dt,
        })?),
        _ => unreachable!(),
    })
}

/// RMS and max tracking error (um) after the first 20 ms, and whether every command was
/// finite and inside 0..150 V.
fn track<T: Real>(law_name: &str, ims: bool) -> (f64, f64, bool) {
    let f = T::from_f64;
    let dt = 1.0 / FS_HZ;
    let mut ff = feedforward::<T>(ims, dt);
    let mut fb = law::<T>(law_name).unwrap();
    let plant = cbw::<f64>();
    let mut ps = plant.init(0.0);
    let lag = 1.0 - (-POLE_PER_S * dt).exp();
    let mut y = 0.0f64;
    let mut u_applied = T::ZERO;
    let (mut sum2, mut max, mut n, mut ok) = (0.0, 0.0f64, 0, true);
    let w = 2.0 * std::f64::consts::PI * 50.0;
    for k in 0..(0.2 * FS_HZ) as usize {
        let t = k as f64 * dt;
        let y_ref = 10.0 + 5.0 * (w * t).sin();
        let sp = Setpoint {
            y_um: f(y_ref),
            dy: f(5.0 * w * (w * t).cos()),
            ddy: f(-5.0 * w * w * (w * t).sin()),
        };
        let code = (y / UM_PER_CODE).round().clamp(0.0, 65_535.0);
        let y_um = f(code) * f(UM_PER_CODE);
        let u_ff = ff.compensate(&sp);
        let u = fb.update(&LoopSignals {
            setpoint: sp,
            y_um,
            u_ff,
            u_applied,
        });
        ok &= u.is_finite();
        let u = u.clamp_to(T::ZERO, f(150.0));
        u_applied = u;
        let yh = plant.step(&mut ps, u.to_f64(), dt);
        y += lag * (yh - y);
        if t >= 0.02 {
            let e = y_ref - y;
            sum2 += e * e;
            max = max.max(e.abs());
            n += 1;
        }
    }
    ((sum2 / n as f64).sqrt(), max, ok)
}

/// ADRC's input gain `b = b0 d_p` (1.6e6 um/(s^2 V) for a 500 Hz stage) is beyond the
/// Q16.16 range: the law refuses the configuration instead of running with a clipped gain.
#[test]
fn adrc_gain_out_of_q16_range_is_refused() {
    assert!(law::<f32>("ff+adrc").is_ok());
    let err = law::<Q16>("ff+adrc").unwrap_err();
    assert!(err.0.contains("ADRC"), "{}", err.0);
}

#[test]
fn fixed_point_tracks_like_f32() {
    println!("law              ff        f32 rms/max (um)     Q16.16 rms/max (um)");
    for law_name in ["open-loop", "ff+pid", "ff+hgo-robust"] {
        for ims in [false, true] {
            let (r32, m32, ok32) = track::<f32>(law_name, ims);
            let (rq, mq, okq) = track::<Q16>(law_name, ims);
            let ff = if ims { "ims-cbw" } else { "linear" };
            println!("{law_name:<16} {ff:<9} {r32:>8.4} / {m32:>7.4}    {rq:>8.4} / {mq:>7.4}");
            assert!(ok32 && okq, "{law_name} {ff}: non-finite command");
            // Fixed point may lose a little accuracy, not the tracking: within 5 % + 0.01 um.
            assert!(
                rq <= 1.05 * r32 + 0.01,
                "{law_name} {ff}: Q16.16 RMS {rq} um vs f32 {r32} um"
            );
        }
    }
}

/// The whole core pipeline as the firmware configures it (16 384 Hz, 15-bit ADC over
/// 0..100 um, 12-bit DAC over 0..150 V, 20 V/ms slew) in Q16.16 and in f32, on the same
/// f64 stage: RMS tracking error of a 5 um, 50 Hz sine around 10 um.
fn track_pipeline<T: Real>(law_name: &str, ims: bool) -> f64 {
    use piezo_core::feedforward::MultiFeedforward;
    use piezo_core::pipeline::{
        AxisConfig, Config, DacScale, Mode, OutputLimits, Pipeline, Sensor, Wave,
    };
    let f = T::from_f64;
    let fs = 16_384.0;
    let dt = 1.0 / fs;
    let config = Config {
        sample_hz: f(fs),
        axes: [AxisConfig {
            sensor: Sensor {
                um_per_code: f(100.0 / 32_767.0),
                offset_um: f(0.0),
                code_min: 0,
                code_max: 32_767,
            },
            open_loop: LinearFf {
                um_per_volt: f(0.16),
                offset_um: f(0.0),
            },
            limits: OutputLimits {
                volts_min: f(0.0),
                volts_max: f(150.0),
                slew_volts_per_s: f(20_000.0),
            },
            dac: DacScale {
                volts_per_code: f(150.0 / 4095.0),
                volts_at_zero: f(0.0),
                code_min: 0,
                code_max: 4095,
            },
            safe_volts: f(0.0),
        }],
    };
    let ff = feedforward::<T>(ims, dt);
    // The laws above are tuned at 65 536 Hz; only their sample period changes here.
    let fb = match law_name {
        "ff+pid" => Feedback::Pid(pid(dt).unwrap()),
        "ff+hgo-robust" => robust(5e-4, 1_000.0, dt).unwrap(),
        _ => Feedback::OpenLoop,
    };
    let wave = Wave::sine(f(10.0), f(5.0), f(50.0));
    let mut p = Pipeline::new(config, [wave], MultiFeedforward::PerAxis([ff]), [fb]).unwrap();
    p.set_mode(if law_name == "open-loop" {
        Mode::Feedforward
    } else {
        Mode::ClosedLoop
    });
    let plant = cbw::<f64>();
    let mut ps = plant.init(0.0);
    let lag = 1.0 - (-POLE_PER_S * dt).exp();
    let (mut y, mut sum2, mut n) = (0.0f64, 0.0, 0);
    let w = 2.0 * std::f64::consts::PI * 50.0;
    for k in 0..(0.2 * fs) as usize {
        let code = (y / (100.0 / 32_767.0)).round().clamp(0.0, 32_767.0) as i32;
        let [dac] = p.step([code]);
        assert!(
            p.state().fault.is_none(),
            "{law_name}: fault {:?}",
            p.state().fault
        );
        let u = dac as f64 * 150.0 / 4095.0;
        y += lag * (plant.step(&mut ps, u, dt) - y);
        // The reference of sample k is applied at k and seen at k + 1.
        let t = k as f64 * dt;
        if t >= 0.02 {
            let e = 10.0 + 5.0 * (w * t).sin() - y;
            sum2 += e * e;
            n += 1;
        }
    }
    (sum2 / n as f64).sqrt()
}

#[test]
fn fixed_point_pipeline_tracks_like_f32() {
    println!("core pipeline at 16 384 Hz   f32 rms (um)   Q16.16 rms (um)");
    for law_name in ["open-loop", "ff+pid", "ff+hgo-robust"] {
        for ims in [false, true] {
            let r32 = track_pipeline::<f32>(law_name, ims);
            let rq = track_pipeline::<Q16>(law_name, ims);
            let ff = if ims { "ims-cbw" } else { "linear" };
            println!("{law_name:<16} {ff:<9} {r32:>10.4}   {rq:>10.4}");
            assert!(r32.is_finite() && rq.is_finite());
            assert!(
                rq <= 1.05 * r32 + 0.01,
                "{law_name} {ff}: Q16.16 RMS {rq} um vs f32 {r32} um"
            );
        }
    }
}
