//! `piezo serial load-fit`: the CBW model of a `piezo fit` report to the firmware.
use std::io::Write;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use piezo_core::command::Command;

use crate::serial::{Client, SerialError};

use super::units::f32_of;

/// Reads the report's CBW model and sends it as one `cbw <d> <alpha> <beta> <gamma>` line
/// (checked and installed as a whole by the firmware).
pub fn run(c: &mut Client, fit: &Path, out: &mut impl Write) -> Result<()> {
    let m = read_fit_cbw(fit)?;
    let [d, alpha, beta, gamma] = m.params;
    writeln!(
        out,
        "{}: CBW of parts[{}]: d {d} um/V, alpha {alpha} um/V, beta {beta} 1/V, gamma {gamma} 1/V",
        fit.display(),
        m.part
    )?;
    let r = c
        .send(&Command::Cbw(m.params.map(f32_of)))
        .map_err(|e| match e {
            e @ SerialError::Firmware { .. } => anyhow!(
                "{}: the firmware refused the CBW model of parts[{}]: {e} (the core \
             accepts alpha > 0, beta >= |gamma| (004 eq. 3) and, for IMS, d above \
             the largest hysteresis slope over 0..150 V, alpha + (beta - gamma) * \
             min(alpha/(beta + gamma), alpha * 150 V))",
                fit.display(),
                m.part
            ),
            other => other.into(),
        })?;
    writeln!(out, "{}", r.reply_line())?;
    if m.offset_um != 0.0 {
        writeln!(
            out,
            "note: the fit's output offset {} um is not sent (the firmware's CBW has \
             none; the sensor reads the stage's own zero)",
            m.offset_um
        )?;
    }
    Ok(())
}

/// The CBW model of a `piezo fit` report, in the firmware's units.
#[derive(Debug, Clone, PartialEq)]
pub struct FitCbw {
    /// Index into the report's `parts`.
    pub part: usize,
    /// `d`, `alpha` (um/V), `beta`, `gamma` (1/V).
    pub params: [f64; 4],
    /// The fit's output offset (um), which the firmware's model does not have.
    pub offset_um: f64,
}

/// Reads the first CBW part (`siso` or `direct`) of the `fit.json` that `piezo fit --model
/// cbw` writes; the fit's `gamma/beta` becomes `gamma`. Errors name the file and the key.
pub fn read_fit_cbw(path: &Path) -> Result<FitCbw> {
    let p = path.display();
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {p}"))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{p}: not JSON (expected the fit.json of `piezo fit`)"))?;
    let parts = v
        .get("parts")
        .and_then(|x| x.as_array())
        .with_context(|| format!("{p}: no `parts` array (not a `piezo fit` report)"))?;
    let mut models = Vec::new();
    for (i, part) in parts.iter().enumerate() {
        let model = part
            .pointer("/fit/model")
            .and_then(|m| m.as_str())
            .with_context(|| format!("{p}: parts[{i}] has no `fit.model`"))?;
        let kind = part.get("kind").and_then(|k| k.as_str()).unwrap_or("siso");
        if model == "cbw" && kind != "coupling" {
            return cbw_of_part(path, i, part);
        }
        models.push(format!("{model} ({kind})"));
    }
    bail!(
        "{p}: no CBW fit in `parts` (found: {}); identify one with `piezo fit --model cbw`",
        if models.is_empty() {
            "none".to_string()
        } else {
            models.join(", ")
        }
    )
}

fn cbw_of_part(path: &Path, i: usize, part: &serde_json::Value) -> Result<FitCbw> {
    let p = path.display();
    let params = part
        .pointer("/fit/params")
        .and_then(|x| x.as_array())
        .with_context(|| format!("{p}: parts[{i}].fit.params is missing or not a list"))?;
    let key = |name: &str| -> Result<f64> {
        let v = params
            .iter()
            .find(|kv| kv.get(0).and_then(|k| k.as_str()) == Some(name))
            .with_context(|| format!("{p}: parts[{i}].fit.params lacks `{name}`"))?;
        v.get(1)
            .and_then(|x| x.as_f64())
            .filter(|x| x.is_finite())
            .with_context(|| format!("{p}: parts[{i}].fit.params `{name}` is not a finite number"))
    };
    let num = |ptr: &str, default: f64| -> Result<f64> {
        match part.pointer(ptr) {
            None => Ok(default),
            Some(x) => x.as_f64().filter(|x| x.is_finite()).with_context(|| {
                format!(
                    "{p}: parts[{i}]{} is not a finite number",
                    ptr.replace('/', ".")
                )
            }),
        }
    };
    let sign = num("/fit/sign", 1.0)?;
    if sign != 1.0 {
        bail!(
            "{p}: parts[{i}].fit.sign is {sign}: the fit mirrors the model (y falls as u rises); \
             the firmware's CBW needs y rising with u"
        );
    }
    let beta = key("beta")?;
    Ok(FitCbw {
        part: i,
        params: [key("d")?, key("alpha")?, beta, key("gamma/beta")? * beta],
        offset_um: num("/fit/offset", 0.0)?,
    })
}
