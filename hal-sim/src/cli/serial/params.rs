//! `piezo serial params` and `limits`: the firmware's parameters by name.
use std::io::Write;

use anyhow::{bail, Result};
use piezo_core::command::Command;

use crate::serial::Client;

use super::units::f32_of;

/// Every parameter with its value and unit; the list comes from the firmware (`help` ends
/// with `params: <names>`), the units from the core's settings table.
pub fn print_params(c: &mut Client, out: &mut impl Write) -> Result<()> {
    let help = c.send(&Command::Help)?;
    let params: Vec<String> = help
        .details
        .split_once("params:")
        .map(|(_, p)| p.split_whitespace().map(str::to_string).collect())
        .unwrap_or_default();
    if params.is_empty() {
        bail!(
            "`help` lists no parameters: {:?} (expected `... params: <names>`)",
            help.reply_line()
        );
    }
    for p in &params {
        let v = c.get(p)?;
        // The unit from the core's settings table (a firmware newer than this host may
        // name one it does not know).
        let unit = piezo_core::firmware::setting(p).map_or("", |s| s.unit);
        writeln!(out, "{p:<15} {v} {unit}")?;
    }
    Ok(())
}

/// Sets the given output limits (V, V/s), then prints all three.
pub fn limits(
    c: &mut Client,
    u_min: Option<f64>,
    u_max: Option<f64>,
    slew: Option<f64>,
    out: &mut impl Write,
) -> Result<()> {
    // Widen before narrowing so the firmware's u_min < u_max check holds in between.
    let mut sets = Vec::new();
    if let Some(v) = u_max {
        sets.push(("u_max", v));
    }
    if let Some(v) = u_min {
        sets.push(("u_min", v));
    }
    if let (Some(_), Some(hi)) = (u_min, u_max) {
        // A new maximum at or below the present minimum needs the minimum first.
        if hi <= c.get("u_min")? {
            sets.reverse();
        }
    }
    if let Some(v) = slew {
        sets.push(("slew", v));
    }
    for (p, v) in sets {
        c.send(&Command::Set(p, f32_of(v)))?;
    }
    let lo = c.get("u_min")?;
    let hi = c.get("u_max")?;
    let sl = c.get("slew")?;
    writeln!(
        out,
        "output {lo} V .. {hi} V, slew limit {sl} V/s ({} V/ms)",
        sl / 1e3
    )?;
    Ok(())
}
