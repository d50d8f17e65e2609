//! `piezo serial load-fit`: the CBW model of a `piezo fit` report to the firmware. The
//! report's `input_unit` and `output_unit` are checked: a model in nm, mm, m or per mV is
//! converted to the firmware's um and V ([`firmware_units`]), an unknown unit refused; a
//! report without units (older `piezo fit`) is taken as um and V, with a note.
use std::io::Write;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use piezo_core::command::Command;

use crate::serial::{Client, SerialError};

use super::units::f32_of;
use crate::record::Quantity;

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
    if let Some(note) = &m.units_note {
        writeln!(out, "note: {note}")?;
    }
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
    /// How the report's units became the firmware's (converted, or assumed for a report
    /// that names none); `None` when they were um and V already.
    pub units_note: Option<String>,
}

/// A CBW model (`d`, `alpha`, `beta`, `gamma` and the offset) in `output_unit` and
/// `input_unit`, in the firmware's um and V. `y = d*u - h` with
/// `h' = alpha*u' - beta*|u'|*h - gamma*u'*|h|` (000 eq. 1-2, n = 1) is linear in `y` and
/// `h` and homogeneous of degree 0 in time: `y_um = c_y*y` scales `d`, `alpha` and the
/// offset by `c_y`; `u = u_V/c_u` scales `d`, `alpha`, `beta` and `gamma` by `1/c_u`.
/// Units the record reader does not know (or of another quantity) are refused: a model is
/// converted or not sent, never sent off by a factor of 10^3.
pub fn firmware_units(
    params: [f64; 4],
    offset: f64,
    input_unit: &str,
    output_unit: &str,
) -> std::result::Result<([f64; 4], f64), String> {
    let c_y = Quantity::Length
        .factor(output_unit)
        .map_err(|e| format!("output unit: {e}"))?;
    let c_u = Quantity::Voltage
        .factor(input_unit)
        .map_err(|e| format!("input unit: {e}"))?;
    let [d, alpha, beta, gamma] = params;
    Ok((
        [c_y * d / c_u, c_y * alpha / c_u, beta / c_u, gamma / c_u],
        c_y * offset,
    ))
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
            return in_firmware_units(path, &v, cbw_of_part(path, i, part)?);
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

/// The model of `fit` (read in the report's units) in um and V; a report without units
/// (written before `piezo fit` recorded them) is taken as um and V, and says so.
fn in_firmware_units(path: &Path, report: &serde_json::Value, fit: FitCbw) -> Result<FitCbw> {
    let p = path.display();
    let unit = |key: &str, internal: &'static str| -> Result<(String, bool)> {
        match report.get(key) {
            None | Some(serde_json::Value::Null) => Ok((internal.to_string(), false)),
            Some(v) => v
                .as_str()
                .map(|s| (s.trim().to_string(), true))
                .with_context(|| format!("{p}: `{key}` is not a unit name")),
        }
    };
    let (input, has_input) = unit("input_unit", Quantity::Voltage.internal())?;
    let (output, has_output) = unit("output_unit", Quantity::Length.internal())?;
    let (params, offset_um) =
        firmware_units(fit.params, fit.offset_um, &input, &output).map_err(|e| {
            anyhow!("{p}: the model's {e}; the firmware's CBW is in um and V, and nothing was sent")
        })?;
    let same = |unit: &str, q: Quantity| q.factor(unit) == Ok(1.0);
    let units_note = if !(has_input && has_output) {
        Some(format!(
            "{p} names no {} (a report written before `piezo fit` recorded units): taken as \
             {output} and {input}",
            match (has_input, has_output) {
                (false, false) => "units",
                (false, true) => "input unit",
                _ => "output unit",
            }
        ))
    } else if same(&output, Quantity::Length) && same(&input, Quantity::Voltage) {
        None
    } else {
        Some(format!(
            "{p}: the model in {output} and {input} was converted to um and V"
        ))
    };
    Ok(FitCbw {
        params,
        offset_um,
        units_note,
        ..fit
    })
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
        units_note: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 4], b: [f64; 4]) -> bool {
        a.iter()
            .zip(&b)
            .all(|(x, y)| (x - y).abs() <= 1e-12 * y.abs().max(1.0))
    }

    #[test]
    fn models_in_other_units_are_converted_to_um_and_volts() {
        let um = [0.21, 0.06, 0.005, 0.002];
        let (p, off) = firmware_units(um, -0.5, "V", "um").unwrap();
        assert_eq!((p, off), (um, -0.5));
        // The same stage identified in nm: d and alpha 1000 times larger, beta and gamma
        // (1/V) the same.
        let (p, off) = firmware_units([210.0, 60.0, 0.005, 0.002], -500.0, "V", "nm").unwrap();
        assert!(close(p, um) && (off + 0.5).abs() < 1e-12, "{p:?} {off}");
        let (p, _) = firmware_units([0.21e-6, 0.06e-6, 0.005, 0.002], 0.0, "V", "m").unwrap();
        assert!(close(p, um), "{p:?}");
        // Per mV: every parameter per volt is 1000 times the one per millivolt.
        let (p, _) = firmware_units([0.21e-3, 0.06e-3, 5e-6, 2e-6], 0.0, "mV", "µm").unwrap();
        assert!(close(p, um), "{p:?}");
    }

    #[test]
    fn unknown_units_are_refused() {
        let m = [0.21, 0.06, 0.005, 0.002];
        let e = firmware_units(m, 0.0, "V", "furlong").unwrap_err();
        assert!(
            e.contains("output unit: unknown length unit `furlong`"),
            "{e}"
        );
        let e = firmware_units(m, 0.0, "N", "um").unwrap_err();
        assert!(e.contains("input unit: unknown voltage unit `N`"), "{e}");
        let e = firmware_units(m, 0.0, "V", "s").unwrap_err();
        assert!(e.contains("`s` is a time unit"), "{e}");
    }

    /// A one-part CBW report as `piezo fit --model cbw` writes it, with `units` merged in.
    fn report(name: &str, params: [f64; 4], units: serde_json::Value) -> std::path::PathBuf {
        let mut v = serde_json::json!({
            "model": "cbw",
            "parts": [{"kind": "siso", "input": 0, "output": 0, "fit": {"model": "cbw",
                "params": [["d", params[0]], ["alpha", params[1]], ["beta", params[2]],
                           ["gamma/beta", params[3]]],
                "sign": 1.0, "offset": -500.0, "upsample": 1, "linear": []}}]
        });
        for (k, u) in units.as_object().unwrap() {
            v[k] = u.clone();
        }
        let dir = std::env::temp_dir().join(format!("load_fit_units_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, v.to_string()).unwrap();
        path
    }

    #[test]
    fn a_report_in_nm_is_read_in_um() {
        let nm = report(
            "nm.json",
            [210.0, 60.0, 0.005, 0.4],
            serde_json::json!({"input_unit": "V", "output_unit": "nm"}),
        );
        let m = read_fit_cbw(&nm).unwrap();
        assert!(
            close(m.params, [0.21, 0.06, 0.005, 0.002]),
            "{:?}",
            m.params
        );
        assert!((m.offset_um + 0.5).abs() < 1e-12);
        assert!(m
            .units_note
            .unwrap()
            .contains("in nm and V was converted to um and V"));
        // Already in the firmware's units: nothing to say.
        let um = report(
            "um.json",
            [0.21, 0.06, 0.005, 0.4],
            serde_json::json!({"input_unit": "V", "output_unit": "um"}),
        );
        assert_eq!(read_fit_cbw(&um).unwrap().units_note, None);
        // Reports from before units were recorded: um and V, said.
        let old = report("old.json", [0.21, 0.06, 0.005, 0.4], serde_json::json!({}));
        let m = read_fit_cbw(&old).unwrap();
        assert_eq!(m.params, [0.21, 0.06, 0.005, 0.002]);
        assert!(m.units_note.unwrap().contains("names no units"));
        let bad = report(
            "ft.json",
            [0.21, 0.06, 0.005, 0.4],
            serde_json::json!({"input_unit": "V", "output_unit": "ft"}),
        );
        let e = format!("{:#}", read_fit_cbw(&bad).unwrap_err());
        assert!(
            e.contains("ft.json: the model's output unit: unknown length unit `ft`")
                && e.contains("nothing was sent"),
            "{e}"
        );
    }
}
