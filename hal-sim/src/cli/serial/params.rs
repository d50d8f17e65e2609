//! `piezo serial params` and `limits`: the firmware's parameters by name.
use std::io::Write;

use std::path::Path;

use anyhow::{bail, Context, Result};
use piezo_core::command::Command;
use piezo_core::firmware::{setting, Access, Setting, SETTINGS};

use crate::serial::Client;

use super::units::{f32_of, parse_hz, parse_seconds, parse_um, parse_volts, parse_volts_per_s};

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
    let (text, n) = settings_file(c)?;
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    writeln!(out, "saved {n} settings to {}", path.display())?;
    Ok(())
}

/// The text of a settings file (`name,value,unit` of every settable parameter, read from
/// the firmware) and the number of settings in it.
pub fn settings_file(c: &mut Client) -> Result<(String, usize)> {
    let mut text = format!("# piezo serial params --save\n{HEADER}\n");
    let mut n = 0;
    for s in settable() {
        let v = c.get(s.name)?;
        text += &format!("{},{v},{}\n", s.name, s.unit);
        n += 1;
    }
    Ok((text, n))
}

/// The settings of a `--save` file, each checked against the table: a known, settable name,
/// the table's unit, a finite value inside the table's range, no name twice.
pub fn read_settings(path: &Path) -> Result<Vec<(&'static str, f64)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_settings(&text, &path.display().to_string())
}

/// [`read_settings`] of a file's text; `origin` names it in the errors.
pub fn parse_settings(text: &str, origin: &str) -> Result<Vec<(&'static str, f64)>> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
    match lines.next() {
        Some((_, h)) if h.trim() == HEADER => {}
        other => bail!(
            "{}: expected the header `{HEADER}`, found {:?}",
            origin,
            other.map(|(_, l)| l)
        ),
    }
    let mut v: Vec<(&'static str, f64)> = Vec::new();
    for (i, line) in lines {
        let at = || format!("{} line {}", origin, i + 1);
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let (name, value, unit) = match f[..] {
            [n, v, u] => (n, v, Some(u)),
            [n, v] => (n, v, None),
            _ => bail!("{}: expected `name,value,unit`, found {line:?}", at()),
        };
        let x: f64 = value
            .parse()
            .map_err(|_| anyhow::anyhow!("{}: {name} = {value:?} is not a number", at()))?;
        let s = check(name, x, unit).map_err(|e| anyhow::anyhow!("{}: {e}", at()))?;
        if v.iter().any(|(n, _)| *n == s.name) {
            bail!("{}: {name} twice", at());
        }
        v.push((s.name, x));
    }
    if v.is_empty() {
        bail!("{}: no settings", origin);
    }
    Ok(v)
}

/// Sets the parameters of a `--save` file: checked as a whole first (nothing is sent from a
/// file with one bad line), then the limits (widening first), the CBW model as one `cbw`
/// line, and the rest one `set` at a time.
pub fn restore(c: &mut Client, path: &Path, out: &mut impl Write) -> Result<()> {
    let all = read_settings(path)?;
    apply(c, &all).with_context(|| path.display().to_string())?;
    writeln!(
        out,
        "restored {} settings from {}",
        all.len(),
        path.display()
    )?;
    Ok(())
}

/// Sends checked settings: the limits first (widening first), the CBW model as one `cbw`
/// line when all four are there, the rest one `set` at a time.
pub fn apply(c: &mut Client, all: &[(&'static str, f64)]) -> Result<()> {
    let get = |n: &str| all.iter().find(|(k, _)| *k == n).map(|(_, v)| *v);
    limits(
        c,
        get("u_min"),
        get("u_max"),
        get("slew"),
        &mut std::io::sink(),
    )?;
    let cbw = ["cbw_d", "cbw_alpha", "cbw_beta", "cbw_gamma"];
    let whole_cbw = cbw.iter().all(|k| get(k).is_some());
    if let [Some(d), Some(a), Some(b), Some(g)] = cbw.map(get) {
        c.send(&Command::Cbw([d, a, b, g].map(f32_of)))
            .context("the CBW model")?;
    }
    for (name, v) in all {
        if !(["u_min", "u_max", "slew"].contains(name) || (whole_cbw && cbw.contains(name))) {
            c.send(&Command::Set(name, f32_of(*v)))
                .with_context(|| format!("set {name} {v}"))?;
        }
    }
    Ok(())
}

/// The settings table's check of one value: a known, settable name, the table's unit (if
/// one is given), a finite value inside the table's range.
pub fn check(name: &str, x: f64, unit: Option<&str>) -> Result<&'static Setting, String> {
    let s = setting(name).ok_or_else(|| {
        format!(
            "unknown setting {name:?} (settable: {})",
            settable().map(|s| s.name).collect::<Vec<_>>().join(", ")
        )
    })?;
    if s.access == Access::ReadOnly {
        return Err(format!("{name} is read-only (the board decides it)"));
    }
    if let Some(u) = unit.filter(|u| *u != s.unit) {
        return Err(format!(
            "{name} in {u}, the firmware takes {} (convert the value, not the unit)",
            s.unit
        ));
    }
    if !s.accepts(x) {
        return Err(format!(
            "{name} = {x} {} outside {} .. {} ({})",
            s.unit, s.min, s.max, s.about
        ));
    }
    Ok(s)
}

/// The settable rows of the table (limits and model settings).
fn settable() -> impl Iterator<Item = &'static Setting> {
    SETTINGS.iter().filter(|s| s.access != Access::ReadOnly)
}

/// `NAME=VALUE` from the command line: the value a number in the setting's unit, or with a
/// unit of the same quantity (`slew=20V/ms`, `notch_hz=2.5kHz`, `hgo_eps=200us`).
pub fn parse_assignment(arg: &str) -> Result<(&'static str, f64)> {
    let (name, value) = arg
        .split_once('=')
        .with_context(|| format!("`{arg}`: use NAME=VALUE (e.g. slew=20V/ms)"))?;
    let (name, value) = (name.trim(), value.trim());
    let unit = setting(name).map_or("", |s| s.unit);
    let x = match unit {
        "V" => parse_volts(value),
        "V/s" => parse_volts_per_s(value),
        "Hz" => parse_hz(value),
        "um" => parse_um(value),
        "s" => parse_seconds(value),
        u => {
            let num = value
                .strip_suffix(u)
                .filter(|_| !u.is_empty())
                .unwrap_or(value);
            num.trim()
                .parse::<f64>()
                .map_err(|_| format!("`{value}`: not a number in {u}"))
        }
    }
    .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    let s = check(name, x, None).map_err(anyhow::Error::msg)?;
    Ok((s.name, x))
}

/// `piezo serial set`: every assignment checked against the settings table before any is
/// sent, then sent in [`apply`]'s order; prints the settings' values after.
pub fn set(c: &mut Client, args: &[String], out: &mut impl Write) -> Result<()> {
    let mut all: Vec<(&'static str, f64)> = Vec::new();
    for a in args {
        let (name, x) = parse_assignment(a)?;
        if all.iter().any(|(n, _)| *n == name) {
            bail!("{name} given twice");
        }
        all.push((name, x));
    }
    apply(c, &all)?;
    for (name, _) in &all {
        let unit = setting(name).map_or("", |s| s.unit);
        writeln!(out, "{name:<15} {} {unit}", c.get(name)?)?;
    }
    Ok(())
}

/// The settings table as help text: name, unit, default, range, meaning.
pub fn table_help() -> String {
    let mut t = String::from("Settings (NAME [unit] default, range: meaning):\n");
    for s in settable() {
        t += &format!(
            "  {:<12} [{}] {}, {} .. {}: {}\n",
            s.name, s.unit, s.default, s.min, s.max, s.about
        );
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn assignments_take_the_tables_units_and_ranges() {
        let ok = |a: &str| parse_assignment(a).unwrap();
        assert_eq!(ok("slew=20V/ms"), ("slew", 20_000.0));
        assert_eq!(ok("slew=20000"), ("slew", 20_000.0));
        assert_eq!(ok("notch_hz=2.5kHz"), ("notch_hz", 2_500.0));
        assert!((ok("hgo_eps=200us").1 - 2e-4).abs() < 1e-12);
        assert_eq!(ok("u_max = 120V"), ("u_max", 120.0));
        assert_eq!(ok("pid_ki=3000V/(um s)"), ("pid_ki", 3000.0));
        let err = |a: &str| parse_assignment(a).unwrap_err().to_string();
        assert!(
            err("u_max=200V").contains("outside 0 .. 150"),
            "{}",
            err("u_max=200V")
        );
        assert!(err("warp=1").contains("unknown setting") && err("warp=1").contains("pid_kp"));
        assert!(err("sample_hz=1").contains("read-only"));
        assert!(
            err("slew=20V").contains("unknown unit `V`"),
            "{}",
            err("slew=20V")
        );
        assert!(err("slew").contains("NAME=VALUE"));
        assert!(
            err("notch_q=nan").contains("outside"),
            "{}",
            err("notch_q=nan")
        );
        assert!(table_help().contains("notch_hz") && !table_help().contains("sample_hz"));
    }

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
