//! Registry entries of the feedforward compensators (FEEDFORWARD engineer): every
//! compensator of `piezo_core::feedforward`, built from the stage's nominal parameters
//! (or 20 % off them), pipeline in `Mode::Feedforward`, no feedback.
//!
//! Only the IMS entries share the stage's model structure (hysteresis family, static
//! quadratic, creep, coupling); `mbw` runs the MBW identified from the stage's
//! open-loop record; the others are built by mapping the stage's parameters into their own
//! model (documented per builder), i.e. they run with a structure mismatch.

use super::identified::identified;
use super::{Controller, Entry, R};
use crate::scenario::HysteresisModel;
use crate::sim::StageInfo;
use anyhow::{anyhow, Result};
use piezo_core::feedback::Feedback;
use piezo_core::feedforward::*;
use piezo_core::hysteresis::*;
use piezo_core::pipeline::Mode;
use piezo_core::registry::FfKind;

/// Scale of the compensator's model parameters against the stage's.
const NOMINAL: f64 = 1.0;
const OFF20: f64 = 1.2;

fn e(err: ParamError) -> anyhow::Error {
    anyhow!("{err}")
}

/// The feedforward entries.
pub fn entries() -> Vec<Entry> {
    macro_rules! entry {
        ($kind:ident, $about:expr, $f:ident) => {
            Entry {
                name: FfKind::$kind.name(),
                about: $about,
                one_axis: $f::<1>,
                two_axis: Some($f::<2>),
            }
        };
    }
    vec![
        entry!(ImsCbw, "IMS u=(y+h(u))/d, algebraic loop solved; stage model + quadratic + creep + decoupler", ims_solved),
        entry!(ImsCbwDelayed, "IMS with the one-sample-delayed h (004 §4.4); same model", ims_delayed),
        entry!(ImsCbwOff20, "ims-cbw with every hysteresis/creep/coupling parameter +20 % (d from calibration)", ims_off20),
        entry!(ImsCbwBare, "IMS on the hysteresis model only (no quadratic, creep, decoupler)", ims_bare),
        entry!(Mbw, "002 feedforward without inversion (eq. 8-12, k_p = 1), MBW identified by piezo fit from the open-loop record", mbw_no_inverse),
        entry!(Wpmbw, "004 direct WPMBW inverse + inverse resonance + prefilter; MBW mapped from the CBW loop", wpmbw),
        entry!(PiInverse, "exact PI inverse; PI fitted to the stage's major loop (Masing)", pi_inverse),
        entry!(PpiInverse, "PPI inverse by bounded solve; same fit, c1 = 0", ppi),
        entry!(DpiInverse, "exact DPI inverse; same fit, one dead zone at 0", dpi),
        entry!(MultiIms, "multivariable IMS U = D^-1(y+h) (003 eq. 16) with D, A, B, Gamma = C*diag(.)", multi_ims),
    ]
}

fn controller<const N: usize>(feedforward: MultiFeedforward<R, N>) -> Controller<N> {
    Controller {
        feedforward,
        feedback: core::array::from_fn(|_| Feedback::OpenLoop),
        mode: Mode::Feedforward,
    }
}

fn dt(s: &StageInfo) -> R {
    (1.0 / s.loop_hz()) as R
}

fn volts(s: &StageInfo) -> (R, R) {
    let (lo, hi) = s.volts_range();
    (lo as R, hi as R)
}

/// The coupling matrix `C = I + M` (scaled off-diagonal by `k`), if enabled.
fn coupling<const N: usize>(s: &StageInfo, k: f64) -> Option<[[R; N]; N]> {
    let c = &s.scenario.stage.coupling;
    if !c.enabled || N < 2 {
        return None;
    }
    Some(core::array::from_fn(|i| {
        core::array::from_fn(|j| {
            if i == j {
                1.0
            } else {
                (k * c
                    .matrix
                    .get(i)
                    .and_then(|r| r.get(j))
                    .copied()
                    .unwrap_or(0.0)) as R
            }
        })
    }))
}

fn per_axis_or_decoupled<const N: usize>(
    s: &StageInfo,
    k: f64,
    decouple: bool,
    axis: impl Fn() -> Result<Feedforward<R>>,
) -> Result<MultiFeedforward<R, N>> {
    let mut axes = Vec::with_capacity(N);
    for _ in 0..N {
        axes.push(axis()?);
    }
    let axes: [Feedforward<R>; N] = axes.try_into().map_err(|_| anyhow!("axis count"))?;
    match coupling::<N>(s, k).filter(|_| decouple) {
        Some(c) => MultiFeedforward::decoupled(c, axes).map_err(e),
        None => Ok(MultiFeedforward::PerAxis(axes)),
    }
}

/// The IMS on the stage's hysteresis family, parameters scaled by `k` (not `d`).
fn ims_axis(s: &StageInfo, closure: ImsLoop, k: f64, full: bool) -> Result<Feedforward<R>> {
    let hy = s.hysteresis();
    let (lo, hi) = volts(s);
    let dt = dt(s);
    let kk = |x: f64| (k * x) as R;
    let creep = &s.scenario.stage.creep;
    let creep = if full && creep.enabled {
        let g: Vec<R> = creep.gains.iter().map(|&g| kk(g)).collect();
        let t: Vec<R> = creep.taus_s.iter().map(|&t| kk(t)).collect();
        Some(CreepInverse::new(&g, &t, dt).map_err(e)?)
    } else {
        None
    };
    let quad = if full { kk(hy.asym_um_per_v2) } else { 0.0 };
    let slew = s.scenario.pipeline.slew_volts_per_s as R;
    macro_rules! build {
        ($model:expr, $variant:ident) => {{
            let mut ims = Ims::new($model, closure, lo, hi, dt)
                .map_err(e)?
                .with_quadratic(quad)
                .map_err(e)?
                .with_slew(slew)
                .map_err(e)?;
            if let Some(c) = creep {
                ims = ims.with_creep(c);
            }
            Feedforward::$variant(ims)
        }};
    }
    Ok(match hy.model {
        HysteresisModel::Cbw | HysteresisModel::None => {
            let (a, b, g) = if hy.model == HysteresisModel::None {
                // d*u exactly: an IMS with a vanishing loop
                (1e-9, 1.0, 0.0)
            } else {
                (hy.alpha, hy.beta, hy.gamma)
            };
            build!(
                Cbw::new(hy.d as R, kk(a), kk(b), kk(g), hy.n as R).map_err(e)?,
                ImsCbw
            )
        }
        HysteresisModel::Gbw => build!(
            // alpha only scales A, B_h, B, G: scaling it too would scale the loop twice.
            Gbw::with_beta_h(
                hy.d as R,
                hy.alpha as R,
                kk(hy.a),
                kk(hy.beta_h),
                kk(hy.beta),
                kk(hy.gamma),
                hy.n as R
            )
            .map_err(e)?,
            ImsGbw
        ),
        HysteresisModel::Dahl => build!(
            Dahl::new(hy.d as R, kk(hy.alpha), kk(hy.hc), hy.n as R).map_err(e)?,
            ImsDahl
        ),
        HysteresisModel::Mbw002 => build!(
            Mbw002::new(
                AbwAbs::new(
                    hy.d as R,
                    kk(hy.alpha),
                    kk(hy.beta),
                    kk(hy.gamma),
                    hy.n as R,
                    kk(hy.delta)
                )
                .map_err(e)?,
                kk(hy.p),
                kk(hy.q)
            )
            .map_err(e)?,
            ImsMbw
        ),
    })
}

fn ims_solved<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        ims_axis(s, ImsLoop::Solved, NOMINAL, true)
    })?;
    Ok(controller(ff))
}

fn ims_delayed<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        ims_axis(s, ImsLoop::Delayed, NOMINAL, true)
    })?;
    Ok(controller(ff))
}

fn ims_off20<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let ff = per_axis_or_decoupled(s, OFF20, true, || ims_axis(s, ImsLoop::Solved, OFF20, true))?;
    Ok(controller(ff))
}

fn ims_bare<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let ff = per_axis_or_decoupled(s, NOMINAL, false, || {
        ims_axis(s, ImsLoop::Solved, NOMINAL, false)
    })?;
    Ok(controller(ff))
}

/// The stage's CBW; on a stage of another family the least-squares CBW of its loop
/// ([`super::models::fitted_cbw`], the CBW the feedback laws get there too).
fn stage_cbw(s: &StageInfo) -> Result<Cbw<f64>> {
    let hy = s.hysteresis();
    if hy.model == HysteresisModel::Cbw {
        return Cbw::new(hy.d, hy.alpha, hy.beta, hy.gamma, hy.n).map_err(e);
    }
    let (lo, hi) = s.volts_range();
    let (d, a, b, g, n) = super::models::fitted_cbw(hy, lo, hi)?;
    Cbw::new(d, a, b, g, n).map_err(e)
}

/// 002's compensator (eq. 8-12, `k_p = 1`) on the MBW that `piezo fit --model mbw002`
/// identifies from the scenario's open-loop record ([`identified`]), with the fit's output
/// offset.
fn mbw_no_inverse<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let f = identified(s, "mbw002")?;
    let p = f.values();
    anyhow::ensure!(
        f.sign > 0.0 && p.len() == 7,
        "the MBW fit of {} has the wrong orientation (sign {})",
        s.scenario.name,
        f.sign
    );
    // mbw002 fit parameters: d, alpha, beta, gamma/beta, delta/alpha, p, q (n = 1).
    let abw = AbwAbs::new(p[0], p[1], p[2], p[3] * p[2], 1.0, p[4] * p[1]).map_err(e)?;
    let mbw = Mbw002::new(abw, p[5], p[6]).map_err(e)?;
    let mbw = Mbw002::new(
        AbwAbs::new(
            abw.d() as R,
            abw.alpha() as R,
            abw.beta() as R,
            abw.gamma() as R,
            1.0,
            abw.delta() as R,
        )
        .map_err(e)?,
        mbw.p() as R,
        mbw.q() as R,
    )
    .map_err(e)?;
    let (lo, hi) = volts(s);
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        Ok(Feedforward::Mbw(
            MbwFf::new(mbw, 1.0, lo, hi, dt(s))
                .and_then(|c| c.with_offset(f.offset as R))
                .map_err(e)?,
        ))
    })?;
    Ok(controller(ff))
}

/// MBW (004 eq. 6) with the CBW loop's saturated slope `d`, half width `h_max` and slope
/// after a reversal `d - 2*alpha*beta/(beta+gamma)` (004 eq. 16: `k_w = lambda/mu`,
/// `b_w = (lambda - rho*mu)/(rho*mu*lambda)`; after a reversal from the band edge
/// `dw/du = rho/(2 - rho*mu/lambda)`); `c2` from the stage's quadratic term.
fn wpmbw<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let m = stage_cbw(s)?;
    let kw = m.d();
    let bw = m.h_bound();
    let rev = m.d() - m.max_h_slope();
    // rev = rho/(2 - rho/kw)  =>  rho = 2*rev*kw/(kw + rev)
    let rho = 2.0 * rev * kw / (kw + rev);
    // bw = (lambda - rho*mu)/(rho*mu*lambda) with lambda = kw*mu  =>  mu = (kw - rho)/(rho*kw*bw)
    let mu = (kw - rho) / (rho * kw * bw);
    let lambda = kw * mu;
    let c2 = s.hysteresis().asym_um_per_v2 / (kw * kw);
    let model = Wpmbw::new(
        MbwRlm::new(rho as R, lambda as R, mu as R).map_err(e)?,
        [1.0 as R, c2 as R],
    )
    .map_err(e)?;
    let res = &s.scenario.stage.resonance;
    let linear = res.enabled.then(|| {
        LinearPart::second_order(
            (2.0 * std::f64::consts::PI * res.freq_hz) as R,
            res.zeta as R,
        )
    });
    let (lo, hi) = volts(s);
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        Ok(Feedforward::Wpmbw(
            WpmbwInverse::new(
                &model,
                linear,
                Some((100.0 * std::f64::consts::PI) as R),
                lo,
                hi,
                dt(s),
            )
            .map_err(e)?,
        ))
    })?;
    Ok(controller(ff))
}

/// Operators of the PI fit.
const PI_OPS: usize = 12;

/// PI (001 eq. 4-5) fitted to the stage's static part by the Masing rule: a PI's branch
/// after a reversal is `2*phi(du/2)`, `phi` its loading curve, so
/// `phi(x) = R(2x)/2` with `R` the stage's descending major branch from the top. Slopes
/// of `phi` on `PI_OPS` equal intervals give `w0` and the weights.
fn pi_fit(s: &StageInfo) -> Result<(R, [R; PI_OPS], [R; PI_OPS])> {
    let hy = s.hysteresis();
    let (lo, hi) = s.volts_range();
    let m = stage_cbw(s)?;
    let q = hy.asym_um_per_v2;
    let y = |st: &mut BwState<f64>, u: f64| m.step(st, u, 1.0) + q * u * u;
    // Major loop: rise to the top twice, then sample the descent.
    let mut st = m.init(lo);
    for _ in 0..2 {
        for k in 0..=1000 {
            y(&mut st, lo + (hi - lo) * k as f64 / 1000.0);
        }
        for k in 0..=1000 {
            y(&mut st, hi - (hi - lo) * k as f64 / 1000.0);
        }
    }
    for k in 0..=1000 {
        y(&mut st, lo + (hi - lo) * k as f64 / 1000.0);
    }
    let top = y(&mut st, hi);
    let half = 0.5 * (hi - lo);
    let dx = half / PI_OPS as f64;
    // phi at the interval ends x_j = j*dx
    let mut phi = [0.0f64; PI_OPS + 1];
    let mut stc = st;
    for (j, p) in phi.iter_mut().enumerate().skip(1) {
        *p = 0.5 * (top - y(&mut stc, hi - 2.0 * dx * j as f64));
    }
    let slope = |j: usize| (phi[j + 1] - phi[j]) / dx;
    let w0 = slope(0);
    let mut w = [0.0 as R; PI_OPS];
    let mut r = [0.0 as R; PI_OPS];
    for j in 1..PI_OPS {
        w[j - 1] = (slope(j) - slope(j - 1)) as R;
        r[j - 1] = (dx * j as f64) as R;
    }
    // Last operator: a zero-weight placeholder past the fitted range.
    w[PI_OPS - 1] = 0.0;
    r[PI_OPS - 1] = (dx * PI_OPS as f64) as R;
    Ok((w0 as R, w, r))
}

fn pi_inverse<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let (w0, w, r) = pi_fit(s)?;
    let pi = Pi::new(w0, w, r).map_err(e)?;
    let (lo, hi) = volts(s);
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        Ok(Feedforward::PiInverse(
            PiInverse::new(&pi, lo, hi).map_err(e)?,
        ))
    })?;
    Ok(controller(ff))
}

fn ppi<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let (w0, w, r) = pi_fit(s)?;
    let m = Ppi::new(0.0, w0, w, r).map_err(e)?;
    let (lo, hi) = volts(s);
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        Ok(Feedforward::PpiInverse(
            ppi_inverse(&m, lo, hi, dt(s)).map_err(e)?,
        ))
    })?;
    Ok(controller(ff))
}

fn dpi<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let (w0, w, r) = pi_fit(s)?;
    // DPI's PI has no linear term: carry w0 on a 1 mV operator.
    let mut wd = [0.0 as R; PI_OPS];
    let mut rd = [0.0 as R; PI_OPS];
    wd[0] = w0;
    rd[0] = 1e-3;
    wd[1..].copy_from_slice(&w[..PI_OPS - 1]);
    rd[1..].copy_from_slice(&r[..PI_OPS - 1]);
    let m = Dpi::new(wd, rd, [1.0 as R], [0.0 as R]).map_err(e)?;
    let (lo, hi) = volts(s);
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        Ok(Feedforward::DpiInverse(
            DpiInverse::new(&m, lo, hi).map_err(e)?,
        ))
    })?;
    Ok(controller(ff))
}

fn multi_ims<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let m = stage_cbw(s)?;
    let c = coupling::<N>(s, NOMINAL).unwrap_or_else(|| {
        core::array::from_fn(|i| core::array::from_fn(|j| if i == j { 1.0 } else { 0.0 }))
    });
    let scaled = |x: f64| -> [[R; N]; N] {
        core::array::from_fn(|i| core::array::from_fn(|j| c[i][j] * x as R))
    };
    let model = MultiBw::new(
        scaled(m.d()),
        scaled(m.alpha()),
        scaled(m.beta()),
        scaled(m.gamma()),
    )
    .map_err(e)?;
    let (lo, hi) = volts(s);
    let ims = MultiIms::new(model, ImsLoop::Solved, lo, hi, dt(s)).map_err(e)?;
    Ok(controller(MultiFeedforward::Ims(ims)))
}
