//! Seed 004's compensator comparison (sec. 4.4, Table 3) on 004's plant: the identified
//! WPMBW (sec. 4.2) cascaded with its linear dynamics (eq. 8, `n = 4`, `m = 2`), 10 kHz,
//! 0-10 V. Each compensator runs on the parameters 004 identified for its own model:
//! * CBW, eq. (25): `u = (y_d + h)/d`, the IMS of 004's CBW (sec. 4.3 (1)), no inverse
//!   dynamics;
//! * the asymmetric BW of [36], eq. (26): the IMS of eq. (21) behind the inverse of its
//!   second-order `m, b, k` ([`ImsDynamics::eq26`]);
//! * WPMBW, eq. (27): the direct inverse (eq. 17-18) behind the inverse of eq. (8).
//!
//! Eq. (25) and (26) close their algebraic loop with 004's one-sample delay (the rows "as
//! 004") and, for comparison, exactly. Eq. (27) needs `y_d` up to the fourth derivative for
//! `n = 4`; the setpoint carries two, so "as 004" uses eq. (8)'s `a0, a1, a2` (zeros and
//! `a3, a4` dropped); the ZPETC row inverts eq. (8) fully (with the order-5 prefilter its
//! fourth-order inverse needs, see `feedforward_zpetc.rs`). Every other row uses the
//! prefilter of eq. (28) (`zeta = 1`, `wn = 100 pi`) from the stage at rest at 0 V.
//!
//! MPME (eq. 22) and RMSE (eq. 23) of `y - y_r` after the prefilter's transient (from
//! 0.2 s on), over 5 s. The plant is 004's best model of its stage, so the WPMBW
//! compensator has the plant's own hysteresis model: the comparison measures how far the
//! CBW and [36] models, identified on the real stage, are from it.
//!
//! `cargo test -p piezo-core --test seed004_compensation -- --nocapture` prints the table.

use core::f64::consts::PI;
use piezo_core::feedforward::{
    FullPass, Ims, ImsDynamics, ImsLoop, InverseDynamics, LinearPart, WpmbwInverse, Zpetc,
};
use piezo_core::hysteresis::{AbwU, Cbw, Hysteresis, MbwRlm, Wpmbw};
use piezo_core::linear::{poly, Discretisation, Linear};
use piezo_core::signals::Setpoint;

/// 004 eq. (8) identified (sec. 4.2), ascending powers of `s`.
const A: [f64; 5] = [5.421e12, 1.183e10, 1.046e7, 8.753e3, 1.0];
const B: [f64; 3] = [5.421e12, -4.002e8, 4.083e6];
const DT: f64 = 1e-4;
/// 004 eq. (28): zeta = 1, wn = 100 pi.
const WN: f64 = 100.0 * PI;
const SECONDS: f64 = 5.0;
/// 004 sec. 4.1: 0-10 V.
const VOLTS: (f64, f64) = (0.0, 10.0);

fn wpmbw() -> Wpmbw<f64, 2> {
    Wpmbw::new(
        MbwRlm::new(0.6485, 0.7217, 0.7440).unwrap(),
        [0.9268, 0.0048],
    )
    .unwrap()
}

/// 004 sec. 4.3 (1): the identified CBW.
fn cbw() -> Cbw<f64> {
    Cbw::with_n1(0.9248, 0.3554, 0.3485, 0.2111).unwrap()
}

/// 004 sec. 4.3 (2): the identified model of [36], eq. (21).
fn abw() -> (AbwU<f64>, (f64, f64, f64)) {
    (
        AbwU::new(0.9221, 0.3050, 0.5913, 0.1649, 1.7170, 0.0415).unwrap(),
        (0.1029, 81.3370, 3.1628e4),
    )
}

/// 004 eq. (29): 1 Hz, decaying amplitude (mrad).
fn y_r1(t: f64) -> f64 {
    3.45 * (-0.21 * t).exp() * ((2.0 * PI * t + 1.5 * PI).sin() + 1.0) + 1.0
}

/// 004 eq. (30): varying amplitude and frequency, about 10 Hz falling to 1 Hz (mrad).
fn y_r2(t: f64) -> f64 {
    3.25 * (-0.15 * t).exp() * ((20.0 * PI * (-1.1 * t).exp() * t + 1.5 * PI).sin() + 1.0) + 1.0
}

/// The setpoint with its derivatives (central differences of the analytic reference).
fn setpoint(r: fn(f64) -> f64, t: f64) -> Setpoint<f64> {
    let h = 1e-5;
    Setpoint {
        y_um: r(t),
        dy: (r(t + h) - r(t - h)) / (2.0 * h),
        ddy: (r(t + h) - 2.0 * r(t) + r(t - h)) / (h * h),
    }
}

/// One compensator: the voltage for the prefiltered setpoint `(y_d, y_d', y_d'')`.
// One per run, never moved: the size difference does not matter.
#[allow(clippy::large_enum_variant)]
enum Comp {
    Cbw(Ims<f64, Cbw<f64>>),
    Abw(ImsDynamics<f64, AbwU<f64>>),
    /// The WPMBW inverse carries its own prefilter.
    Wpmbw(WpmbwInverse<f64>),
}

#[derive(Clone, Copy, Debug)]
struct Errors {
    /// 004 eq. (22), %.
    mpme: f64,
    /// 004 eq. (23), mrad.
    rmse: f64,
    u_max: f64,
}

/// Runs `comp` on 004's plant from rest at 0 V against the reference `r`.
fn run(mut comp: Comp, r: fn(f64) -> f64) -> Errors {
    let plant = wpmbw();
    let lin = Linear::<f64, 2>::from_tf(&B, &A, DT, Discretisation::Zoh).unwrap();
    let (mut hs, mut ls) = (plant.init(0.0), lin.init(0.0));
    let mut pre = FullPass::eq28(WN, DT).unwrap();
    let preview = match &comp {
        Comp::Wpmbw(w) => w.preview(),
        _ => 0,
    };
    let n = (SECONDS / DT) as usize;
    let (mut se, mut cnt, mut worst, mut u_max) = (0.0, 0usize, 0.0f64, 0.0f64);
    let (mut y_lo, mut y_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for k in 0..n {
        let t = k as f64 * DT;
        let sp = setpoint(r, (k + preview) as f64 * DT);
        let u = match &mut comp {
            Comp::Wpmbw(w) => w.compensate(&sp),
            other => {
                let (y, dy, ddy) = pre.apply(&sp);
                let sd = Setpoint { y_um: y, dy, ddy };
                match other {
                    Comp::Cbw(c) => c.compensate(sd.y_um),
                    Comp::Abw(c) => c.compensate(&sd),
                    Comp::Wpmbw(_) => unreachable!(),
                }
            }
        };
        assert!(u.is_finite() && u >= VOLTS.0 && u <= VOLTS.1, "{u}");
        u_max = u_max.max(u);
        let y = lin.step(&mut ls, plant.step(&mut hs, u, DT));
        // The ZOH output at the end of the sample answers the setpoint of its start.
        let e = y - r(t + DT);
        if t >= 0.2 {
            se += e * e;
            cnt += 1;
            worst = worst.max(e.abs());
            y_lo = y_lo.min(y);
            y_hi = y_hi.max(y);
        }
    }
    Errors {
        mpme: 100.0 * worst / (y_hi - y_lo),
        rmse: (se / cnt as f64).sqrt(),
        u_max,
    }
}

fn cbw_comp(closure: ImsLoop) -> Comp {
    Comp::Cbw(Ims::new(cbw(), closure, VOLTS.0, VOLTS.1, DT).unwrap())
}

fn abw_comp(closure: ImsLoop) -> Comp {
    let (m, (mass, b, k)) = abw();
    Comp::Abw(ImsDynamics::eq26(m, mass, b, k, closure, VOLTS.0, VOLTS.1, DT).unwrap())
}

fn wpmbw_comp(zpetc: bool) -> Comp {
    let (dynamics, prefilter) = if zpetc {
        let (gain, secs, n) = poly::sections(&B, &A).unwrap();
        (
            InverseDynamics::Zpetc(Zpetc::new(gain, &secs[..n], DT, 0.99).unwrap()),
            FullPass::new(WN, 5, DT).unwrap(),
        )
    } else {
        (
            InverseDynamics::Derivatives(LinearPart {
                a0: A[0],
                a1: A[1],
                a2: A[2],
                b0: B[0],
            }),
            FullPass::eq28(WN, DT).unwrap(),
        )
    };
    Comp::Wpmbw(
        WpmbwInverse::with_dynamics(&wpmbw(), dynamics, Some(prefilter), VOLTS.0, VOLTS.1, DT)
            .unwrap(),
    )
}

#[test]
fn table3_cbw_abw_and_wpmbw_compensation_on_004s_plant() {
    type Row = (&'static str, fn() -> Comp);
    let rows: [Row; 6] = [
        ("CBW, eq. (25), delayed (as 004)", || {
            cbw_comp(ImsLoop::Delayed)
        }),
        ("CBW, eq. (25), solved", || cbw_comp(ImsLoop::Solved)),
        ("[36], eq. (26), delayed (as 004)", || {
            abw_comp(ImsLoop::Delayed)
        }),
        ("[36], eq. (26), solved", || abw_comp(ImsLoop::Solved)),
        ("WPMBW, eq. (27), a0..a2 (as 004)", || wpmbw_comp(false)),
        ("WPMBW, eq. (27), ZPETC", || wpmbw_comp(true)),
    ];
    type Reference = (&'static str, fn(f64) -> f64);
    let refs: [Reference; 2] = [("(29)", y_r1), ("(30)", y_r2)];
    let mut table = vec![];
    for (rname, r) in refs {
        let errs: Vec<Errors> = rows.iter().map(|(_, c)| run(c(), r)).collect();
        for ((name, _), e) in rows.iter().zip(&errs) {
            eprintln!(
                "{rname} {name:34}: MPME {:6.2} %  RMSE {:.4} mrad  peak {:.2} V",
                e.mpme, e.rmse, e.u_max
            );
        }
        table.push(errs);
    }
    // 004 Table 3, the rows as 004 ran them: the seed's ordering, CBW worst, WPMBW best.
    for (errs, (rname, _)) in table.iter().zip(refs) {
        let (cbw, abw, wp) = (errs[0], errs[2], errs[4]);
        assert!(
            wp.rmse < abw.rmse && abw.rmse < cbw.rmse,
            "{rname}: RMSE CBW {} [36] {} WPMBW {}",
            cbw.rmse,
            abw.rmse,
            wp.rmse
        );
        assert!(
            wp.mpme < cbw.mpme && abw.mpme < cbw.mpme,
            "{rname}: MPME CBW {} [36] {} WPMBW {}",
            cbw.mpme,
            abw.mpme,
            wp.mpme
        );
    }
}
