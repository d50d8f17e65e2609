//! `piezo serial params` and `limits`: the firmware's parameters by name.
use std::io::Write;

use std::path::Path;

use anyhow::{bail, Context, Result};
use piezo_core::command::Command;
use piezo_core::firmware::{setting, Access, SETTINGS};

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

/// Header line of a settings file.
const HEADER: &str = "name,value,unit";

/// Writes every settable parameter (the settings table's limit and model settings) as
/// `name,value,unit` lines to `path`.
pub fn save(c: &mut Client, path: &Path, out: &mut impl Write) -> Result<()> {
    let mut text = format!("# piezo serial params --save\n{HEADER}\n");
    let mut n = 0;
    for s in SETTINGS.iter().filter(|s| s.access != Access::ReadOnly) {
        let v = c.get(s.name)?;
        text += &format!("{},{v},{}\n", s.name, s.unit);
        n += 1;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    writeln!(out, "saved {n} settings to {}", path.display())?;
    Ok(())
}

/// The settings of a `--save` file, each checked against the table: a known, settable name,
/// the table's unit, a finite value inside the table's range, no name twice.
pub fn read_settings(path: &Path) -> Result<Vec<(&'static str, f64)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
    match lines.next() {
        Some((_, h)) if h.trim() == HEADER => {}
        other => bail!(
            "{}: expected the header `{HEADER}`, found {:?}",
            path.display(),
            other.map(|(_, l)| l)
        ),
    }
    let mut v: Vec<(&'static str, f64)> = Vec::new();
    for (i, line) in lines {
        let at = || format!("{} line {}", path.display(), i + 1);
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let (name, value, unit) = match f[..] {
            [n, v, u] => (n, v, Some(u)),
            [n, v] => (n, v, None),
            _ => bail!("{}: expected `name,value,unit`, found {line:?}", at()),
        };
        let s = setting(name).with_context(|| format!("{}: unknown setting {name:?}", at()))?;
        if s.access == Access::ReadOnly {
            bail!("{}: {name} is read-only (the board decides it)", at());
        }
        if let Some(u) = unit.filter(|u| *u != s.unit) {
            bail!(
                "{}: {name} in {u}, the firmware takes {} (convert the value, not the unit)",
                at(),
                s.unit
            );
        }
        let x: f64 = value
            .parse()
            .map_err(|_| anyhow::anyhow!("{}: {name} = {value:?} is not a number", at()))?;
        if !s.accepts(x) {
            bail!(
                "{}: {name} = {x} {} outside {} .. {}",
                at(),
                s.unit,
                s.min,
                s.max
            );
        }
        if v.iter().any(|(n, _)| *n == s.name) {
            bail!("{}: {name} twice", at());
        }
        v.push((s.name, x));
    }
    if v.is_empty() {
        bail!("{}: no settings", path.display());
    }
    Ok(v)
}

/// Sets the parameters of a `--save` file: checked as a whole first (nothing is sent from a
/// file with one bad line), then the limits (widening first), the CBW model as one `cbw`
/// line, and the rest one `set` at a time.
pub fn restore(c: &mut Client, path: &Path, out: &mut impl Write) -> Result<()> {
    let all = read_settings(path)?;
    let get = |n: &str| all.iter().find(|(k, _)| *k == n).map(|(_, v)| *v);
    limits(
        c,
        get("u_min"),
        get("u_max"),
        get("slew"),
        &mut std::io::sink(),
    )?;
    let cbw = ["cbw_d", "cbw_alpha", "cbw_beta", "cbw_gamma"];
    if let [Some(d), Some(a), Some(b), Some(g)] = cbw.map(get) {
        c.send(&Command::Cbw([d, a, b, g].map(f32_of)))
            .with_context(|| format!("{}: the CBW model", path.display()))?;
    }
    let mut n = 0;
    for (name, v) in &all {
        let done = ["u_min", "u_max", "slew"].contains(name)
            || (cbw.contains(name) && cbw.iter().all(|k| get(k).is_some()));
        if !done {
            c.send(&Command::Set(name, f32_of(*v)))
                .with_context(|| format!("{}: set {name} {v}", path.display()))?;
        }
        n += 1;
    }
    writeln!(out, "restored {n} settings from {}", path.display())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A settings file with `text` in the temporary directory (one per call).
    fn file(text: &str) -> std::path::PathBuf {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static N: AtomicUsize = AtomicUsize::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!("piezo-params-{}-{n}.csv", std::process::id()));
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_settings_file_is_checked_as_a_whole() {
        let ok = file("# x\nname,value,unit\nu_max,120,V\ncbw_d,0.2,um/V\nlambda1,1500\n");
        assert_eq!(
            read_settings(&ok).unwrap(),
            vec![("u_max", 120.0), ("cbw_d", 0.2), ("lambda1", 1500.0)]
        );
        for (bad, says) in [
            ("u_max,120,V\n", "header"),
            ("name,value,unit\nkp,1,V/um\n", "unknown setting"),
            ("name,value,unit\nsample_hz,1000,Hz\n", "read-only"),
            ("name,value,unit\ncbw_d,160,nm/V\n", "convert the value"),
            ("name,value,unit\nu_max,200,V\n", "outside"),
            ("name,value,unit\nu_max,NaN,V\n", "outside"),
            ("name,value,unit\nu_max,abc,V\n", "not a number"),
            ("name,value,unit\nu_max,100,V\nu_max,90,V\n", "twice"),
            ("name,value,unit\n", "no settings"),
        ] {
            let e = format!("{:#}", read_settings(&file(bad)).unwrap_err());
            assert!(e.contains(says), "{bad:?}: {e}");
        }
    }
}
