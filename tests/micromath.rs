//! The design card's `micromath` against what each per-sample function of the control step
//! needs (issue 15 item 7): its worst error over the inputs the step gives each function,
//! next to the functions the step uses (our `sin_cos_turns`, libm through `Real`). The
//! step keeps a function unless micromath meets the need; the cost per call on the M4F is
//! the QEMU board's (`bench: math` lines of `30-qemu.sh`). Run with `--nocapture` for the
//! table the README quotes.
use micromath::F32Ext;
use piezo_core::pipeline::excitation::sin_cos_turns;
use piezo_core::real::Real;

/// Worst absolute and relative error of `f` against `exact` over `n` points of `[lo, hi]`.
fn worst(
    n: usize,
    lo: f64,
    hi: f64,
    f: impl Fn(f32) -> f32,
    exact: impl Fn(f64) -> f64,
) -> (f64, f64) {
    let (mut abs, mut rel) = (0.0f64, 0.0f64);
    for i in 0..=n {
        let x = (lo + (hi - lo) * i as f64 / n as f64) as f32;
        let e = exact(x as f64);
        let d = (f(x) as f64 - e).abs();
        abs = abs.max(d);
        if e.abs() > 1e-30 {
            rel = rel.max(d / e.abs());
        }
    }
    (abs, rel)
}

#[test]
fn micromath_against_the_steps_needs() {
    let tau = core::f64::consts::TAU;
    // Reference sine: 1 nm at 100 um amplitude, 1e-5 of the amplitude.
    let need_sine = 1e-5;
    let (ours, _) = worst(
        200_000,
        0.0,
        1.0,
        |x| sin_cos_turns(x).0,
        |x| (tau * x).sin(),
    );
    let (mm, _) = worst(
        200_000,
        0.0,
        1.0,
        |x| (x * tau as f32).sin(),
        |x| (tau * x).sin(),
    );
    // IMS residual and observer (the CBW's exact step): exp(-x) - 1 for x in 0..20 and
    // exp; 1e-5 relative (0.1 nm of a 10 um hysteresis state).
    let need_exp = 1e-5;
    let (_, ours_expm1) = worst(200_000, -20.0, -1e-4, <f32 as Real>::exp_m1, f64::exp_m1);
    let (_, mm_expm1) = worst(200_000, -20.0, -1e-4, |x| x.exp() - 1.0, f64::exp_m1);
    let (_, ours_exp) = worst(200_000, -20.0, 5.0, <f32 as Real>::exp, f64::exp);
    let (_, mm_exp) = worst(200_000, -20.0, 5.0, F32Ext::exp, f64::exp);
    // Bouc-Wen exponent n (001 eq. 2): |h|^n for |h| in 1e-3..1 (normalised), n = 1.5.
    let (_, ours_pow) = worst(
        200_000,
        1e-3,
        1.0,
        |x| <f32 as Real>::powf(x, 1.5),
        |x| x.powf(1.5),
    );
    let (_, mm_pow) = worst(
        200_000,
        1e-3,
        1.0,
        |x| F32Ext::powf(x, 1.5),
        |x| x.powf(1.5),
    );
    // ln: absolute error (its values pass through 0).
    let (ours_ln, _) = worst(200_000, 1e-3, 10.0, <f32 as Real>::ln, f64::ln);
    let (mm_ln, _) = worst(200_000, 1e-3, 10.0, F32Ext::ln, f64::ln);
    println!("function (need)              ours (libm / sin_cos_turns)   micromath");
    println!("sin, abs of amplitude (1e-5) {ours:>12.2e}                  {mm:>10.2e}");
    println!("exp_m1, rel (1e-5)           {ours_expm1:>12.2e}                  {mm_expm1:>10.2e}");
    println!("exp, rel (1e-5)              {ours_exp:>12.2e}                  {mm_exp:>10.2e}");
    println!("powf(x, 1.5), rel (1e-5)     {ours_pow:>12.2e}                  {mm_pow:>10.2e}");
    println!("ln, abs (1e-5)               {ours_ln:>12.2e}                  {mm_ln:>10.2e}");
    // The step's own functions meet every need.
    assert!(ours < need_sine && ours_expm1 < need_exp && ours_exp < need_exp);
    assert!(ours_pow < need_exp && ours_ln < need_exp);
    // What the README states: micromath's sine meets the reference's need (the choice is
    // then the cost per call, QEMU); its exp, powf and ln do not (if a new micromath did,
    // this fails and the choice should be revisited).
    assert!(mm < need_sine, "micromath sin: {mm}");
    assert!(
        mm_expm1 > need_exp && mm_exp > need_exp,
        "micromath exp now meets the need"
    );
    assert!(
        mm_pow > need_exp && mm_ln > need_exp,
        "micromath powf/ln now meet the need"
    );
}
