//! What the console's buttons do on the link's thread, through the same code as `piezo
//! serial` (its settings check, bode and identify) and the same client.
use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Parser;
use piezo_core::command::{Command, Shape};
use piezo_core::firmware::{Access, Ctl, OnChip, SETTINGS};
use serde::Deserialize;
use serde_json::{json, Value};

use crate::cli::serial::bode::{self, BodeArgs};
use crate::cli::serial::identify::{self, IdentifyArgs};
use crate::cli::serial::params;
use crate::cli::serial::units::f32_of;
use crate::serial::lines::checked_line;
use crate::serial::{Client, SerialError};

/// A firmware's refusal as the page shows it: the command, `err N` and the error's name.
pub fn refusal(e: &anyhow::Error) -> Value {
    for c in e.chain() {
        if let Some(SerialError::Firmware {
            command,
            code,
            message,
        }) = c.downcast_ref::<SerialError>()
        {
            let name = (*code)
                .and_then(crate::serial::error::known_error)
                .map(|e| format!("{e:?}"));
            return json!({"error": format!("{e:#}"), "command": command, "code": code,
                          "message": message, "name": name});
        }
    }
    json!({"error": format!("{e:#}")})
}

/// Every setting of the table with the firmware's value (`get`).
pub fn settings(c: &mut Client) -> Result<Value> {
    let mut values = serde_json::Map::new();
    for s in SETTINGS.iter() {
        values.insert(s.name.into(), json!(c.get(s.name)?));
    }
    Ok(Value::Object(values))
}

/// The settings table for the page: name, unit, meaning, access, default, range.
pub fn table() -> Value {
    SETTINGS
        .iter()
        .map(|s| {
            json!({
                "name": s.name, "unit": s.unit, "about": s.about,
                "settable": s.access != Access::ReadOnly,
                "default": if s.default.is_finite() { json!(s.default) } else { Value::Null },
                "min": if s.min.is_finite() { json!(s.min) } else { Value::Null },
                "max": if s.max.is_finite() { json!(s.max) } else { Value::Null },
            })
        })
        .collect()
}

/// Checks one setting against the table (as `piezo serial set` does); the error text, or
/// the checked name.
pub fn check_setting(name: &str, value: f64) -> Result<&'static str, String> {
    params::check(name, value, None).map(|s| s.name)
}

/// `set` then `get`: the value the firmware took.
pub fn set(c: &mut Client, name: &'static str, value: f64) -> Result<Value> {
    c.send(&Command::Set(name, f32_of(value)))?;
    Ok(json!({"name": name, "value": c.get(name)?}))
}

/// `save`, `load` or `defaults` on the board's settings flash.
pub fn flash(c: &mut Client, op: &str) -> Result<Value> {
    let cmd = match op {
        "save" => Command::Save,
        "load" => Command::Load,
        "defaults" => Command::Defaults,
        other => bail!("unknown settings operation `{other}` (save, load, defaults)"),
    };
    let r = c.send(&cmd)?;
    Ok(json!({"reply": r.reply_line()}))
}

/// A settings file (`piezo serial params --save`'s) sent as a whole (checked already).
pub fn restore(c: &mut Client, all: Vec<(&'static str, f64)>) -> Result<Value> {
    params::apply(c, &all)?;
    Ok(json!({"restored": all.len()}))
}

/// The settings as a `params --save` file.
pub fn settings_file(c: &mut Client) -> Result<Value> {
    let (text, n) = params::settings_file(c)?;
    Ok(json!({"text": text, "count": n}))
}

/// `ff` then `mode` (the replies, or the first refusal).
pub fn mode(c: &mut Client, law: &str, ff: Option<&str>) -> Result<Value> {
    let mut replies = Vec::new();
    if let Some(ff) = ff.filter(|f| !f.is_empty()) {
        replies.push(c.send(&Command::Feedforward(ff))?.reply_line());
    }
    replies.push(c.send(&Command::Mode(law))?.reply_line());
    Ok(json!({"replies": replies}))
}

/// A waveform of the Wave panel, in the units of `piezo serial wave`.
#[derive(Debug, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case")]
pub enum Wave {
    Sine {
        amp_um: f64,
        freq_hz: f64,
        offset_um: f64,
    },
    Triangle {
        amp_um: f64,
        freq_hz: f64,
        offset_um: f64,
    },
    Square {
        amp_um: f64,
        freq_hz: f64,
        offset_um: f64,
    },
    Hold {
        position_um: f64,
    },
    Off,
    Prbs {
        low_um: f64,
        high_um: f64,
        order: u8,
        bit_hz: f64,
        seed: u32,
    },
    Chirp {
        amp_um: f64,
        f0_hz: f64,
        f1_hz: f64,
        duration_s: f64,
        offset_um: f64,
    },
    Multisine {
        amp_um: f64,
        f0_hz: f64,
        harmonics: u8,
        offset_um: f64,
        seed: u32,
    },
    Raster {
        x_span_um: f64,
        y_span_um: f64,
        lines: u16,
        line_hz: f64,
        xc_um: f64,
        yc_um: f64,
    },
}

impl Wave {
    /// The protocol's command (checked with the firmware's parser when sent).
    pub fn command(&self) -> Command<'static> {
        let f = f32_of;
        let periodic = |shape, amp_um, freq_hz, offset_um| Command::Wave {
            shape,
            amp_um: f(amp_um),
            freq_hz: f(freq_hz),
            offset_um: f(offset_um),
        };
        match *self {
            Wave::Sine {
                amp_um,
                freq_hz,
                offset_um,
            } => periodic(Shape::Sine, amp_um, freq_hz, offset_um),
            Wave::Triangle {
                amp_um,
                freq_hz,
                offset_um,
            } => periodic(Shape::Triangle, amp_um, freq_hz, offset_um),
            Wave::Square {
                amp_um,
                freq_hz,
                offset_um,
            } => periodic(Shape::Square, amp_um, freq_hz, offset_um),
            Wave::Hold { position_um } => Command::WaveHold(f(position_um)),
            Wave::Off => Command::WaveOff,
            Wave::Prbs {
                low_um,
                high_um,
                order,
                bit_hz,
                seed,
            } => Command::WavePrbs {
                low_um: f(low_um),
                high_um: f(high_um),
                order,
                bit_hz: f(bit_hz),
                seed,
            },
            Wave::Chirp {
                amp_um,
                f0_hz,
                f1_hz,
                duration_s,
                offset_um,
            } => Command::WaveChirp {
                amp_um: f(amp_um),
                f0_hz: f(f0_hz),
                f1_hz: f(f1_hz),
                duration_s: f(duration_s),
                offset_um: f(offset_um),
            },
            Wave::Multisine {
                amp_um,
                f0_hz,
                harmonics,
                offset_um,
                seed,
            } => Command::WaveMultisine {
                amp_um: f(amp_um),
                f0_hz: f(f0_hz),
                harmonics,
                offset_um: f(offset_um),
                seed,
            },
            Wave::Raster {
                x_span_um,
                y_span_um,
                lines,
                line_hz,
                xc_um,
                yc_um,
            } => Command::WaveRaster {
                span_um: [f(x_span_um), f(y_span_um)],
                lines,
                line_hz: f(line_hz),
                center_um: [f(xc_um), f(yc_um)],
            },
        }
    }
}

/// Starts `w`. A one-axis wave the firmware would refuse is refused here, before anything
/// is sent: its line runs first on the firmware's own executor in this process (a scratch
/// control state at the board's `sample_hz`; the wave checks depend on nothing else). The
/// raster needs two axes, which only an xy board has: the board decides.
pub fn wave(c: &mut Client, w: &Wave) -> Result<Value> {
    let cmd = w.command();
    if !matches!(w, Wave::Raster { .. }) {
        let line = checked_line(&cmd)?;
        let hz = c.get("sample_hz")?;
        let mut dry = Ctl::<OnChip>::new(piezo_core::firmware::c(hz));
        let reply = dry.answer(&line);
        if reply.as_str().starts_with("err") {
            bail!(
                "`{line}`: {} (the firmware's own check at {hz} Hz, run here first; nothing sent)",
                reply.as_str()
            );
        }
    }
    let r = c.send(&cmd)?;
    Ok(json!({"reply": r.reply_line()}))
}

/// Stop: no waveform, open loop with the linear scaling, holding the reference that scaling
/// maps to 0 V (`offset_um`): the output slews to the pipeline's safe voltage (0 V, the DAC's
/// safe code) at the slew limit and stays there. A command that fails still lets the rest
/// run (the first refusal is reported).
pub fn stop(c: &mut Client) -> Result<Value> {
    let mut replies = Vec::new();
    let mut first_err: Option<anyhow::Error> = None;
    for k in 0..4 {
        let r = match k {
            0 => c.send(&Command::WaveOff),
            1 => c.send(&Command::Mode("open-loop")),
            2 => c.send(&Command::Feedforward("linear")),
            _ => c
                .get("offset_um")
                .and_then(|off| c.send(&Command::WaveHold(f32_of(off)))),
        };
        match r {
            Ok(r) => replies.push(r.reply_line()),
            Err(e) => {
                first_err.get_or_insert(e.into());
            }
        }
    }
    match first_err {
        Some(e) => Err(e),
        None => Ok(json!({"replies": replies})),
    }
}

/// One raw line; its data lines and reply.
pub fn raw(c: &mut Client, line: &str) -> Result<Value> {
    let r = c.raw(line)?;
    Ok(json!({"data": r.data, "reply": r.reply_line()}))
}

/// A bode request from the Tools panel (`piezo serial bode`'s options).
#[derive(Debug, Deserialize)]
pub struct BodeReq {
    #[serde(rename = "loop")]
    pub loop_kind: String,
    pub excitation: String,
    pub amplitude_um: f64,
    pub offset_um: f64,
    pub averages: u32,
    pub f_max_hz: Option<f64>,
    /// Frames per record (`rec len`; the scope leaves its own): 1024 unless given.
    pub frames: Option<usize>,
}

impl BodeReq {
    /// `piezo serial bode`'s arguments (checked by its parser).
    pub fn args(&self) -> Result<BodeArgs> {
        #[derive(Parser)]
        struct P {
            #[command(flatten)]
            a: BodeArgs,
        }
        let mut argv = vec![
            "bode".to_string(),
            format!("--loop={}", self.loop_kind),
            format!("--excitation={}", self.excitation),
            format!("--amplitude={}um", self.amplitude_um),
            format!("--offset={}um", self.offset_um),
            format!("--averages={}", self.averages),
            "--out=unused.csv".into(),
        ];
        if let Some(f) = self.f_max_hz {
            argv.push(format!("--f-max={f}Hz"));
        }
        Ok(P::try_parse_from(argv)
            .map_err(|e| anyhow::anyhow!("{}", e.render()))?
            .a)
    }
}

/// `bode` on records of `frames`: the response, the resonance and the notch suggested for it.
pub fn bode(c: &mut Client, a: &BodeArgs, frames: usize) -> Result<Value> {
    c.send(&Command::Rec(piezo_core::command::RecCmd::Stop))?;
    c.send(&Command::Rec(piezo_core::command::RecCmd::Length(Some(
        frames,
    ))))?;
    let mut log = Vec::new();
    let m = bode::measure(c, a, &mut log)?;
    let res = bode::find_resonance(&m.lines);
    let notch = res.as_ref().map(bode::suggest_notch);
    Ok(json!({
        "what": m.what,
        "unit": m.unit,
        "f_hz": m.lines.iter().map(|l| l.f_hz).collect::<Vec<_>>(),
        "magnitude_db": m.lines.iter().map(|l| 20.0 * l.h.norm().log10()).collect::<Vec<_>>(),
        "phase_deg": m.phase_deg(),
        "coherence": m.lines.iter().map(|l| l.coherence).collect::<Vec<_>>(),
        "resonance": res.map(|r| json!({"f_hz": r.f_hz, "prominence_db": r.prominence_db, "q": r.q})),
        "notch": notch.map(|(hz, q)| json!({"notch_hz": hz, "notch_q": q})),
        "log": String::from_utf8_lossy(&log),
    }))
}

/// `identify` with its defaults into `dir`; the progress per phase goes to `progress`.
pub fn identify(c: &mut Client, dir: PathBuf, progress: Box<dyn FnMut(&str)>) -> Result<Value> {
    #[derive(Parser)]
    struct P {
        #[command(flatten)]
        a: IdentifyArgs,
    }
    let a = P::try_parse_from(["identify".into(), format!("--out={}", dir.display())])
        .map_err(|e| anyhow::anyhow!("{}", e.render()))?
        .a;
    identify::progress_to(Some(progress));
    let mut log = Vec::new();
    let r = identify::run(c, &a, &mut log);
    identify::progress_to(None);
    let r = r?;
    Ok(json!({
        "rmse_before_um": r.rmse_before_um,
        "rmse_after_um": r.rmse_after_um,
        "cbw": r.cbw,
        "cbw_before": r.cbw_before,
        "held_back_rmse_um": r.held_back_rmse_um,
        "diagnosis": r.diagnosis,
        "log": String::from_utf8_lossy(&log),
    }))
}
