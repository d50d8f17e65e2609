//! Seed 002's compensation experiment (sec. 5, Table 3) on 002's own stage model: the MBW of
//! its Table 1 as the plant, and 002's compensator (eq. 8-12, `k_p = 1`: `h` estimated from
//! `v_r = y_r/d`, no inversion) on each of the three models of Table 1. A 0.1 Hz sine over
//! the output of 002's 0-5 V input (`k = 1.1`: 0-5.5 in the model's output unit) at 2 kHz;
//! RE as 002's Table 3 computes it: RMSE over the second period divided by the total
//! travel.
//!
//! `cargo test -p piezo-core --test seed002_compensation -- --nocapture` prints the table.

use core::f64::consts::PI;
use piezo_core::feedforward::MbwFf;
use piezo_core::hysteresis::{AbwAbs, Hysteresis, Mbw002};

const FS: f64 = 2000.0;
/// The output of 0-5 V (002 sec. 3: full-range 0-5 V input) through `k = 1.1`.
const TRAVEL: f64 = 5.5;

fn mbw() -> Mbw002<f64> {
    Mbw002::from_002(1.0998, -0.0656, 0.3922, -0.15, 1.0, -0.011, 0.0108, 3.68e-5).unwrap()
}

/// A static model of Table 1 (CBW: no `delta`) as the MBW the compensator takes.
fn static_model(k: f64, alpha: f64, beta: f64, gamma: f64, delta: f64) -> Mbw002<f64> {
    Mbw002::new(
        AbwAbs::from_002(k, alpha, beta, gamma, 1.0, delta).unwrap(),
        0.0,
        0.0,
    )
    .unwrap()
}

/// RE (% of travel) of the plant driven by `ff` from rest, over the second period.
fn re(mut ff: impl FnMut(f64) -> f64) -> f64 {
    let plant = mbw();
    let mut s = plant.init(0.0);
    let f_hz = 0.1;
    let n = (2.0 * FS / f_hz) as usize;
    let (mut se, mut cnt) = (0.0, 0);
    for k in 0..n {
        let t = k as f64 / FS;
        let y_ref = TRAVEL / 2.0 * (1.0 - (2.0 * PI * f_hz * t).cos());
        let y = plant.step(&mut s, ff(y_ref), 1.0 / FS);
        if k >= n / 2 {
            se += (y - y_ref).powi(2);
            cnt += 1;
        }
    }
    100.0 * (se / cnt as f64).sqrt() / TRAVEL
}

fn comp(m: Mbw002<f64>) -> impl FnMut(f64) -> f64 {
    let mut ff = MbwFf::new(m, 1.0, -10.0, 20.0, 1.0 / FS).unwrap();
    move |y| ff.compensate(y)
}

#[test]
fn table3_002s_compensator_on_002s_model() {
    let d = mbw().abw().d();
    let none = re(|y| y / d);
    let cbw = re(comp(static_model(1.0974, -0.7051, 1.9251, -0.62, 0.0)));
    let abw = re(comp(static_model(1.0986, -0.6715, 1.9231, -0.35, 0.032)));
    let own = re(comp(mbw()));
    eprintln!(
        "RE at 0.1 Hz, % of travel: none {none:.2} (002: 4.75), CBW {cbw:.2} (1.52), \
         ABW {abw:.2} (1.47), MBW {own:.2} (0.52)"
    );
    // On its own model the MBW compensator is well inside the seed's measured 0.52 %: what
    // is left is eq. 9-10's h(v_r) in place of h(u). The CBW and ABW of Table 1 are not
    // models of this plant (their loops are 3-4 times the MBW's), so on it they do worse
    // than no compensation: 002's CBW and ABW columns are not reproduced by its MBW.
    assert!(own < 0.1 * none && own < 0.52, "MBW {own} %, none {none} %");
    assert!(cbw > own && abw > own, "CBW {cbw} %, ABW {abw} %");
}
