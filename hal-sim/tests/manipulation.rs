//! Manipulation scenarios (000 Part V): force estimation, object identification, BLF force
//! control, beam observers. Every bound below is checked on a noisy simulated run.
use hal_sim::object::{
    blf_errors, blf_force, force_errors, identify, indentation, BlfConfig, ManipConfig,
};

#[test]
fn force_estimate_tracks_true_force_under_noise() {
    let cfg = ManipConfig::default();
    let tr = indentation(&cfg, 1.0).unwrap();
    let (rms, max, peak) = force_errors(&tr, 500);
    println!("force estimation: rms {rms:.3} mN, max {max:.3} mN, peak force {peak:.1} mN");
    assert!(peak > 100.0, "the object must be indented");
    assert!(rms < 0.015 * peak, "rms {rms} mN vs peak {peak} mN");
}

#[test]
fn identified_object_matches_truth() {
    let cfg = ManipConfig::default();
    let tr = indentation(&cfg, 2.0).unwrap();
    let fit = identify(&tr, cfg.observer_hz, cfg.rate_hz, 500).unwrap();
    let o = cfg.plant.object;
    println!("identified {fit:?}\ntruth {o:?}");
    let rel = |a: f64, b: f64| ((a - b) / b).abs();
    assert!((fit.gap_um - o.gap_um).abs() < 0.05, "gap {}", fit.gap_um);
    assert!(rel(fit.k1, o.k1) < 0.05, "k1 {}", fit.k1);
    assert!(rel(fit.k3, o.k3) < 0.05, "k3 {}", fit.k3);
    assert!(rel(fit.c, o.c) < 0.25, "c {}", fit.c);
}

#[test]
fn blf_force_error_stays_inside_kb() {
    let cfg = ManipConfig::default();
    let b = BlfConfig::default();
    for estimated in [false, true] {
        let tr = blf_force(&cfg, &b, estimated, 1.5).unwrap();
        let (max_true, max_fb, rms_true) = blf_errors(&tr);
        let n = tr.force_ref.iter().filter(|f| f.is_finite()).count();
        println!(
            "BLF estimated={estimated}: max |F-Fd| {max_true:.3}, max |Ffb-Fd| {max_fb:.3}, rms {rms_true:.3} mN over {n} samples, k_b {}",
            b.kb_mn
        );
        assert!(n > 10_000, "force control must run, got {n} samples");
        assert!(max_fb < b.kb_mn, "fed-back error {max_fb} left k_b");
        assert!(max_true < b.kb_mn, "true error {max_true} left k_b");
    }
    // The barrier is what keeps it inside: the same law without it leaves k_b.
    let nb = BlfConfig { kb_mn: 1e6, ..b };
    let (_, max_fb, _) = blf_errors(&blf_force(&cfg, &nb, false, 1.5).unwrap());
    println!("no barrier: max |Ffb-Fd| {max_fb:.3} mN");
    assert!(
        max_fb > b.kb_mn,
        "baseline {max_fb} stayed inside k_b: the test shows nothing"
    );
}

#[test]
fn hgo_and_nno_track_the_control_point() {
    use hal_sim::beam::{est_errors, run_beam, BeamConfig};
    let cfg = BeamConfig {
        duration_s: 1.0,
        ..Default::default()
    };
    let run = run_beam(&cfg).unwrap();
    let r = &run.y_c[run.skip..];
    let range = r.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - r.iter().copied().fold(f64::INFINITY, f64::min);
    let (h_rms, h_max) = est_errors(&run, &run.hgo);
    let (n_rms, n_max) = est_errors(&run, &run.nno);
    let (l_rms, _) = est_errors(&run, &run.luenberger);
    println!(
        "beam x_c = 0.5, range {range:.3} um: HGO rms {h_rms:.4} max {h_max:.4}; NNO rms {n_rms:.4} max {n_max:.4}; no-learning rms {l_rms:.4} um"
    );
    assert!(range > 3.0, "the beam must move, range {range}");
    for (name, rms, max) in [("HGO", h_rms, h_max), ("NNO", n_rms, n_max)] {
        assert!(rms < 0.02 * range, "{name} rms {rms} um");
        assert!(max < 0.05 * range, "{name} max {max} um");
    }
    // The network must earn its keep against the same observer without learning.
    assert!(n_rms < 0.9 * l_rms, "NNO {n_rms} vs no learning {l_rms}");
}

/// The firmware runs the observers in f32: same measurements, same bounds.
#[test]
fn observers_work_in_f32() {
    use hal_sim::beam::{beam_input, nominal_cbw, observer_model, BeamConfig, BeamPlant};
    use hal_sim::numeric::Rng;
    use piezo_core::hysteresis::Cbw;
    use piezo_core::manipulation::beam::ModalModel;
    use piezo_core::manipulation::{ForceEso, Hgo, StageDynamics, VoltageInput};

    // Force ESO on the recorded indentation.
    let cfg = ManipConfig::default();
    let tr = indentation(&cfg, 1.0).unwrap();
    let cbw32 = Cbw::<f32>::with_n1(0.16, 0.07, 0.02, 0.01).unwrap();
    let inp = VoltageInput::<f32>::new(0.0, cfg.u_play_volts as f32, 1e-4).unwrap();
    let st = StageDynamics {
        natural_hz: 800.0f32,
        damping_ratio: 0.15,
        stiffness_mn_per_um: 200.0,
    };
    let eso = ForceEso::new(cbw32, st, cfg.observer_hz as f32, inp, 10_000.0).unwrap();
    let mut es = eso.init(0.0, 0.0);
    let (mut e2, mut n) = (0.0, 0);
    for k in 0..tr.t.len() {
        let f = eso.update(&mut es, tr.y_meas[k] as f32, tr.u_meas[k] as f32) as f64;
        if k >= 500 {
            e2 += (f - tr.force[k]).powi(2);
            n += 1;
        }
    }
    let rms = (e2 / n as f64).sqrt();
    let (_, _, peak) = force_errors(&tr, 500);
    println!("f32 force ESO rms {rms:.3} mN (peak {peak:.1} mN)");
    assert!(rms < 0.015 * peak, "f32 ESO rms {rms}");

    // HGO on the beam: f32 and f64 give the same control-point estimate.
    let bc = BeamConfig::default();
    let m = observer_model(&bc);
    let mf: ModalModel<f32, 4> = ModalModel {
        a: m.a.map(|r| r.map(|v| v as f32)),
        b: m.b.map(|v| v as f32),
        c_tip: m.c_tip.map(|v| v as f32),
        c_out: m.c_out.map(|v| v as f32),
    };
    let eps = 1.0 / (std::f64::consts::TAU * bc.hgo_hz);
    let h32: Hgo<f32, 5> = Hgo::new(&mf, cbw32, eps as f32, inp, 10_000.0).unwrap();
    let inp64 = VoltageInput::<f64>::new(0.0, bc.u_play_volts, 1e-4).unwrap();
    let h64: Hgo<f64, 5> = Hgo::new(&m, nominal_cbw(), eps, inp64, 10_000.0).unwrap();
    let plant = BeamPlant::new(&bc).unwrap();
    let mut ps = plant.init();
    let (mut s32, mut s64) = (h32.init(0.0), h64.init(0.0));
    let mut g = Rng::new(5);
    let mut worst: f64 = 0.0;
    for k in 0..8000 {
        let u = beam_input(k as f64 * 1e-4);
        plant.step(&mut ps, u, 1e-4);
        let y = plant.deflection(&ps, 1.0) + g.normal(0.005);
        let um = u + g.normal(0.02);
        let a = h32.update(&mut s32, y as f32, um as f32) as f64;
        let b = h64.update(&mut s64, y, um);
        worst = worst.max((a - b).abs());
    }
    println!("HGO f32 vs f64: max difference {worst:.2e} um");
    assert!(worst < 2e-3, "f32 HGO departs from f64 by {worst} um");
}
