//! Registry entries of the feedforward compensators (FEEDFORWARD engineer): every
//! compensator of `piezo_core::feedforward`, built from the stage's nominal parameters
//! (or 20 % off them), pipeline in `Mode::Feedforward`, no feedback.
//!
//! Only the IMS entries share the stage's model structure (hysteresis family, static
//! quadratic, creep, coupling). `mbw`, `wpmbw`, `pi-inverse`, `ppi-inverse` and
//! `dpi-inverse` run on the model `piezo fit` identifies from the stage's open-loop record
//! ([`identified`]), with the fit's output offset, i.e. with a structure mismatch a user
//! would have too; `multi-ims` runs on 003's multivariable Bouc-Wen identified the same
//! way from the record of every axis (`piezo fit --model cbw`).

use super::identified::{identified, identified_multibw, open_loop_record};
use super::{Controller, Entry, R};
use crate::ident::fit::{models as fit_models, Fitted};
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
        entry!(Wpmbw, "004 direct WPMBW inverse + inverse resonance + prefilter; WPMBW identified by piezo fit from the open-loop record (linear if not invertible), resonance the stage's", wpmbw),
        entry!(PiInverse, "exact PI inverse; PI identified by piezo fit from the open-loop record (linear if not invertible)", pi_inverse),
        entry!(PpiInverse, "PPI inverse by bounded solve; PPI identified by piezo fit from the open-loop record (c1 < 0 taken as 0; linear if not invertible)", ppi),
        entry!(DpiInverse, "exact DPI inverse; DPI identified by piezo fit from the open-loop record (linear if not invertible)", dpi),
        entry!(MultiIms, "multivariable IMS U = D^+(y+h) (003 eq. 16); D, A, B, Gamma identified by piezo fit --model cbw from the open-loop record of every axis (003 sec. IV)", multi_ims),
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

/// The fit `piezo fit --model name` makes of the scenario's open-loop record
/// ([`identified`]) and its parameter vector, checked for the stage's orientation (`y`
/// rising with `u`) and for the vector's length.
fn fit_of(s: &StageInfo, name: &str, len: usize) -> Result<(Fitted, Vec<f64>)> {
    let f = identified(s, name)?;
    let p = f.values();
    anyhow::ensure!(
        f.sign > 0.0 && p.len() == len,
        "the {name} fit of {} has the wrong orientation (sign {}) or shape ({} parameters)",
        s.scenario.name,
        f.sign,
        p.len()
    );
    Ok((f, p))
}

/// The compensator `built`, or, when the identified model cannot be inverted (a record that
/// does not excite the stage, e.g. a hold, or a fit outside the inverse's conditions), the
/// linear feedforward of the calibrated stage, said on stderr.
fn or_linear<const N: usize>(
    s: &StageInfo,
    name: &str,
    built: Result<Controller<N>>,
) -> Result<Controller<N>> {
    built.or_else(|err| {
        eprintln!(
            "{name} on {}: {err:#}; running the linear feedforward instead",
            s.scenario.name
        );
        Ok(controller(MultiFeedforward::PerAxis(super::linear_ff(s))))
    })
}

fn r_array<const K: usize>(a: &[f64; K]) -> [R; K] {
    a.map(|x| x as R)
}

/// 004's direct inverse (eq. 17-18, 27-28) of the WPMBW (`L = 3`) that `piezo fit --model
/// wpmbw` identifies from the scenario's open-loop record ([`identified`]); the inverse
/// resonance is the stage's (the open-loop record, slow, does not excite it).
fn wpmbw<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    or_linear(s, "wpmbw", wpmbw_identified(s))
}

fn wpmbw_identified<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let (_, p) = fit_of(s, "wpmbw", 7)?;
    let m = fit_models::wpmbw(&p).map_err(e)?;
    let rlm = m.mbw();
    let model = Wpmbw::new(
        MbwRlm::new(rlm.rho() as R, rlm.lambda() as R, rlm.mu() as R).map_err(e)?,
        r_array(m.coefficients()),
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

/// Parameters of the `pi` fit: `w0`, the weights, the fixed `u_range`.
const PI_LEN: usize = fit_models::PI_OPERATORS + 2;

/// Exact inverse (Kuhnen) of the PI that `piezo fit --model pi` identifies from the
/// scenario's open-loop record.
fn pi_inverse<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    or_linear(s, "pi-inverse", pi_inverse_identified(s))
}

fn pi_inverse_identified<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let (f, p) = fit_of(s, "pi", PI_LEN)?;
    let m = fit_models::pi(&p).map_err(e)?;
    let pi = Pi::new(m.w0() as R, r_array(m.weights()), r_array(m.thresholds())).map_err(e)?;
    let (lo, hi) = volts(s);
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        Ok(Feedforward::PiInverse(
            PiInverse::new(&pi, lo, hi)
                .and_then(|c| c.with_offset(f.offset as R))
                .map_err(e)?,
        ))
    })?;
    Ok(controller(ff))
}

/// Inverse by bounded solve of the PPI (cubic `c1*u^3 + c2*u` and PI) that `piezo fit
/// --model ppi` identifies from the scenario's open-loop record. The inverse needs
/// `c1 >= 0` (`y` increasing for every `u`); a negative fitted `c1` is taken as 0.
fn ppi<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    or_linear(s, "ppi-inverse", ppi_identified(s))
}

fn ppi_identified<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let (fit, p) = fit_of(s, "ppi", PI_LEN + 1)?;
    let f = fit_models::ppi(&p).map_err(e)?;
    let m = Ppi::new(
        f.c1().max(0.0) as R,
        f.c2() as R,
        r_array(f.pi().weights()),
        r_array(f.pi().thresholds()),
    )
    .map_err(e)?;
    let (lo, hi) = volts(s);
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        Ok(Feedforward::PpiInverse(
            ppi_inverse(&m, lo, hi, dt(s))
                .and_then(|c| c.with_offset(fit.offset as R))
                .map_err(e)?,
        ))
    })?;
    Ok(controller(ff))
}

/// Exact inverse of the DPI (PI, then three one-sided dead zones) that `piezo fit --model
/// dpi` identifies from the scenario's open-loop record.
///
/// The fit may land on the mirrored form the inverse refuses: a decreasing PI `P` behind a
/// negative first (linear) dead-zone weight `ws_1`. When `P` stays below the second dead
/// zone all over that record, the fitted model there is `ws_1*P`, so the compensator
/// inverts the same model written invertibly: the PI `ws_1*P` behind the dead zones
/// `[1, 0, 0]` (same thresholds). Otherwise the fit is refused.
fn dpi<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    or_linear(s, "dpi-inverse", dpi_identified(s))
}

fn dpi_identified<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let (fit, p) = fit_of(
        s,
        "dpi",
        fit_models::PI_OPERATORS + fit_models::DPI_DEAD_ZONES + 2,
    )?;
    let f = fit_models::dpi(&p).map_err(e)?;
    let (lo, hi) = volts(s);
    let build = |w: [f64; fit_models::PI_OPERATORS], ws: [f64; fit_models::DPI_DEAD_ZONES]| {
        Dpi::new(
            w.map(|x| x as R),
            r_array(f.pi().thresholds()),
            ws.map(|x| x as R),
            r_array(f.dead_zone_thresholds()),
        )
        .and_then(|m| DpiInverse::new(&m, lo, hi))
        .and_then(|c| c.with_offset(fit.offset as R))
        .map_err(e)
    };
    let inverse = match build(*f.pi().weights(), *f.dead_zone_weights()) {
        Ok(c) => c,
        Err(refused) => {
            let ws1 = f.dead_zone_weights()[0];
            let rec = open_loop_record(s)?;
            let mut pi_out = vec![0.0; rec.u[0].len()];
            fit_models::run(f.pi(), &rec.u[0], rec.dt(), &mut pi_out);
            let p_max = pi_out.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let d2 = f.dead_zone_thresholds()[1];
            anyhow::ensure!(
                ws1 < 0.0 && p_max < d2,
                "the identified DPI of {} is not invertible ({refused}) and not its mirror \
                 (ws_1 {ws1}, PI output up to {p_max} against the second dead zone at {d2})",
                s.scenario.name
            );
            let mut ws = [0.0; fit_models::DPI_DEAD_ZONES];
            ws[0] = 1.0;
            build(f.pi().weights().map(|w| ws1 * w), ws)?
        }
    };
    let ff = per_axis_or_decoupled(s, NOMINAL, true, || {
        Ok(Feedforward::DpiInverse(inverse.clone()))
    })?;
    Ok(controller(ff))
}

/// 003's multivariable IMS (eq. 16-19) on the model `piezo fit --model cbw` identifies
/// from the scenario's open-loop record of every axis, with the fit's output offsets: on one
/// axis the CBW (003's step 1 alone), on two the multivariable Bouc-Wen of 003 sec. IV
/// ([`identified_multibw`]). Linear feedforward if the fit fails or does not invert.
fn multi_ims<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    or_linear(s, "multi-ims", multi_ims_identified(s))
}

fn multi_ims_identified<const N: usize>(s: &StageInfo) -> Result<Controller<N>> {
    let to_r = |m: &[Vec<f64>]| -> [[R; N]; N] {
        core::array::from_fn(|i| core::array::from_fn(|j| m[i][j] as R))
    };
    let (d, a, b, g, offset) = if N == 1 {
        let f = identified(s, "cbw")?;
        let p = f.values(); // d, alpha, beta, gamma/beta
        anyhow::ensure!(
            f.sign > 0.0 && p.len() == 4,
            "the CBW fit of {} has the wrong orientation (sign {})",
            s.scenario.name,
            f.sign
        );
        let one = |x: f64| vec![vec![x]];
        (
            one(p[0]),
            one(p[1]),
            one(p[2]),
            one(p[3] * p[2]),
            vec![f.offset],
        )
    } else {
        let f = identified_multibw(s)?;
        anyhow::ensure!(
            f.outputs == N && f.inputs == N,
            "the multivariable fit of {} is {} x {}, the scenario has {N} axes",
            s.scenario.name,
            f.outputs,
            f.inputs
        );
        (f.d, f.a, f.b, f.gamma, f.offset)
    };
    let model = MultiBw::new(to_r(&d), to_r(&a), to_r(&b), to_r(&g)).map_err(e)?;
    let (lo, hi) = volts(s);
    let ims = MultiIms::new(model, ImsLoop::Solved, lo, hi, dt(s))
        .and_then(|m| m.with_offset(core::array::from_fn(|i| offset[i] as R)))
        .map_err(e)?;
    Ok(controller(MultiFeedforward::Ims(ims)))
}
