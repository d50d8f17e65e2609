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
