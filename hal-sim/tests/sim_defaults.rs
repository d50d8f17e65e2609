//! The built-in scenarios start cleanly (no sensor fault at start-up, no bus error) and the
//! default stage shows its hysteresis in open loop: max error above 5 % of the commanded
//! stroke at 10 Hz over 80 % of the stroke, above 10 % over the full stroke at 1 Hz
//! (hysteresis alone) and above 10 % at 100 Hz (hysteresis + dynamics).

use hal_sim::sim::controllers::find;
use hal_sim::sim::{default_scenarios, run};

#[test]
fn default_scenarios_run_open_loop_without_faults() {
    let ol = find("open-loop").unwrap();
    for mut sc in default_scenarios(None, None) {
        // Short runs keep the dev-profile test fast; the settling time shrinks with them.
        // The full-stroke 1 Hz loop needs its whole period after settling.
        if sc.name != "sine-1hz-full-stroke" {
            sc.run.duration_s = sc.run.duration_s.min(0.12);
            sc.run.settle_s = sc.run.settle_s.map(|s| s.min(0.05));
        }
        let (r, _) = run(&sc, &ol, false).unwrap();
        assert_eq!(r.sensor_faults, 0, "{}", sc.name);
        assert_eq!(r.nonfinite_commands, 0, "{}", sc.name);
        assert_eq!(r.bus_errors, 0, "{}", sc.name);
        let floor = match sc.name.as_str() {
            "sine-10hz" => 5.0,
            "sine-100hz" | "sine-1hz-full-stroke" => 10.0,
            _ => 0.0,
        };
        eprintln!("{} open loop: max error {:.2} %", sc.name, r.max_err_pct);
        assert!(r.max_err_pct > floor, "{}: {}", sc.name, r.max_err_pct);
    }
}
