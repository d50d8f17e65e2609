//! The manipulation scenarios of `piezo sim` (000 Part V): the object characterisation and
//! BLF force control on the stage pushing an object ([`crate::object`]), and the beam
//! observers ([`crate::beam`]); their table rows and plots.
use std::path::Path;

use anyhow::Result;
use serde::Serialize;

use crate::beam::{est_errors, run_beam, BeamConfig, BEAM_CONDITIONS};
use crate::numeric::rms;
use crate::object::{
    blf_errors, blf_force, force_errors, identify, indentation, BlfConfig, ManipConfig, Object,
    ObjectFit, Traces,
};
use crate::plot::{write_grid, Plot};

/// One row of the scenario table (same leading fields as `piezo sim`).
#[derive(Debug, Clone, Serialize)]
pub struct ManipRow {
    pub scenario: String,
    pub controller: String,
    pub rmse_um: f64,
    pub rmse_pct: f64,
    pub max_err_pct: f64,
    pub saturated_samples: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub force_err_rms_mn: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub force_err_max_mn: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub force_peak_mn: Option<f64>,
    /// BLF: largest `|F_fed_back - F_d|` (the error the barrier acts on), mN.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub force_fb_err_max_mn: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kb_mn: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub identified: Option<ObjectFit>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<Object>,
}

impl ManipRow {
    /// One line in the `piezo sim` table layout, extra fields at the end.
    pub fn table_line(&self) -> String {
        let mut extra = String::new();
        if let (Some(r), Some(m)) = (self.force_err_rms_mn, self.force_err_max_mn) {
            extra += &format!("  force err rms {r:.2} mN max {m:.2} mN");
        }
        if let Some(fb) = self.force_fb_err_max_mn {
            extra += &format!(", fed-back max {fb:.2} mN");
        }
        if let Some(kb) = self.kb_mn {
            extra += &format!(" (k_b {kb} mN)");
        }
        if let (Some(f), Some(t)) = (self.identified, self.truth) {
            extra += &format!(
                "  k1 {:.2}/{} k3 {:.3}/{} c {:.4}/{} gap {:.3}/{}",
                f.k1, t.k1, f.k3, t.k3, f.c, t.c, f.gap_um, t.gap_um
            );
        }
        format!(
            "{:<16} {:<22} {:>10.4} {:>9.3} {:>11.3} {:>10} {:>7}{extra}",
            self.scenario,
            self.controller,
            self.rmse_um,
            self.rmse_pct,
            self.max_err_pct,
            self.saturated_samples,
            0
        )
    }

    pub fn new(scenario: &str, controller: &str) -> Self {
        Self {
            scenario: scenario.into(),
            controller: controller.into(),
            rmse_um: f64::NAN,
            rmse_pct: f64::NAN,
            max_err_pct: f64::NAN,
            saturated_samples: 0,
            force_err_rms_mn: None,
            force_err_max_mn: None,
            force_peak_mn: None,
            force_fb_err_max_mn: None,
            kb_mn: None,
            identified: None,
            truth: None,
        }
    }
}

/// Names of the manipulation scenarios of `piezo sim` (000 Part V).
pub const SCENARIOS: [&str; 4] = [
    "object-characterisation",
    "blf-force",
    "beam",
    "beam-conditions",
];

/// Runs the named manipulation scenarios (all of [`SCENARIOS`] if `names` is empty); plots
/// go into `out` when given.
pub fn run_manipulation(names: &[String], out: Option<&Path>) -> Result<Vec<ManipRow>> {
    for n in names {
        anyhow::ensure!(
            SCENARIOS.contains(&n.as_str()),
            "no manipulation scenario {n} (known: {})",
            SCENARIOS.join(", ")
        );
    }
    let want = |n: &str| names.is_empty() || names.iter().any(|x| x == n);
    let cfg = ManipConfig::default();
    let mut rows = Vec::new();
    if want(SCENARIOS[0]) {
        rows.extend(characterisation_scenario(&cfg, out)?);
    }
    if want(SCENARIOS[1]) {
        rows.extend(blf_scenario(&cfg, out)?);
    }
    if want(SCENARIOS[2]) {
        rows.extend(beam_scenario(&BeamConfig::default(), out)?);
    }
    if want(SCENARIOS[3]) {
        rows.extend(beam_conditions_scenario(&BeamConfig::default())?);
    }
    Ok(rows)
}

/// Force estimation + characterisation: one row, plots into `out`.
pub fn characterisation_scenario(cfg: &ManipConfig, out: Option<&Path>) -> Result<Vec<ManipRow>> {
    let mut rows = Vec::new();
    let skip = (0.05 * cfg.rate_hz) as usize;
    // 1 + 2 + 3: indentation, force estimation, identification.
    let tr = indentation(cfg, 2.0)?;
    let (f_rms, f_max, f_peak) = force_errors(&tr, skip);
    let (rmse, rmse_pct, max_pct) = tracking(&tr, (0.4 * cfg.rate_hz) as usize);
    let fit = identify(&tr, cfg.observer_hz, cfg.rate_hz, skip)?;
    let mut row = ManipRow::new("object-characterisation", "pi+force-eso");
    row.rmse_um = rmse;
    row.rmse_pct = rmse_pct;
    row.max_err_pct = max_pct;
    row.saturated_samples = tr.saturated;
    row.force_err_rms_mn = Some(f_rms);
    row.force_err_max_mn = Some(f_max);
    row.force_peak_mn = Some(f_peak);
    row.identified = Some(fit);
    row.truth = Some(cfg.plant.object);
    rows.push(row);
    let o = cfg.plant.object;
    let dgrid: Vec<f64> = (0..=100)
        .map(|i| o.gap_um + 3.6 * i as f64 / 100.0)
        .collect();
    let curve = |g: f64, k1: f64, k3: f64| -> Vec<f64> {
        dgrid
            .iter()
            .map(|y| {
                let d = (y - g).max(0.0);
                k1 * d + k3 * d * d * d
            })
            .collect()
    };
    let plots = vec![
        Plot::new("indentation: force (no force sensor)", "t [s]", "F [mN]")
            .line("true F", &tr.t, &tr.force)
            .line("ESO estimate", &tr.t, &tr.force_hat),
        Plot::new("force-deformation curve", "y [um]", "F [mN]")
            .points(
                "estimate vs measured y",
                &tr.y_meas[skip..],
                &tr.force_hat[skip..],
            )
            .line("true static psi", &dgrid, &curve(o.gap_um, o.k1, o.k3))
            .line(
                "identified static psi",
                &dgrid,
                &curve(fit.gap_um, fit.k1, fit.k3),
            ),
        Plot::new("position tracking", "t [s]", "y [um]")
            .line("reference", &tr.t, &tr.y_ref)
            .line("y", &tr.t, &tr.y),
        Plot::new("force estimation error", "t [s]", "F^ - F [mN]").line(
            "error",
            &tr.t[skip..],
            &tr.force_hat[skip..]
                .iter()
                .zip(&tr.force[skip..])
                .map(|(h, f)| h - f)
                .collect::<Vec<_>>(),
        ),
    ];
    if let Some(out) = out {
        write_grid(out.join("object_characterisation.svg"), &plots, 2)?;
    }
    Ok(rows)
}

/// BLF force control with the force sensor and with the ESO estimate: two rows.
pub fn blf_scenario(cfg: &ManipConfig, out: Option<&Path>) -> Result<Vec<ManipRow>> {
    let mut rows = Vec::new();
    let bcfg = BlfConfig::default();
    let mut plots = Vec::new();
    // The same law without a barrier (k_b huge: factor ~ 1) is the baseline.
    let variants = [
        (false, bcfg, "blf+force-sensor"),
        (true, bcfg, "blf+force-eso"),
        (
            false,
            BlfConfig { kb_mn: 1e6, ..bcfg },
            "no-barrier+force-sensor",
        ),
    ];
    for (estimated, bcfg, name) in variants {
        let tr = blf_force(cfg, &bcfg, estimated, 1.5)?;
        let (max_true, max_fb, rms_true) = blf_errors(&tr);
        let mut row = ManipRow::new("blf-force", name);
        let fr: Vec<f64> = tr
            .force_ref
            .iter()
            .copied()
            .filter(|f| f.is_finite())
            .collect();
        let span = fr.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - fr.iter().copied().fold(f64::INFINITY, f64::min);
        row.saturated_samples = tr.saturated;
        row.force_err_rms_mn = Some(rms_true);
        row.force_err_max_mn = Some(max_true);
        row.kb_mn = (bcfg.kb_mn < 1e3).then_some(bcfg.kb_mn);
        row.force_fb_err_max_mn = Some(max_fb);
        row.rmse_pct = 100.0 * rms_true / span.max(1e-12);
        row.max_err_pct = 100.0 * max_true / span.max(1e-12);
        rows.push(row);
        let e_fb: Vec<f64> = tr
            .force_hat
            .iter()
            .zip(&tr.force_ref)
            .map(|(f, r)| f - r)
            .collect();
        let e_true: Vec<f64> = tr
            .force
            .iter()
            .zip(&tr.force_ref)
            .map(|(f, r)| f - r)
            .collect();
        // The baseline is drawn against the BLF's bound.
        let kb_line = if bcfg.kb_mn < 1e3 {
            bcfg.kb_mn
        } else {
            BlfConfig::default().kb_mn
        };
        let kb = vec![kb_line; tr.t.len()];
        let nkb = vec![-kb_line; tr.t.len()];
        plots.push(
            Plot::new(&format!("{name}: force"), "t [s]", "F [mN]")
                .line("F_d", &tr.t, &tr.force_ref)
                .line("true F", &tr.t, &tr.force)
                .line("fed back", &tr.t, &tr.force_hat),
        );
        plots.push(
            Plot::new(&format!("{name}: force error"), "t [s]", "e_F [mN]")
                .line("fed back - F_d", &tr.t, &e_fb)
                .line("true F - F_d", &tr.t, &e_true)
                .line("+k_b", &tr.t, &kb)
                .line("-k_b", &tr.t, &nkb),
        );
    }
    if let Some(out) = out {
        write_grid(out.join("blf_force.svg"), &plots, 2)?;
    }
    Ok(rows)
}

/// The beam scenario (with and without CBW mismatch): six rows, plots into `out`.
pub fn beam_scenario(cfg: &BeamConfig, out: Option<&Path>) -> Result<Vec<ManipRow>> {
    let mut rows = Vec::new();
    let mut plots = Vec::new();
    for mismatch in [true, false] {
        let c = BeamConfig { mismatch, ..*cfg };
        let run = run_beam(&c)?;
        let tag = if mismatch {
            "beam-x0.5-cbw-mismatch"
        } else {
            "beam-x0.5-cbw-exact"
        };
        let r = &run.y_c[run.skip..];
        let range = r.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - r.iter().copied().fold(f64::INFINITY, f64::min);
        for (name, est) in [
            ("hgo", &run.hgo),
            ("nno", &run.nno),
            ("luenberger(nno,eta=0)", &run.luenberger),
        ] {
            let (rms, max) = est_errors(&run, est);
            let mut row = ManipRow::new(tag, name);
            row.rmse_um = rms;
            row.rmse_pct = 100.0 * rms / range.max(1e-12);
            row.max_err_pct = 100.0 * max / range.max(1e-12);
            rows.push(row);
        }
        let s = run.skip;
        let err = |e: &[f64]| -> Vec<f64> {
            e[s..]
                .iter()
                .zip(&run.y_c[s..])
                .map(|(a, b)| a - b)
                .collect()
        };
        plots.push(
            Plot::new(&format!("{tag}: y(x_c)"), "t [s]", "y [um]")
                .line("true y(x_c)", &run.t, &run.y_c)
                .line("HGO", &run.t, &run.hgo)
                .line("NNO", &run.t, &run.nno),
        );
        plots.push(
            Plot::new(&format!("{tag}: estimation error"), "t [s]", "error [um]")
                .line("HGO", &run.t[s..], &err(&run.hgo))
                .line("NNO", &run.t[s..], &err(&run.nno))
                .line("Luenberger (no NN)", &run.t[s..], &err(&run.luenberger)),
        );
    }
    if let Some(out) = out {
        write_grid(out.join("beam_observers.svg"), &plots, 2)?;
    }
    Ok(rows)
}

/// The HGO against the NNO under the conditions the seed's comparison may have had (000
/// Part V; [`BEAM_CONDITIONS`]), each observer at its best of the same sweep: three rows
/// per condition (HGO, NNO, NNO without learning), the observer settings in the name.
pub fn beam_conditions_scenario(cfg: &BeamConfig) -> Result<Vec<ManipRow>> {
    let mut rows = Vec::new();
    // The range of y(x_c) after the warm-up (the same input in every run): the % columns.
    let run = run_beam(cfg)?;
    let r = &run.y_c[run.skip..];
    let range = r.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - r.iter().copied().fold(f64::INFINITY, f64::min);
    for cond in BEAM_CONDITIONS {
        let best = crate::beam::best_of_sweep(&cond.apply(cfg))?;
        let tag = format!("beam-{}", cond.name);
        for (name, rms) in [
            (format!("hgo@{}Hz", best.hgo_hz), best.hgo_um),
            (
                format!("nno@{}Hz,eta={}", best.nno_hz, best.nno_eta),
                best.nno_um,
            ),
            (format!("luenberger@{}Hz", best.nno_hz), best.luenberger_um),
        ] {
            let mut row = ManipRow::new(&tag, &name);
            row.rmse_um = rms;
            row.rmse_pct = 100.0 * rms / range.max(1e-12);
            rows.push(row);
        }
    }
    Ok(rows)
}

/// Position tracking errors: (rmse um, rmse %, max %) of the range of the reference.
fn tracking(tr: &Traces, skip: usize) -> (f64, f64, f64) {
    let r = &tr.y_ref[skip..];
    let lo = r.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = r.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let range = (hi - lo).max(1e-12);
    let e = || tr.y[skip..].iter().zip(r).map(|(y, r)| y - r);
    let rmse = rms(e());
    let max = e().map(f64::abs).fold(0.0, f64::max);
    (rmse, 100.0 * rmse / range, 100.0 * max / range)
}
